"""Range from a point on the robot to a known beacon. Paper eq. 12-16.

The paper measures from the robot origin (eq. 12-16); like the GPS model we
allow a lever arm l in the robot frame (the paper notes the extension), and an
optional constant range bias (for real UWB, see ``bias``):

    a = p + R(theta) l,   d = a - beacon,   h = |d| + bias
    dh/dp = d^T / |d|,  dh/dtheta = d^T / |d| * dR/dtheta l,  dh/dbias = 1

At |d| -> 0 the direction d/|d| is undefined; we return the subgradient 0
there instead of NaN (the branch is only taken for |d| < 1e-9 m).
"""
from __future__ import annotations

import numpy as np

from odomgraph.factors._math import shape_of

INPUTS = ("x", "y", "theta", "bias")

_MIN_RANGE = 1e-9


def beacon_range(x, y, theta, beacon, lever_arm=(0.0, 0.0), bias=0.0):
    """Predicted range to one beacon.

    Args:
        x, y, theta: (...) robot origin [m] and heading [rad], world frame.
        beacon: (..., 2) beacon position, world frame [m].
        lever_arm: (2,) ranging antenna in the robot frame [m].
        bias: (...) constant range offset [m] (0 when not estimated).

    Returns:
        h: (..., 1) range [m]; J: (..., 1, 4) d h / d (x, y, theta, bias).
    """
    beacon = np.asarray(beacon, dtype=float)
    shape = shape_of(x, y, theta, bias, beacon[..., 0])
    lx, ly = float(lever_arm[0]), float(lever_arm[1])
    c, s = np.cos(theta), np.sin(theta)
    ox, oy = lx * c - ly * s, lx * s + ly * c
    dx = x + ox - beacon[..., 0]
    dy = y + oy - beacon[..., 1]
    r = np.hypot(dx, dy)
    if shape == ():
        inv = 1.0 / r if r > _MIN_RANGE else 0.0
    else:
        far = r > _MIN_RANGE
        inv = np.where(far, 1.0 / np.where(far, r, 1.0), 0.0)
    ux, uy = dx * inv, dy * inv  # unit vector beacon -> antenna (0 at the singularity)
    h = np.empty(shape + (1,))
    h[..., 0] = r + bias
    J = np.zeros(shape + (1, 4))
    J[..., 0, 0] = ux
    J[..., 0, 1] = uy
    J[..., 0, 2] = -ux * oy + uy * ox
    J[..., 0, 3] = 1.0
    return h, J
