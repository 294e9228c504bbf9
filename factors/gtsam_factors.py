"""GTSAM adapters of the models: one gtsam.CustomFactor per model.

Each error function calls the same numpy model as the EKF and the vectorised
smoother (scalar path), converts world-frame pose Jacobians to GTSAM's
body-frame Pose2 tangent (factors.pose2.to_body), and fills Jacobians only
when GTSAM asks. Noise models stay outside the error functions.

Variables, as in the incremental smoothers (odomgraph/estimators/incremental.py):
    X(k): gtsam.Pose2, robot pose at keyframe k
    W(k): Vector6 (v, omega, gyro_bias, scale_left, scale_right, scale_track), interval averages
    S(k): Vector2 (slip_left, slip_right), interval averages

These factors are the "straightforward design": correct and simple, but
inside GTSAM's optimisers every Python callback receives a copy of the
whole Values, so large graphs built from them are slow (benchmarks/README.md).
The estimators use the vectorised linearisation in odomgraph/estimators/graph.py,
which the tests check against these factors.
"""
from __future__ import annotations

from functools import partial

import gtsam
import numpy as np

from odomgraph.factors import encoder, gps, gyro, pose2, pseudo, ranging, velocity
from odomgraph.factors.motion import arc_at, transition_residual


def _pose(values, key):
    p = values.atPose2(key)
    return p.x(), p.y(), p.theta()


# ------------------------------------------------------------------ errors
def _encoder_error(z, track, this, values, jacobians):
    kw, ks = this.keys()
    w, s = values.atVector(kw), values.atVector(ks)
    h, J = encoder.wheel_speeds(w[0], w[1], s[0], s[1], w[3], w[4], w[5], track)   # eq. 29-34
    if jacobians is not None:
        JW = np.zeros((2, 6))
        JW[:, [0, 1, 3, 4, 5]] = J[:, [0, 1, 4, 5, 6]]
        jacobians[0] = JW
        jacobians[1] = J[:, 2:4].copy()
    return h - z


def _gyro_error(z, this, values, jacobians):
    w = values.atVector(this.keys()[0])
    h, J = gyro.yaw_rate(w[1], w[2])                                                 # eq. 10-11
    if jacobians is not None:
        JW = np.zeros((1, 6))
        JW[0, 1:3] = J[0]
        jacobians[0] = JW
    return h - z


def _velocity_error(z, this, values, jacobians):
    w = values.atVector(this.keys()[0])
    h, J = velocity.body_velocity(w[0], w[1])
    if jacobians is not None:
        JW = np.zeros((2, 6))
        JW[:, 0:2] = J
        jacobians[0] = JW
    return h - z


def _arc_to(values, kx, kw, tau, q):
    """tau: a time [s], or the effective (tau_v, tau_omega) of motion.arc_at;
    q: the path's bend (motion.bend), or None."""
    x, y, th = _pose(values, kx)
    w = values.atVector(kw)
    tv, tw = (tau, tau) if np.ndim(tau) == 0 else tau
    p, Jf = arc_at(x, y, th, w[0], w[1], tv, tw, q)
    return p, Jf, th


def _gps_error(z, tau, lever, q, this, values, jacobians):
    kx, kw = this.keys()
    p, Jf, th = _arc_to(values, kx, kw, tau, q)
    h, Jh = gps.antenna_position(p[0], p[1], p[2], lever)                            # eq. 8-9
    if jacobians is not None:
        Jt = Jh @ Jf
        jacobians[0] = pose2.to_body(Jt[:, 0:3], th)
        JW = np.zeros((2, 6))
        JW[:, 0:2] = Jt[:, 3:5]
        jacobians[1] = JW
    return h - z


def _range_error(z, tau, beacon, lever, q, this, values, jacobians):
    kx, kw = this.keys()
    p, Jf, th = _arc_to(values, kx, kw, tau, q)
    h, Jh = ranging.beacon_range(p[0], p[1], p[2], beacon, lever)                   # eq. 12-16
    if jacobians is not None:
        Jt = Jh[:, 0:3] @ Jf
        jacobians[0] = pose2.to_body(Jt[:, 0:3], th)
        JW = np.zeros((1, 6))
        JW[:, 0:2] = Jt[:, 3:5]
        jacobians[1] = JW
    return h - np.array([z])


