"""The paper-size Monte-Carlo study (sec. VI) on this machine: 3 configurations
x a 6x6 noise grid x 50 runs x 60 s logs, for the EKF and the batch smoother,
on the local process pool. Target: <= 30 minutes on 2 cores.

Each configuration's study directory is results/montecarlo/work/configN
(resumable; not committed); its results.csv, heatmap and summary.html are
copied to results/montecarlo/ (results.json, every run's scores, stays). The
wall time, the paper's
findings on our numbers and the smoother/EKF ratios go to
results/montecarlo_study.{json,md}.

    python -m benchmarks.montecarlo_study [--runs 50 --grid 6 --workers 2]
"""
from __future__ import annotations

import argparse
import shutil
import time

import numpy as np

from benchmarks._common import RESULTS, save
from odomgraph.analysis.montecarlo import QUANTITIES, StudySpec, run_study
from odomgraph.analysis.montecarlo_report import write_outputs
from odomgraph.analysis.montecarlo_report import findings, quantity_grid


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--grid", type=int, default=6)
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--resume", action="store_true",
                    help="keep the grid points an interrupted run finished (by default every point runs afresh: "
                         "points kept from older code would be reported as this code's, and the wall time with them)")
    args = ap.parse_args(argv)
    dest = RESULTS / "montecarlo"
    work = dest / "work"
    if not args.resume:
        shutil.rmtree(work, ignore_errors=True)
    out, rows, frows = {}, [], []
    t_all = time.perf_counter()
    grids = {}
    for config in (1, 2, 3):
        spec = StudySpec.grid(config, args.grid, runs=args.runs)
        t0 = time.perf_counter()
        last = [0.0]

        def progress(done, total, config=config):
            if time.perf_counter() - last[0] > 30 or done == total:
                last[0] = time.perf_counter()
                print(f"config {config}: {done}/{total} points, {time.perf_counter() - t0:.0f} s", flush=True)
        res = run_study(spec, work / f"config{config}", workers=args.workers, progress=progress)
        wall = time.perf_counter() - t0
        files = write_outputs(spec, res, work / f"config{config}")
        for f in files:  # results.json (every run's scores, ~0.6 MB) stays in the work directory
            if f.suffix != ".json":
                shutil.copy(f, dest / (f.name if f.name.startswith("heatmap") else f"config{config}_{f.name}"))
        cpu = {k: sum(r.wall_s.get(k, 0.0) for r in res) for k in ("simulate", "ekf", "batch")}
        ratio = {}
        for q in QUANTITIES:
            e, b = quantity_grid(spec, res, "ekf", (q,)), quantity_grid(spec, res, "batch", (q,))
            ratio[q] = float(np.nanmedian(b / e))
        fail = {est: float(np.mean([r.failure_rate(est) for r in res])) for est in ("ekf", "batch")}
        track = {est: float(np.nanmedian(quantity_grid(spec, res, est, ("scale_track",)))) for est in ("ekf", "batch")}
        grids[config] = track
        fnd = findings(spec, res)
        out[f"config{config}"] = {"wall_s": wall, "cpu_s": cpu, "median_ratio_smoother_over_ekf": ratio,
                                  "failure_rate": fail, "grid_median_track_error": track, "findings": fnd}
        rows.append(f"| {config} | {wall / 60:.1f} | {cpu['ekf']:.0f} | {cpu['batch']:.0f} | "
                    + " | ".join(f"{ratio[q]:.2f}" for q in QUANTITIES)
                    + f" | {100 * fail['ekf']:.1f} % / {100 * fail['batch']:.1f} % |")
        for f in fnd:
            frows.append(f"| {config} | {f['claim']} | {f['measured']} | "
                         f"{ {True: 'yes', False: 'no', None: 'n/a'}[f['holds']]} |")
    total = time.perf_counter() - t_all
    c2_beats = grids[2]["ekf"] < grids[1]["ekf"]
    frows.append(f"| 1 vs 2 | configuration 2 beats configuration 1 on track width | grid-median track error "
                 f"(EKF) {100 * grids[1]['ekf']:.2f} % (config 1) vs {100 * grids[2]['ekf']:.2f} % (config 2) | "
                 f"{'yes' if c2_beats else 'no'} |")
    md = "\n".join([
        "# Monte-Carlo study (paper sec. VI), paper size",
        "",
        f"3 configurations × {args.grid}×{args.grid} noise grid × {args.runs} runs × 60 s, EKF and batch smoother, "
        f"local process pool. **Total wall time {total / 60:.1f} min** (target ≤ 30 min on 2 cores).",
        "",
        "| config | wall [min] | EKF CPU [s] | smoother CPU [s] | " + " | ".join(
            f"smoother/EKF {q}" for q in QUANTITIES) + " | failures EKF / smoother |",
        "|---|---|---|---|" + "---|" * len(QUANTITIES) + "---|",
        *rows,
        "",
        "Ratios are the median over grid points of (smoother median RMS) / (EKF median RMS); below 1 the "
        "smoother is better.",
        "",
        "## The paper's findings on our numbers (EKF)",
        "",
        "| config | paper | ours | reproduces |",
        "|---|---|---|---|",
        *frows,
        "",
        "Per configuration in `montecarlo/`: `heatmap_configN.png` (paper figs. 8-10 with the smoother and the "
        "ratio), `configN_results.csv` and `configN_summary.html`; every run's scores are in "
        "`work/configN/results.json` (not committed).",
    ])
    save("montecarlo_study", {"total_wall_s": total, "runs": args.runs, "grid": args.grid, "configs": out}, md)


if __name__ == "__main__":
    main()
