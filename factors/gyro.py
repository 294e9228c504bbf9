"""Z-axis gyro with an additive bias. Paper eq. 10-11.

    h = omega + b,   H = [1, 1] with respect to (omega, gyro_bias)
"""
from __future__ import annotations

import numpy as np

from odomgraph.factors._math import shape_of

INPUTS = ("omega", "gyro_bias")


def yaw_rate(omega, gyro_bias):
    """Predicted gyro reading.

    Args:
        omega: (...) yaw rate of the body [rad/s].
        gyro_bias: (...) additive gyro bias [rad/s].

    Returns:
        h: (..., 1) reading [rad/s]; J: (..., 1, 2) d h / d (omega, gyro_bias).
    """
    shape = shape_of(omega, gyro_bias)
    h = np.empty(shape + (1,))
    h[..., 0] = omega + gyro_bias
    J = np.ones(shape + (1, 2))
    return h, J
