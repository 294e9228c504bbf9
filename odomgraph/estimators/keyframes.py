"""Keyframes for the factor-graph smoothers, with preintegrated odometry.

Keyframe k sits at time t_k, a subset of the encoder timestamps (every n-th,
n = round(encoder rate / keyframe rate)). Its variables are the pose X_k at
t_k (Pose2) and W_k, the *averages* over the interval [t_k, t_{k+1}] of
(v, omega, gyro_bias, slip_left, slip_right) plus the scale factors:

    W_k = [v, omega, gyro_bias, slip_left, slip_right, scale_left, scale_right, scale_track]

Averages make the wheel odometry exact: summing the encoder ticks over the
interval gives the average wheel speed, which the encoder model (paper
eq. 29) predicts from W_k with no approximation, because the model is linear
in v, omega and slip for constant scale factors. Tick quantisation counts only
once per interval. The pose moves by the exact arc of the average velocity
(factors.motion). Gyro and velocity-sensor readings are averaged over each
interval by integrating their linear interpolant (interval_means); GPS fixes
and ranges keep their own time, at offset tau after t_k.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from odomgraph.factors.encoder import speed_sigma
from odomgraph.estimators.measurements import PAUSE_S
from odomgraph.estimators.shares import BEND_WIDTH, Shares
from odomgraph.io.log import Log

W_NAMES = ("v", "omega", "gyro_bias", "slip_left", "slip_right", "scale_left", "scale_right", "scale_track")


@dataclass(frozen=True)
class Keyframes:
    t: np.ndarray
    """(N,) keyframe times [s]."""
    enc_m: np.ndarray
    """(N-1, 2) average nominal-converted (left, right) wheel speed over each interval [m/s]."""
    enc_sigma: np.ndarray
    """(N-1, 2) its 1-sigma: eq. 41 averaged over the samples, plus quantisation [m/s]."""
    enc_n: np.ndarray
    """(N-1,) wheel rows (encoders.csv or wheel_speeds.csv) in each interval
    (t_k, t_{k+1}]: the rows the smoothers count as used (batch.measurement_counts)."""
    gyro_z: np.ndarray
    """(N-1,) average gyro reading over each interval [rad/s] (interval_means)."""
    gyro_sigma: np.ndarray
    """(N-1,) its 1-sigma [rad/s]; inf where the interval has no gyro data."""
    gyro_n: np.ndarray
    """(N-1,) gyro samples inside each interval."""
    vel_z: np.ndarray
    """(N-1, 2) average velocity-sensor reading [m/s, rad/s]."""
    vel_sigma: np.ndarray
    """(N-1, 2) its 1-sigma; inf where none."""
    vel_n: np.ndarray
    """(N-1,) velocity samples inside each interval."""
    gps_k: np.ndarray
    """(G,) interval of each GPS fix."""
    gps_tau_vw: np.ndarray
    """(G, 2) effective times (tau_v, tau_omega) of each fix after t_k
    (motion.arc_at): the share of the interval's wheel travel, and of the
    wheels' difference, done by the fix time, times dt [s]."""
    gps_xy: np.ndarray
    """(G, 2) antenna position [m]."""
    gps_sigma: np.ndarray
    """(G,) 1-sigma [m]."""
    rng_k: np.ndarray
    """(R,) interval of each range."""
    rng_tau_vw: np.ndarray
    """(R, 2) the same effective times for each range."""
    rng_beacon: np.ndarray
    """(R, 2) beacon position [m]."""
    rng_z: np.ndarray
    """(R,) measured range [m]."""
    rng_id: np.ndarray
    """(R,) index of the beacon in robot.beacons."""
    mid_tau_vw: np.ndarray
    """(N-1, 2) effective times (tau_v, tau_omega) of each interval's
    midpoint, its row's time (batch.keyframe_rows) [s]: tau_v as
    gps_tau_vw's (the wheels' travel), tau_omega the gyro's share of the
    interval's turn (estimators.shares; half the interval without one)."""
    trans_bend: np.ndarray | None = None
    """(N-1, 8) each interval's path against its arc: a complex factor on
    the transition's chord, an offset, a heading offset, and the chord's
    change with the turn rate (shares.Shares.bend, factors.motion.bend);
    mid_bend, gps_bend (G, 8), rng_bend (R, 8): likewise at the rows',
    fixes' and ranges' places. None: arcs."""
    mid_bend: np.ndarray | None = None
    gps_bend: np.ndarray | None = None
    rng_bend: np.ndarray | None = None
    gps_t: np.ndarray | None = None
    """(G,) time of each fix [s]."""

    @cached_property
    def dt(self) -> np.ndarray:
        """(N-1,) interval lengths [s], computed once (a stream's problem,
        estimators.growing, makes a new Keyframes per keyframe)."""
        return np.diff(self.t)

    @property
    def n(self) -> int:
        return len(self.t)


