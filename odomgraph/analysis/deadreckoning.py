"""Dead reckoning: wheel odometry alone, with given parameters, from a given pose.

The reference every calibration is judged by: integrate the encoder model
(factors.encoder.body_velocity, paper eq. 19-20 inverted) with the exact arc
(factors.motion) and compare with truth.
"""
from __future__ import annotations

import numpy as np

from odomgraph.factors.encoder import body_velocity
from odomgraph.factors.motion import propagate
from odomgraph.io.log import Log


def wheel_speeds_of(log: Log) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t_end of each interval, m_left, m_right) in m/s with the log's nominal ticks/m."""
    r = log.robot
    if log.encoders is not None:
        e = log.encoders
        dt = np.diff(e.t)
        return e.t[1:], e.ticks_left[1:] / (r.ticks_per_meter_left * dt), e.ticks_right[1:] / (r.ticks_per_meter_right * dt)
    w = log.wheel_speeds
    return w.t, w.v_left, w.v_right


def dead_reckon(log: Log, scales=(1.0, 1.0, 1.0), start=None) -> tuple[np.ndarray, np.ndarray]:
    """Path (t (K,), pose (K, 3) world) of pure odometry.

    ``scales`` = (scale_left, scale_right, scale_track) applied to the log's
    nominal parameters (LOG_FORMAT convention). ``start`` = (t0, x, y, theta);
    default: the first truth pose at the first encoder time.
    """
    t, ml, mr = wheel_speeds_of(log)
    t_prev = np.concatenate([[log.encoders.t[0] if log.encoders is not None else t[0]], t[:-1]])
    if start is None:
        t0 = t_prev[0]
        start = (t0, *(log.truth.at(k, np.array([t0]))[0] for k in ("x", "y", "theta")))
    t0, x, y, th = start
    v, w = body_velocity(ml, mr, 0.0, 0.0, scales[0], scales[1], scales[2], log.robot.track_width)
    keep = t_prev >= t0 - 1e-9
    poses = np.empty((int(keep.sum()), 3))
    pose = np.array([x, y, th], float)
    for j, i in enumerate(np.nonzero(keep)[0]):
        pose, _ = propagate(pose[0], pose[1], pose[2], v[i], w[i], t[i] - t_prev[i])
        poses[j] = pose
    return t[keep], poses


def final_position_error(log: Log, scales=(1.0, 1.0, 1.0)) -> float:
    """Distance [m] between the dead-reckoned and the true position at the end."""
    t, p = dead_reckon(log, scales)
    te = min(t[-1], log.truth.t[-1])
    k = int(np.searchsorted(t, te)) - 1 if te < t[-1] else len(t) - 1
    return float(np.hypot(p[k, 0] - log.truth.at("x", np.array([t[k]]))[0],
                          p[k, 1] - log.truth.at("y", np.array([t[k]]))[0]))


def best_fit_scales(logs: list[Log], start=(1.0, 1.0, 1.0), iterations: int = 20,
                    whole_path: bool = False) -> np.ndarray:
    """The three scale factors minimising the squared final-position errors of
    dead reckoning over ``logs`` (Gauss-Newton, numerical Jacobian): the
    oracle a calibration is compared with. ``whole_path`` fits every tenth
    position of the path instead of the final one."""
    s = np.asarray(start, float)
    rows = slice(None, None, 10) if whole_path else slice(-1, None)

    def residual(sc):
        out = []
        for lg in logs:
            t, p = dead_reckon(lg, sc)
            t, p = t[rows], p[rows]
            out += [p[:, 0] - lg.truth.at("x", t), p[:, 1] - lg.truth.at("y", t)]
        return np.concatenate(out)

    for _ in range(iterations):
        r0 = residual(s)
        J = np.stack([(residual(s + d) - r0) / 1e-6 for d in np.eye(3) * 1e-6], 1)
        step, *_ = np.linalg.lstsq(J, -r0, rcond=None)
        s = s + step
        if np.abs(step).max() < 1e-9:
            break
    return s
