"""Property-based fuzzing of everything a user hands odomgraph: log files,
robot.toml, importer inputs and CLI option values (hypothesis).

The one property: the outcome is a valid result, or one line
``odomgraph: error: ...`` with exit code 1. Never a traceback, never NaN in
an output, never a changed input file. ``tests/test_fuzz.py`` runs it on a
fixed seed in the default suite; ``benchmarks/fuzz.py`` runs it long and
counts the cases.
"""
from __future__ import annotations

import hashlib
import math
import shutil
from pathlib import Path

import numpy as np
from hypothesis import strategies as st
from typer.testing import CliRunner

from odomgraph.cli import app

RUNNER = CliRunner()
FILES = ("encoders.csv", "gps.csv", "gyro.csv", "robot.toml")


def make_base_log(d: Path) -> Path:
    """A small valid log (12 s of the paper scenario at low rates) at d."""
    from odomgraph.io.log import write_log
    from odomgraph.sim.scenarios import Rates, paper
    from odomgraph.sim.simulate import simulate
    sc = paper(12.0).with_(rates=Rates(encoders=10, gyro=10, gps=5, truth=5))
    write_log(simulate(sc, 0), d)
    return d


def digest(d: Path) -> dict[str, str]:
    return {p.relative_to(d).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(d.rglob("*")) if p.is_file()}


# ------------------------------------------------------------------ strategies
_weird_numbers = st.sampled_from(["nan", "inf", "-inf", "1e308", "-1e308", "1e-320", "0", "-0", "1e300", "0x10",
                                  "1_000", "", " ", "１", "1,5", "1e", "--1", "NaN", "+inf", "9" * 400])
_weird_text = st.text(alphabet=st.characters(codec="utf-8", exclude_categories=("Cs",)), max_size=40)


@st.composite
def csv_mutation(draw):
    """(file name, function text -> text) mutating one CSV of the base log."""
    name = draw(st.sampled_from(FILES[:3]))
    # Weighted towards damage that leaves a readable log (gaps, lost rows, a
    # clock offset), which is what reaches the estimators.
    kind = draw(st.sampled_from(["cell", "line", "drop", "drop", "drop_run", "drop_run", "dup", "swap", "truncate",
                                 "truncate", "bom", "scale_t", "shift_t", "shift_t", "bytes", "header", "crlf",
                                 "empty", "gap", "gap"]))
    row = draw(st.integers(0, 60))
    col = draw(st.integers(0, 3))
    cell = draw(st.one_of(_weird_numbers, _weird_text))
    line = draw(_weird_text)
    factor = draw(st.sampled_from([1e3, 1e6, 1e9, -1.0, 0.0, 1e-3, 1e12]))
    factor_gap = draw(st.sampled_from([0.5, 3.0, 10.0, 100.0]))
    shift = draw(st.sampled_from([-5.0, -0.3, 0.3, 2.0, 11.0, 1.7e9]))
    junk = draw(st.binary(max_size=30))

    def apply(data: bytes) -> bytes:
        text = data.decode("utf-8", errors="surrogateescape")   # an earlier mutation may have broken it
        lines = text.split("\n")
        body = [i for i, ln in enumerate(lines) if ln and not ln.startswith("#")][1:]
        i = body[row % len(body)] if body else 0
        if kind == "cell" and body:
            f = lines[i].split(",")
            f[col % len(f)] = cell
            lines[i] = ",".join(f)
        elif kind == "line":
            lines.insert(i, line)
        elif kind == "drop" and body:
            del lines[i]
        elif kind == "drop_run" and body:
            del lines[i:i + 1 + (row * 7) % 40]
        elif kind == "gap" and body:
            # shift everything after row i later by a gap: a dropout in the file
            out = lines[:i]
            for ln in lines[i:]:
                f = ln.split(",")
                try:
                    f[0] = repr(float(f[0]) + factor_gap)
                except ValueError:
                    pass
                out.append(",".join(f))
            lines = out
        elif kind == "shift_t":
            out = [lines[0]]
            for ln in lines[1:]:
                f = ln.split(",")
                try:
                    f[0] = repr(float(f[0]) + shift)
                except ValueError:
                    pass
                out.append(",".join(f))
            lines = out
        elif kind == "dup" and body:
            lines.insert(i, lines[i])
        elif kind == "swap" and len(body) > 1:
            j = body[(row + 1) % len(body)]
            lines[i], lines[j] = lines[j], lines[i]
        elif kind == "truncate":
            lines = lines[:max(1, i)]
        elif kind == "bom":
            return b"\xef\xbb\xbf" + data
        elif kind == "scale_t":
            out = [lines[0]]
            for ln in lines[1:]:
                f = ln.split(",")
                try:
                    f[0] = repr(float(f[0]) * factor)
                except ValueError:
                    pass
                out.append(",".join(f))
            lines = out
        elif kind == "bytes":
            pos = (row * 97) % max(1, len(data))
            return data[:pos] + junk + data[pos:]
        elif kind == "header":
            lines[0] = line
        elif kind == "crlf":
            return text.replace("\n", "\r\n").encode("utf-8", errors="surrogateescape")
        elif kind == "empty":
            return b""
        return "\n".join(lines).encode("utf-8", errors="surrogateescape")
    return name, _Described(apply, f"{kind}(row={row}, col={col}, cell={cell!r}, line={line!r}, factor={factor}, "
                                   f"gap={factor_gap}, shift={shift}, junk={junk!r})")


class _Described:
    """A mutation that says what it does when hypothesis prints a failing case."""

    def __init__(self, fn, text):
        self.fn, self.text = fn, text

    def __call__(self, *a):
        return self.fn(*a)

    def __repr__(self):
        return self.text


