"""The vectorised EKF (all runs of a Monte-Carlo grid point at once) against
running the same EKF one log at a time, in the same run, interleaved.

Both give the same numbers (checked here and in tests/test_montecarlo.py);
the question is time. Writes results/ekf_vectorised.{json,md,png}.

    python -m benchmarks.ekf_vectorised [--repeats 3]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks._common import RESULTS, save
from odomgraph.estimators.ekf import run_ekf
from odomgraph.estimators.ekf_many import run_ekf_many
from odomgraph.estimators.schedule import Schedule
from odomgraph.sim.sensor_configs import study_scenario
from odomgraph.sim.simulate import simulate


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    sch = Schedule(20.0)
    out, rows = {}, []
    for config in (1, 3):
        sc = study_scenario(config, 0.3, 0.02)
        for n in (1, 10, 50):
            logs = [simulate(sc, s, timing_seed=5) for s in range(n)]
            one, many = [], []
            for _ in range(args.repeats):
                t = time.perf_counter(); a = [run_ekf(log, sch) for log in logs]; one.append(time.perf_counter() - t)
                t = time.perf_counter(); b = run_ekf_many(logs, sch); many.append(time.perf_counter() - t)
            diff = max(float(np.abs(x.mean - y.mean).max()) for x, y in zip(a, b))
            r = {"runs": n, "one_by_one_best_s": min(one), "vectorised_best_s": min(many),
                 "speedup": min(one) / min(many), "per_run_ms_one_by_one": 1e3 * min(one) / n,
                 "per_run_ms_vectorised": 1e3 * min(many) / n, "max_abs_difference": diff}
            out[f"config{config}_n{n}"] = r
            rows.append(f"| {config} | {n} | {r['per_run_ms_one_by_one']:.0f} | {r['per_run_ms_vectorised']:.0f} | "
                        f"{r['speedup']:.1f}× | {diff:.1e} |")
            print(rows[-1], flush=True)
    _plot(out)
    md = "\n".join([
        "# Vectorised EKF over Monte-Carlo runs",
        "",
        "60 s runs of the study's configuration 1 (GPS 10 Hz + gyro 25 Hz) and 3 (three beacons at 20 Hz + "
        f"gyro); best of {args.repeats} interleaved repeats.",
        "",
        "| config | runs | ms per run, one by one | ms per run, vectorised | speed-up | max state difference |",
        "|---|---|---|---|---|---|",
        *rows,
    ])
    save("ekf_vectorised", {"results": out}, md)


def _plot(out):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4), constrained_layout=True)
    for config, c in ((1, "tab:blue"), (3, "tab:red")):
        rs = [v for k, v in out.items() if k.startswith(f"config{config}_")]
        n = [r["runs"] for r in rs]
        ax.plot(n, [r["per_run_ms_one_by_one"] for r in rs], "o--", color=c, label=f"config {config}, one by one")
        ax.plot(n, [r["per_run_ms_vectorised"] for r in rs], "o-", color=c, label=f"config {config}, vectorised")
    ax.set_xscale("log"); ax.set_yscale("log")
    ax.set_xlabel("runs per grid point"); ax.set_ylabel("EKF time per 60 s run [ms]")
    ax.legend(fontsize=8)
    fig.savefig(RESULTS / "ekf_vectorised.png", dpi=110)


if __name__ == "__main__":
    main()
