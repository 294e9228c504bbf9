"""Estimates no robot can have driven, found after the estimator has run.

A differential-drive model with slip states has a mirror solution: the
heading turned by half a turn, the body speed v negated, and each wheel's
slip equal to twice its speed. The fixes cannot tell the two apart (the path
is the same) except through the lever arm, and without a gyro the heading
has little else to hold it. A probe's logs (no gyro, or a GPS multipath
burst) settled into that mirror after a slip event: heading off by 3.14 rad,
both wheels "slipping" 2 m/s, position sigma 2 cm against a 0.9 m error,
status ok. Here such a stretch is named, and the estimate flagged.
"""
from __future__ import annotations

import numpy as np

from odomgraph import state as S

#: Ground speed under each wheel [m/s] against the wheel's own surface speed,
#: in opposite directions and both beyond this...
MIN_SPEED = 0.2
#: ...on both wheels for at least this long [s].
MIN_DURATION = 3.0


def reversed_motion_warnings(est, track_width: float) -> list[str]:
    """One line per stretch where ``est`` has the robot travelling one way
    while both wheels drive it the other (LOG_FORMAT's error model: the
    surface speed is ground speed plus slip), lasting MIN_DURATION or more;
    [] when there is none."""
    t = est.t
    if len(t) < 2:
        return []
    x = est.mean
    half = 0.5 * track_width * x[:, S.SCALE][:, 2]
    v, w = x[:, S.V], x[:, S.OMEGA]
    ground = np.stack([v - w * half, v + w * half], -1)          # speed of the ground under each wheel
    surface = ground + x[:, S.SLIP]                               # the wheel's own surface speed
    against = np.all((ground * surface < 0) & (np.abs(ground) > MIN_SPEED) & (np.abs(surface) > MIN_SPEED), 1)
    out = []
    edges = np.flatnonzero(np.diff(np.concatenate([[0], against.astype(np.int8), [0]])))
    for a, b in zip(edges[::2], edges[1::2]):
        t0, t1 = float(t[a]), float(t[b - 1])
        if t1 - t0 < MIN_DURATION:
            continue
        seg = slice(a, b)
        out.append(f"{est.method}: from t={t0:.1f} to {t1:.1f} s the estimate has the robot moving at "
                   f"{float(np.median(v[seg])):+.2f} m/s while both wheels drive it the other way (slip "
                   f"{float(np.median(x[seg, S.SLIP][:, 0])):+.2f} / {float(np.median(x[seg, S.SLIP][:, 1])):+.2f} "
                   "m/s): the heading is likely half a turn off there (the mirror solution of the slip model); "
                   "not trustworthy")
    return out
