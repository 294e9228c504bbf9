"""Encoder rows missing with their ticks: a gap the wheels did not count.

LOG_FORMAT.md: each encoders.csv row counts the ticks since the row before,
so the row after a dropout carries the whole gap's travel, and the
estimators use it as such (measurements.from_log). A logger that drops rows
and their ticks breaks that: the wheels then say the robot barely moved
while it drove on. A probe's yard log with the rows from 25 to 45 s deleted
had batch 2.6 m off at sigma 3 cm (z 72), status ok, and `calibrate` wrote
ticks/m 8 sigma off. The fixes either side of the gap say how far the robot
went; wheels that counted far less than that lost their ticks (or slipped
the whole gap, which the estimate cannot tell apart either).
"""
from __future__ import annotations

import numpy as np

from odomgraph.estimators.measurements import GAP_FACTOR

#: A wheel gap is at least this long [s] (and GAP_FACTOR median intervals).
MIN_GAP = 1.0
#: Fixes within this long [s] before and after the gap give its ends'
#: positions, at least MIN_FIXES each side (one outlier is no end).
EDGE = 2.0
MIN_FIXES = 2
#: The fixes' distance must exceed the wheels' by this many sigma of it...
N_SIGMA = 4.0
#: ...by this share of the wheels' own travel, and by this much [m].
REL = 0.1
MIN_SHORTFALL = 0.3


def lost_tick_warnings(log) -> list[str]:
    """One line per encoder gap (MIN_GAP s and GAP_FACTOR median intervals
    or longer) over which the GPS fixes either side moved further than the
    wheels counted, beyond N_SIGMA of the fixes' noise, the lever arm's
    swing, REL of the travel and MIN_SHORTFALL; [] without encoders or GPS.
    The wheels' count is each row's net travel (a row's ticks are summed
    over its interval, so a reversal inside one cancels): a gap across which
    the robot drove the other way is left out."""
    e, g = log.encoders, log.gps
    if e is None or g is None or len(e.t) < 3 or len(g.t) < 2:
        return []
    r = log.robot
    dt = np.diff(e.t)
    gap = np.flatnonzero(dt > max(MIN_GAP, GAP_FACTOR * float(np.median(dt))))
    if not gap.size:
        return []
    sig = g.sigma if g.sigma is not None else np.full(len(g.t), r.gps_sigma)
    lever = float(np.hypot(*r.gps_lever_arm))
    # each row's net travel [m] (nominal ticks/m), and its sum from the first row
    net = 0.5 * (e.ticks_left[1:] / r.ticks_per_meter_left + e.ticks_right[1:] / r.ticks_per_meter_right)
    path = np.concatenate([[0.0], np.cumsum(np.abs(net))])
    out = []
    for i in gap:
        a, b = float(e.t[i]), float(e.t[i + 1])
        before = (g.t >= a - EDGE) & (g.t <= a)
        after = (g.t >= b) & (g.t <= b + EDGE)
        if before.sum() < MIN_FIXES or after.sum() < MIN_FIXES:
            continue
        if i >= 1 and i + 1 < len(net) and net[i - 1] * net[i + 1] < 0:
            continue                                  # it drove the other way after: a reversal inside may cancel
        # each end: the fixes' median place and time; the wheels over the same span
        t0, t1 = float(np.median(g.t[before])), float(np.median(g.t[after]))
        p0 = np.array([np.median(g.x[before]), np.median(g.y[before])])
        p1 = np.array([np.median(g.x[after]), np.median(g.y[after])])
        moved = float(np.hypot(*(p1 - p0)))
        s = float(np.sqrt(np.median(sig[before]) ** 2 / before.sum() + np.median(sig[after]) ** 2 / after.sum()))
        counted = float(np.interp(t1, e.t, path) - np.interp(t0, e.t, path))
        short = moved - counted
        if short > max(N_SIGMA * s + 2.0 * lever, REL * counted, MIN_SHORTFALL):
            out.append((a, b, counted, moved))
    if not out:
        return []
    parts = ", ".join(f"t={a:.1f}-{b:.1f} s: the wheels counted {c:.2f} m, the fixes moved {m:.2f} m"
                      for a, b, c, m in out)
    return [f"encoders: gaps in the rows over which the wheels counted less than the robot went ({parts}): the "
            "rows and their ticks were lost (LOG_FORMAT.md: the row after a gap counts every tick since the row "
            "before), or the wheels slipped the whole gap; the estimate there and any calibration over it are "
            "not trustworthy"]