_toml_scalar = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**20, 10**20), st.booleans(),
                         _weird_text, st.lists(st.floats(-1e6, 1e6), max_size=4))
_known = {"wheels": ["ticks_per_meter_left", "ticks_per_meter_right", "track_width"], "encoders": ["sigma"],
          "gps": ["lever_arm", "sigma", "origin", "lever_armm"], "gyro": ["sigma"], "range": ["sigma", "beacons"],
          "velocity": ["sigma"], "initial": ["x", "y", "theta", "sigma"],
          "process": ["accel", "yaw_accel", "slip", "initial_scale_sigma", "slip_differential", "scale"],
          "calibration": ["written_by"], "gyros": ["sigma"]}


@st.composite
def toml_edit(draw):
    """A function robot.toml text -> text: one key set to an odd value, a table
    added, or the text damaged."""
    kind = draw(st.sampled_from(["set", "set", "set", "text", "bom", "beacons"]))
    table = draw(st.sampled_from(sorted(_known)))
    key = draw(st.sampled_from(_known[table]))
    value = draw(_toml_scalar)
    text = draw(_weird_text)

    def lit(v) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, float):
            return "nan" if math.isnan(v) else ("inf" if v == math.inf else ("-inf" if v == -math.inf else repr(v)))
        if isinstance(v, int):
            return str(v)
        if isinstance(v, str):
            import json
            return json.dumps(v, ensure_ascii=False).replace("\x7f", "\\u007f")
        return "[" + ", ".join(lit(x) for x in v) + "]"

    def apply(src: str) -> str:
        if kind == "text":
            return src + "\n" + text
        if kind == "bom":
            return "\ufeff" + src
        if kind == "beacons":
            return src + f'\n[range]\nbeacons = [{{ id = {lit(value) if not isinstance(value, list) else 1}, ' \
                         f'x = 0.0, y = 1.0 }}]\n'
        lines = src.split("\n")
        header = f"[{table}]"
        if header in lines:
            start = lines.index(header) + 1
            for j in range(start, len(lines)):
                if lines[j].startswith("["):
                    break
                if lines[j].split("=")[0].strip() == key:
                    lines[j] = f"{key} = {lit(value)}"
                    return "\n".join(lines)
            lines.insert(start, f"{key} = {lit(value)}")
            return "\n".join(lines)
        return src + f"\n{header}\n{key} = {lit(value)}\n"
    return _Described(apply, f"{kind}([{table}] {key} = {value!r}, text={text!r})")


_opt_number = st.one_of(st.sampled_from(["0", "-1", "nan", "inf", "-inf", "1e308", "abc", "", "1e-300", "3"]),
                        st.floats(-1e4, 1e4).map(repr))


@st.composite
def estimate_options(draw):
    """A list of CLI arguments for ``estimate`` with odd values."""
    args = ["--method", draw(st.sampled_from(["ekf", "batch", "isam2", "fixed-lag", "bach", "EKF"]))]
    for opt in draw(st.lists(st.sampled_from(["--keyframe-hz", "--lag", "--slip-cauchy", "--robust-k", "--gate",
                                              "--calibrate-until"]), max_size=3, unique=True)):
        args += [opt, draw(_opt_number)]
    if draw(st.booleans()):
        args += ["--robust", draw(st.sampled_from(["huber", "cauchy", "tukey"]))]
    return args


# ------------------------------------------------------------------ outcomes
def error_class(res) -> str:
    """The gist of a result's error line, for tallies: its last clause with
    paths, numbers and quoted values removed."""
    import re
    line = next((ln for ln in res.stderr.splitlines() if ln.startswith("odomgraph: error:")), "")
    text = re.sub(r"\S*/\S*", "", line[len("odomgraph: error:"):])          # paths
    text = re.sub(r"'[^']*'|\([^)]*\)|-?\d[\w.+-]*", "", text)           # values, numbers, asides
    return " ".join(text.replace(":", " ").split())[:60]


def outcome(res) -> str:
    """'ok' or 'error' for a CliRunner result that keeps the contract; raises
    AssertionError otherwise (a traceback, several lines, a wrong exit code)."""
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        import traceback
        raise AssertionError("".join(traceback.format_exception(res.exception)))
    if res.exit_code == 0:
        return "ok"
    err = res.stderr.strip().splitlines()
    errors = [ln for ln in err if not ln.startswith("odomgraph: warning:")]
    assert res.exit_code == 1, (res.exit_code, res.output)
    assert len(errors) == 1 and errors[0].startswith("odomgraph: error:"), res.stderr
    assert "Traceback" not in res.output and "np.float64" not in res.stderr
    return "error"


def check_estimate_dir(out: Path) -> None:
    """An estimate directory that was written holds finite numbers only."""
    text = (out / "states.csv").read_text()
    assert "nan" not in text.lower() and "inf" not in text.lower().replace("info", "")
    data = np.loadtxt(out / "states.csv", delimiter=",", skiprows=1, ndmin=2)
    assert data.size and np.isfinite(data).all()


def run_estimate(log: Path, out: Path, args=(), errors=None) -> str:
    """Run ``estimate`` and check the contract; ``errors`` (a Counter) tallies error classes."""
    before = digest(log)
    res = RUNNER.invoke(app, ["estimate", str(log), "-o", str(out), *args])
    result = outcome(res)
    if result == "error" and errors is not None:
        errors[error_class(res)] += 1
    assert digest(log) == before, "an input file changed"
    if result == "ok":
        check_estimate_dir(out)
        shutil.rmtree(out)
    else:
        assert not out.exists(), "a refused run left output behind"
    return result


def fresh_copy(base: Path, work: Path) -> Path:
    if work.exists():
        shutil.rmtree(work)
    shutil.copytree(base, work)
    return work
