"""Is the GPS clock off? Its time offset against the wheels.

A fix stamped delta seconds late was taken where the antenna was delta
seconds earlier. An estimate fitted to such fixes follows them, and its own
residuals hide most of the offset; the wheels do not. Over windows of WINDOW
seconds, the wheels' own path (dead reckoning with the estimated scale
factors, lever arm applied) is moved by the rigid map that best fits the
fixes, once for each trial offset: the offset with the smallest misfit is
the window's, and a parabola through the misfits gives its sigma. Combined
over the windows they give the log's offset; windows that disagree show a
clock that jumps. (A receiver latency of 0.1-0.5 s is common;
ESTIMATION-NOTES.md: 0.3 s biased a wheel scale by 3 % with nothing flagged.)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from odomgraph import state as S

#: An offset is reported when it is this many sigmas from 0, and at least MIN_OFFSET.
N_SIGMA = 5.0
MIN_OFFSET = 0.05
#: Window length [s], and the trial offsets [s].
WINDOW = 10.0
TRIALS = np.arange(-3.0, 3.0001, 0.1)
FINE = 0.02


@dataclass(frozen=True)
class Offset:
    delta: float
    """How late the stamps are [s] (positive: each fix was taken before its stamp)."""
    sigma: float
    """Its 1-sigma [s]."""
    t0: float
    t1: float
    """The span it was fitted on [s]."""

    @property
    def significant(self) -> bool:
        return abs(self.delta) > max(N_SIGMA * self.sigma, MIN_OFFSET)


def _wheel_antenna(log, scales):
    """(times (K+1,), antenna positions (K+1, 2)) of dead reckoning from the
    first wheel measurement with the given scale factors."""
    from odomgraph.estimators.measurements import dead_reckoning, from_log
    t, dr = dead_reckoning(from_log(log), log.robot.track_width, scales)
    lx, ly = log.robot.gps_lever_arm
    c, s = np.cos(dr[:, 2]), np.sin(dr[:, 2])
    return t, np.stack([dr[:, 0] + c * lx - s * ly, dr[:, 1] + s * lx + c * ly], -1)


def _misfit(d, p, w):
    """Weighted rigid-fit residual sum of squares of p ~ R d + c (closed form)."""
    from odomgraph.estimators.initial import rigid_fit
    phi, c = rigid_fit(d, p, w)
    cs, sn = np.cos(phi), np.sin(phi)
    r = p - np.stack([cs * d[:, 0] - sn * d[:, 1], sn * d[:, 0] + cs * d[:, 1]], -1) - c
    return float(np.sum(w[:, None] * r**2))


def window_offsets(log, scales=(1.0, 1.0, 1.0), skip=(), max_misfit: float | None = None) -> list[Offset]:
    """The GPS offset of each WINDOW-second window with enough fixes and motion,
    left after the configured [gps] time_offset (measurements.clean). Windows
    that overlap a ``skip`` span are left out, and with ``max_misfit`` those
    whose best shifted fit still leaves more than that many times the fix
    variance: a slip bends the wheels' path there, which no time shift
    explains, while a clock offset is explained exactly by one."""
    from odomgraph.estimators.measurements import clean
    log = clean(log)[0]
    g = log.gps
    if g is None or len(g.t) < 10:
        return []
    t_dr, a_dr = _wheel_antenna(log, scales)
    sig = g.sigma if g.sigma is not None else np.full(len(g.t), log.robot.gps_sigma)
    p_all = np.stack([g.x, g.y], -1)
    out = []
    for a in np.arange(max(g.t[0], t_dr[0]) + 1.0, min(g.t[-1], t_dr[-1]) - 1.0 - WINDOW, WINDOW):
        if any(sa < a + WINDOW and sb > a for sa, sb in skip):
            continue
        sel = (g.t >= a) & (g.t < a + WINDOW)
        if sel.sum() < 10:
            continue
        p, w, tf = p_all[sel], 1.0 / sig[sel] ** 2, g.t[sel]

        def cost(dl):
            d = np.stack([np.interp(tf - dl, t_dr, a_dr[:, 0]), np.interp(tf - dl, t_dr, a_dr[:, 1])], -1)
            return _misfit(d, p, w)
        # coarse over TRIALS, then fine around the best
        coarse = np.array([cost(dl) for dl in TRIALS])
        i = int(np.argmin(coarse))
        if i == 0 or i == len(TRIALS) - 1:
            continue                                   # outside the range tried: cannot tell
        step = FINE
        fine_t = TRIALS[i] + step * np.arange(-5, 6)
        costs = np.array([cost(dl) for dl in fine_t])
        i = int(np.argmin(costs))
        if i == 0 or i == len(fine_t) - 1:
            continue
        c0, c1, c2 = costs[i - 1:i + 2]
        curv = (c0 - 2 * c1 + c2) / step**2
        if curv <= 0:
            continue
        shift = 0.5 * (c0 - c2) / (c0 - 2 * c1 + c2) * step
        TRIAL_i = fine_t[i]
        dof = max(1, 2 * int(sel.sum()) - 4)
        if max_misfit is not None and c1 / dof > max_misfit:
            continue
        scale = max(1.0, c1 / dof)                      # misfit beyond the fix sigma widens it
        out.append(Offset(float(TRIAL_i + shift), float(np.sqrt(2.0 * scale / curv)), float(a),
                          float(a + WINDOW)))
    return out


def combine(parts: list[Offset]) -> Offset | None:
    """The weighted mean of window offsets, its sigma widened by their scatter.
    Windows far from the median (4 robust sigmas: a slip bends the wheels'
    path there) are left out."""
    if not parts:
        return None
    d = np.array([p.delta for p in parts])
    if len(d) >= 4:
        med = np.median(d)
        mad = 1.4826 * np.median(np.abs(d - med))
        keep = np.abs(d - med) <= max(4.0 * mad, 0.02)
        parts = [p for p, k in zip(parts, keep) if k]
        d = d[keep]
    w = 1.0 / np.array([p.sigma for p in parts]) ** 2
    mean = float(np.sum(w * d) / w.sum())
    chi2 = float(np.sum(w * (d - mean) ** 2)) / max(1, len(d) - 1)
    return Offset(mean, float(np.sqrt(max(1.0, chi2) / w.sum())), parts[0].t0, parts[-1].t1)


def _consistent(parts: list[Offset]) -> bool:
    """The window offsets agree with their weighted mean within their sigmas
    (reduced chi-square below 4) and within 0.1 s."""
    d = np.array([p.delta for p in parts])
    w = 1.0 / np.array([p.sigma for p in parts]) ** 2
    mean = np.sum(w * d) / w.sum()
    return bool(np.sum(w * (d - mean) ** 2) / max(1, len(d) - 1) < 4.0 and np.max(np.abs(d - mean)) < 0.1)


def gps_offset(log, scales=(1.0, 1.0, 1.0)) -> Offset | None:
    """The log's GPS time offset against the wheels (see the module doc)."""
    return combine(window_offsets(log, scales))


