"""Issue 14: the layers hold (import-linter, no exceptions), nothing imports
in a cycle, the models import no estimator or file code, and the package
installs under one name."""
import ast
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _graph():
    grimp = pytest.importorskip("grimp")
    return grimp.build_graph("odomgraph")


def test_the_layer_contract_is_kept():
    import shutil
    import subprocess
    exe = Path(sys.executable).parent / "lint-imports"
    if not exe.exists():
        exe = shutil.which("lint-imports")
    assert exe, "import-linter is in the test extra"
    res = subprocess.run([str(exe), "--config", str(ROOT / "pyproject.toml"), "--no-cache"], cwd=ROOT,
                         capture_output=True, text=True)
    assert res.returncode == 0 and "Contracts: 1 kept, 0 broken." in res.stdout, res.stdout[-2000:]


def test_no_module_imports_itself_through_others():
    g = _graph()
    mods = sorted(g.modules)
    state: dict[str, int] = {}
    cycle: list[str] = []

    def visit(m, path):
        state[m] = 1
        for n in sorted(g.find_modules_directly_imported_by(m)):
            if not n.startswith("odomgraph") or n in ("odomgraph",):
                continue
            if state.get(n) == 1:
                cycle.extend(path[path.index(n):] + [m, n] if n in path else [m, n])
                return True
            if state.get(n) is None and visit(n, path + [m]):
                return True
        state[m] = 2
        return False
    sys.setrecursionlimit(10_000)
    for m in mods:
        if m != "odomgraph" and state.get(m) is None and visit(m, []):
            break
    assert cycle == [], " -> ".join(cycle)


ALLOWED_IN_MODELS = {"__future__", "math", "dataclasses", "typing", "functools", "numpy", "gtsam"}


def test_the_models_import_only_numpy_gtsam_and_each_other():
    for f in sorted((ROOT / "factors").glob("*.py")):
        tree = ast.parse(f.read_text(), str(f))
        for node in ast.walk(tree):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module] if isinstance(node, ast.ImportFrom) and node.level == 0 else [])
            for n in names:
                top = n.split(".")[0]
                assert top in ALLOWED_IN_MODELS or n.startswith("odomgraph.factors") or n == "odomgraph.state", \
                    f"{f.name} imports {n}"


def test_nothing_imports_a_top_level_factors_package():
    offenders = []
    for f in [*ROOT.glob("odomgraph/**/*.py"), *ROOT.glob("factors/*.py"), *ROOT.glob("tests/*.py"),
              *ROOT.glob("benchmarks/*.py")]:
        for node in ast.walk(ast.parse(f.read_text(), str(f))):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").split(".")[0] == "factors":
                offenders.append(f"{f.relative_to(ROOT)}:{node.lineno}")
            if isinstance(node, ast.Import) and any(a.name.split(".")[0] == "factors" for a in node.names):
                offenders.append(f"{f.relative_to(ROOT)}:{node.lineno}")
    assert offenders == []


def test_every_package_is_installed_and_factors_as_odomgraph_factors():
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    on_disk = {".".join(p.parent.relative_to(ROOT).parts) for p in ROOT.glob("odomgraph/**/__init__.py")}
    assert set(cfg["packages"]) == on_disk | {"odomgraph.factors"}
    assert cfg["package-dir"] == {"odomgraph.factors": "factors"}
    import odomgraph.factors.motion as motion
    assert Path(motion.__file__).parent == ROOT / "factors"


def test_robot_toml_writer_escapes_what_tomllib_reads_back():
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from odomgraph.io.robot import dump_toml
    text = st.text(st.characters(blacklist_categories=("Cs",)), max_size=20)
    value = st.one_of(st.booleans(), st.floats(allow_nan=False, allow_infinity=False), text,
                      st.lists(st.floats(allow_nan=False, allow_infinity=False), max_size=3))

    @settings(max_examples=200, deadline=None, derandomize=True)
    @given(st.dictionaries(st.from_regex(r"[a-z_][a-z0-9_]{0,8}", fullmatch=True), value, min_size=1, max_size=4))
    def roundtrip(body):
        back = tomllib.loads(dump_toml({"calibration": body}))["calibration"]
        assert back == {k: ([float(x) for x in v] if isinstance(v, list) else
                            v if isinstance(v, (bool, str)) else float(v)) for k, v in body.items()}
    roundtrip()
