"""How well a log can determine the track width at best: an oracle with truth.

Track width is seen only by comparing the wheels' travel difference with the
heading change (paper eq. 29 with eq. 4): over an encoder interval i with no
slip,

    y_i = d_right,i / scale_right - d_left,i / scale_left = scale_track * track * dtheta_i + n_i,

with d the nominal-converted wheel distances and n_i their noise (eq. 41:
(a + b |u|) dt per wheel, u the true surface speed). The oracle knows what no
estimator knows: the true heading at every encoder sample, which intervals
are slip-free, and both wheel scale factors. What is left is encoder noise, and
weighted least squares over the slip-free intervals is its efficient
estimator. Its error and its Cramer-Rao sigma

    sigma(scale_track) = 1 / (track * sqrt(sum_i dtheta_i^2 / var(n_i)))

are a floor under any estimator's track-width error on that log. Tick
quantisation is left out of the weights and the sigma: it would only raise the
floor.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from odomgraph.io.log import Log


@dataclass(frozen=True)
class TrackBound:
    error: float
    """The oracle's relative track-width error, estimate / truth - 1 [-]."""
    sigma: float
    """Its Cramer-Rao 1-sigma, relative [-]."""
    intervals: int
    """Slip-free encoder intervals used."""


def _heading(log: Log, t: np.ndarray) -> np.ndarray:
    """True unwrapped heading at t [rad]: cubic Hermite on truth's theta and omega.

    Linear interpolation of a 20 Hz truth would add an error of order
    (d omega/dt) h^2 / 8 per interval at every ramp, larger than the floor
    being measured; with the yaw rate as slope the error is third order.
    """
    tr = log.truth
    th = np.unwrap(tr.values["theta"])
    om = tr.values["omega"]
    k = np.clip(np.searchsorted(tr.t, t, side="right") - 1, 0, len(tr.t) - 2)
    h = tr.t[k + 1] - tr.t[k]
    s = (t - tr.t[k]) / h
    h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
    h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
    return h00 * th[k] + h10 * h * om[k] + h01 * th[k + 1] + h11 * h * om[k + 1]


def track_width_bound(log: Log, t_end: float | None = None) -> TrackBound:
    """The oracle's track-width estimate over the log (or up to ``t_end`` [s], the
    log's clock) and its Cramer-Rao sigma. Needs encoder ticks, truth with
    theta, omega, v and slips, and truth_scales."""
    if log.encoders is None or log.truth is None or log.truth_scales is None:
        raise ValueError("track_width_bound needs encoder ticks, truth.csv and the true scale factors")
    r, e, tr = log.robot, log.encoders, log.truth
    kl, kr, kb = log.truth_scales
    a, b = r.encoder_sigma
    dt = np.diff(e.t)
    dth = np.diff(_heading(log, e.t))
    y = e.ticks_right[1:] / (r.ticks_per_meter_right * kr) - e.ticks_left[1:] / (r.ticks_per_meter_left * kl)
    tm = 0.5 * (e.t[1:] + e.t[:-1])
    v, om = tr.at("v", tm), tr.at("omega", tm)
    sl = np.maximum(np.abs(tr.at("slip_left", e.t[1:])), np.abs(tr.at("slip_left", e.t[:-1])))
    sr = np.maximum(np.abs(tr.at("slip_right", e.t[1:])), np.abs(tr.at("slip_right", e.t[:-1])))
    half = 0.5 * kb * r.track_width
    var = ((a + b * np.abs(v - om * half)) * dt) ** 2 + ((a + b * np.abs(v + om * half)) * dt) ** 2
    use = (sl < 1e-9) & (sr < 1e-9) & (dt > 0)
    if t_end is not None:
        use &= e.t[1:] <= t_end
    w = 1.0 / var[use]
    info = np.sum(w * dth[use] ** 2)
    if not info > 0:
        raise ValueError("track_width_bound: the log never turns without slip")
    estimate = np.sum(w * dth[use] * y[use]) / (r.track_width * info)
    return TrackBound(error=float(estimate / kb - 1.0), sigma=float(1.0 / (r.track_width * kb * np.sqrt(info))),
                      intervals=int(use.sum()))
