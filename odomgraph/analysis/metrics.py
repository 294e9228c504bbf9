"""Errors and consistency of an Estimate against a log's truth.

Pure functions of arrays: no I/O, no plotting (as evo's ``core``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from factors._math import wrap_angle
from odomgraph import state as S
from odomgraph.estimators.result import Estimate
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
    nees = None
    if est.pose_cov is not None and "theta" in series:
        e = np.stack([series["x"], series["y"], series["theta"]], -1)
        C = est.pose_cov[inside]
        ok = np.linalg.det(C) > 0
        if ok.any():
            nees = float(np.mean(np.einsum("ni,ni->n", e[ok], np.linalg.solve(C[ok], e[ok][..., None])[..., 0])))
    return Errors(rms_pos, rms_slip, final, cover, nees, t, series, post)


def nis_summary(est: Estimate) -> dict[str, dict[str, float]]:
    """Mean NIS per sensor and its expected value (the measurement dimension)."""
    return {k: {"mean": float(np.mean(v.nis)), "expected": float(v.dof), "n": int(v.nis.size)}
            for k, v in est.innovations.items() if v.nis.size}
