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

With a gyro the turn rate is checked too: one wheel slipping while the other
grips turns the wheels' yaw rate away from the gyro's by slip / track, even
where the distance travelled barely changes (a probe's log: a 0.15 m/s slip
of one wheel, 12-17 s into a 20 s window, left every estimator with a track
9 % off at a 0.2 % sigma, status ok).
"""
from __future__ import annotations

import numpy as np

from odomgraph.factors._math import robust_sigma


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
#: The gyro check: the gyro's rate less the wheels' yaw rate times their
#: ratio (the median over turns: the scale errors) and the bias (the median
#: difference), beyond GYRO_REL of the larger rate plus GYRO_ABS rad/s plus 4
#: sigma of a one-second median. On 33 simulated logs (9 robots and
#: scenarios x 3 seeds, 2850 slip-free seconds) no slip-free second crossed
#: it, and 256 of the 279 seconds of differential slip above 0.1 rad/s did.
#: A gyro that disagrees over more than GYRO_MAX_SHARE of the log is a
#: mounting or unit problem (analysis.mounting), not slip.
GYRO_REL = 0.1
GYRO_ABS = 0.1
GYRO_MAX_SHARE = 0.5
GYRO_FOLLOW = 0.6
#: Wheel yaw rates [rad/s] above this count as turns for the ratio.
TURN = 0.3
#: _scale_free's priors: the gyro-to-wheels factor within this of its median
#: ratio (track and common scale errors of a few percent, a skid-steer's
#: scrub up to 2x), and the speed term [rad/m] (a left/right scale difference
#: d turns at d v / track: 10 % on a 0.5 m track is 0.2)...
FACTOR_SIGMA = 0.5
SPEED_TERM_SIGMA = 0.3


def slipping_stretches(meas, robot, t0: float, t1: float) -> list[tuple[float, float]]:
    """(start, end) [s] of the stretches of [t0, t1] where the wheels report a
    motion the GPS fixes do not see, or the reverse (``fix_stretches``; ranges
    alone are too sparse in geometry for a second-by-second check), or where
    the wheels' yaw rate contradicts the gyro's (``gyro_stretches``)."""
    if t1 <= t0:
        return []
    return merged(fix_stretches(meas, robot, t0, t1) + gyro_stretches(meas, robot, t0, t1))


def merged(stretches) -> list[tuple[float, float]]:
    """Overlapping (start, end) stretches joined, in time order."""
    out: list[tuple[float, float]] = []
    for a, b in sorted(stretches):
        if out and a <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], b))
        else:
            out.append((a, b))
    return out


def gyro_stretches(meas, robot, t0: float, t1: float) -> list[tuple[float, float]]:
    """(start, end) [s] of the stretches of [t0, t1] where the wheels turn
    otherwise than the gyro says (nominal parameters; the scale errors and
    the bias fitted out by ``_scale_free``); [] without a gyro. The wheels'
    rates are interval means at their midpoints (measurements.from_log)."""
    if meas.gyro is None:
        return []
    gt, g = meas.gyro
    w = meas.wheel
    sel = (gt >= max(t0, w.t[0])) & (gt <= min(t1, w.t[-1]))
    if sel.sum() < 10:
        return []
    gt, g = gt[sel], g[sel]
    om = np.interp(gt, w.t, (w.m[:, 1] - w.m[:, 0]) / robot.track_width)
    sg = np.interp(gt, w.t, np.hypot(w.sigma[:, 0], w.sigma[:, 1]) / robot.track_width)
    v = np.interp(gt, w.t, 0.5 * (w.m[:, 0] + w.m[:, 1]))
    # One-second medians: single spikes do not count, and the noise (tick
    # quantisation makes the wheels' rate noisy sample by sample) shrinks.
    edges = np.arange(gt[0], gt[-1] + STEP, STEP)
    k = np.searchsorted(edges, gt, side="right") - 1
    nb = len(edges) - 1
    gm, omm, vm, big, noise = (np.full(nb, np.nan) for _ in range(5))
    for b in range(nb):
        m = k == b
        n = int(m.sum())
        if n < 3:
            continue
        gm[b], omm[b], vm[b] = np.median(g[m]), np.median(om[m]), np.median(v[m])
        big[b] = max(float(np.max(np.abs(om[m]))), float(np.max(np.abs(g[m]))))
        noise[b] = 1.2533 * float(np.sqrt(np.mean(sg[m] ** 2) + robot.gyro_sigma**2)) / np.sqrt(n)
    ok = np.isfinite(gm)
    if ok.sum() < 5:
        return []
    res = np.zeros(nb)
    fit = _scale_free(gm[ok], omm[ok], vm[ok])
    if fit is None:
        return []                        # a gyro upside down or on another axis: analysis.mounting says so
    res[ok] = fit
    score = np.where(ok, np.abs(res) / (GYRO_REL * np.nan_to_num(big) + GYRO_ABS + 4.0 * np.nan_to_num(noise)), 0.0)
    flag = score > 1.0
    if flag.sum() > GYRO_MAX_SHARE * max(1, len(score)):
        return []
    # Hysteresis: a slip found is followed while its seconds stay above
    # GYRO_FOLLOW of the threshold (a slip during a fast turn sits near it).
    while True:
        near = np.zeros_like(flag)
        near[1:] |= flag[:-1]
        near[:-1] |= flag[1:]
        grow = near & ~flag & (score > GYRO_FOLLOW)
        if not grow.any():
            break
        flag |= grow
    return merged([(max(edges[b] - PAD, t0), min(edges[b + 1] + PAD, t1)) for b in np.flatnonzero(flag)])


def _scale_free(g: np.ndarray, om: np.ndarray, v: np.ndarray) -> np.ndarray | None:
    """The gyro rate g less what the scale errors and the bias explain
    [rad/s], per one-second median: with wheel scale errors the wheels' yaw
    rate om (nominal parameters) is the true rate times a factor (track,
    common scale) plus a term in the speed v (a left/right scale difference
    turns a straight line): g ~ a om + c v + bias. Started from the median
    ratio over the turns both see and the median offset, then fitted by least
    squares to the seconds within 3 MAD, four times over (slip is the
    minority it leaves out). None when the gyro's rate is not the wheels'
    within a factor of 2 (a mounting or unit mistake: analysis.mounting)."""
    turn = (np.abs(om) > TURN) & (np.abs(g) > TURN)
    q = g[turn] / om[turn]
    if q.size >= 3 and not 0.5 < np.median(q) < 2.0:
        return None                      # upside down, in other units, on another axis
    q = q[(q > 0.5) & (q < 2.0)]
    a0 = float(np.median(q)) if q.size >= 3 else 1.0
    res = g - a0 * om
    res = res - np.median(res)
    X = np.stack([om, v, np.ones_like(om)], -1)
    # The floor of the kept residuals shrinks pass by pass: the first start
    # (a0 om + bias) has no speed term, and a tight first cut left out every
    # second whose speed differs from the bulk's (a log mostly circling at
    # 0.35 m/s lost its 1.5 m/s straights, whose 0.13 rad/s is a left/right
    # scale difference, and read them as slip).
    for floor in (0.2, 0.1, 0.02, 0.02):
        mad = robust_sigma(res)
        keep = np.abs(res) < max(3.0 * mad, floor)
        if keep.sum() < 5:
            break
        # Anchored by priors (a at a0 within FACTOR_SIGMA, c at 0 within
        # SPEED_TERM_SIGMA): a log that mostly circles at one (om, v) makes
        # the three regressors collinear, and the free fit then followed the
        # circle and left every other second off it (a probe's clean
        # robot circling at 0.35 m/s: its whole calibration window "slipped").
        w = 1.0 / max(mad, 0.01)
        A = np.vstack([X[keep] * w, [[1.0 / FACTOR_SIGMA, 0.0, 0.0], [0.0, 1.0 / SPEED_TERM_SIGMA, 0.0]]])
        b = np.concatenate([g[keep] * w, [a0 / FACTOR_SIGMA, 0.0]])
        coef, *_ = np.linalg.lstsq(A, b, rcond=None)
        res = g - X @ coef
        if np.ptp(om[keep]) > 2 * TURN and not 0.5 < coef[0] < 2.0:
            return None                  # the gyro's rate is no scale error away from the wheels'
    return res


def fix_stretches(meas, robot, t0: float, t1: float) -> list[tuple[float, float]]:
    """(start, end) [s] of the stretches of [t0, t1] where the wheels report a
    motion the absolute fixes do not see (or the reverse); [] without GPS."""
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
    h = min(h, len(ft) - 1)
    # Mirrored at the ends, not the end repeated: h copies of a wild first
    # fix made it the median of the first windows (a probe's 10 m first fix
    # was "slip inside the calibration window (0.1-1.5 s)").
    pad = lambda x: np.concatenate([x[h:0:-1], x, x[-2:-h - 2:-1]])
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
        bad = np.median(sliding_window_view(np.pad(bad.astype(float), 2, mode="reflect"), 5), 1) > 0.5
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
    return inside, [f"the wheels slipped inside the calibration window ({spans}): the fixes (or the gyro) do not "
                    "move as the wheels say, so those seconds are not taken as slip-free; slip is estimated there"]