def bin_times(t_kf: np.ndarray, t: np.ndarray):
    """Interval index of each time (t_k <= t < t_{k+1}) and the mask of those inside."""
    k = np.searchsorted(t_kf, t, side="right") - 1
    inside = (k >= 0) & (k < len(t_kf) - 1)
    return k, inside


def interval_means(t_kf: np.ndarray, ts: np.ndarray, z: np.ndarray, sigma, q, causal: bool = False,
                   max_gap: float | None = None):
    """Average over each keyframe interval of a sampled rate signal, with its 1-sigma.

    The signal (a gyro's yaw rate, a velocity sensor's v and omega) is
    interpolated linearly between samples and held beyond the first and last,
    and the interpolant is integrated exactly over [t_k, t_{k+1}]. A plain mean
    of the samples inside the interval would be a Riemann sum whose sample
    times wander against the interval (25 Hz gyro, 5 Hz keyframes); while the
    rate ramps that error is correlated over the whole ramp and it biased the
    track width (benchmarks/track_bias.py).

    The variance has two parts: the sample noise through the integration
    weights, sum_i (w_i sigma)^2 / dt^2, and the interpolation error when the
    signal is a random walk of intensity q, pinned at the samples (a Brownian
    bridge between samples, a free walk beyond the ends): for a stretch
    [u0, u0 + L] of a gap [0, h] it is q^2 (u0 L^2 + L^3/3 - ((u0+L)^2 - u0^2)^2 / (4 h)).
    Samples next to an interval boundary feed both neighbours; that small
    correlation is ignored.

    ``causal``: interval k reads no sample after t_{k+1}; its tail after the
    last sample inside is held, with the free-walk variance. The incremental
    smoothers use this so that their online estimate at t_{k+1} needs no
    later data.

    Args:
        t_kf: (N,) keyframe times [s].
        ts: (M,) sample times [s], increasing.
        z: (M,) or (M, C) samples.
        sigma, q: scalar or (C,) sample 1-sigma and random-walk intensity per channel.
        causal: see above.

        max_gap: the longest gap between samples [s] the interpolant may
            bridge (None: any). A sparse sensor must not be held or
            interpolated over long stretches as if it had been measured
            there: an interval that would lean on a longer gap uses only the
            samples inside it, each standing for its own instant (variance
            sigma^2 / n plus q^2 dt / 3 for point against average), or none.

    Returns:
        mean: (N-1, C); sd: (N-1, C), inf where the interval has no sample
        inside and is not between two samples (close enough); n: (N-1,)
        samples inside.
    """
    t_kf = np.asarray(t_kf, float)
    ts = np.asarray(ts, float)
    z = np.asarray(z, float).reshape(len(ts), -1)
    sigma = np.broadcast_to(np.asarray(sigma, float), (z.shape[1],))
    q = np.broadcast_to(np.asarray(q, float), (z.shape[1],))
    M, nint = len(ts), len(t_kf) - 1
    a, b = t_kf[:-1], t_kf[1:]
    ja = np.searchsorted(ts, a, side="right") - 1               # last sample <= a (-1: none)
    jb = np.searchsorted(ts, b, side="right") - 1
    last = jb if causal else np.full(nint, M - 1)                  # last sample each interval may read
    span = np.clip(np.minimum(jb + 1, last), 0, M - 1) - np.clip(ja, 0, M - 1) + 1
    mean = np.empty((nint, z.shape[1]))
    var = np.empty((nint, z.shape[1]))
    # Rows are padded to the widest interval of their group: the few intervals
    # that span a sensor-rate gap in the keyframes go one at a time, so that a
    # single long gap cannot blow up the (intervals x samples) arrays.
    wide = span > max(8, 2 * int(np.median(span)))
    for rows in (np.flatnonzero(~wide), *np.flatnonzero(wide)[:, None]):
        if rows.size == 0:
            continue
        w, i = _hat_weights(ts, a[rows], b[rows], ja[rows], jb[rows], last[rows])
        dt = b[rows] - a[rows]
        mean[rows] = np.einsum("kw,kwc->kc", w, z[i]) / dt[:, None]
        model = _bridge_variance(ts, a[rows], b[rows], ja[rows], jb[rows], last[rows])
        var[rows] = (np.sum(w**2, 1)[:, None] * sigma**2 + model[:, None] * q**2) / dt[:, None] ** 2
    sd = np.sqrt(var)
    k, inside = bin_times(t_kf, ts)
    n = np.bincount(k[inside], minlength=nint)
    between = (ja >= 0) & (jb + 1 <= last)
    sd[~((n > 0) | between)] = np.inf
    if max_gap is not None and M > 0:
        big = np.concatenate([[0], np.cumsum(np.diff(ts) > max_gap)])       # big gaps before sample i
        lo, hi = np.clip(ja, 0, M - 1), np.clip(np.minimum(jb + 1, last), 0, M - 1)
        sparse = big[hi] - big[lo] > 0
        sparse |= (ja < 0) & (ts[0] - a > 0.5 * max_gap)                     # held before the first sample
        tail = ts[np.clip(np.where(causal, jb, np.minimum(jb + 1, M - 1)), 0, M - 1)]
        sparse |= (jb + 1 > last) & (b - tail > 0.5 * max_gap)               # held after the last one read
        if sparse.any():
            rows = np.flatnonzero(sparse)
            dt = (b - a)[rows]
            sums = np.stack([np.bincount(k[inside], z[inside, c], minlength=nint) for c in range(z.shape[1])], -1)
            with np.errstate(invalid="ignore", divide="ignore"):
                mean[rows] = sums[rows] / n[rows, None]
                sd[rows] = np.sqrt(sigma**2 / n[rows, None] + q**2 * dt[:, None] / 3.0)
            sd[rows[n[rows] == 0]] = np.inf
            mean[rows[n[rows] == 0]] = 0.0
    return mean, sd, n


