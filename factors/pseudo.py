"""The paper's two pseudo-updates (sec. III-D, eq. 35-38).

* zero slip (eq. 35-36): a measurement z = 0 of (slip_left, slip_right), used
  while calibrating so the scale factors absorb all systematic error;
* hold the scale factors (eq. 37-38): a measurement z = current value of
  (scale_left, scale_right, scale_track), used while estimating slip.

Both are identity selections of states; writing them as models keeps the EKF
and the smoother on the same footing (the smoother turns them into priors).
"""
from __future__ import annotations

import numpy as np

from odomgraph.factors._math import shape_of

ZERO_SLIP_INPUTS = ("slip_left", "slip_right")
HOLD_SCALE_INPUTS = ("scale_left", "scale_right", "scale_track")


def zero_slip(slip_left, slip_right):
    """h: (..., 2) the slips [m/s]; J: (..., 2, 2) identity."""
    return _select(slip_left, slip_right)


def hold_scale(scale_left, scale_right, scale_track):
    """h: (..., 3) the scale factors [-]; J: (..., 3, 3) identity."""
    return _select(scale_left, scale_right, scale_track)


def _select(*states):
    shape = shape_of(*states)
    n = len(states)
    h = np.empty(shape + (n,))
    J = np.zeros(shape + (n, n))
    for k, s in enumerate(states):
        h[..., k] = s
        J[..., k, k] = 1.0
    return h, J
