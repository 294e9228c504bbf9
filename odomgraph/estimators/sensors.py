"""The filters' sensor table: one code per sensor, its name in the log
(LOG_FORMAT.md), its measurement dimension and the state blocks its model
touches. The EKF (ekf.py) and the batched EKF (ekf_many.py) both read it,
and the event stream that orders every measurement by time is built here.

Sensor codes order measurements at equal times: lower codes go first (the
wheels before the gyro before the fixes), so both filters process a log in
exactly the same order.
"""
from __future__ import annotations

import numpy as np

from odomgraph import state as S
from odomgraph.estimators.measurements import Measurements

WHEEL, GYRO, GPS, RANGE, VEL = range(5)
#: Each code's sensor name, as in the log's file names and summary.json's counts.
SENSOR_NAMES = ("encoders", "gyro", "gps", "ranges", "velocity")
#: Each code's measurement dimension (the NIS degrees of freedom).
DOF = (2, 1, 2, 1, 2)
#: Sensors behind the outlier gate; the others are never rejected.
GATED = (GPS, RANGE, VEL)

#: The states each model reads (paper eq. 29-34 for the wheels: speed, yaw
#: rate, slips and scale factors). Contiguous blocks are slices: views
#: instead of fancy-indexing copies in the filters' hot loops.
ENC_IDX = np.array([S.V, S.OMEGA, S.SLIP_L, S.SLIP_R, S.SCALE_L, S.SCALE_R, S.SCALE_B])
GYRO_IDX = slice(S.OMEGA, S.BIAS + 1)          # eq. 10-11: omega and the bias
POSE_IDX = S.POSE_S                            # eq. 8-9, 12-16: GPS and ranges
VEL_IDX = S.VEL_S                              # sec. VI-B: body velocity
SLIP_IDX = S.SLIP_S                            # eq. 35-36: the zero-slip pseudo-update
SCALE_IDX = S.SCALE_S                          # eq. 37-38: the scale-hold pseudo-update


def event_stream(meas: Measurements, t0: float):
    """(times (K,), sensor codes (K,), row indices into each sensor's arrays
    (K,)) of every measurement at or after t0 [s], in time order (ties by code)."""
    ts, codes, rows = [], [], []
    for code, src in ((WHEEL, meas.wheel.t), (GYRO, meas.gyro), (GPS, meas.gps), (RANGE, meas.ranges),
                      (VEL, meas.velocity)):
        if src is None:
            continue
        t = src if code == WHEEL else src[0]
        sel = np.nonzero(t >= t0)[0]
        ts.append(t[sel]); codes.append(np.full(sel.size, code)); rows.append(sel)
    t = np.concatenate(ts); c = np.concatenate(codes); r = np.concatenate(rows)
    order = np.lexsort((c, t))
    return t[order], c[order], r[order]
