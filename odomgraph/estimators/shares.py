"""How far the robot got inside an interval by a given time: the share of the
interval's wheel travel, of the wheels' difference, and of the gyro's turn.

A pose inside an interval [t0, t1] lies on the arc of the interval's average
velocity (factors.motion.arc_at), but not at the time's share of it: a robot
that accelerates covers most of an interval's travel late, and one whose
pivot ends early in an interval has done most of its turn by its middle.
The wheels say how far it went; the gyro says how far it turned (the
wheels' difference is slip and noise as much as turning). Each share falls
back to another where its channel moved no more than its noise.

Used by the smoothers' keyframes (fixes' and rows' places in their
intervals, estimators.keyframes) and by rows written at other times
(analysis.resample), so that both place a pose the same way.
"""
from __future__ import annotations

import numpy as np

from odomgraph.io.log import Log

#: The gyro's turn inside an interval is taken as a turn beyond this many
#: sigmas of its integrated noise.
GYRO_Z = 3.0


def share(c0, c1, ct, eps, fallback) -> np.ndarray:
    """(len,) fraction of a channel's change over an interval done by a time
    (c0, c1, ct: its values at t0, t1 and the time), clipped to [0, 1];
    ``fallback`` (as given) where it changed by no more than ``eps``."""
    total = np.asarray(c1, float) - c0
    moving = np.abs(total) > eps
    return np.where(moving, np.clip((ct - c0) / np.where(moving, total, 1.0), 0.0, 1.0), fallback)


class Shares:
    """A log's cumulative wheel travel and gyro turn, read at any times.

    ``travel(t0, t1, ts)``: (len,) share of the wheels' mean travel over
    [t0, t1] done by ts; ``wheel_turn``: the same for their difference;
    ``gyro_turn``: for the gyro's integral, or ``fallback`` where the log has
    no gyro, the interval fewer than two samples, or a turn within GYRO_Z of
    the gyro's noise. All arguments are arrays (len,) [s], one interval per
    time; shares where a channel did not move are the time's share."""

    def __init__(self, log: Log):
        r = log.robot
        if log.encoders is not None:
            e = log.encoders
            tpm = np.array([r.ticks_per_meter_left, r.ticks_per_meter_right])
            ticks = np.stack([e.ticks_left, e.ticks_right], -1)
            self.t = e.t
            self.wheels = np.concatenate([np.zeros((1, 2)), np.cumsum(ticks[1:], 0)]) / tpm   # [m] at each row
        else:
            w = log.wheel_speeds
            ms = np.stack([w.v_left, w.v_right], -1)
            self.t = w.t
            # the trapezoid rule between speed samples
            self.wheels = np.concatenate([np.zeros((1, 2)),
                                          np.cumsum(0.5 * (ms[1:] + ms[:-1]) * np.diff(w.t)[:, None], 0)])
        self.fwd = self.wheels.mean(1)
        self.diff = self.wheels[:, 1] - self.wheels[:, 0]
        # More than two ticks [m]. The quarter tick keeps tick counts off the
        # threshold: forward travel is a mean of two wheels' whole ticks, so it
        # moves in half ticks, and at exactly a count on that grid rounding in
        # the cumulative travel decided (a stream, whose windows sum from
        # another origin, decided otherwise).
        self.eps = 2.25 / max(r.ticks_per_meter_left, r.ticks_per_meter_right, 1.0)
        g = log.gyro
        self.gyro = g if g is not None and len(g.t) > 1 else None
        if self.gyro is not None:
            self.gcum = np.concatenate([[0.0], np.cumsum(0.5 * (g.omega[1:] + g.omega[:-1]) * np.diff(g.t))])
        self.gyro_sigma = r.gyro_sigma

    def _wheels(self, c, t0, t1, ts):
        frac = (ts - t0) / np.maximum(t1 - t0, 1e-12)
        at = lambda x: np.interp(x, self.t, c)
        return share(at(t0), at(t1), at(ts), self.eps, frac)

    def travel(self, t0, t1, ts) -> np.ndarray:
        return self._wheels(self.fwd, t0, t1, ts)

    def wheel_turn(self, t0, t1, ts) -> np.ndarray:
        return self._wheels(self.diff, t0, t1, ts)

    def gyro_turn(self, t0, t1, ts, fallback) -> np.ndarray:
        if self.gyro is None:
            return np.broadcast_to(np.asarray(fallback, float), np.shape(ts)).copy()
        gt = self.gyro.t
        # The integral's white noise over [t0, t1] from the n samples inside
        # it: sigma dt / sqrt(n) [rad]. From those samples only: a period
        # from the log's extent differed between a stream's windows and the
        # whole log, and a standing robot's bias-sized turns fell on either
        # side of the threshold (tests/test_heading.py's stream and replay).
        n = np.searchsorted(gt, t1, side="right") - np.searchsorted(gt, t0, side="left")
        eps = np.where(n >= 2, GYRO_Z * self.gyro_sigma * (t1 - t0) / np.sqrt(np.maximum(n, 1)), np.inf)
        return share(self._turned(t0, t1), self._turned(t1, t1), self._turned(ts, t1), eps, fallback)

    def _turned(self, ts, t_end) -> np.ndarray:
        """(len,) the gyro's turn [rad] from its first sample to times ts:
        the integral of the rate interpolated linearly between samples (as
        keyframes.interval_means integrates it), the first and last rates
        held beyond the ends, reading no sample after t_end (len,): a
        stream's keyframes (odomgraph.online) then equal the log's to
        rounding."""
        gt, gw, M = self.gyro.t, self.gyro.omega, len(self.gyro.t)
        ts = np.asarray(ts, float)
        j = np.clip(np.searchsorted(gt, ts, side="right") - 1, 0, M - 1)
        jend = np.clip(np.searchsorted(gt, t_end, side="right") - 1, 0, M - 1)
        inner = (j < jend) & (ts >= gt[0])
        # inside [gt_j, gt_j+1]: the trapezoid up to ts of the linear rate
        j1 = np.minimum(j + 1, M - 1)
        h = gt[j1] - gt[j]
        u = ts - gt[j]
        slope = np.where(h > 0, (gw[j1] - gw[j]) / np.where(h > 0, h, 1.0), 0.0)
        between = self.gcum[j] + gw[j] * u + 0.5 * slope * u**2
        held = self.gcum[jend] + gw[jend] * (ts - gt[jend])
        return np.where(inner, between, np.where(ts < gt[0], gw[0] * (ts - gt[0]), held))