def gps_offset_warnings(log, est) -> list[str]:
    """One line each for a GPS clock that is off over the log, or that jumps.

    The wheels' path is drawn with the estimated scale factors, and again
    with the nominal ones when those differ by more than IMPLAUSIBLE: an
    estimate fitted to late fixes bends its scale factors to follow them
    (a 1 s late GPS gave scales of 1.42 and 0.77), and its own path then
    hides the offset. Windows bent by slip are left out (MAX_MISFIT: a late
    slip made a false 0.22 s "jump" that refused good logs)."""
    k = tuple(float(v) for v in est.mean[-1, S.SCALE])
    out = []
    for scales in ([k] + ([(1.0, 1.0, 1.0)] if max(abs(v - 1.0) for v in k) > IMPLAUSIBLE else [])):
        out = _offset_lines(window_offsets(log, scales, max_misfit=MAX_MISFIT))
        if out:
            break
    return out


#: Scale factors further than this from nominal are not trusted to draw the wheels' path.
IMPLAUSIBLE = 0.10
#: A window whose best time-shifted rigid fit leaves more than this many
#: times the fix variance is bent by slip, not shifted by the clock.
MAX_MISFIT = 9.0


def _offset_lines(parts: list[Offset]) -> list[str]:
    whole = combine(parts)
    out = []
    if whole is not None and whole.significant:
        out.append(f"GPS time stamps look {whole.delta:+.2f} s late (sigma {whole.sigma:.2f} s) against the wheels: "
                   "a receiver latency or clock offset biases the calibration; set [gps] time_offset in "
                   "robot.toml, or estimate it with --time-offset")
    # A jump: the windows before and after a point disagree, and each side
    # agrees with itself (windows that scatter everywhere say the wheels'
    # path is off, from wrong parameters or a mounting mistake, not the clock).
    # The window that holds the jump sees part of each clock: it may be left out.
    for k in range(2, len(parts) - 1):
        for gap in (0, 1):
            before, after = parts[:k], parts[k + gap:]
            if len(after) < 2 or not (_consistent(before) and _consistent(after)):
                continue
            a, b = combine(before), combine(after)
            if abs(b.delta - a.delta) > max(N_SIGMA * np.hypot(a.sigma, b.sigma), MIN_OFFSET):
                out.append(f"the GPS clock seems to jump by {b.delta - a.delta:+.2f} s near t={after[0].t0:.0f} s "
                           f"(offsets {a.delta:+.2f} s before, {b.delta:+.2f} s after)")
                return out
    return out
