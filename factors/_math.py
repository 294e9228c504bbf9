"""Small numerically safe helpers shared by the models."""
from __future__ import annotations

import numpy as np

# Below this |x| the series branches are used; the discarded closed-form
# branch is evaluated at a safe argument so it can never produce NaN/inf.
_SMALL = 1e-4


def wrap_angle(a):
    """Wrap angles to (-pi, pi] (LOG_FORMAT convention). Any shape, rad."""
    a = np.asarray(a, dtype=float)
    w = np.mod(a + np.pi, 2.0 * np.pi) - np.pi
    # np.mod maps +pi to -pi; the convention keeps +pi.
    return np.where(w == -np.pi, np.pi, w)


def sinc(x):
    """sin(x)/x, exact at and near 0. Any shape."""
    x = np.asarray(x, dtype=float)
    small = np.abs(x) < _SMALL
    xs = np.where(small, 1.0, x)
    x2 = x * x
    return np.where(small, 1.0 - x2 / 6.0 + x2 * x2 / 120.0, np.sin(xs) / xs)


def dsinc(x):
    """d/dx of sin(x)/x = (x cos x - sin x)/x^2, exact at and near 0."""
    x = np.asarray(x, dtype=float)
    small = np.abs(x) < _SMALL
    xs = np.where(small, 1.0, x)
    return np.where(small, -x / 3.0 + x**3 / 30.0, (xs * np.cos(xs) - np.sin(xs)) / (xs * xs))


def rot2(theta):
    """Rotation matrices R(theta), shape (..., 2, 2), body -> world."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
