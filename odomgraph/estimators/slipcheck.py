"""Stretches of the calibration window in which the wheels slipped.

The paper's schedule assumes no slip while calibrating (the zero-slip
pseudo-update, eq. 35-36). A wheel spinning in that window (a stall: the
robot held while its wheels turn) breaks the assumption, and then every
estimator must either fight the fixes or bend the scale factors by tens of
percent. Here the assumption is checked against the fixes before anything
is estimated: over each second, the distance the antenna moved by the fixes
against the distance the wheels say it moved (nominal parameters, lever arm
applied). Where they disagree by far more than a scale error can explain,
the stretch is left out of the window: slip is estimated there, not forced
to zero, and the run says so.
"""
from __future__ import annotations

import numpy as np


#: Length of the comparisons [s], and the half-width over which fixes are averaged first.
STEP = 1.0
SMOOTH = 0.25
#: Wheels and fixes disagree beyond this share of the wheels' distance (a
#: scale error of a few percent stays far below)...
REL = 0.3
#: ...and beyond this many fix sigmas (plus ABS metres).
N_SIGMA = 4.0
ABS = 0.05
#: Flagged stretches are widened by this much each side [s] (slip ramps).
PAD = 0.5


def slipping_stretches(meas, robot, t0: float, t1: float) -> list[tuple[float, float]]:
    """(start, end) [s] of the stretches of [t0, t1] where the wheels report a
    motion the absolute fixes do not see (or the reverse). [] without GPS
    (ranges alone are too sparse in geometry for a second-by-second check)."""
    if meas.gps is None or t1 <= t0:
        return []
    ft, fp, fs = meas.gps
    sel = (ft >= t0 - STEP) & (ft <= t1 + STEP)
    if sel.sum() < 3:
        return []
    ft, fp, fs = ft[sel], fp[sel], fs[sel]
    from odomgraph.estimators.measurements import dead_reckoning
    t_dr, dr = dead_reckoning(meas, robot.track_width)
    lever = np.asarray(robot.gps_lever_arm, float)

    def antenna(t):
        th = np.interp(t, t_dr, dr[:, 2])
        return np.stack([np.interp(t, t_dr, dr[:, 0]) + np.cos(th) * lever[0] - np.sin(th) * lever[1],
                         np.interp(t, t_dr, dr[:, 1]) + np.sin(th) * lever[0] + np.cos(th) * lever[1]], -1)

    # Fixes smoothed by the median of about 2 SMOOTH seconds of them (their
    # noise shrinks, and an outlier among them does not count), then pairs
    # about STEP apart, and the same span on the wheels.
    from numpy.lib.stride_tricks import sliding_window_view
    rate = (len(ft) - 1) / max(ft[-1] - ft[0], 1e-9)
    h = max(1, int(round(SMOOTH * rate)))
    pad = lambda x: np.concatenate([np.repeat(x[:1], h, 0), x, np.repeat(x[-1:], h, 0)])
    fm = np.median(sliding_window_view(pad(fp), 2 * h + 1, axis=0), -1)
    am = np.median(sliding_window_view(pad(antenna(ft)), 2 * h + 1, axis=0), -1)
    sm = 1.2533 * fs / np.sqrt(2 * h + 1)            # the median's sigma
    j = np.searchsorted(ft, ft + STEP)
    ok = j < len(ft)
    i, j = np.flatnonzero(ok), j[ok]
    if i.size == 0:
        return []
    d_fix = np.hypot(*(fm[j] - fm[i]).T)
    d_dr = np.hypot(*(am[j] - am[i]).T)
    noise = N_SIGMA * np.sqrt(sm[i] ** 2 + sm[j] ** 2) + ABS
    bad = np.abs(d_dr - d_fix) > REL * np.maximum(d_dr, d_fix) + noise
    # Median over neighbouring pairs: one outlying fix cannot flag a stretch.
    if bad.size >= 5:
        from numpy.lib.stride_tricks import sliding_window_view
        bad = np.median(sliding_window_view(np.pad(bad.astype(float), 2, mode="edge"), 5), 1) > 0.5
    out: list[tuple[float, float]] = []
    for a, b, flag in zip(ft[i], ft[j], bad):
        if not flag:
            continue
        a, b = max(a - PAD, t0), min(b + PAD, t1)
        if out and a <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], b))
        else:
            out.append((a, b))
    return [(a, b) for a, b in out if b > a]


def in_stretches(t, stretches) -> np.ndarray:
    """Mask of times t inside any (start, end) stretch."""
    t = np.asarray(t, float)
    m = np.zeros(t.shape, bool)
    for a, b in stretches:
        m |= (t >= a) & (t <= b)
    return m


def in_window(stretches, t_lo: float, t_hi: float | None) -> tuple[list[tuple[float, float]], list[str]]:
    """The stretches that fall inside a calibration window [t_lo, t_hi], and a
    warning naming them (none without a window)."""
    if t_hi is None:
        return [], []
    inside = [(max(a, t_lo), min(b, t_hi)) for a, b in stretches if b > t_lo and a < t_hi]
    if not inside:
        return [], []
    spans = ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in inside)
    return inside, [f"the wheels slipped inside the calibration window ({spans}): the fixes do not move as the "
                    "wheels say, so those seconds are not taken as slip-free; slip is estimated there"]