def _hat_weights(ts, a, b, ja, jb, last):
    """Integration weights [s] of the samples over each [a, b] (interval_means):
    (w (K, width), sample index i (K, width)), zero-padded."""
    M = len(ts)
    T0 = min(a.min(), ts[0]) - 1.0
    lo = np.clip(ja, 0, M - 1)
    hi = np.clip(np.minimum(jb + 1, last), 0, M - 1)
    width = int((hi - lo).max()) + 1
    cols = lo[:, None] + np.arange(width)[None, :]
    valid = cols <= hi[:, None]
    i = np.minimum(cols, M - 1)

    def hat_integral(t):
        """(K, width) integral from T0 to t of sample i's hat basis function."""
        t = t[:, None]
        tl = np.where(i > 0, ts[np.maximum(i - 1, 0)], T0)
        ti = ts[i]
        hl = ti - tl
        s = np.clip(t - tl, 0.0, hl)
        left = np.where(i > 0, s**2 / (2 * np.where(hl > 0, hl, 1.0)), s)   # first sample: held
        has_r = i < last[:, None]
        hr = np.where(has_r, ts[np.minimum(i + 1, M - 1)] - ti, 1.0)
        s = np.clip(t - ti, 0.0, np.where(has_r, hr, np.inf))
        right = np.where(has_r, s - s**2 / (2 * hr), s)                     # last sample: held
        return left + right

    return np.where(valid, hat_integral(b) - hat_integral(a), 0.0), i


