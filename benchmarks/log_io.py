"""Issue 17's log I/O: how fast a log is read, and how much memory that takes,
against the files' size; and how fast states.csv is written.

The logs are the paper scenario at the one-hour benchmark's rates (encoders
and gyro 20 Hz, GPS 10 Hz; truth 100 Hz, as a simulated truth.csv), 10, 30
and 60 minutes long. Each measurement runs in its own process, so its peak
memory (VmHWM) is its own; the process's peak before the read (odomgraph and
numpy imported) is subtracted. The peer is
``numpy.loadtxt`` reading the same CSV files (header skipped), named and
timed in the same run, so the ratio holds whatever else the machine does.
Two reads: ``read`` as an estimator reads a log (truth.csv is read on first
use, so not at all), ``read-truth`` as a scoring tool reads it (every file).
Targets (issue 17): at least 50 MB/s, peak memory at most 3x the files.

python -m benchmarks.log_io [--minutes 10 30 60]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmarks._common import save

_CHILD = r"""
import json, sys, time
from pathlib import Path
what, d = sys.argv[1], Path(sys.argv[2])
import numpy as np
import odomgraph.io.log as L

def hwm():
    # VmHWM: this process's peak resident set [kB]. (ru_maxrss is kept across
    # exec, so it would report the parent's peak: the parent simulated the log.)
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1])

base = hwm()
t0 = time.perf_counter()
if what == "read":                    # as an estimator reads a log: truth.csv is left unread
    log = L.read_log(d)
    assert not log.truth.loaded
elif what == "read-truth":            # as a scoring tool reads it: every file
    log = L.read_log(d)
    log.truth.values
elif what == "loadtxt":
    for f in sorted(d.glob("*.csv")):
        np.loadtxt(f, delimiter=",", skiprows=1, ndmin=2)
elif what == "write-states":
    from odomgraph.io.estimate import read_states, write_states
    est = read_states(d / "states.csv")
    t0 = time.perf_counter()
    write_states(d / "states-again.csv", est)
wall = time.perf_counter() - t0
peak = hwm()
print(json.dumps({"wall_s": wall, "peak_kb": peak, "base_kb": base}))
"""


def _measure(what: str, d: Path) -> dict:
    out = subprocess.run([sys.executable, "-c", _CHILD, what, str(d)], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, nargs="*", default=[10.0, 30.0, 60.0])
    args = ap.parse_args(argv)
    from odomgraph.estimators.ekf import run_ekf
    from odomgraph.estimators.schedule import Schedule
    from odomgraph.io.estimate import write_states
    from odomgraph.io.log import write_log
    from odomgraph.sim.scenarios import Rates, paper
    from odomgraph.sim.simulate import simulate
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for minutes in args.minutes:
            d = Path(tmp) / f"log{minutes:g}"
            log = simulate(paper(60.0 * minutes).with_(rates=Rates(encoders=20.0, gyro=20.0, gps=10.0,
                                                                   truth=100.0)), 0)
            write_log(log, d)
            write_states(d / "states.csv", run_ekf(log, Schedule(20.0)))
            sizes = {p.name: p.stat().st_size for p in d.glob("*.csv")}
            log_bytes = sum(v for k, v in sizes.items() if k != "states.csv")
            truth_bytes = sizes.get("truth.csv", 0)
            row = {"minutes": minutes, "log_bytes": log_bytes, "truth_bytes": truth_bytes,
                   "states_bytes": sizes["states.csv"]}
            (d / "states.csv").rename(Path(tmp) / "states.csv")
            for what in ("read", "read-truth", "loadtxt"):
                row[what] = _measure(what, d)
            (Path(tmp) / "states.csv").rename(d / "states.csv")
            row["write-states"] = _measure("write-states", d)
            runs.append(row)
            print(json.dumps(row), flush=True)
    lines = ["# Log I/O (issue 17)", "",
             "Each cell is one process; peak memory is its VmHWM less that before the read "
             "(odomgraph and numpy imported). *Sensors*: `read_log` as an estimator calls it (truth.csv is "
             "read on first use, so not at all); *every file*: then the truth read too, as a scoring tool "
             "does. The peer is `numpy.loadtxt` on the same CSV files (every file).", "",
             "| log | files | sensors: read | MB/s | peak over files | every file: read | MB/s | peak over files "
             "| numpy.loadtxt | MB/s | read ÷ loadtxt | write states.csv |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in runs:
        mb, smb = r["log_bytes"] / 1e6, (r["log_bytes"] - r["truth_bytes"]) / 1e6
        rd, rt, lt, ws = r["read"], r["read-truth"], r["loadtxt"], r["write-states"]
        s_extra = (rd["peak_kb"] - rd["base_kb"]) * 1024 / (r["log_bytes"] - r["truth_bytes"])
        extra = (rt["peak_kb"] - rt["base_kb"]) * 1024 / r["log_bytes"]
        lines.append(f"| {r['minutes']:g} min | {mb:.1f} MB (truth {r['truth_bytes'] / 1e6:.1f}) | "
                     f"{rd['wall_s']:.2f} s | {smb / rd['wall_s']:.0f} | {s_extra:.1f}x | "
                     f"{rt['wall_s']:.2f} s | {mb / rt['wall_s']:.0f} | {extra:.1f}x | "
                     f"{lt['wall_s']:.2f} s | {mb / lt['wall_s']:.0f} | {rt['wall_s'] / lt['wall_s']:.2f}× | "
                     f"{ws['wall_s']:.2f} s ({r['states_bytes'] / 1e6:.1f} MB) |")
    last = runs[-1]
    speed = min(last["log_bytes"] / 1e6 / last["read-truth"]["wall_s"],
                (last["log_bytes"] - last["truth_bytes"]) / 1e6 / last["read"]["wall_s"])
    extra = max((last["read-truth"]["peak_kb"] - last["read-truth"]["base_kb"]) * 1024 / last["log_bytes"],
                (last["read"]["peak_kb"] - last["read"]["base_kb"]) * 1024
                / (last["log_bytes"] - last["truth_bytes"]))
    lines += ["", f"Targets (issue 17), the worse of the two reads on the longest log: read at 50 MB/s or more "
                  f"({'met' if speed >= 50 else 'missed'}: {speed:.0f} MB/s), peak memory at most 3x the files "
                  f"({'met' if extra <= 3 else 'missed'}: {extra:.1f}x). An estimator does not read truth.csv "
                  f"({last['truth_bytes'] / 1e6:.0f} of the {last['log_bytes'] / 1e6:.0f} MB here).",
              "", "How: each file is parsed by `numpy.loadtxt` in chunks of 256 KiB of text into one preallocated "
                  "(columns, rows) array, each column a view of it (`io/csvtable.py`); only a file that is not "
                  "plain numbers (comments or blank lines among the rows, a bad value) is read row by row, to "
                  "name the line."]
    save("log_io", {"runs": runs, "targets": {"mb_per_s": 50.0, "peak_over_files": 3.0}}, "\n".join(lines))


if __name__ == "__main__":
    main()
