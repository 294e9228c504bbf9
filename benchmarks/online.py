"""Issue 15's live estimator: per-measurement latency, throughput and memory
of ``odomgraph.online.Online`` over a one-hour stream, and its rows against
the replay's.

The log is the paper scenario, one hour, encoders at 20 Hz, GPS at 10 Hz, and
the gyro at 20 Hz, then at 100 Hz. Each (method, gyro rate) runs in its own
process: it reads the log, streams every measurement in time order through
``Online.push`` (timing each call: the latency of one measurement, including
the filter or smoother work it completes), samples its resident memory
(VmRSS) every 30 s of log time, and writes each row to a file as it comes
(so the memory measured is the estimator's, not a list of rows). Another
process runs the replay (``estimate``); the rows are compared: isam2's
with online.csv, fixed-lag's and the EKF's with states.csv. The first push after the warm-up filters the warm-up's data at
once: that is the max; p99 is the steady state. The output lag is how far
each row's time lies behind the newest measurement pushed when the row came
out [s of log time]: the reorder window, the cleaning's look-ahead and, for
the smoothers, the next keyframe (isam2) or the lag window (fixed-lag). ``close()`` (for the
smoothers, the fully smoothed history of the whole hour) is timed apart.

Targets (issue 15): isam2 p99 <= 5 ms and at least 30x real time; memory of
the last 10 % within 1.2x of the first 10 %; streamed rows equal to the replay.

python -m benchmarks.online [--minutes 60] [--methods ekf isam2 fixed-lag]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmarks._common import RESULTS, save

_CHILD = r"""
import json, sys, time
import numpy as np
from pathlib import Path
what, method, d, out = sys.argv[1], sys.argv[2], Path(sys.argv[3]), Path(sys.argv[4])

def rss():
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0        # MB

from odomgraph.estimators.schedule import Schedule
from odomgraph.io.log import read_log
log = read_log(d)
sch = Schedule(calibrate_until=20.0)
if what == "replay":
    from odomgraph.pipeline import estimate
    w1 = time.perf_counter()
    est = estimate(log, method, sch)
    wall = time.perf_counter() - w1
    ref = est.online if method == "isam2" else est
    np.save(out, np.column_stack([ref.t, ref.mean, ref.sigma]))
    print(json.dumps({"replay_wall_s": wall}))
    sys.exit(0)
from odomgraph.io.stream import log_lines, parse_line
from odomgraph.online import Online
items = []
for line in log_lines(log):
    s, t, v = parse_line(line)
    items.append((s, float(t), v))
del log
live = Online(read_log(d).robot, method, sch)
lat = np.empty(len(items))
mem = []
n_rows = 0
i_start = None
next_mem = items[0][1]
sink = open(out, "wb")            # rows go out as a robot's would: nothing kept here

lags = []                         # log time of the newest measurement pushed, minus each row's time [s]

def emit(rows, t_now, live_rows=True):
    global n_rows
    for r in rows:
        sink.write(np.concatenate([[r.t], r.mean, r.sigma]).tobytes())
        if live_rows:
            lags.append(t_now - r.t)
    n_rows += len(rows)

wall0 = time.perf_counter()
for i, (s, t, v) in enumerate(items):
    a = time.perf_counter()
    rows = live.push(s, t, *v)
    lat[i] = time.perf_counter() - a
    if i_start is None and (live.ekf is not None or live.smoother is not None):
        i_start = i                # the push that ended the warm-up and caught up on it
    emit(rows, t, i_start is not None and i > i_start)   # the warm-up's rows come out at once: not lag
    if t >= next_mem:
        mem.append((t - items[0][1], rss()))
        next_mem = t + 30.0
