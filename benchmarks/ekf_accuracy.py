"""Issue 2 acceptance: the paper's EKF on the paper scenario and on the unseen
'yard' scenario, 20 seeds each. Writes results/ekf_accuracy.{json,md}.

    python -m benchmarks.ekf_accuracy [--seeds 20]
"""
from __future__ import annotations

import argparse
import dataclasses

from benchmarks._common import save
from odomgraph.analysis.study import summarize
from odomgraph.runs import run_study
from odomgraph.sim.scenarios import paper, yard

TARGETS = {"scale": 0.005, "slip": 0.04, "coverage": 0.95}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, default=20)
    args = ap.parse_args(argv)
    rows, data = [], {}
    for sc, seeds in ((paper(), range(args.seeds)), (yard(), range(100, 100 + args.seeds))):
        s = summarize(run_study(sc, seeds))
        data[sc.name] = dataclasses.asdict(s)
        cov = {k: s.coverage_min[k] for k in ("x", "y", "slip_left", "slip_right", "scale_left", "scale_right",
                                               "scale_track")}
        rows.append(
            f"| {sc.name} | {s.seeds} | {100 * max(s.scale_rel_error_max[:2]):.2f} | "
            f"{100 * s.scale_rel_error_max[2]:.2f} | {s.slip_rms_pooled[0]:.4f} / {s.slip_rms_pooled[1]:.4f} | "
            f"{s.slip_rms_worst_seed[0]:.4f} / {s.slip_rms_worst_seed[1]:.4f} | {100 * min(cov.values()):.1f} "
            f"({min(cov, key=cov.get)}) |")
    md = "\n".join([
        "| scenario | seeds | worst ticks/m error % | worst track error % | slip RMS L / R (all rows) m/s "
        "| worst seed slip RMS L / R | worst 3σ coverage % (state) |",
        "|---|---|---|---|---|---|---|",
        *rows, "",
        f"Targets (issue 2): scale error < {100 * TARGETS['scale']:.1f} % on every seed; slip RMS after the "
        f"calibration window < {TARGETS['slip']} m/s per wheel; >= {100 * TARGETS['coverage']:.0f} % of rows inside "
        "±3σ for x, y, each slip and each scale factor, on every seed.",
    ])
    save("ekf_accuracy", {"targets": TARGETS, **data}, md)


if __name__ == "__main__":
    main()
