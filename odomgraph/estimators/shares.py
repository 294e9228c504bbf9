"""How far the robot got inside an interval by a given time: the share of the
interval's wheel travel, of the wheels' difference, and of the gyro's turn.

A pose inside an interval [t0, t1] is placed on the arc of the interval's
average velocity (factors.motion.arc_at), not at the time's share of it: a
robot that accelerates covers most of an interval's travel late, and one
whose pivot ends early in an interval has done most of its turn by its
middle. The wheels say how far it went; the gyro says how far it turned
(the wheels' difference is slip and noise as much as turning). Each share
falls back to another where its channel moved no more than its noise.

The arc itself bends the whole distance, where a robot that drove straight
and then pivoted went straight: ``bend`` says how the path dead-reckoned
inside the interval differs from it (factors.motion.bend), ``chord_angle``
how its chord runs against the mean heading (analysis.sideways), and
``path_between`` gives the path itself (analysis.resample).

Used by the smoothers' keyframes (transitions', fixes' and rows' places in
their intervals, estimators.keyframes) and by rows written at other times
(analysis.resample), so that both place a pose the same way.
"""
from __future__ import annotations

import numpy as np

from odomgraph.estimators.measurements import PAUSE_S
from odomgraph.factors._math import dsinc
from odomgraph.io.log import Log

#: The gyro's turn inside an interval is taken as a turn beyond this many
#: sigmas of its integrated noise.
GYRO_Z = 3.0
#: A turn that goes beyond the interval's own by more than this [rad] and
#: back has the heading's offset in Shares.bend.
OVERSHOOT_RAD = 0.01
#: A gap between gyro samples longer than this many of their median period
#: is a dropout: the path's heading there is the wheels' (Shares.bend).
GAP_PERIODS = 3.0
#: With the wheels' heading, Shares.bend gives the path's own change with
#: the turn rate where the interval turns by more than this [rad]; the
#: arc's below (with the gyro's, wherever the path is bent).
TURN_CLEAR_RAD = 0.05
#: Columns of Shares.bend (factors.motion.bend's q).
BEND_WIDTH = 8


def share(c0, c1, ct, eps, fallback) -> np.ndarray:
    """(len,) fraction of a channel's change over an interval done by a time
    (c0, c1, ct: its values at t0, t1 and the time), clipped to [0, 1];
    ``fallback`` (as given) where it changed by no more than ``eps``."""
    total = np.asarray(c1, float) - c0
    moving = np.abs(total) > eps
    return np.where(moving, np.clip((ct - c0) / np.where(moving, total, 1.0), 0.0, 1.0), fallback)


