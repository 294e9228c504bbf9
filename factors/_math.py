"""Small numerically safe helpers shared by the models.

Each helper takes a fast pure-Python path for scalars (the EKF calls the
models one state at a time, where numpy's per-call overhead would dominate)
and a vectorised path for arrays (Monte-Carlo and smoother linearisation).
``tests/test_factors.py`` checks that both paths agree.
"""
from __future__ import annotations

import math

import numpy as np

# Below this |x| the series branches are used; the discarded closed-form
# branch is evaluated at a safe argument so it can never produce NaN/inf.
_SMALL = 1e-4
_PI = math.pi
_TWO_PI = 2.0 * math.pi


def wrap_angle(a):
    """Wrap angles to (-pi, pi] (LOG_FORMAT convention). Any shape, rad."""
    if np.ndim(a) == 0:
        w = math.fmod(float(a) + _PI, _TWO_PI)
        w = w + _TWO_PI if w < 0 else w
        w -= _PI
        return _PI if w == -_PI else w
    a = np.asarray(a, dtype=float)
    w = np.mod(a + np.pi, 2.0 * np.pi) - np.pi
    # np.mod maps +pi to -pi; the convention keeps +pi.
    return np.where(w == -np.pi, np.pi, w)


def sinc(x):
    """sin(x)/x, exact at and near 0. Any shape."""
    if np.ndim(x) == 0:
        x = float(x)
        if abs(x) < _SMALL:
            x2 = x * x
            return 1.0 - x2 / 6.0 + x2 * x2 / 120.0
        return math.sin(x) / x
    x = np.asarray(x, dtype=float)
    small = np.abs(x) < _SMALL
    xs = np.where(small, 1.0, x)
    x2 = x * x
    return np.where(small, 1.0 - x2 / 6.0 + x2 * x2 / 120.0, np.sin(xs) / xs)


def dsinc(x):
    """d/dx of sin(x)/x = (x cos x - sin x)/x^2, exact at and near 0."""
    if np.ndim(x) == 0:
        x = float(x)
        if abs(x) < _SMALL:
            return -x / 3.0 + x**3 / 30.0
        return (x * math.cos(x) - math.sin(x)) / (x * x)
    x = np.asarray(x, dtype=float)
    small = np.abs(x) < _SMALL
    xs = np.where(small, 1.0, x)
    return np.where(small, -x / 3.0 + x**3 / 30.0, (xs * np.cos(xs) - np.sin(xs)) / (xs * xs))


#: A Gaussian's sigma per median absolute deviation (1 / Phi^-1(3/4)).
MAD_SIGMA = 1.4826


def robust_sigma(x) -> float:
    """The sigma of zero-mean Gaussian samples ``x`` (any shape, any unit),
    from their median absolute value: MAD_SIGMA median |x|, unmoved by up to
    half of them being outliers. Centre ``x`` first (``x - median(x)``) for
    the usual MAD about the median."""
    return float(MAD_SIGMA * np.median(np.abs(x)))


def shape_of(*args) -> tuple:
    """The broadcast shape of the arguments; () for scalars, cheaply."""
    for a in args:
        if (isinstance(a, np.ndarray) and a.ndim) or isinstance(a, (list, tuple)):
            return np.broadcast_shapes(*(np.shape(a) for a in args))
    return ()


def rot2(theta):
    """Rotation matrices R(theta), shape (..., 2, 2), body -> world."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