def _bridge_variance(ts, a, b, ja, jb, last):
    """(K,) variance [s^3] per unit q^2 of the integral over [a, b] of a random
    walk's interpolation error, pinned at the samples (interval_means)."""
    M = len(ts)
    j = ja[:, None] + np.arange(int((jb - ja).max()) + 2)[None, :]          # (K, W) gap [ts[j], ts[j+1]]
    last = last[:, None]
    a, b = a[:, None], b[:, None]
    segl = np.where(j >= 0, ts[np.clip(j, 0, M - 1)], -np.inf)
    segr = np.where(j + 1 <= last, ts[np.clip(j + 1, 0, M - 1)], np.inf)
    u0, u1 = np.maximum(a, segl), np.minimum(b, segr)
    L = np.clip(u1 - u0, 0.0, None)
    bridge = np.isfinite(segl) & np.isfinite(segr)
    left_pinned = np.isfinite(segl)
    # distance of the stretch from the pinned end (the left sample, or the right one before the first sample)
    d0 = np.where(left_pinned, u0 - np.where(left_pinned, segl, 0.0), np.where(left_pinned, 0.0, segr) - u1)
    h = np.where(bridge, segr - segl, 1.0)
    base = np.where(left_pinned, segl, 0.0)
    pin = np.where(bridge, ((u1 - base) ** 2 - (u0 - base) ** 2) ** 2 / (4 * h), 0.0)
    return np.where((j <= jb[:, None]) & (L > 0), d0 * L**2 + L**3 / 3 - pin, 0.0).sum(1)


def _max_gap(ts: np.ndarray, t_kf: np.ndarray) -> float:
    """The longest sample gap a rate sensor's interpolant may bridge [s]: two
    keyframe intervals, or three of the sensor's periods up to half a second.
    A yaw rate interpolated over longer is a guess, not a measurement (a
    25 Hz gyro at 5 Hz keyframes bridges 0.4 s; five samples in 40 s bridge
    nothing, each standing for its own instant)."""
    period = float(np.median(np.diff(ts))) if len(ts) > 1 else np.inf
    return max(min(3.0 * period, 0.5), 2.0 * float(np.median(np.diff(t_kf))))


def keyframe_step(t: np.ndarray, keyframe_hz: float) -> int:
    """Wheel rows per keyframe: about ``keyframe_hz`` [Hz] on rows at times t [s] (at least 1)."""
    return max(1, int(round((1.0 / keyframe_hz) / np.median(np.diff(t))))) if len(t) > 1 else 1


