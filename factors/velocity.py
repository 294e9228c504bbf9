"""Independent body-velocity sensor, e.g. visual odometry. Paper sec. VI-B.

    h = (v, omega),  H = I_2 with respect to (v, omega)
"""
from __future__ import annotations

import numpy as np

INPUTS = ("v", "omega")


def body_velocity(v, omega):
    """Predicted velocity-sensor reading.

    Args:
        v: (...) forward speed [m/s]; omega: (...) yaw rate [rad/s].

    Returns:
        h: (..., 2) [v, omega]; J: (..., 2, 2) identity.
    """
    v, omega = np.broadcast_arrays(np.asarray(v, dtype=float), np.asarray(omega, dtype=float))
    h = np.stack([v, omega], -1)
    J = np.broadcast_to(np.eye(2), v.shape + (2, 2)).copy()
    return h, J
