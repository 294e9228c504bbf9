"""Turn a Scenario into a log: true motion on a fine grid, then each sensor at
its own rate and phase, with the noise of paper eq. 39-41.

The true pose is integrated with the same exact-arc model the estimators use
(factors.motion), on a 200 Hz grid. Encoder ticks are true integer counts: the
noisy wheel distance is accumulated and floored, so quantisation is real.
"""
from __future__ import annotations

import numpy as np

from odomgraph.factors import gps as gps_model
from odomgraph.factors import ranging
from odomgraph.factors._math import wrap_angle
from odomgraph.io.log import Encoders, Gps, Gyro, Log, Ranges, Truth, Velocity
from odomgraph.io.robot import InitialPose
from odomgraph.sim.scenarios import Scenario

FINE_HZ = 200.0


def _commands(sc: Scenario, t: np.ndarray):
    """Commanded (v, omega) on the fine grid: prologue then the loop repeated."""
    segs, ends, total = [], [], 0.0
    for s in sc.prologue:
        segs.append(s); total += s.duration; ends.append(total)
    loop_len = sum(s.duration for s in sc.loop)
    while total < sc.duration + sc.smoothing and loop_len > 0:
        for s in sc.loop:
            segs.append(s); total += s.duration; ends.append(total)
    k = np.minimum(np.searchsorted(np.asarray(ends), t, side="right"), len(segs) - 1)
    v = np.asarray([s.v for s in segs])[k]
    w = np.asarray([s.omega for s in segs])[k]
    for a, b in sc.holds:
        held = (t >= a) & (t <= b)
        v, w = np.where(held, 0.0, v), np.where(held, 0.0, w)
    return v, w


def _smooth(x: np.ndarray, width_s: float) -> np.ndarray:
    n = max(1, int(round(width_s * FINE_HZ)))
    if n == 1:
        return x
    pad = np.concatenate([np.full(n, x[0]), x, np.full(n, x[-1])])
    return np.convolve(pad, np.ones(n) / n, mode="same")[n:-n]


def slip_profile(sc: Scenario, t: np.ndarray):
    """True (slip_left, slip_right) [m/s] at times t: trapezoids of each event."""
    out = {"left": np.zeros_like(t), "right": np.zeros_like(t)}
    for e in sc.slips:
        r = max(e.ramp, 1e-6)
        up = np.clip((t - (e.start - r)) / r, 0.0, 1.0)
        down = np.clip(((e.end + r) - t) / r, 0.0, 1.0)
        out[e.wheel] = out[e.wheel] + e.speed * np.minimum(up, down)
    return out["left"], out["right"]


def _sensor_times(rng, rate: float, t0: float, t1: float, jitter: float) -> np.ndarray:
    """Times at ``rate`` with a random phase and jitter; strictly increasing."""
    if rate <= 0:
        return np.zeros(0)
    period = 1.0 / rate
    base = np.arange(t0 + rng.uniform(0, period), t1, period)
    return base + rng.uniform(-jitter, jitter, base.size) * period


