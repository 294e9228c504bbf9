"""Issue 18: the READMEs' results blocks are what benchmarks/results/ say."""
import re

from benchmarks.readme_blocks import BLOCK, BLOCKS, READMES, differing, render


def test_readme_blocks_are_generated_from_the_results():
    assert differing() == [], "run: python -m benchmarks.readme_blocks"


def test_every_block_is_used_and_every_marker_is_known():
    used = {m.group("name") for p in READMES for m in BLOCK.finditer(p.read_text(encoding="utf-8"))}
    assert used == set(BLOCKS)
    openers = {n for p in READMES for n in re.findall(r"<!-- results:([a-z0-9_]+) -->", p.read_text())}
    assert openers == used    # an opener without its closer would not be matched


def test_render_rewrites_only_inside_blocks(tmp_path):
    text = "before 1.23\n<!-- results:ekf_throughput -->\nstale 9.99\n<!-- /results:ekf_throughput -->\nafter 4.56\n"
    new = render(text)
    assert new.startswith("before 1.23\n<!-- results:ekf_throughput -->\n- **Throughput:** ")
    assert new.endswith("\n<!-- /results:ekf_throughput -->\nafter 4.56\n") and "stale 9.99" not in new
    assert render(new) == new
