"""The fault suite: every estimator on logs with the faults real recordings
contain, scored against the same log without the fault.

``CASES`` names each fault (odomgraph.sim.faults) on a base scenario: the
paper's robot without its slip events (so that what goes wrong is the fault),
GPS at 10 Hz, a 20 s calibration window. ``run_case`` simulates the faulty
and the clean log with one seed, writes and reads both (so that file faults,
duplicated rows say, meet the reader), runs one estimator on each, and
scores it. ``benchmarks/faults.py`` runs the whole table; tests/test_faults.py
asserts the acceptance numbers on short logs.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from odomgraph.sim.faults import Faults, Stall

#: (start, end) of the window the stall and outage cases are scored over [s].
STALL = (40.0, 55.0)
OUTAGE = (40.0, 100.0)


@dataclass(frozen=True)
class Case:
    name: str
    faults: Faults
    description: str
    rates: dict | None = None
    """Sensor rates replacing the base scenario's (e.g. a sparse gyro)."""
    min_duration: float = 0.0
    """The case needs a log at least this long [s]."""


CASES = {c.name: c for c in (
    Case("outliers", Faults(outlier_rate=0.05, outlier_size=5.0, outlier_from=0.0),
         "5 % of GPS fixes 5 m off, from t = 0"),
    Case("outage", Faults(outages=(("gps", *OUTAGE),)), "no GPS for 60 s", min_duration=120.0),
    Case("gps stops", Faults(stops=(("gps", 60.0),)), "GPS silent for good from 60 s", min_duration=90.0),
    Case("stall", Faults(stalls=(Stall(*STALL, 0.5, 0.5),)),
         "15 s stall after the window: robot still, both wheels at 0.5 m/s", min_duration=70.0),
    Case("stall in window", Faults(stalls=(Stall(8.0, 14.0, 0.4, 0.4),)),
         "6 s stall inside the calibration window"),
    Case("rotation", Faults(motion="rotate"), "pure rotation in place"),
    Case("still", Faults(motion="still"), "standing still"),
    Case("slow", Faults(motion="slow"), "very slow motion (3 % speed)"),
    Case("encoder dropout", Faults(encoder_dropouts=((50.0, 52.0),), encoder_drop_rate=0.02),
         "2 s encoder dropout and 2 % single rows lost, ticks summed into the next row", min_duration=60.0),
    Case("duplicated rows", Faults(encoder_dup_rate=0.02), "2 % of encoder rows written twice"),
    Case("clock jump", Faults(clock_jumps=(("gps", 30.0, 0.5),)), "GPS stamps 0.5 s late from 30 s"),
    Case("wheel spike", Faults(spikes=(("encoders", 30.0, 50.0),)), "one 50 m/s wheel-speed sample"),
    Case("gyro spike", Faults(spikes=(("gyro", 30.0, 5.0),)), "one 5 rad/s gyro sample"),
    Case("sparse gyro", Faults(), "a gyro sending one sample every 8 s", rates={"gyro": 0.125}),
)}

METHODS = ("ekf", "batch", "isam2", "fixed-lag")


def scenario(case: Case, duration: float):
    """The base scenario of the suite with the case's rates."""
    from odomgraph.sim.scenarios import Rates, paper
    rates = dict(encoders=20.0, gyro=25.0, gps=10.0)
    rates.update(case.rates or {})
    return paper(max(duration, case.min_duration)).with_(slips=(), rates=Rates(**rates))


def written(log, d: Path):
    """The log as a user would have it: written and read back."""
    from odomgraph.io.log import read_log, write_log
    write_log(log, d)
    back = read_log(d)
    if back.truth is not None:
        back.truth.values       # read now: truth.csv is read on first use, and d may be gone by then
    return back


def _window_rms(err, name_x: str, name_y: str | None, t0: float, t1: float) -> float | None:
    sel = (err.t >= t0) & (err.t <= t1)
    if not sel.any():
        return None
    e2 = err.error_series[name_x][sel] ** 2
    if name_y is not None:
        e2 = e2 + err.error_series[name_y][sel] ** 2
    return float(np.sqrt(np.mean(e2)))


def score(est, log, clean_rms: float | None, case: Case) -> dict:
    """The numbers of one faulty run (see run_case)."""
    from odomgraph.analysis.metrics import truth_errors
    from odomgraph.result import status_of
    err = truth_errors(est, log)
    t0 = 0.0                       # fault times are on the scenario's clock
    out = {
        "finished": True,
        "nan": bool(not (np.isfinite(est.mean).all() and np.isfinite(est.sigma).all())),
        "rms_position_m": err.rms_position_m,
        "clean_rms_position_m": clean_rms,
        "rms_ratio": err.rms_position_m / clean_rms if clean_rms else None,
        "coverage_3sigma_xy": min(err.coverage_3sigma.get("x", 1.0), err.coverage_3sigma.get("y", 1.0)),
        "worst_scale_error": (max(abs(v) for v in err.final_scale_error.values())
                              if err.final_scale_error else None),
        "unobservable": sorted(est.unobservable()),
        "scale_sigma": [c["sigma"] for c in est.calibration.values()],
        "status": status_of(est)[0],
        "recoveries": len(est.recoveries),
        "departures": len(est.departures),
        "rejected": dict(est.rejected),
    }
    if case.name == "stall":
        a, b = t0 + STALL[0], t0 + STALL[1]
        out["stall_slip_rms_mps"] = max(_window_rms(err, "slip_left", None, a, b) or 0.0,
                                        _window_rms(err, "slip_right", None, a, b) or 0.0)
        out["stall_position_rms_m"] = _window_rms(err, "x", "y", a, b)
    if case.name == "outage":
        a, b = t0 + OUTAGE[0], t0 + OUTAGE[1]
        sel = (err.t >= a) & (err.t <= b)
        i_x, i_y = 0, 1
        sig = est.sigma[(est.t >= err.t[0]) & (est.t <= err.t[-1])]
        inside = (np.abs(err.error_series["x"]) <= 3 * sig[:, i_x]) & (np.abs(err.error_series["y"]) <= 3 * sig[:, i_y])
        out["outage_coverage_3sigma"] = float(np.mean(inside[sel])) if sel.any() else None
        pos = np.hypot(err.error_series["x"], err.error_series["y"])
        after = err.t > b
        limit = 3.0 * (clean_rms or 0.05)
        late = after & (pos > limit)
        out["reconverged_after_s"] = float(err.t[late].max() - b) if late.any() else 0.0
        s_in, s_before = sig[sel, 0], sig[(err.t < a) & (err.t > a - 10), 0]
        out["sigma_grows_in_outage"] = bool(s_in.size and s_before.size and s_in.max() > 2 * s_before.mean())
    return out


