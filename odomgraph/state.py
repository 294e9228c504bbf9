"""The estimated state, shared by every estimator and by the output format.

Order and names are those of LOG_FORMAT.md's ``states.csv``; the EKF state
vector uses the same order (paper eq. 1 and eq. 28, plus the gyro bias of
sec. II-C).
"""
from __future__ import annotations

import numpy as np

NAMES = (
    "x", "y", "theta", "v", "omega", "gyro_bias",
    "slip_left", "slip_right", "scale_left", "scale_right", "scale_track",
)
UNITS = ("m", "m", "rad", "m/s", "rad/s", "rad/s", "m/s", "m/s", "-", "-", "-")
N = len(NAMES)
IDX = {name: i for i, name in enumerate(NAMES)}

X, Y, THETA, V, OMEGA, BIAS, SLIP_L, SLIP_R, SCALE_L, SCALE_R, SCALE_B = range(N)
POSE = np.array([X, Y, THETA])
SLIP = np.array([SLIP_L, SLIP_R])
SCALE = np.array([SCALE_L, SCALE_R, SCALE_B])

#: The contiguous blocks as slices: views, not the copies fancy indexing
#: makes (the filters' hot loops, in-place updates).
POSE_S = slice(X, THETA + 1)
VEL_S = slice(V, OMEGA + 1)                    # (v, omega)
SLIP_S = slice(SLIP_L, SLIP_R + 1)
SCALE_S = slice(SCALE_L, SCALE_B + 1)
WHEEL_SCALE_S = slice(SCALE_L, SCALE_R + 1)    # the wheels' two, without the track's

#: The smoothers' per-interval vector W (estimators.keyframes.W_NAMES) is
#: the state after the pose, in the same order: W[i] is state W_OFFSET + i,
#: and a smoother's tangent block [pose, W] has the state's indices.
W_OFFSET = V


def in_w(block: slice) -> slice:
    """A state block's slice of W."""
    return slice(block.start - W_OFFSET, block.stop - W_OFFSET)


W_VEL, W_SLIP, W_SCALE, W_WHEEL_SCALE = (in_w(b) for b in (VEL_S, SLIP_S, SCALE_S, WHEEL_SCALE_S))

#: The value an estimator writes for a state it does not estimate.
NOMINAL = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0])
