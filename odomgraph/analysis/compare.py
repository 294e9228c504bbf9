"""Run the EKF and the smoothers on one log and score them side by side.

The numbers behind ``odomgraph compare`` and the demo's report: for each
estimator the RMS position error (against truth, or against GPS when a log
has no truth), slip RMS per wheel, the final scale factors with sigma, 3-sigma
coverage, wall time and updates per second. Pure computation: figures and
HTML are ``analysis.report``'s job.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from odomgraph.analysis.metrics import gps_deviation, range_residuals, truth_errors
from odomgraph.result import Estimate
from odomgraph.estimators.schedule import Schedule
from odomgraph.io.log import Log

#: Estimators in the report, in drawing order: (label, method run to get it).
#: isam2-online is the causal estimate of the isam2 run (online.csv).
ESTIMATORS = ("ekf", "isam2-online", "isam2", "batch")


@dataclass
class Comparison:
    log: Log
    schedule: Schedule
    estimates: dict[str, Estimate]
    """Label (ESTIMATORS) -> estimate, for those that did not diverge
    (metrics["estimators"][label]["failed"] says why for the others)."""
    no_slip: Estimate | None
    """The EKF without slip states: the paper's fig. 7 baseline (None if it diverged)."""
    metrics: dict
    """metrics.json content (see ``comparison_metrics``)."""


def _rms(x: np.ndarray) -> float | None:
    return float(np.sqrt(np.mean(x**2))) if x.size else None


def estimator_metrics(est: Estimate, log: Log) -> dict:
    """One estimator's row of the comparison (None where the log cannot tell)."""
    out = {
        "wall_time_s": est.wall_time_s,
        "n_updates": est.n_updates,
        "updates_per_second": est.n_updates / est.wall_time_s if est.wall_time_s > 0 else None,
        "rms_position_m": None,
        "rms_gps_deviation_m": None,
        "rms_range_residual_m": None,
        "rms_slip_mps": {"left": None, "right": None},
        "scale": {},
        "coverage_3sigma": {},
        "coverage_3sigma_min": None,
        "mean_nees_pose": None,
        "range_bias": est.range_bias,
    }
    cal = est.calibration
    err = truth_errors(est, log)
    for name, c in cal.items():
        out["scale"][name] = {"value": c["value"], "sigma": c["sigma"], "error": None}
    if err is not None:
        out["rms_position_m"] = err.rms_position_m
        out["rms_slip_mps"].update(err.rms_slip_mps)
        for k, e in err.final_scale_error.items():
            out["scale"][f"scale_{k}"]["error"] = e
        out["coverage_3sigma"] = err.coverage_3sigma
        out["coverage_3sigma_min"] = min(err.coverage_3sigma.values()) if err.coverage_3sigma else None
        out["mean_nees_pose"] = err.mean_nees_pose
    dev = gps_deviation(est, log)
    if dev is not None:
        out["rms_gps_deviation_m"] = _rms(dev[1])
    res = range_residuals(est, log)
    if res is not None:
        out["rms_range_residual_m"] = _rms(res[1])
    return out


def reference_of(log: Log) -> str:
    """What positions are scored against: 'truth', else 'gps', else 'ranges', else 'none'."""
    if log.truth is not None:
        return "truth"
    if log.gps is not None and len(log.gps.t):
        return "gps"
    if log.ranges is not None and len(log.ranges.t):
        return "ranges"
    return "none"


def comparison_metrics(ests: dict[str, Estimate], log: Log, schedule: Schedule,
                       no_slip: Estimate | None = None) -> dict:
    """metrics.json: the log, the reference, the schedule and one entry per estimator."""
    rows = {label: estimator_metrics(e, log) for label, e in ests.items()}
    if no_slip is not None:
        rows["ekf-no-slip"] = estimator_metrics(no_slip, log)
    ref = reference_of(log)
    return {
        "log": str(log.path) if log.path else None,
        "reference": ref,
        "reference_note": {
            "truth": "errors against the log's truth.csv",
            "gps": "the log has no truth: positions are compared with the GPS fixes (antenna, lever arm applied)",
            "ranges": "the log has no truth and no GPS: positions are judged by their range residuals",
            "none": "the log has no truth, GPS or ranges: positions cannot be scored",
        }[ref],
        "truth_scales": (dict(zip(("scale_left", "scale_right", "scale_track"), log.truth_scales))
                         if log.truth_scales is not None else None),
        "schedule": {"calibrate_until": schedule.calibrate_until, "hold": schedule.hold.value},
        "estimators": rows,
    }
