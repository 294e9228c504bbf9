"""Independent body-velocity sensor, e.g. visual odometry. Paper sec. VI-B.

    h = (v, omega),  H = I_2 with respect to (v, omega)
"""
from __future__ import annotations

import numpy as np

from odomgraph.factors._math import shape_of

INPUTS = ("v", "omega")


def body_velocity(v, omega):
    """Predicted velocity-sensor reading.

    Args:
        v: (...) forward speed [m/s]; omega: (...) yaw rate [rad/s].

    Returns:
        h: (..., 2) [v, omega]; J: (..., 2, 2) identity.
    """
    shape = shape_of(v, omega)
    h = np.empty(shape + (2,))
    h[..., 0] = v
    h[..., 1] = omega
    J = np.zeros(shape + (2, 2))
    J[..., 0, 0] = J[..., 1, 1] = 1.0
    return h, J
