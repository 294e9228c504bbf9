"""Differential-drive motion over one (variable) time step. Paper eq. 2-6.

The paper writes the position update with the midpoint heading,

    x' = x + v dt cos(theta + omega dt / 2)                      (eq. 2)
    y' = y + v dt sin(theta + omega dt / 2)                      (eq. 3)

which is the first-order form of the exact constant-twist arc. We integrate
the arc exactly, because the smoother integrates over keyframe intervals much
longer than an EKF step:

    x' = x + v dt sinc(omega dt / 2) cos(theta + omega dt / 2)
    y' = y + v dt sinc(omega dt / 2) sin(theta + omega dt / 2)
    theta' = theta + omega dt                                    (eq. 4)
    v' = v,  omega' = omega                                      (eq. 5-6)

(Derivation: integrate x' = v cos(theta + omega t) over [0, dt]; the result
v/omega (sin(theta + a) - sin theta), a = omega dt, equals the line above by the
sum-to-product identity.) sinc(a/2) -> 1 recovers eq. 2-3; at omega -> 0 the
series branch of ``sinc`` keeps it exact. Velocities are states with a random
walk; that part lives in the estimators' process models.
"""
from __future__ import annotations

import numpy as np

from odomgraph.factors._math import dsinc, shape_of, sinc

INPUTS = ("x", "y", "theta", "v", "omega")


def propagate(x, y, theta, v, omega, dt):
    """Pose after moving with constant body velocity for ``dt``.

    Args:
        x, y: (...) position of the robot origin, world frame [m].
        theta: (...) heading, world frame, CCW from x [rad].
        v: (...) forward speed of the origin [m/s].
        omega: (...) yaw rate [rad/s].
        dt: (...) time step [s]; any sign, any size.

    Returns:
        pose: (..., 3) [x', y', theta'] (theta' not wrapped, so that the
            Jacobian stays continuous; callers wrap).
        J: (..., 3, 5) d pose / d (x, y, theta, v, omega).
    """
    shape = shape_of(x, y, theta, v, omega, dt)
    half = 0.5 * omega * dt
    s, ds = sinc(half), dsinc(half)
    phi = theta + half
    c, sn = np.cos(phi), np.sin(phi)
    d = v * dt * s  # chord length of the arc [m]

    pose = np.empty(shape + (3,))
    pose[..., 0] = x + d * c
    pose[..., 1] = y + d * sn
    pose[..., 2] = theta + omega * dt

    J = np.zeros(shape + (3, 5))
    J[..., 0, 0] = 1.0
    J[..., 1, 1] = 1.0
    J[..., 2, 2] = 1.0
    J[..., 0, 2] = -d * sn
    J[..., 1, 2] = d * c
    J[..., 0, 3] = dt * s * c
    J[..., 1, 3] = dt * s * sn
    # d/d omega through both the chord length (sinc) and the midpoint heading.
    k = v * dt * 0.5 * dt
    J[..., 0, 4] = k * (ds * c - s * sn)
    J[..., 1, 4] = k * (ds * sn + s * c)
    J[..., 2, 4] = dt
    return pose, J


def velocity_between(x, y, theta, x1, y1, theta1, dt):
    """The constant body velocity whose arc (``propagate``) runs from one pose
    to the next: the inverse of the motion model, for starting a solve.

    omega = wrap(theta1 - theta) / dt; the arc's chord runs along the mid
    heading theta + omega dt / 2 with length v dt sinc(omega dt / 2), chosen
    so that the chord ends level with pose 1 along pose 1's heading. The
    heading and along-track residuals of ``transition_residual`` are then
    zero (its frame is the predicted pose's, whose heading is theta1); what
    is left is the sideways part, which no arc flies.

    Args:
        x, y, theta, x1, y1, theta1: (...) the two poses, world frame [m, rad].
        dt: (...) time between them [s], nonzero.

    Returns:
        v [m/s], omega [rad/s]: (...) each.
    """
    from odomgraph.factors._math import wrap_angle
    dt = np.asarray(dt, float)
    omega = wrap_angle(np.asarray(theta1, float) - theta) / dt
    half = 0.5 * omega * dt
    th1 = theta + omega * dt
    along = np.cos(th1) * (np.asarray(x1, float) - x) + np.sin(th1) * (np.asarray(y1, float) - y)
    # the chord (direction theta + half) projects onto theta1 by cos(half), |half| < pi/2
    return along / (dt * sinc(half) * np.cos(half)), omega