def _motion_error(dt, q, this, values, jacobians):
    kx0, kw, kx1 = this.keys()
    x, y, th = _pose(values, kx0)
    x1, y1, th1 = _pose(values, kx1)
    w = values.atVector(kw)
    e, J0, J1 = transition_residual(x, y, th, w[0], w[1], dt, x1, y1, th1, q)       # eq. 2-6
    if jacobians is not None:
        jacobians[0] = pose2.to_body(J0[:, 0:3], th)
        JW = np.zeros((3, 6))
        JW[:, 0:2] = J0[:, 3:5]
        jacobians[1] = JW
        jacobians[2] = pose2.to_body(J1, th1)
    return e


def _zero_slip_error(this, values, jacobians):
    s = values.atVector(this.keys()[0])
    h, J = pseudo.zero_slip(s[0], s[1])                                             # eq. 35-36
    if jacobians is not None:
        jacobians[0] = J
    return h


def _hold_scale_error(held, this, values, jacobians):
    w = values.atVector(this.keys()[0])
    h, J = pseudo.hold_scale(w[3], w[4], w[5])                                      # eq. 37-38
    if jacobians is not None:
        JW = np.zeros((3, 6))
        JW[:, 3:6] = J
        jacobians[0] = JW
    return h - held


# ---------------------------------------------------------------- builders
def encoder_factor(kw, ks, z, noise, track) -> gtsam.CustomFactor:
    """Average wheel speeds z (2,) [m/s] over an interval, on W(k), S(k)."""
    return gtsam.CustomFactor(noise, [kw, ks], partial(_encoder_error, np.asarray(z, float), float(track)))


def gyro_factor(kw, z, noise) -> gtsam.CustomFactor:
    """Average gyro reading z [rad/s] over an interval, on W(k)."""
    return gtsam.CustomFactor(noise, [kw], partial(_gyro_error, np.array([z], float)))


def velocity_factor(kw, z, noise) -> gtsam.CustomFactor:
    """Average velocity-sensor reading z = (v, omega), on W(k)."""
    return gtsam.CustomFactor(noise, [kw], partial(_velocity_error, np.asarray(z, float)))


def _tau(tau):
    return float(tau) if np.ndim(tau) == 0 else (float(tau[0]), float(tau[1]))


def _q(q):
    return None if q is None else np.asarray(q, float)


def gps_factor(kx, kw, z, tau, lever, noise, q=None) -> gtsam.CustomFactor:
    """Antenna fix z (2,) [m] at tau after keyframe k, on X(k), W(k); tau [s] is a
    time or the effective (tau_v, tau_omega) of motion.arc_at; q (4,), (5,) or (8,): the
    path's bend there (Keyframes.gps_bend), or None: the arc."""
    return gtsam.CustomFactor(noise, [kx, kw], partial(_gps_error, np.asarray(z, float), _tau(tau),
                                                      tuple(lever), _q(q)))


def range_factor(kx, kw, z, tau, beacon, lever, noise, q=None) -> gtsam.CustomFactor:
    """Range z [m] to ``beacon`` (2,) at tau after keyframe k (as gps_factor), on X(k), W(k)."""
    return gtsam.CustomFactor(noise, [kx, kw], partial(_range_error, float(z), _tau(tau),
                                                      np.asarray(beacon, float), tuple(lever), _q(q)))


def motion_factor(kx0, kw, kx1, dt, noise, q=None) -> gtsam.CustomFactor:
    """X(k+1) against the arc flown from X(k) with W(k)'s average velocity for
    dt [s], its chord bent by q (Keyframes.trans_bend), or None: the arc."""
    return gtsam.CustomFactor(noise, [kx0, kw, kx1], partial(_motion_error, float(dt), _q(q)))


def zero_slip_factor(ks, noise) -> gtsam.CustomFactor:
    """The zero-slip pseudo-update as a factor on S(k)."""
    return gtsam.CustomFactor(noise, [ks], _zero_slip_error)


def hold_scale_factor(kw, held, noise) -> gtsam.CustomFactor:
    """The hold-scale pseudo-update: scale factors of W(k) at ``held`` (3,)."""
    return gtsam.CustomFactor(noise, [kw], partial(_hold_scale_error, np.asarray(held, float)))