def build_keyframes(log: Log, t_start: float, keyframe_hz: float, causal: bool = False,
                    step: int | None = None) -> Keyframes:
    """Keyframes from ``t_start`` on, at about ``keyframe_hz`` (at most the encoder rate).

    ``causal``: no interval reads data after its end (interval_means); for
    the incremental smoothers. ``step``: wheel rows per keyframe, when the
    caller fixed it (a stream, odomgraph.online: the rows so far decide it);
    None: keyframe_step over the log's wheel rows."""
    r = log.robot
    a, b = r.encoder_sigma
    if log.encoders is not None:
        e = log.encoders
        tpm = np.array([r.ticks_per_meter_left, r.ticks_per_meter_right])
        t_all = e.t
        first = int(np.searchsorted(t_all, t_start, side="left"))
        step = step or keyframe_step(t_all, keyframe_hz)
        idx = np.arange(first, len(t_all), step)
        if idx[-1] != len(t_all) - 1:
            idx = np.append(idx, len(t_all) - 1)
        t = t_all[idx]
        ticks = np.stack([e.ticks_left, e.ticks_right], -1)
        cum = np.concatenate([np.zeros((1, 2)), np.cumsum(ticks[1:], 0)])      # ticks up to row i
        dt_k = np.diff(t)
        m = (cum[idx[1:]] - cum[idx[:-1]]) / (tpm * dt_k[:, None])
        # eq. 41 per encoder sample, averaged: var = sum (sigma_i dt_i)^2 / dt_k^2
        dti = np.diff(t_all)
        mi = ticks[1:] / (tpm * dti[:, None])
        vi = (speed_sigma(mi, a, b) * dti[:, None]) ** 2
        cumv = np.concatenate([np.zeros((1, 2)), np.cumsum(vi, 0)])
        # quantisation counts once per keyframe interval (only its two ends are floored)
        quant = speed_sigma(np.zeros_like(m), 0.0, 0.0, tpm, dt_k[:, None])
        sigma = np.sqrt((cumv[idx[1:]] - cumv[idx[:-1]]) / dt_k[:, None] ** 2 + quant**2)
    else:
        w = log.wheel_speeds
        first = int(np.searchsorted(w.t, t_start, side="left"))
        step = step or keyframe_step(w.t, keyframe_hz)
        idx = np.arange(first, len(w.t), step)
        if idx[-1] != len(w.t) - 1:
            idx = np.append(idx, len(w.t) - 1)
        t = w.t[idx]
        # The speeds are instants (LOG_FORMAT), the keyframes sit on samples:
        # each interval's mean speed is the trapezoid over its samples, both
        # ends included (interval_means with q = 0). The mean of the samples
        # in [t_k, t_{k+1}) was a left Riemann sum, half a sample period late:
        # while the robot accelerated the wheels lagged the gyro and the
        # fixes, and a 5 s drive's scale factors came out 1-3 % low at z 3-5
        # (a probe's short bags; tests/test_wheel_speed_means.py).
        ms = np.stack([w.v_left, w.v_right], -1)
        m = interval_means(t, w.t, ms, 0.0, 0.0, causal)[0]
        # eq. 41 at the interval's mean speed over its n rows: each row counts
        # in one interval (the trapezoid shares its end rows with the
        # neighbours, and its weights' sqrt(sum w^2) / dt counted them twice:
        # 29 % too confident at one row per interval, a second read)
        sigma = speed_sigma(m, a, b) / np.sqrt(np.diff(idx))[:, None]
        # An interval that spans a pause in the log (no sample for longer than
        # PAUSE_S) has no speed measured over it: its one sample is an
        # instant, not its average (a day's pause after a sample of 0.5 m/s
        # put the robot 3.6 km away in the smoothers' first linearisation).
        # Taken as standing still, with a random walk's spread over it.
        paused = np.diff(t) > PAUSE_S
        if paused.any():
            pn = r.process
            q2 = pn.accel**2 + (0.5 * r.track_width * pn.yaw_accel) ** 2
            m[paused] = 0.0
            sigma[paused] = np.sqrt(sigma[paused] ** 2 + q2 * np.diff(t)[paused, None] / 3.0)
    nint = len(t) - 1
    pn = r.process
    gyro_z, gyro_sd, gyro_n = np.zeros(nint), np.full(nint, np.inf), np.zeros(nint, int)
    if log.gyro is not None and len(log.gyro.t):
        z, sd, gyro_n = interval_means(t, log.gyro.t, log.gyro.omega, r.gyro_sigma,
                                       np.hypot(pn.yaw_accel, pn.gyro_bias), causal, _max_gap(log.gyro.t, t))
        gyro_z, gyro_sd = z[:, 0], sd[:, 0]
    # The rows' midpoints. A row flown half an interval at the average speed
    # is off by a dt^2 / 8 along the track where the robot accelerates: 10 cm
    # at 20 m/s^2 and 5 Hz keyframes, at a sigma of 5 mm (a probe's fast
    # robot); the wheels' travel says how far it got. Not how far it turned:
    # the wheels' difference is slip and noise as much as turning (its share
    # put a steady turn's row 3 degrees off at a sigma of 0.4, a second read),
    # and half the interval's turn put the row after a pivot that ended early
    # in its interval 0.09 rad off at a sigma of 0.007 (a probe's paper log
    # run 3x faster): the gyro's share, or half without a gyro's turn.
    sh = Shares(log)
    t0, t1, tm = t[:-1], t[1:], t[:-1] + 0.5 * np.diff(t)
    mid_share = np.stack([sh.travel(t0, t1, tm), sh.gyro_turn(t0, t1, tm, 0.5)], -1)
    mid_tau = mid_share * np.diff(t)[:, None]
    mid_bend = sh.bend(t0, t1, tm, mid_share[:, 0], mid_share[:, 1])
    trans_bend = sh.bend(t0, t1, t1, np.ones(nint), np.ones(nint))

    def bent(k, ts, tvw):
        """(len, BEND_WIDTH) the bend (Shares.bend) at times ts in intervals k placed by tvw (effective)."""
        dt = t[k + 1] - t[k]
        return sh.bend(t[k], t[k + 1], ts, tvw[:, 0] / dt, tvw[:, 1] / dt)

    def effective(k, ts):
        """(len, 2) effective (tau_v, tau_omega) [s] of times ts in intervals
        k: the shares of the wheels' travel and of their difference, times dt.
        (The wheels' difference, not the gyro: on a nearly noise-free log it
        placed the fixes better than a 25 Hz gyro's interpolated turn, track
        scale 6e-5 against 1.4e-4 off, tests/test_smoothers.py, measured on
        plain arcs. The bend, gps_bend, then lays the place on the path the
        gyro turned.)"""
        t0, t1 = t[k], t[k + 1]
        return np.stack([sh.travel(t0, t1, ts), sh.wheel_turn(t0, t1, ts)], -1) * (t1 - t0)[:, None]

    vel_z, vel_sd, vel_n = np.zeros((nint, 2)), np.full((nint, 2), np.inf), np.zeros(nint, int)
    if log.velocity is not None and len(log.velocity.t):
        vel_z, vel_sd, vel_n = interval_means(t, log.velocity.t, np.stack([log.velocity.v, log.velocity.omega], -1),
                                              r.velocity_sigma, (pn.accel, pn.yaw_accel), causal,
                                              _max_gap(log.velocity.t, t))
    empty2 = np.zeros((0, 2))
    gk = gs = gt = np.zeros(0)
    gxy = gvw = empty2
    gb = np.zeros((0, BEND_WIDTH))
    if log.gps is not None and len(log.gps.t):
        g = log.gps
        k, inside = bin_times(t, g.t)
        gk = k[inside]
        gvw = effective(gk, g.t[inside])
        gb = bent(gk, g.t[inside], gvw)
        gxy = np.stack([g.x, g.y], -1)[inside]
        gs = (g.sigma if g.sigma is not None else np.full(len(g.t), r.gps_sigma))[inside]
        gt = g.t[inside]
    rk = rz = rid = np.zeros(0)
    rb = rvw = empty2
    rbd = np.zeros((0, BEND_WIDTH))
    if log.ranges is not None and len(log.ranges.t):
        rg = log.ranges
        k, inside = bin_times(t, rg.t)
        rk, rz = k[inside], rg.range[inside]
        rvw = effective(rk, rg.t[inside])
        rbd = bent(rk, rg.t[inside], rvw)
        rb = np.asarray([[bc.x, bc.y] for bc in r.beacons])[rg.beacon[inside]]
        rid = rg.beacon[inside]
    return Keyframes(t=t, enc_m=m, enc_sigma=sigma, enc_n=np.diff(idx), gyro_z=gyro_z, gyro_sigma=gyro_sd,
                     gyro_n=np.asarray(gyro_n),
                     vel_z=vel_z, vel_sigma=vel_sd, vel_n=np.asarray(vel_n), gps_k=gk.astype(int), gps_tau_vw=gvw,
                     gps_xy=gxy, gps_sigma=gs, gps_t=gt, rng_k=rk.astype(int), rng_tau_vw=rvw, rng_beacon=rb, rng_z=rz,
                     rng_id=np.asarray(rid, int), mid_tau_vw=mid_tau,
                     trans_bend=trans_bend, mid_bend=mid_bend, gps_bend=gb, rng_bend=rbd)