def bend(pose, J, x, y, theta, q, omega=None):
    """The arc's displacement from (x, y) bent to the path's shape: turned
    and stretched by a complex factor, plus an offset in the start's body
    frame, plus the path's own change with the turn rate.

    An arc of the interval's average curvature bends the whole distance; a
    robot that drove straight and then pivoted went straight (a probe's
    paper log 3x faster at 2 Hz keyframes: keyframes 0.31 m off at z 14). q
    is data (estimators.shares.Shares.bend, from the dead-reckoned path and
    the nominal calibration), (1, 0, 0, 0) for a constant-curvature
    interval; the heading is the arc's, plus q's offset (..., 4) where the
    path's turn overshot the interval's.

    The factor alone would move the bent chord with omega as the arc's chord
    moves (turned by half the extra turn); the path's chord moves by where
    its turn happened (none for a straight run ending in a pivot, the whole
    extra turn for one starting with it). With (..., 8) q the displacement
    gains c (omega - omega0), c in the start's body frame, so that its
    omega-derivative is the path's (Shares.bend: a gyro's bias turns the
    path's heading evenly in time; a track-width error scales the wheels'
    heading profile with the turn).

    Args:
        pose: (..., 3) from propagate or arc_at; J: (..., 3, 5) its Jacobian.
        x, y, theta: (...) the start pose [m, rad].
        q: (..., 4) (re, im) of the factor, (re, im) of the offset [m, body
            frame at the start]; or (..., 5) with an offset of the heading
            [rad]; or (..., 8) with (re, im) of c [m s/rad] and omega0
            [rad/s]; or None.
        omega: (...) the interval's yaw rate [rad/s]; needed with (..., 8) q.

    Returns:
        pose, J: bent (new arrays); the inputs when q is None.
    """
    if q is None:
        return pose, J
    q = np.asarray(q, float)
    a, b, ox, oy = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    c, s = np.cos(theta), np.sin(theta)
    pose, J = pose.copy(), J.copy()
    dx, dy = pose[..., 0] - x, pose[..., 1] - y
    if q.shape[-1] > 5:
        if omega is None:
            raise ValueError("bend: an (..., 8) q needs omega")
        # c (omega - omega0) joins the offset; its omega-column below
        d_w = np.asarray(omega, float) - q[..., 7]
        ox, oy = ox + q[..., 5] * d_w, oy + q[..., 6] * d_w
    pose[..., 0] = x + a * dx - b * dy + c * ox - s * oy
    pose[..., 1] = y + b * dx + a * dy + s * ox + c * oy
    # the columns of theta, v, omega move the displacement; x, y the start;
    # theta turns the offset too
    jx, jy = J[..., 0, 2:].copy(), J[..., 1, 2:].copy()
    J[..., 0, 2:] = a[..., None] * jx - b[..., None] * jy
    J[..., 1, 2:] = b[..., None] * jx + a[..., None] * jy
    J[..., 0, 2] += -s * ox - c * oy
    J[..., 1, 2] += c * ox - s * oy
    if q.shape[-1] > 5:
        J[..., 0, 4] += c * q[..., 5] - s * q[..., 6]
        J[..., 1, 4] += s * q[..., 5] + c * q[..., 6]
    if q.shape[-1] > 4:
        pose[..., 2] += q[..., 4]
    return pose, J


