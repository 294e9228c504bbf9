"""Wheel-encoder model with per-wheel slip and three scale factors. Paper eq. 17-34.

Convention (LOG_FORMAT.md, "The error model"): a scale factor multiplies the
nominal parameter to give the true one,

    tpm_true_left = scale_left * tpm_left,   track_true = scale_track * track,

(eq. 25-27). A wheel speed computed from ticks with the *nominal* ticks per
metre is therefore ``scale * u`` with ``u`` the true surface speed, and the true
surface speed is the kinematic wheel speed plus slip (eq. 23-24, 19-20):

    m_left  = scale_left  * (v - omega * scale_track * track / 2 + slip_left)
    m_right = scale_right * (v + omega * scale_track * track / 2 + slip_right)

This is eq. 29 re-derived; its Jacobian (eq. 30-34) is below. With all scale
factors 1 and no slip it reduces to eq. 21-22.
"""
from __future__ import annotations

import numpy as np

from odomgraph.factors._math import shape_of

INPUTS = ("v", "omega", "slip_left", "slip_right", "scale_left", "scale_right", "scale_track")


def wheel_speeds(v, omega, slip_left, slip_right, scale_left, scale_right, scale_track, track):
    """Predicted nominal-converted wheel speeds and their Jacobian.

    Args:
        v, omega: (...) body velocity of the origin [m/s], [rad/s].
        slip_left, slip_right: (...) wheel velocity errors [m/s].
        scale_left, scale_right, scale_track: (...) scale factors [-].
        track: nominal track width [m] (a parameter, no Jacobian).

    Returns:
        m: (..., 2) [m_left, m_right] as computed with nominal ticks/m [m/s].
        J: (..., 2, 7) d m / d INPUTS.
    """
    shape = shape_of(v, omega, slip_left, slip_right, scale_left, scale_right, scale_track)
    sl, sr, kl, kr, kb = slip_left, slip_right, scale_left, scale_right, scale_track
    half_b = 0.5 * kb * track  # half the true track [m]
    ul = v - omega * half_b + sl  # true left surface speed [m/s]
    ur = v + omega * half_b + sr
    m = np.empty(shape + (2,))
    m[..., 0] = kl * ul
    m[..., 1] = kr * ur

    J = np.zeros(shape + (2, 7))
    J[..., 0, 0] = kl
    J[..., 0, 1] = -kl * half_b
    J[..., 0, 2] = kl
    J[..., 0, 4] = ul
    J[..., 0, 6] = -kl * omega * 0.5 * track
    J[..., 1, 0] = kr
    J[..., 1, 1] = kr * half_b
    J[..., 1, 3] = kr
    J[..., 1, 5] = ur
    J[..., 1, 6] = kr * omega * 0.5 * track
    return m, J


def body_velocity(m_left, m_right, slip_left, slip_right, scale_left, scale_right, scale_track, track):
    """Invert ``wheel_speeds``: body (v, omega) from measured wheel speeds.

    Used for dead reckoning and for the simulator; estimators use the forward
    model. Shapes broadcast; returns (v [m/s], omega [rad/s]).
    """
    ul = np.asarray(m_left, dtype=float) / scale_left - slip_left
    ur = np.asarray(m_right, dtype=float) / scale_right - slip_right
    return 0.5 * (ul + ur), (ur - ul) / (scale_track * track)


def speed_sigma(m, a, b, ticks_per_meter=None, dt=None):
    """1-sigma of a nominal-converted wheel speed [m/s]. Paper eq. 41 + quantisation.

    ``a + b |m|`` is the paper's eq. 41. When the speed comes from a tick count
    over ``dt`` seconds, counting quantises it: the count over an interval is the
    difference of two floor() errors, each uniform on [0, 1) tick, so its
    variance is 1/6 tick^2, i.e. (1 / (tpm dt))^2 / 6 in (m/s)^2.
    """
    m = np.asarray(m, dtype=float)
    var = (a + b * np.abs(m)) ** 2
    if ticks_per_meter is not None:
        var = var + 1.0 / (6.0 * (np.asarray(ticks_per_meter) * np.asarray(dt)) ** 2)
    return np.sqrt(var)
