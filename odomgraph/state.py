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

#: The value an estimator writes for a state it does not estimate.
NOMINAL = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0])