def arc_at(x, y, theta, v, omega, tau_v, tau_omega, q=None):
    """Pose partway through an interval flown with average velocities (v, omega):
    the arc of length v tau_v that turns by omega tau_omega.

    With tau_v = tau_omega = tau this is ``propagate(..., tau)``. Inside a
    keyframe interval the robot is rarely at constant speed, so the smoother
    passes the *effective* times: tau_v = dt x the share of the interval's
    wheel travel done by the measurement time, tau_omega likewise for the
    wheels' difference at a fix's time and for the gyro's turn at a row's
    (odomgraph/estimators/shares.py). Both are data, not states.

    Args:
        x, y, theta: (...) pose at the start of the interval, world frame [m, rad].
        v, omega: (...) interval-average forward speed [m/s] and yaw rate [rad/s].
        tau_v, tau_omega: (...) effective times [s].
        q: (..., 4|5|8) the path's bend (``bend``), or None: the arc.

    Returns:
        pose: (..., 3); J: (..., 3, 5) d pose / d (x, y, theta, v, omega).
    """
    tau_v = np.asarray(tau_v, float)
    tau_omega = np.asarray(tau_omega, float)
    pose, J = propagate(x, y, theta, v * tau_v, omega * tau_omega, np.ones_like(tau_v))
    J[..., 3] *= tau_v[..., None]
    J[..., 4] *= tau_omega[..., None]
    return bend(pose, J, x, y, theta, q, omega)


def transition_residual(x, y, theta, v, omega, dt, x1, y1, theta1, q=None):
    """Residual of the next pose against the motion model, in the predicted body frame.

    e = [R(theta_p)^T (p1 - p_p), wrap(theta1 - theta_p)] with (p_p, theta_p) =
    propagate(x, y, theta, v, omega, dt): the along-track, lateral [m] and
    heading [rad] disagreement of pose 1 with the arc flown from pose 0,
    its chord bent by q ((..., 4|5|8), ``bend``; None: the arc).

    Returns:
        e: (..., 3).
        J0: (..., 3, 5) d e / d (x, y, theta, v, omega) of the first pose and velocity.
        J1: (..., 3, 3) d e / d (x1, y1, theta1), world-frame coordinates.
    """
    from odomgraph.factors._math import wrap_angle
    pred, Jf = bend(*propagate(x, y, theta, v, omega, dt), x, y, theta, q, omega)
    shape = pred.shape[:-1]
    tp = pred[..., 2]
    c, s = np.cos(tp), np.sin(tp)
    dx = np.asarray(x1, dtype=float) - pred[..., 0]
    dy = np.asarray(y1, dtype=float) - pred[..., 1]
    e = np.empty(shape + (3,))
    e[..., 0] = c * dx + s * dy
    e[..., 1] = -s * dx + c * dy
    e[..., 2] = wrap_angle(np.asarray(theta1, dtype=float) - tp)
    # d e_p / d pred = -R^T on the position, plus the rotation of R^T by theta_p.
    de_dpred = np.zeros(shape + (3, 3))
    de_dpred[..., 0, 0] = -c
    de_dpred[..., 0, 1] = -s
    de_dpred[..., 1, 0] = s
    de_dpred[..., 1, 1] = -c
    de_dpred[..., 0, 2] = -s * dx + c * dy
    de_dpred[..., 1, 2] = -c * dx - s * dy
    de_dpred[..., 2, 2] = -1.0
    J0 = de_dpred @ Jf
    J1 = np.zeros(shape + (3, 3))
    J1[..., 0, 0] = c
    J1[..., 0, 1] = s
    J1[..., 1, 0] = -s
    J1[..., 1, 1] = c
    J1[..., 2, 2] = 1.0
    return e, J0, J1


def integrate(v, omega, dt, start=(0.0, 0.0, 0.0)):
    """Poses after each of a sequence of constant-velocity steps (dead reckoning).

    Args:
        v, omega: (K,) body velocity of step k [m/s, rad/s].
        dt: (K,) its length [s].
        start: (x, y, theta) before the first step, world frame [m, rad].

    Returns:
        (K + 1, 3) poses: the start, then after each step (theta not wrapped).
    Vectorised: headings by a running sum, then every step's exact arc chord
    (``propagate`` from the origin) at once.
    """
    v, omega, dt = (np.asarray(a, float) for a in (v, omega, dt))
    x0, y0, th0 = start
    th = th0 + np.concatenate([[0.0], np.cumsum(omega * dt)])
    step, _ = propagate(0.0, 0.0, th[:-1], v, omega, dt)
    out = np.empty((len(v) + 1, 3))
    out[:, 0] = x0 + np.concatenate([[0.0], np.cumsum(step[..., 0])])
    out[:, 1] = y0 + np.concatenate([[0.0], np.cumsum(step[..., 1])])
    out[:, 2] = th
    return out