def simulate(sc: Scenario, seed: int = 0, timing_seed: int | None = None) -> Log:
    """Simulate ``sc`` with random seed ``seed``; returns a Log with truth.

    ``timing_seed``, when given, draws every sensor's phase and jitter from its
    own generator, so logs with different ``seed`` and the same
    ``timing_seed`` share their timestamps exactly and differ only in noise
    (what a Monte-Carlo study vectorised over runs needs, see ekf_many).
    """
    rng = np.random.default_rng(seed)
    rng_t = rng if timing_seed is None else np.random.default_rng(timing_seed)
    robot, (kl, kr, kb) = sc.robot, sc.scales
    track_true = kb * robot.track_width
    tpm_true = (kl * robot.ticks_per_meter_left, kr * robot.ticks_per_meter_right)

    dt = 1.0 / FINE_HZ
    tf = np.arange(0.0, sc.duration + 2 * dt, dt)
    v_cmd, w_cmd = _commands(sc, tf)
    v, w = _smooth(v_cmd, sc.smoothing), _smooth(w_cmd, sc.smoothing)

    # Exact-arc integration on the fine grid (factors.motion, vectorised):
    # theta_k from the running sum, then each step's chord in one call.
    x0, y0, th0 = sc.start_pose
    th = th0 + np.concatenate([[0.0], np.cumsum(w[:-1] * dt)])
    from odomgraph.factors.motion import propagate
    step, _ = propagate(0.0, 0.0, th[:-1], v[:-1], w[:-1], dt)
    x = x0 + np.concatenate([[0.0], np.cumsum(step[:, 0])])
    y = y0 + np.concatenate([[0.0], np.cumsum(step[:, 1])])

    slip_l, slip_r = slip_profile(sc, tf)
    u_l = v - w * track_true / 2 + slip_l   # true wheel surface speeds [m/s]
    u_r = v + w * track_true / 2 + slip_r
    dist_l = np.concatenate([[0.0], np.cumsum(0.5 * (u_l[1:] + u_l[:-1]) * dt)])
    dist_r = np.concatenate([[0.0], np.cumsum(0.5 * (u_r[1:] + u_r[:-1]) * dt)])

    R = sc.rates
    t_end = sc.duration
    log_parts = {}

    # --- encoders: noisy distance per interval (eq. 41), then integer ticks.
    te = _sensor_times(rng_t, R.encoders, 0.0, t_end, R.jitter)
    a, b = robot.encoder_sigma
    noisy = []
    for dist, tpm in ((dist_l, tpm_true[0]), (dist_r, tpm_true[1])):
        d = np.interp(te, tf, dist)
        inc = np.diff(d)
        dte = np.diff(te)
        sig = a + b * np.abs(inc / dte)
        inc_noisy = inc + rng.normal(size=inc.size) * sig * dte
        cum = np.concatenate([[d[0]], d[0] + np.cumsum(inc_noisy)])
        ticks = np.floor(cum * tpm)
        noisy.append(np.concatenate([[0.0], np.diff(ticks)]))
    log_parts["encoders"] = Encoders(te, noisy[0], noisy[1])

    # --- gyro: true rate + (drifting) bias + white noise (eq. 10, 40).
    tg = _sensor_times(rng_t, R.gyro, 0.0, t_end, R.jitter)
    if tg.size:
        bias_f = sc.gyro_bias + np.concatenate([[0.0], np.cumsum(rng.normal(size=tf.size - 1))]) \
            * sc.gyro_bias_walk * np.sqrt(dt)
        om = np.interp(tg, tf, w) + np.interp(tg, tf, bias_f) + rng.normal(size=tg.size) * robot.gyro_sigma
        log_parts["gyro"] = Gyro(tg, om)
    else:
        bias_f = np.full_like(tf, sc.gyro_bias)

    def pose_at(t):
        return np.interp(t, tf, x), np.interp(t, tf, y), np.interp(t, tf, th)

    # --- GPS: antenna position with lever arm (eq. 8) + noise (eq. 39).
    tp = _sensor_times(rng_t, R.gps, 0.0, t_end, R.jitter)
    if tp.size:
        h, _ = gps_model.antenna_position(*pose_at(tp), robot.gps_lever_arm)
        h = h + rng.normal(size=h.shape) * robot.gps_sigma
        log_parts["gps"] = Gps(tp, h[:, 0], h[:, 1])

    # --- ranges: beacons polled round-robin, each at R.ranges Hz (eq. 12).
    nb = len(robot.beacons)
    if R.ranges > 0 and nb:
        tr = _sensor_times(rng_t, R.ranges * nb, 0.0, t_end, R.jitter)
        which = np.arange(tr.size) % nb
        bxy = np.asarray([[bc.x, bc.y] for bc in robot.beacons])[which]
        h, _ = ranging.beacon_range(*pose_at(tr), bxy, robot.range_lever_arm)
        r = np.abs(h[:, 0] + rng.normal(size=tr.size) * robot.range_sigma)
        log_parts["ranges"] = Ranges(tr, which, r)

    # --- body-velocity sensor (visual odometry, sec. VI-B).
    tv = _sensor_times(rng_t, R.velocity, 0.0, t_end, R.jitter)
    if tv.size:
        sv, sw = robot.velocity_sigma
        log_parts["velocity"] = Velocity(tv, np.interp(tv, tf, v) + rng.normal(size=tv.size) * sv,
                                         np.interp(tv, tf, w) + rng.normal(size=tv.size) * sw)

    # --- truth at its own rate, wheel slips as LOG_FORMAT defines them.
    tt = np.arange(0.0, t_end, 1.0 / R.truth)
    truth = Truth(tt, {
        "x": np.interp(tt, tf, x), "y": np.interp(tt, tf, y), "theta": wrap_angle(np.interp(tt, tf, th)),
        "v": np.interp(tt, tf, v), "omega": np.interp(tt, tf, w),
        "slip_left": np.interp(tt, tf, slip_l), "slip_right": np.interp(tt, tf, slip_r),
        "gyro_bias": np.interp(tt, tf, bias_f),
    })
    if sc.write_initial:
        robot = robot.with_(initial=InitialPose(x0, y0, th0, (0.05, 0.05, 0.02)))
    return Log(robot=robot, truth=truth, truth_scales=tuple(sc.scales), **log_parts)


def beacons_around_path(sc: Scenario, n: int = 3):
    """n beacons around the true path of ``sc`` (scenarios.beacons_around on its
    bounding box; the motion does not depend on noise or seed)."""
    from odomgraph.sim.scenarios import Rates, beacons_around
    v = simulate(sc.with_(rates=Rates(encoders=5.0, gyro=0.0, gps=0.0, truth=sc.rates.truth)), 0).truth.values
    return beacons_around(v["x"].min(), v["x"].max(), v["y"].min(), v["y"].max(), n)
