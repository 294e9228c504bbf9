"""A log's sensor files as measurement arrays that estimators consume.

Each sensor keeps its own timestamps; nothing is resampled. Encoder counts
become average wheel speeds over their interval, stamped at the interval's
midpoint (where the average equals the instantaneous speed to second order),
with the noise of paper eq. 41 plus tick quantisation.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from factors.encoder import speed_sigma
from odomgraph.io.log import Log

#: An encoder interval longer than this many median intervals is a gap in the
#: log; its average speed says little about any instant, so it is not used.
GAP_FACTOR = 5.0


@dataclass(frozen=True)
class WheelMeas:
    t: np.ndarray
    """(K,) measurement times [s]."""
    m: np.ndarray
    """(K, 2) nominal-converted (left, right) wheel speeds [m/s]."""
    sigma: np.ndarray
    """(K, 2) 1-sigma [m/s]."""
    dt: np.ndarray | None = None
    """(K,) encoder interval [s] (None for wheel_speeds.csv)."""


@dataclass(frozen=True)
class Measurements:
    t_start: float
    wheel: WheelMeas
    gyro: tuple[np.ndarray, np.ndarray] | None = None
    """(t, omega [rad/s])."""
    gps: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    """(t, xy (K,2) antenna [m], sigma (K,) [m])."""
    ranges: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    """(t, beacon xy (K,2) [m], range (K,) [m])."""
    velocity: tuple[np.ndarray, np.ndarray] | None = None
    """(t, (K,2) [v, omega])."""
    notes: tuple[str, ...] = field(default=())
    ranges_id: np.ndarray | None = None
    """(K,) index into robot.beacons of each range."""


def from_log(log: Log) -> Measurements:
    r = log.robot
    a, b = r.encoder_sigma
    notes = []
    if log.encoders is not None:
        e = log.encoders
        dt = np.diff(e.t)
        tpm = np.array([r.ticks_per_meter_left, r.ticks_per_meter_right])
        m = np.stack([e.ticks_left[1:], e.ticks_right[1:]], -1) / (tpm * dt[:, None])
        sig = speed_sigma(m, a, b, tpm, dt[:, None])
        t = 0.5 * (e.t[1:] + e.t[:-1])
        gap = dt > GAP_FACTOR * np.median(dt)
        if gap.any():
            notes.append(f"encoders: {int(gap.sum())} interval(s) longer than {GAP_FACTOR:g}x the median "
                         f"({np.median(dt):.3g} s) skipped as gaps")
        keep = ~gap
        wheel = WheelMeas(t[keep], m[keep], sig[keep], dt[keep])
    else:
        w = log.wheel_speeds
        m = np.stack([w.v_left, w.v_right], -1)
        wheel = WheelMeas(w.t, m, speed_sigma(m, a, b))
    gyro = (log.gyro.t, log.gyro.omega) if log.gyro is not None and len(log.gyro.t) else None
    gps = None
    if log.gps is not None and len(log.gps.t):
        g = log.gps
        sig = g.sigma if g.sigma is not None else np.full(len(g.t), r.gps_sigma)
        gps = (g.t, np.stack([g.x, g.y], -1), sig)
    ranges = None
    if log.ranges is not None and len(log.ranges.t):
        bxy = np.asarray([[bc.x, bc.y] for bc in r.beacons])[log.ranges.beacon]
        ranges = (log.ranges.t, bxy, log.ranges.range)
    vel = None
    if log.velocity is not None and len(log.velocity.t):
        vel = (log.velocity.t, np.stack([log.velocity.v, log.velocity.omega], -1))
    rid = None if ranges is None else np.asarray(log.ranges.beacon)
    return Measurements(log.t_start, wheel, gyro, gps, ranges, vel, tuple(notes), rid)


def slip_intensity(process, meas: Measurements) -> np.ndarray:
    """(2, 2) slip random-walk intensity in (left, right) [(m/s)^2/s], for the EKF and the smoothers.

    Built in common-mode c = (sL+sR)/2 and differential d = sR-sL coordinates,
    mapped by (sL, sR) = (c - d/2, c + d/2). The differential default depends
    on the log: see ProcessNoise.slip_differential.
    """
    q_d = process.slip_differential
    if q_d is None:
        q_d = 1.0 if (meas.gyro is not None or meas.velocity is not None) else 0.02
    return process.slip**2 * np.ones((2, 2)) + 0.25 * q_d**2 * np.array([[1.0, -1.0], [-1.0, 1.0]])
