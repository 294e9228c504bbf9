"""Library entry points behind the CLI: every command is a function here.

    from odomgraph.pipeline import estimate, summary
    est = estimate(read_log("LOG"), Method.ekf, Schedule(calibrate_until=20))
"""
from __future__ import annotations

from enum import Enum
from pathlib import Path

from odomgraph.analysis.metrics import nis_summary, truth_errors
from odomgraph.estimators.result import Estimate
from odomgraph.estimators.schedule import Schedule
from odomgraph.io.log import Log


class Method(str, Enum):
    ekf = "ekf"
    """The paper's velocity-augmented EKF."""


def estimate(log: Log, method: Method = Method.ekf, schedule: Schedule = Schedule(), progress=None,
             **options) -> Estimate:
    """Run one estimator over a log. ``progress(done, total)`` is optional."""
    if method is Method.ekf:
        from odomgraph.estimators.ekf import EKFOptions, run_ekf
        return run_ekf(log, schedule, EKFOptions(**options), progress)
    raise ValueError(f"unknown method {method!r}")


def summary(est: Estimate, log: Log, schedule: Schedule) -> dict:
    """summary.json content (LOG_FORMAT.md plus consistency and throughput)."""
    out = {
        "method": est.method,
        "log": str(log.path) if log.path else None,
        "n_steps": int(len(est.t)),
        "wall_time_s": est.wall_time_s,
        "n_updates": est.n_updates,
        "updates_per_second": est.n_updates / est.wall_time_s if est.wall_time_s > 0 else None,
        "schedule": {"calibrate_until": schedule.calibrate_until, "hold": schedule.hold.value,
                     "t_switch": est.t_switch},
        "calibration": est.calibration,
        "nis": nis_summary(est),
        "notes": est.notes,
    }
    err = truth_errors(est, log)
    if err is not None:
        out["errors"] = err.as_dict()
        if log.truth_scales is not None:
            out["truth_scales"] = dict(zip(("scale_left", "scale_right", "scale_track"), log.truth_scales))
    return out


def estimate_to_dir(log: Log, out: Path, method: Method, schedule: Schedule, progress=None, **options) -> dict:
    """Estimate and write the estimate directory; returns the summary."""
    from odomgraph.io.estimate import write_estimate
    est = estimate(log, method, schedule, progress, **options)
    summ = summary(est, log, schedule)
    write_estimate(est, out, summ)
    return summ
