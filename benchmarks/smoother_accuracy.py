"""Issue 3 accuracy: EKF, batch, iSAM2 (smoothed and online) and fixed-lag side
by side on the paper scenario, 20 seeds, same logs.

Targets: batch scale-factor errors at most half the EKF's and slip RMS at most
0.7x; the iSAM2 online estimate no worse than the EKF; every estimator
consistent (>= 95 % of rows inside +-3 sigma). Writes results/smoother_accuracy.*

    python -m benchmarks.smoother_accuracy [--seeds 20]
"""
from __future__ import annotations

import argparse
import dataclasses

from benchmarks._common import save
from odomgraph.analysis.study import run_study, summarize
from odomgraph.sim.scenarios import paper

STATES = ("x", "y", "slip_left", "slip_right", "scale_left", "scale_right", "scale_track")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, default=20)
    args = ap.parse_args(argv)
    sc = paper()
    seeds = range(args.seeds)
    summaries = {}
    for method in ("ekf", "batch", "isam2", "fixed-lag"):
        res = run_study(sc, seeds, method=method)
        summaries[method] = summarize(res)
        if method == "isam2":
            summaries["isam2 online"] = summarize([r.online for r in res])
    ekf = summaries["ekf"]
    rows = []
    for name, s in summaries.items():
        cov = min(s.coverage_min[k] for k in STATES)
        ratio_scale = "/".join(f"{a / b:.2f}" for a, b in zip(s.scale_rel_error_rms, ekf.scale_rel_error_rms))
        ratio_slip = "/".join(f"{a / b:.2f}" for a, b in zip(s.slip_rms_pooled, ekf.slip_rms_pooled))
        rows.append(f"| {name} | {s.rms_position:.4f} | "
                    + " / ".join(f"{100 * v:.3f}" for v in s.scale_rel_error_rms) + f" | {ratio_scale} | "
                    + f"{s.slip_rms_pooled[0]:.4f} / {s.slip_rms_pooled[1]:.4f} | {ratio_slip} | {100 * cov:.1f} |")
    md = "\n".join([
        f"Paper scenario, {args.seeds} seeds, identical logs for every estimator.", "",
        "| estimator | RMS position m | scale error RMS % (L / R / track) | vs EKF | slip RMS L / R m/s | vs EKF "
        "| worst 3σ coverage % |",
        "|---|---|---|---|---|---|---|", *rows, "",
        "Targets: batch scale ≤ 0.5× and slip ≤ 0.7× the EKF; isam2 online ≤ 1× the EKF; coverage ≥ 95 % "
        "(x, y, slips, scale factors, worst seed).",
    ])
    save("smoother_accuracy", {k: dataclasses.asdict(v) for k, v in summaries.items()}, md)


if __name__ == "__main__":
    main()
