"""Issue 18: the READMEs' results blocks are what benchmarks/results/ say."""
import re
from pathlib import Path

import pytest

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


def test_every_block_renders_from_other_results_and_follows_them(tmp_path):
    """A fresh benchmark run changes the values, not the structure: every
    block must render from such results, and its text must change with them
    (a number written into a render function would not)."""
    import csv
    import json

    from benchmarks.readme_blocks import RESULTS
    count = [0]

    keep = ("machine", "sources", "targets", "gps_sigma", "factor", "sensor_sigma", "duration")   # configuration

    def nudge(v):   # every measured float moves by a different factor in 0.95..1.05
        if isinstance(v, dict):
            return {k: (v[k] if k in keep else nudge(v[k])) for k in v}
        if isinstance(v, list):
            return [nudge(x) for x in v]
        if isinstance(v, float):
            count[0] += 1
            return v * (1 + 0.05 * ((count[0] * 7919) % 13 - 6) / 6)
        return v
    for p in RESULTS.glob("*.json"):
        (tmp_path / p.name).write_text(json.dumps(nudge(json.loads(p.read_text()))))
    (tmp_path / "montecarlo").mkdir()
    for p in (RESULTS / "montecarlo").glob("*_results.csv"):
        with p.open(newline="") as f:
            rows = list(csv.DictReader(f))
        for r in rows:
            for k in r:
                if k.startswith("median_rms_") and r[k]:
                    r[k] = str(nudge(float(r[k])))
        with (tmp_path / "montecarlo" / p.name).open("w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    same = [name for name, block in BLOCKS.items() if block(tmp_path) == block(RESULTS)]
    assert same == [], f"blocks that did not follow their results: {same}"


def test_the_python_api_example_runs_and_its_numbers_hold(tmp_path, monkeypatch):
    """The README's Python API block, run as written (in a scratch directory)."""
    from pathlib import Path

    import numpy as np
    text = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    block = text.split("<!-- python-api -->", 1)[1].split("<!-- /python-api -->", 1)[0]
    code = block.split("```python", 1)[1].split("```", 1)[0]
    monkeypatch.chdir(tmp_path)
    ns: dict = {}
    exec(compile(code, "README.md (Python API)", "exec"), ns)
    log, est, track = ns["log"], ns["est"], ns["track"]
    true_track = log.truth_scales[2]
    assert abs(track["value"] - true_track) < 3 * track["sigma"] and track["observable"]
    assert list(ns["rows"]) == list(est.columns) and np.array_equal(ns["rows"]["sigma_x"], est.sigma[:, 0])
    robot = ns["robot"]
    assert robot.track_width == pytest.approx(log.robot.track_width * true_track, rel=0.01)
    assert ns["report"]["held_out"]["calibrated"] < ns["report"]["held_out"]["nominal"]
    assert 0.002 < ns["batch_rms"] < 0.025          # measured 0.0093 m


def test_no_results_file_is_older_than_the_code_it_ran():
    """Every results JSON records the code hash of each source its run
    imported (benchmarks._common.sources); a change to any of them since
    makes it stale: re-run it (python -m benchmarks.run_all --stale)."""
    from benchmarks.stale import stale
    assert stale() == {}, "stale results; run: python -m benchmarks.run_all --stale"


def test_a_benchmark_records_the_code_its_pool_workers_ran(tmp_path, monkeypatch):
    """smoother_scaling's log lengths run in spawned processes, so its own
    process imports none of the estimators; the record must still name
    them (static_sources), and an empty record counts as stale."""
    import json

    import benchmarks.stale as st
    from benchmarks._common import code_hash, static_sources
    root = Path(__file__).resolve().parent.parent
    rec = static_sources(root / "benchmarks" / "smoother_scaling.py")
    for f in ("odomgraph/estimators/incremental.py", "odomgraph/estimators/batch.py", "factors/encoder.py",
              "odomgraph/sim/simulate.py"):
        assert rec[f] == code_hash(root / f)
    assert not any(k.startswith(("benchmarks", "tests")) for k in rec)
    fuzz = static_sources(root / "tests" / "test_fuzz.py")
    assert "odomgraph/cli.py" in fuzz and "odomgraph/io/csvtable.py" in fuzz
    # benchmarks.online runs its streams as `python -c <code string>`: the
    # string's imports count (before, online.json never went stale)
    online = static_sources(root / "benchmarks" / "online.py")
    for f in ("odomgraph/online.py", "odomgraph/io/stream.py", "odomgraph/estimators/incremental.py"):
        assert online[f] == code_hash(root / f)
    res = tmp_path / "benchmarks" / "results"
    res.mkdir(parents=True)
    (res / "x.json").write_text(json.dumps({"sources": {}, "sources_kind": "code"}))
    (res / "y.json").write_text(json.dumps(
        {"sources": {"factors/encoder.py": "0" * 16}, "sources_kind": "code"}))
    (res / "z.json").write_text(json.dumps(
        {"sources": {"factors/encoder.py": code_hash(root / "factors/encoder.py")}, "sources_kind": "code"}))
    monkeypatch.setattr(st, "RESULTS", res)
    (tmp_path / "factors").symlink_to(root / "factors")
    assert st.stale() == {"x.json": ["no record of the code it ran"], "y.json": ["factors/encoder.py"]}
