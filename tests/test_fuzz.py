"""The fuzz suite on a fixed seed (about a minute): log files, robot.toml,
importer inputs and CLI options. ``benchmarks/fuzz.py`` runs it longer
(ODOMGRAPH_FUZZ_SCALE multiplies the examples and draws a random seed).
See tests/fuzzing.py for the property."""
import json
import os
import tempfile
from collections import Counter
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from odomgraph.errors import LogFormatError, OdomgraphError
from odomgraph.io.log import read_log
from tests import fuzzing as fz

DATA = Path(__file__).parent / "data"
SCALE = float(os.environ.get("ODOMGRAPH_FUZZ_SCALE", "1"))
FIXED = settings(derandomize=SCALE == 1, deadline=None, database=None, suppress_health_check=list(HealthCheck))
TALLY: Counter = Counter()
ERRORS: Counter = Counter()


def cases(n: int) -> settings:
    return settings(FIXED, max_examples=max(1, int(n * SCALE)))


@pytest.fixture(scope="module", autouse=True)
def report():
    """With ODOMGRAPH_FUZZ_REPORT set, write the tally of outcomes there (benchmarks/fuzz.py)."""
    yield
    path = os.environ.get("ODOMGRAPH_FUZZ_REPORT")
    if path:
        Path(path).write_text(json.dumps({"outcomes": dict(sorted(TALLY.items())),
                                          "errors": dict(ERRORS.most_common())}, indent=1) + "\n")


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    return fz.make_base_log(tmp_path_factory.mktemp("fuzzbase") / "log")


@cases(200)
@given(mutations=st.lists(fz.csv_mutation(), min_size=1, max_size=3))
def test_the_log_reader_returns_a_log_or_one_error_line(base, mutations):
    with tempfile.TemporaryDirectory() as tmp:
        log = fz.fresh_copy(base, Path(tmp) / "log")
        for name, apply in mutations:
            (log / name).write_bytes(apply((log / name).read_bytes()))
        try:
            read_log(log)
            TALLY["reader: ok"] += 1
        except LogFormatError as exc:
            assert "\n" not in str(exc) and "\r" not in str(exc)
            TALLY["reader: error"] += 1
            ERRORS[exc.problem.split("(")[0].split("'")[0].strip()[:60]] += 1


@cases(80)
@given(mutations=st.lists(fz.csv_mutation(), min_size=1, max_size=2),
       method=st.sampled_from(["ekf", "batch", "isam2", "fixed-lag"]))
def test_estimate_on_damaged_logs_keeps_the_contract(base, mutations, method):
    with tempfile.TemporaryDirectory() as tmp:
        log = fz.fresh_copy(base, Path(tmp) / "log")
        for name, apply in mutations:
            (log / name).write_bytes(apply((log / name).read_bytes()))
        TALLY[f"damaged log, {method}: " + fz.run_estimate(log, Path(tmp) / "out", ["--method", method], ERRORS)] += 1


@cases(80)
@given(edits=st.lists(fz.toml_edit(), min_size=1, max_size=3))
def test_robot_toml_fuzz(base, edits):
    from odomgraph.io.robot import load_robot
    with tempfile.TemporaryDirectory() as tmp:
        log = fz.fresh_copy(base, Path(tmp) / "log")
        p = log / "robot.toml"
        text = p.read_text(encoding="utf-8")
        for apply in edits:
            text = apply(text)
        p.write_text(text, encoding="utf-8")
        try:
            load_robot(p)
        except LogFormatError as exc:
            assert "\n" not in str(exc)
            TALLY["robot.toml: error"] += 1
            return
        TALLY["robot.toml, ekf: " + fz.run_estimate(log, Path(tmp) / "out", ["--method", "ekf"], ERRORS)] += 1


@cases(40)
@given(args=fz.estimate_options())
def test_option_fuzz(base, args):
    with tempfile.TemporaryDirectory() as tmp:
        TALLY["options: " + fz.run_estimate(base, Path(tmp) / "out", args, ERRORS)] += 1


@cases(60)
@given(kind=st.sampled_from(["librsf", "librsf-gt", "optiodom-run", "optiodom-meta"]),
       mutation=fz.csv_mutation(), junk=st.binary(max_size=200), use_junk=st.booleans())
def test_importer_fuzz(kind, mutation, junk, use_junk):
    src = {"librsf": DATA / "librsf" / "Indoor_UWB_Input.txt", "librsf-gt": DATA / "librsf" / "Indoor_UWB_GT.txt",
           "optiodom-run": DATA / "optiodom" / "231220200029_run-01.csv",
           "optiodom-meta": DATA / "optiodom" / "231220200029_metadata.csv"}[kind]
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        data = src.read_bytes()
        bad = junk if use_junk else mutation[1](data)
        if kind == "librsf":
            (d / "x_Input.txt").write_bytes(bad)
            args = ["librsf", str(d / "x_Input.txt")]
        elif kind == "librsf-gt":
            (d / "x_Input.txt").write_bytes((DATA / "librsf" / "Indoor_UWB_Input.txt").read_bytes())
            (d / "gt.txt").write_bytes(bad)
            args = ["librsf", str(d / "x_Input.txt"), "--ground-truth", str(d / "gt.txt")]
        elif kind == "optiodom-run":
            (d / "s_run-01.csv").write_bytes(bad)
            (d / "s_metadata.csv").write_bytes((DATA / "optiodom" / "231220200029_metadata.csv").read_bytes())
            args = ["optiodom", str(d / "s_run-01.csv")]
        else:
            (d / "s_run-01.csv").write_bytes((DATA / "optiodom" / "231220200029_run-01.csv").read_bytes())
            (d / "s_metadata.csv").write_bytes(bad)
            args = ["optiodom", str(d / "s_run-01.csv")]
        before = fz.digest(d)
        res = fz.RUNNER.invoke(fz.app, ["import", *args, "-o", str(d / "out")])
        result = fz.outcome(res)
        TALLY[f"import {kind}: {result}"] += 1
        if result == "error":
            ERRORS[fz.error_class(res)] += 1
        after = {k: v for k, v in fz.digest(d).items() if not k.startswith("out/")}
        assert after == before
        if result == "ok":
            try:
                read_log(d / "out")
            except OdomgraphError as exc:
                raise AssertionError(f"an imported log does not read back: {exc}") from None
