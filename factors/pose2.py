"""World-frame pose Jacobians for GTSAM's Pose2, whose perturbations are body-frame.

The models differentiate with respect to world-frame (x, y, theta). GTSAM
retracts a Pose2 by composition, X' = X * Exp(d), d = (dx, dy, dtheta) in the
body frame. To first order at d = 0 the world position moves by R(theta)(dx, dy)
and the heading by dtheta, so

    J_body = J_world @ blockdiag(R(theta), 1).

Forgetting R(theta) is the classic bug of world-frame GPS factors.
"""
from __future__ import annotations

import numpy as np


def to_body(J_world, theta):
    """(..., m, 3) world-frame pose Jacobian -> body-frame (Pose2 tangent) Jacobian."""
    J_world = np.asarray(J_world, dtype=float)
    c, s = np.cos(theta), np.sin(theta)
    c = np.asarray(c)[..., None]
    s = np.asarray(s)[..., None]
    out = J_world.copy()
    jx, jy = J_world[..., 0], J_world[..., 1]
    out[..., 0] = jx * c + jy * s
    out[..., 1] = -jx * s + jy * c
    return out


def retract(x, y, theta, d):
    """Pose2 retraction X * Exp(d) for arrays: x, y, theta (...), d (..., 3) body-frame.

    Exp of a Pose2 twist (dx, dy, dtheta) moves along an arc; returns world-frame
    (x', y', theta') arrays (theta' not wrapped).
    """
    from odomgraph.factors._math import sinc
    d = np.asarray(d, dtype=float)
    dx, dy, dth = d[..., 0], d[..., 1], d[..., 2]
    # Exp: translation V(dth) (dx, dy) with V = [[s/a, -(1-c)/a], [(1-c)/a, s/a]]
    a = dth
    sa = sinc(a)
    ca = np.where(np.abs(a) < 1e-4, a / 2 - a**3 / 24, (1 - np.cos(np.where(np.abs(a) < 1e-4, 1.0, a)))
                  / np.where(np.abs(a) < 1e-4, 1.0, a))
    tx = sa * dx - ca * dy
    ty = ca * dx + sa * dy
    c, s = np.cos(theta), np.sin(theta)
    return x + c * tx - s * ty, y + s * tx + c * ty, theta + dth