a = time.perf_counter()
rows = live.close()
close_s = time.perf_counter() - a           # the smoothers' whole-history smoothing: no measurement's
wall = time.perf_counter() - wall0
lag = np.quantile(lags, [0.5, 0.99]) if lags else [float("nan")] * 2    # before close(): the live rows'
emit(rows, items[-1][1], False)
sink.close()
span = items[-1][1] - items[0][1]
q = np.quantile(lat, [0.5, 0.99])
print(json.dumps({"method": method, "measurements": int(len(lat)), "rows": n_rows, "close_s": close_s,
                  "span_s": span, "wall_s": wall, "realtime_x": span / wall, "p50_ms": 1e3 * q[0],
                  "p99_ms": 1e3 * q[1], "max_ms": 1e3 * float(lat.max()), "rss": mem,
                  "lag_p50_s": float(lag[0]), "lag_p99_s": float(lag[1]),
                  "warmup_push_ms": 1e3 * float(lat[i_start]), "max_live_ms": 1e3 * float(lat[i_start + 1:].max()),
                  "latency_ms_sample": (1e3 * np.sort(lat)[:: max(1, len(lat) // 2000)]).tolist()}))
"""


def _child(what: str, method: str, d: Path, out: Path) -> dict:
    r = subprocess.run([sys.executable, "-c", _CHILD, what, method, str(d), str(out)], capture_output=True,
                       text=True)
    if r.returncode != 0:
        last = r.stderr.strip().splitlines()[-1] if r.stderr.strip() else str(r.returncode)
        raise RuntimeError(f"{what} {method}: {last}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def _run(method: str, d: Path) -> dict:
    """Stream in one process, replay in another; compare their rows here."""
    import numpy as np
    res = _child("stream", method, d, d / "stream.bin")
    res.update(_child("replay", method, d, d / "replay.npy"))
    got = np.fromfile(d / "stream.bin").reshape(-1, 23)
    ref = np.load(d / "replay.npy")
    res["replay_rows"] = int(len(ref))
    res["max_abs_diff"] = None
    if got.shape == ref.shape:
        dm = got - ref
        dm[:, 3] = (dm[:, 3] + np.pi) % (2 * np.pi) - np.pi        # theta
        res["max_abs_diff"] = float(np.abs(dm).max())
    return res


def _memory(rss: list) -> tuple[float, float]:
    """Peak RSS [MB] in the first and in the last 10 % of the stream's time."""
    t = [a for a, _ in rss]
    span = max(t) if t else 0.0
    first = max((m for a, m in rss if a <= 0.1 * span), default=0.0)
    last = max((m for a, m in rss if a >= 0.9 * span), default=0.0)
    return first, last


def _plot(runs: list[dict], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    for r in runs:
        lab = f"{r['method']}, gyro {r['gyro_hz']:g} Hz"
        lat = np.asarray(r["latency_ms_sample"])
        a1.plot(np.maximum(lat, 1e-4), np.linspace(0, 1, len(lat)), label=lab)
        t, m = zip(*r["rss"]) if r["rss"] else ((), ())
        a2.plot(np.asarray(t) / 60.0, m, label=lab)
    a1.set_xscale("log")
    a1.axvline(5.0, color="k", ls=":", lw=1)
    a1.set_xlabel("latency of one measurement [ms]")
    a1.set_ylabel("share of measurements")
    a1.set_title("Online.push latency (dotted: isam2 p99 target)")
    a2.set_xlabel("stream time [min]")
    a2.set_ylabel("resident memory [MB]")
    a2.set_title("memory over the stream")
    for a in (a1, a2):
        a.grid(alpha=0.3)
    a2.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--methods", nargs="*", default=["ekf", "isam2", "fixed-lag"])
    args = ap.parse_args(argv)
    from odomgraph.io.log import write_log
    from odomgraph.sim.scenarios import Rates, paper
    from odomgraph.sim.simulate import simulate
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for gyro_hz in (20.0, 100.0):
            d = Path(tmp) / f"gyro{gyro_hz:g}"
            log = simulate(paper(60.0 * args.minutes).with_(rates=Rates(encoders=20.0, gyro=gyro_hz, gps=10.0,
                                                                        truth=1.0)), 0)
            write_log(log.with_(truth=None), d)
            del log
            for method in args.methods:
                r = {"gyro_hz": gyro_hz, **_run(method, d)}
                r["rss_first_mb"], r["rss_last_mb"] = _memory(r["rss"])
                runs.append(r)
                print(json.dumps({k: v for k, v in r.items() if k not in ("rss", "latency_ms_sample")}), flush=True)
    _plot(runs, RESULTS / "online.png")
    lines = [f"# Live estimator (issue 15): a {args.minutes:g}-minute stream", "",
             "Paper scenario, encoders 20 Hz, GPS 10 Hz, gyro 20 or 100 Hz; every measurement pushed in time "
             "order through `Online.push`, each call timed. Memory: peak VmRSS in the first and last 10 % of "
             "the stream's time. Equal: the largest difference of any streamed row (state, sigma, time) from "
             "the replay's (`estimate`: isam2's online.csv, the others' states.csv).", "",
             "| method | gyro | measurements | rows | p50 ms | p99 ms | max ms after the warm-up | warm-up push ms | "
             "output lag p50 / p99 s | "
             "× real time | close() s | memory first → last 10 % MB | ratio | equal to the replay | replay wall s |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in runs:
        ratio = r["rss_last_mb"] / r["rss_first_mb"] if r["rss_first_mb"] else float("nan")
        eq = "rows differ in number" if r["max_abs_diff"] is None else f"{r['max_abs_diff']:.1e}"
        lines.append(f"| {r['method']} | {r['gyro_hz']:g} Hz | {r['measurements']} | {r['rows']} | "
                     f"{r['p50_ms']:.3f} | {r['p99_ms']:.2f} | {r['max_live_ms']:.0f} | {r['warmup_push_ms']:.0f} | "
                     f"{r['lag_p50_s']:.2f} / {r['lag_p99_s']:.2f} | "
                     f"{r['realtime_x']:.0f}× | "
                     f"{r['close_s']:.1f} | "
                     f"{r['rss_first_mb']:.0f} → {r['rss_last_mb']:.0f} | {ratio:.2f} | {eq} | "
                     f"{r['replay_wall_s']:.1f} |")
    isam = [r for r in runs if r["method"] == "isam2"]
    verdict = []
    if isam:
        p99 = max(r["p99_ms"] for r in isam)
        rt = min(r["realtime_x"] for r in isam)
        verdict.append(f"isam2 p99 <= 5 ms: {'met' if p99 <= 5.0 else 'missed'} ({p99:.2f} ms); "
                       f"at least 30x real time: {'met' if rt >= 30 else 'missed'} ({rt:.0f}x)")
    worst = max(r["rss_last_mb"] / r["rss_first_mb"] for r in runs if r["rss_first_mb"])
    verdict.append(f"memory of the last 10 % within 1.2x of the first: {'met' if worst <= 1.2 else 'missed'} "
                   f"(worst {worst:.2f}x)")
    diffs = [r["max_abs_diff"] for r in runs]
    ok = all(d is not None and d <= 1e-9 for d in diffs)
    verdict.append(f"streamed rows equal to the replay to 1e-9: {'met' if ok else 'missed'}")
    lines += ["", "Targets: " + "; ".join(verdict) + ".", "", "![latency and memory](online.png)"]
    save("online", {"minutes": args.minutes, "runs": runs}, "\n".join(lines))


if __name__ == "__main__":
    main()
