"""Issue 5: the estimators on the shipped real data (tests/data/).

* OptiOdom (MIT): on the square run with motion-capture fixes at 1 Hz, the
  EKF and batch tracking errors; `calibrate` on it, then dead reckoning on the
  circular and free runs (encoders only) with nominal, calibrated and
  best-fit (oracle) parameters.
* libRSF Labyrinth UWB cut (CC BY-SA 4.0): EKF and batch with ranges against
  ground truth, with and without robust losses, beside dead reckoning.

Writes results/real_data.{json,md}.  python -m benchmarks.real_data
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from benchmarks._common import save
from odomgraph.analysis.deadreckoning import best_fit_scales, dead_reckon, final_position_error
from odomgraph.analysis.metrics import truth_errors
from odomgraph.estimators.schedule import Schedule
from odomgraph.io.importers.librsf import import_librsf
from odomgraph.io.importers.optiodom import import_optiodom
from odomgraph.pipeline import Method, calibrate, estimate

DATA = Path(__file__).resolve().parent.parent / "tests" / "data"


def main():
    out, md = {}, []
    o = DATA / "optiodom"
    square = import_optiodom(o / "231220200029_run-01.csv", fixes_hz=1.0)
    tests = {"circular": import_optiodom(o / "231220200141_run-01.csv"),
             "free": import_optiodom(o / "020120212354_run-01.csv")}
    md += ["### OptiOdom square run, motion capture as 1 Hz position fixes", "",
           "| estimator | RMS position m | scale L / R / track |", "|---|---|---|"]
    for m, sch in ((Method.ekf, Schedule(0.0)), (Method.batch, Schedule(None))):
        est = estimate(square, m, sch)
        e = truth_errors(est, square)
        out[f"square_{m.value}"] = {"rms_position_m": e.rms_position_m, "scales": est.mean[-1, 8:11].tolist()}
        label = "ekf (slip only, scales held at 1)" if m is Method.ekf else "batch (schedule none)"
        md.append(f"| {label} | {e.rms_position_m:.4f} | " + " / ".join(f"{v:.4f}" for v in est.mean[-1, 8:11]) + " |")
    _, rep = calibrate(square)
    k_cal = np.array([rep["scale"][w] for w in ("left", "right", "track")])
    k_best = best_fit_scales(list(tests.values()))
    md += ["", "Dead reckoning, encoders only, final-position error [m]:", "",
           "| run | nominal | calibrated on square | best fit to these runs (oracle) |", "|---|---|---|---|"]
    for name, lg in tests.items():
        row = [final_position_error(lg, k) for k in ((1, 1, 1), k_cal, k_best)]
        out[f"dr_{name}"] = dict(zip(("nominal", "calibrated", "oracle"), row))
        md.append(f"| {name} | {row[0]:.3f} | {row[1]:.3f} | {row[2]:.3f} |")
    md += ["", f"Scales calibrated on square: {np.round(k_cal, 4).tolist()}; oracle: {np.round(k_best, 4).tolist()}."]

    rsf = import_librsf(DATA / "librsf" / "Indoor_UWB_Input.txt")
    md += ["", "### libRSF Labyrinth UWB cut (ranges to 4 anchors, wheel speeds)", "",
           "| estimator | RMS position m |", "|---|---|"]
    for label, m, opts in (("ekf", Method.ekf, {}), ("batch", Method.batch, {}),
                           ("batch, Huber", Method.batch, {"robust": "huber"}),
                           ("batch, Cauchy", Method.batch, {"robust": "cauchy"})):
        est = estimate(rsf, m, Schedule(0.0), **opts)
        e = truth_errors(est, rsf)
        out[f"librsf_{label}"] = e.rms_position_m
        md.append(f"| {label} | {e.rms_position_m:.3f} |")
    t, p = dead_reckon(rsf, start=(est.t[0], *est.mean[0, 0:3]))
    dr = float(np.sqrt(np.mean((p[:, 0] - rsf.truth.at("x", t)) ** 2 + (p[:, 1] - rsf.truth.at("y", t)) ** 2)))
    out["librsf_dead_reckoning"] = dr
    md.append(f"| dead reckoning (from the smoother's first pose) | {dr:.3f} |")
    save("real_data", out, "\n".join(md))


if __name__ == "__main__":
    main()
