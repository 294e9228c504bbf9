"""GPS antenna position with a lever arm. Paper eq. 8-9.

    h = p + R(theta) l,   l = (l_x, l_y) in the robot frame

    H = [[1, 0, -l_x sin(theta) - l_y cos(theta)],
         [0, 1,  l_x cos(theta) - l_y sin(theta)]]

The Jacobian is with respect to the world-frame (x, y, theta). GTSAM's Pose2
perturbs in the body frame; the adapter converts (see factors.gtsam).
"""
from __future__ import annotations

import numpy as np

from odomgraph.factors._math import shape_of

INPUTS = ("x", "y", "theta")


def antenna_position(x, y, theta, lever_arm):
    """Predicted antenna position.

    Args:
        x, y, theta: (...) robot origin [m] and heading [rad], world frame.
        lever_arm: (2,) antenna position in the robot frame [m].

    Returns:
        h: (..., 2) antenna position, world frame [m].
        J: (..., 2, 3) d h / d (x, y, theta).
    """
    shape = shape_of(x, y, theta)
    lx, ly = float(lever_arm[0]), float(lever_arm[1])
    c, s = np.cos(theta), np.sin(theta)
    ox = lx * c - ly * s  # lever arm rotated into the world frame
    oy = lx * s + ly * c
    h = np.empty(shape + (2,))
    h[..., 0] = x + ox
    h[..., 1] = y + oy
    J = np.zeros(shape + (2, 3))
    J[..., 0, 0] = 1.0
    J[..., 1, 1] = 1.0
    J[..., 0, 2] = -oy
    J[..., 1, 2] = ox
    return h, J
