"""The vendored plotly.js bundle: the file its README names, with its licence,
shipped as package data, and the only plotly.js the reports inline."""
import hashlib
import re
import tomllib
from pathlib import Path

from odomgraph.analysis.interactive import PLOTLY_BUNDLE, plotly_js

ROOT = Path(__file__).resolve().parent.parent
ASSETS = ROOT / "odomgraph" / "analysis" / "assets"


def test_the_bundle_is_the_one_its_readme_names():
    readme = (ASSETS / "README.md").read_text()
    sha = re.search(r"sha256\s+`([0-9a-f]{64})`", readme).group(1)
    data = (ASSETS / PLOTLY_BUNDLE).read_bytes()
    assert hashlib.sha256(data).hexdigest() == sha
    version = re.search(r"version (\d+\.\d+\.\d+)", readme).group(1)
    assert f"plotly.js (cartesian - minified) v{version}" in data[:200].decode()
    assert "MIT License" in (ASSETS / "plotly-LICENSE.txt").read_text()
    assert plotly_js() == data.decode("utf-8")


def test_the_bundle_is_package_data_and_plotly_is_no_dependency():
    py = tomllib.loads((ROOT / "pyproject.toml").read_text())
    globs = py["tool"]["setuptools"]["package-data"]["odomgraph.analysis"]
    for f in (PLOTLY_BUNDLE, "plotly-LICENSE.txt", "README.md"):
        assert any(Path("assets", f).match(g) for g in globs), f
    assert not any(d.startswith("plotly") for d in py["project"]["dependencies"])
    # The figures use only traces this partial bundle holds.
    src = "".join((ROOT / "odomgraph" / "analysis" / f).read_text() for f in ("interactive.py", "montecarlo_report.py"))
    traces = set(re.findall(r'"type": "(\w+)"', src)) - {"line", "rect", "category", "log"}  # shapes, axis types
    assert traces == {"scatter", "heatmap"}