def _interp(x, xp, fp) -> np.ndarray:
    """np.interp of a complex series."""
    return np.interp(x, xp, fp.real) + 1j * np.interp(x, xp, fp.imag)


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
            # the trapezoid rule between speed samples; none across a pause
            # (a sample is an instant: the speed before a day's pause said
            # nothing of it, and put a row in one 35 m away)
            dt = np.diff(w.t)
            step = np.where((dt > PAUSE_S)[:, None], 0.0, 0.5 * (ms[1:] + ms[:-1]) * dt[:, None])
            self.wheels = np.concatenate([np.zeros((1, 2)), np.cumsum(step, 0)])
        self.fwd = self.wheels.mean(1)
        self.diff = self.wheels[:, 1] - self.wheels[:, 0]
        self.track = r.track_width
        self._paths = None
        # More than two ticks [m]. The quarter tick keeps tick counts off the
        # threshold: forward travel is a mean of two wheels' whole ticks, so it
        # moves in half ticks, and at exactly a count on that grid rounding in
        # the cumulative travel decided (a stream, whose windows sum from
        # another origin, decided otherwise).
        self.eps = 2.25 / max(r.ticks_per_meter_left, r.ticks_per_meter_right, 1.0)
        g = log.gyro
        self.gyro = g if g is not None and len(g.t) > 1 else None
        if self.gyro is not None:
            dt = np.diff(g.t)
            # likewise no turn across a pause of the gyro
            self.gcum = np.concatenate([[0.0], np.cumsum(np.where(dt > PAUSE_S, 0.0, 0.5 * (g.omega[1:] + g.omega[:-1]) * dt))])
        self.gyro_sigma = r.gyro_sigma
        if self.gyro is not None:
            self._gaps = np.append(np.diff(g.t), 0.0)       # (the last pads reduceat)
            self._gap_max = GAP_PERIODS * float(np.median(self._gaps[:-1]))

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
        # The integral's white noise over [t0, t1] from the n samples inside
        # it: sigma dt / sqrt(n) [rad]. From those samples only: a period
        # from the log's extent differed between a stream's windows and the
        # whole log, and a standing robot's bias-sized turns fell on either
        # side of the threshold (tests/test_heading.py's stream and replay).
        n = self._gyro_n(t0, t1)
        eps = np.where(n >= 2, GYRO_Z * self.gyro_sigma * (t1 - t0) / np.sqrt(np.maximum(n, 1)), np.inf)
        return share(self._turned(t0, t1), self._turned(t1, t1), self._turned(ts, t1), eps, fallback)

    def _gyro_covers(self, t0, t1) -> np.ndarray:
        """(len,) whether the gyro's samples cover [t0, t1], from the last
        sample at or before t0 on, with no gap longer than GAP_PERIODS of
        their median period (the log's: an interval's own mean period grows
        with the gap inside it and let a 2.6 s gap through): the headings
        the path reads (each from the last sample before its row) are then
        the gyro's, not a rate held across a dropout (a second read: a 3 s
        dropout in a turn bent a transition's chord 21 mm sideways, 5 sigma;
        0.13 m on another log)."""
        t0, t1 = np.atleast_1d(t0), np.atleast_1d(t1)
        if self.gyro is None:
            return np.zeros(np.shape(t0), bool)
        gt = self.gyro.t
        a = np.searchsorted(gt, t0, side="right") - 1
        b = np.searchsorted(gt, t1, side="right") - 1
        ok = (a >= 0) & (b > a)
        a, b = np.where(ok, a, 0), np.where(ok, b, 1)
        widest = np.maximum.reduceat(self._gaps, np.column_stack([a, b]).ravel())[::2]
        return ok & (widest <= self._gap_max) & (t1 - gt[b] <= self._gap_max)

    def _gyro_n(self, t0, t1) -> np.ndarray:
        """(len,) gyro samples inside [t0, t1]."""
        gt = self.gyro.t
        return np.searchsorted(gt, t1, side="right") - np.searchsorted(gt, t0, side="left")

    def bend(self, t0, t1, ts, s_v, s_w) -> np.ndarray:
        """(len, BEND_WIDTH) how the path from t0 to ts differs from the arc
        that places ts (factors.motion.bend): (re, im) of a complex factor q
        on the arc's displacement, (re, im) of an offset o [m] in the body
        frame at t0, an offset [rad] of the heading where the path's turn
        went beyond the interval's and back (else 0), (re, im) of c [m s/rad]
        and omega0 [rad/s], the chord's change with the turn rate beyond q's
        (below). The path is dead-reckoned from the wheels' travel,
        turned by the gyro's integral (by the wheels' difference over the
        nominal track where the gyro's samples do not cover [t0, t1],
        ``_gyro_covers``); the
        arc is the interval's travel and turn at the shares (s_v, s_w) the
        caller places ts by (arrays (len,); 1, 1 at t1), both from the
        nominal calibration. Where the path is within two ticks of the arc,
        the arc itself (1, 0, 0, 0, o_th, 0, 0, omega0): the difference is noise.
        Elsewhere where the arc's displacement is well
        conditioned, q = path / arc and o = 0: the path's shape, which the
        estimated calibration scales as it scales the arc. Elsewhere (a
        displacement under two ticks, a reversal or a loop: the path
        runs more than twice its displacement, or q outside [1/2, 2]), q = 1
        and o = path - arc: the path as the nominal calibration flew it,
        corrected by the arc's change.

        Why: an arc of the interval's average curvature bends the whole
        distance, where a robot that drove straight and then pivoted went
        straight (a probe's paper log 3x faster at 2 Hz keyframes: keyframes
        0.31 m off, z 14, status ok); and a robot that reversed inside an
        interval is not at its start at the interval's middle."""
        t0, t1, ts, s_v, s_w = (np.asarray(a, float) for a in (t0, t1, ts, s_v, s_w))
        P, H, _ = self._path(t0, t1)
        h0 = H(t0)
        D = np.exp(-1j * h0) * (P(ts) - P(t0))
        travel = np.interp(t1, self.t, self.fwd) - np.interp(t0, self.t, self.fwd)
        half = 0.5 * s_w * (H(t1) - h0)
        A = s_v * travel * np.sinc(half / np.pi) * np.exp(1j * half)
        length = self._paths[2]
        along = np.abs(np.interp(ts, self.t, length) - np.interp(t0, self.t, length))
        q = D / np.where(np.abs(A) > self.eps, A, 1.0)
        ok = (np.abs(A) > self.eps) & (along <= 2.0 * np.abs(D)) & (np.abs(q) >= 0.5) & (np.abs(q) <= 2.0)
        # A bend within two ticks of the arc is the wheels' and the gyro's
        # noise, not the path's shape: the arc stands there (bent by it, the
        # paper scenario's smooth paths gave track scale errors 1 % larger
        # over 80 seeds, 0.1289 against 0.1276 %).
        straight = np.abs(D - A) <= self.eps
        q = np.where(ok & ~straight, q, 1.0)
        o = np.where(ok | straight, 0.0, D - A)
        # A turn that overshoots and comes back inside the interval: its share
        # (clipped to [0, 1]) cannot say where the heading was; the path's
        # turn beyond the interval's does (a probe's S-curves at 1 Hz
        # keyframes: rows 0.88 rad off at sigma 0.038, status ok).
        turn, turned = H(t1) - h0, H(ts) - h0
        beyond = np.maximum(turned - np.maximum(turn, 0.0), 0.0) + np.minimum(turned - np.minimum(turn, 0.0), 0.0)
        o_th = np.where(np.abs(beyond) > OVERSHOOT_RAD, turned - s_w * turn, 0.0)
        # The chord's change with the turn rate, less what q A already gives
        # (A's: the arc turns its chord by half the change). How the path's
        # heading changes with omega depends on what moves omega off the
        # path's: with the gyro's heading, the gyro's bias (omega + bias is
        # what it reads), even in time: dD/domega = i \int (t - t0) e^{i (h - h0)} ds
        # (a second read: a heading-profile term was 16 mm off there, none
        # 2 mm, this 0.1 mm); with the wheels', the track width, which scales
        # the heading profile with the turn: dD/domega = i dt / turn \int (h - h0)
        # e^{i (h - h0)} ds, only where the turn is clear of noise and the
        # profile a share of it (mean |h - h0| at most |turn|, with room for
        # noise: a pivot and then a straight run is the bound itself).
        # Elsewhere the arc's own change stands.
        dt = t1 - t0
        omega0 = turn / np.maximum(dt, 1e-12)
        gyro = self._gyro_covers(t0, t1)       # (again: _path's choice; kept out of its return for now)
        M = self._paths[3]
        col = lambda j: _interp(ts, self.t, M[:, j]) - _interp(t0, self.t, M[:, j])
        m0 = P(ts) - P(t0)
        by_time = np.exp(-1j * h0) * (col(1) - (t0 - self.t[0]) * m0)        # \int (t - t0) e^{i(h - h0)} ds [m s]
        by_turn = np.exp(-1j * h0) * (col(0) - h0 * m0)                       # \int (h - h0) e^{i(h - h0)} ds [m rad]
        clear = ok & ~straight & (gyro | ((np.abs(turn) > TURN_CLEAR_RAD)
                                          & (np.abs(by_turn) <= 1.25 * np.abs(turn) * np.maximum(along, 1e-12))))
        dD = 1j * np.where(gyro, by_time, dt * by_turn / np.where(np.abs(turn) > 0, turn, 1.0))
        dA = s_v * travel * (dsinc(half) + 1j * np.sinc(half / np.pi)) * np.exp(1j * half) * 0.5 * s_w * dt
        cw = np.where(clear, dD - q * dA, 0.0)
        return np.stack([q.real, q.imag, o.real, o.imag, o_th, cw.real, cw.imag, omega0], -1)

    def path_between(self, t0, t1, ts):
        """The dead-reckoned path inside [t0, t1] (arrays (len,) [s]), in
        the body frame at t0: (d_ts, d_t1) complex displacements [m] to ts
        and to t1, (h_ts, h_t1) turns [rad] to them, and whether the
        displacement to t1 is well conditioned (``_path``). For placing
        points between two known poses (analysis.resample)."""
        t0, t1, ts = (np.asarray(a, float) for a in (t0, t1, ts))
        P, H, ok = self._path(t0, t1)
        h0 = H(t0)
        turn = np.exp(-1j * h0)
        p0 = P(t0)
        return turn * (P(ts) - p0), turn * (P(t1) - p0), H(ts) - h0, H(t1) - h0, ok

    def _path(self, t0, t1):
        """(P, H, ok): the dead-reckoned positions P(times) (complex) and
        headings H(times) [rad] of each interval's source (the gyro where its
        samples cover [t0, t1], ``_gyro_covers``, else the wheels), and whether the
        interval's displacement is well conditioned (over two ticks, and at
        least half the path's length)."""
        if self._paths is None:
            self._paths = self._dead_reckoned()
        Pa, Ha, length, _ = self._paths
        j = self._gyro_covers(t0, t1)
        P = lambda x: np.where(j, _interp(x, self.t, Pa[:, 1]), _interp(x, self.t, Pa[:, 0]))
        H = lambda x: np.where(j, np.interp(x, self.t, Ha[:, 1]), np.interp(x, self.t, Ha[:, 0]))
        D = np.abs(P(t1) - P(t0))
        along = np.abs(np.interp(t1, self.t, length) - np.interp(t0, self.t, length))
        return P, H, (D > self.eps) & (along <= 2.0 * D)

    def chord_angle(self, t0, t1) -> np.ndarray:
        """(len,) the angle [rad] of the path's displacement over [t0, t1]
        from its mean heading there: 0 on an arc; a robot that drove
        straight and then turned by T went along its first heading, T/2 off
        the mean (analysis.sideways, whose rows a second apart otherwise
        moved a robot sideways: 0.19 m, z 13, on a clean log). 0 where the
        displacement is under two ticks, or the path runs more than twice
        as far (a reversal or a loop)."""
        t0, t1 = np.asarray(t0, float), np.asarray(t1, float)
        P, H, ok = self._path(t0, t1)
        D = P(t1) - P(t0)
        return np.where(ok, np.angle(D * np.exp(-0.5j * (H(t0) + H(t1)))), 0.0)

    def _dead_reckoned(self):
        """((M, 2) complex positions and (M, 2) headings [rad] at the wheel
        rows, column 0 from the wheels' difference, column 1 from the gyro
        (the wheels' where there is no gyro); (M,) cumulative path length
        [m]; (M, 2) cumulative moments of the steps for bend's turn-rate
        term: column 0 the wheels' heading times the step [m rad], column 1
        the time since the first row times the gyro-heading step [m s]).
        Each step an arc between its ends' headings; the gyro's
        heading at a row reads no sample after it (a stream's equals the
        log's: the origin's position and heading cancel in ``bend``)."""
        ds = np.diff(self.fwd)
        H = np.zeros((len(self.t), 2))
        H[:, 0] = self.diff / self.track
        H[:, 1] = self._turned(self.t, self.t) if self.gyro is not None else H[:, 0]
        P = np.zeros((len(self.t), 2), complex)
        M = np.zeros((len(self.t), 2), complex)
        tm = 0.5 * (self.t[1:] + self.t[:-1]) - self.t[0]
        for j in range(2):
            # each step an arc: its chord is sinc(turn / 2) of its length
            dh = np.diff(H[:, j])
            hm = 0.5 * (H[1:, j] + H[:-1, j])
            step = ds * np.sinc(0.5 * dh / np.pi) * np.exp(1j * hm)
            P[1:, j] = np.cumsum(step)
            M[1:, j] = np.cumsum((hm if j == 0 else tm) * step)
        return P, H, np.concatenate([[0.0], np.cumsum(np.abs(ds))]), M

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
        between = np.where(h > PAUSE_S, self.gcum[j], self.gcum[j] + gw[j] * u + 0.5 * slope * u**2)
        held = self.gcum[jend] + gw[jend] * (ts - gt[jend])
        return np.where(inner, between, np.where(ts < gt[0], gw[0] * (ts - gt[0]), held))
