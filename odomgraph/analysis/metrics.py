"""Errors and consistency of an Estimate against a log's truth.

Pure functions of arrays: no I/O, no plotting (as evo's ``core``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from odomgraph.factors._math import wrap_angle
from odomgraph import state as S
from odomgraph.result import Estimate
from odomgraph.io.log import Log

#: States compared with truth.csv columns of the same name.
_TRUTH_STATES = ("x", "y", "theta", "v", "omega", "gyro_bias", "slip_left", "slip_right")


@dataclass(frozen=True)
class Errors:
    rms_position_m: float
    """RMS of the 2-D position error over all rows [m]."""
    rms_slip_mps: dict[str, float]
    """RMS slip error per wheel after the calibration window [m/s]."""
    final_scale_error: dict[str, float]
    """Final estimate minus truth, per scale factor [-]."""
    coverage_3sigma: dict[str, float]
    """Fraction of rows whose error lies inside +-3 sigma, per state with truth."""
    mean_nees_pose: float | None
    """Mean NEES of (x, y, theta); 3 for a consistent filter."""
    t: np.ndarray
    """(M,) times of the scored rows (those inside the truth's time span) [s]."""
    error_series: dict[str, np.ndarray]
    """Per scored row, the error of each state with truth (M,)."""
    slip_mask: np.ndarray
    """(M,) rows scored for slip (after the schedule's switch)."""

    def as_dict(self) -> dict:
        return {
            "rms_position_m": self.rms_position_m,
            "rms_slip_mps": self.rms_slip_mps,
            "final_scale_error": self.final_scale_error,
            "coverage_3sigma": self.coverage_3sigma,
            "mean_nees_pose": self.mean_nees_pose,
        }


def truth_errors(est: Estimate, log: Log) -> Errors | None:
    """Errors of ``est`` against ``log.truth`` (None when the log has no truth).

    Rows outside the truth's time span are not scored. Slip is scored from the
    schedule's switch on (slip is forced to zero while calibrating); with no
    switch, over all rows.
    """
    tr = log.truth
    if tr is None:
        return None
    inside = (est.t >= tr.t[0]) & (est.t <= tr.t[-1])
    t = est.t[inside]
    mean, sig = est.mean[inside], est.sigma[inside]
    series, cover = {}, {}
    for name in _TRUTH_STATES:
        ref = tr.at(name, t)
        if ref is None:
            continue
        i = S.IDX[name]
        e = mean[:, i] - ref
        if name == "theta":
            e = wrap_angle(e)
        series[name] = e
        if np.any(sig[:, i] > 0):
            cover[name] = float(np.mean(np.abs(e) <= 3 * sig[:, i]))
    if log.truth_scales is not None:
        for name, i, true in zip(("scale_left", "scale_right", "scale_track"), S.SCALE, log.truth_scales):
            e = mean[:, i] - true
            series[name] = e
            if np.any(sig[:, i] > 0):
                cover[name] = float(np.mean(np.abs(e) <= 3 * sig[:, i]))
    rms_pos = float(np.sqrt(np.mean(series["x"] ** 2 + series["y"] ** 2)))
    post = t >= est.t_switch if est.t_switch is not None else np.ones(t.size, bool)
    rms_slip = {}
    for w in ("left", "right"):
        e = series.get(f"slip_{w}")
        if e is not None and post.any():
            rms_slip[w] = float(np.sqrt(np.mean(e[post] ** 2)))
    final = {}
    if log.truth_scales is not None:
        final = {n: float(est.mean[-1, i] - tv)
                 for n, i, tv in zip(("left", "right", "track"), S.SCALE, log.truth_scales)}
    ns = nees_series(est, log)
    nees = float(np.mean(ns[1])) if ns is not None and ns[1].size else None
    return Errors(rms_pos, rms_slip, final, cover, nees, t, series, post)


def nis_summary(est: Estimate) -> dict[str, dict[str, float]]:
    """Mean NIS per sensor and its expected value (the measurement dimension)."""
    return {k: {"mean": float(np.mean(v.nis)), "expected": float(v.dof), "n": int(v.nis.size)}
            for k, v in est.innovations.items() if v.nis.size}


#: A sensor's mean NIS beyond this many times its dimension, over at least
#: NIS_MIN_COUNT updates: the estimate's sigma understates its error. The
#: simulator's logs, clean and with every fault of analysis.faults, give the
#: EKF a mean NIS / dimension of 0.03-1.02 per sensor.
NIS_WARN = 3.0
NIS_MIN_COUNT = 100


def nis_warning(sensor: str, total: float, n: int, dof: int, row_scale: float | None = None) -> str | None:
    """The warning for a sensor whose ``n`` accepted updates summed ``total``
    NIS (dimension ``dof``) when their mean is above NIS_WARN x dof; else None.
    Estimate's EKF and the stream share the text. ``row_scale``: the
    sensor's own scatter against robot.toml's sigma (analysis.noise.
    row_scales), when measured (estimate; the stream does not measure it):
    the sigma the run used then covers the rows' scatter (widened above 1.5,
    at most 1.5^2 = 2.25 of NIS below), so the line names the model, not the
    sigma (the Jackal's wheels measure 0.25 while their NIS is 9x their
    dimension: a skid-steer's turns, which the model does not hold)."""
    if n < NIS_MIN_COUNT or not total / n > NIS_WARN * dof:     # (not >: a NaN is no verdict)
        return None
    head = f"{sensor}: mean NIS {total / n:.1f} over {n} updates, expected {dof}: the estimate's sigma understates its error"
    if row_scale is not None:
        cause = ("a gyro scale or bias the model does not hold, or a clock off?" if sensor == "gyro" else
                 "motion the model does not hold (a skid-steer's turns, slip) or a clock off?")
        return (f"{head}; the rows scatter {row_scale:.2g}x robot.toml's sigma from one to the next (the run widens "
                f"it above 1.5), which does not explain it: {cause}")
    return f"{head} (a clock off, a sigma too small, or motion the model does not hold: a skid-steer's turns, slip?)"


def nis_warnings(est: Estimate, row_scales: dict[str, float] | None = None) -> list[str]:
    """nis_warning of each sensor in ``est.innovations`` (the EKF's);
    ``row_scales``: analysis.noise.row_scales of the log it ran on."""
    rows = row_scales or {}
    out = (nis_warning(k, float(np.sum(v.nis)), int(v.nis.size), int(v.dof), rows.get(k))
           for k, v in est.innovations.items())
    return [w for w in out if w]


def pose_at(est: Estimate, t: np.ndarray) -> np.ndarray:
    """(M, 3) estimated (x, y, theta) at times t inside the estimate's span, by linear
    interpolation (heading unwrapped first, so it does not jump at +-pi)."""
    th = np.unwrap(est.mean[:, S.THETA])
    return np.stack([np.interp(t, est.t, est.mean[:, S.X]), np.interp(t, est.t, est.mean[:, S.Y]),
                     wrap_angle(np.interp(t, est.t, th))], -1)


def gps_deviation(est: Estimate, log: Log) -> tuple[np.ndarray, np.ndarray] | None:
    """Distance between the measured GPS fixes and the antenna position the estimate
    predicts (pose + lever arm, paper eq. 8), as in the paper's fig. 7.

    Returns (t (M,) [s], deviation (M,) [m]) for fixes inside the estimate's span,
    or None when the log has no GPS.
    """
    res = gps_residuals(est, log)
    if res is None:
        return None
    t, r, _ = res
    return t, np.hypot(r[:, 0], r[:, 1])


def gps_times(log: Log) -> np.ndarray:
    """(G,) the fixes' times [s] on the wheels' clock: gps.csv's stamps less
    robot.toml's [gps] time_offset, as the estimators read them
    (measurements.clean). Every comparison of fixes with an estimate's rows
    goes by these (with the raw stamps a configured or estimated 2 s offset
    read as a slip in the calibration window: a probe's EKF, status degraded)."""
    return log.gps.t - log.robot.gps_time_offset if log.robot.gps_time_offset else log.gps.t


def gps_residuals(est: Estimate, log: Log) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Measured minus predicted antenna position (pose + lever arm, paper eq.
    8) for the fixes inside the estimate's span: (t (M,) [s] (gps_times),
    residual (M, 2) east/north [m], each fix's sigma (M,) [m]); None when
    the log has no GPS."""
    from odomgraph.factors.gps import antenna_position
    g = log.gps
    if g is None or len(g.t) == 0:
        return None
    tg = gps_times(log)
    inside = (tg >= est.t[0]) & (tg <= est.t[-1])
    t = tg[inside]
    p = pose_at(est, t)
    h, _ = antenna_position(p[:, 0], p[:, 1], p[:, 2], log.robot.gps_lever_arm)
    sig = g.sigma[inside] if g.sigma is not None else np.full(t.size, log.robot.gps_sigma)
    return t, np.stack([g.x[inside] - h[:, 0], g.y[inside] - h[:, 1]], -1), sig


def range_residuals(est: Estimate, log: Log) -> tuple[np.ndarray, np.ndarray] | None:
    """Measured minus predicted range (paper eq. 12) at each range time inside the
    estimate's span: (t (M,) [s], residual (M,) [m]); None without ranges.
    An estimator that estimated per-beacon range biases is judged with them."""
    from odomgraph.factors.ranging import beacon_range
    r = log.ranges
    if r is None or len(r.t) == 0 or not log.robot.beacons:
        return None
    inside = (r.t >= est.t[0]) & (r.t <= est.t[-1])
    t = r.t[inside]
    p = pose_at(est, t)
    bxy = np.asarray([[b.x, b.y] for b in log.robot.beacons])[r.beacon[inside]]
    bias = 0.0
    if est.range_bias:
        per_beacon = np.array([est.range_bias.get(b.id, {"value": 0.0})["value"] for b in log.robot.beacons])
        bias = per_beacon[r.beacon[inside]]
    h, _ = beacon_range(p[:, 0], p[:, 1], p[:, 2], bxy, log.robot.range_lever_arm, bias)
    return t, r.range[inside] - h[:, 0]


def nees_series(est: Estimate, log: Log) -> tuple[np.ndarray, np.ndarray] | None:
    """Pose NEES (x, y, theta) at each row inside the truth's span: (t, nees);
    None without truth heading or pose covariance. 3 on average when consistent."""
    tr = log.truth
    if tr is None or est.pose_cov is None or tr.at("theta", est.t[:1]) is None:
        return None
    inside = (est.t >= tr.t[0]) & (est.t <= tr.t[-1])
    t = est.t[inside]
    e = np.stack([est.mean[inside, S.X] - tr.at("x", t), est.mean[inside, S.Y] - tr.at("y", t),
                  wrap_angle(est.mean[inside, S.THETA] - tr.at("theta", t))], -1)
    C = est.pose_cov[inside]
    ok = np.linalg.det(C) > 0
    nees = np.full(t.size, np.nan)
    nees[ok] = np.einsum("ni,ni->n", e[ok], np.linalg.solve(C[ok], e[ok][..., None])[..., 0])
    return t[ok], nees[ok]
