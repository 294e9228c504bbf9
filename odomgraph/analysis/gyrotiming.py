"""Is the gyro clock off? Its time offset against the wheels.

A gyro sample stamped delta seconds late was taken delta seconds earlier:
its yaw rate is the wheels' yaw rate delta seconds before its stamp. Every
estimator takes it at its stamp, and a turn then looks like a wheel that
slipped at its start and end; the scale factors bend to explain it (a
hostile probe: a gyro clock that jumped 0.5 s at 40 s left a wheel scale 4
sigma off and 19 % of positions outside +-3 sigma, status ok; a gyro 0.25 s
late was taken for a GPS clock jump). Only the GPS was timed against the
wheels before.

Over windows of WINDOW seconds the gyro's rate is fitted to the wheels'
yaw rate (right minus left speed over the nominal track) shifted by each
trial offset, with a free factor and bias (the track scale and the gyro
bias: a calibration error is not a clock error): the offset with the
smallest misfit is the window's, refined by a parabola, and its sigma is
from the window's Fisher information. Windows whose best fit still misses
by more than MAX_MISFIT times the noise are bent by slip, not shifted by a
clock, and are left out; so are windows that hardly turn. The windows are
combined, and a clock that jumps is found, as the GPS's are
(analysis.timing.combine and .jump).
"""
from __future__ import annotations

import re

import numpy as np

from odomgraph.analysis.timing import N_SIGMA, Offset, combine, jump

#: Window length [s], and the trial offsets [s] (a gyro clock a second or
#: more off is a file on another clock: io.log refuses those).
WINDOW = 10.0
TRIALS = np.arange(-1.0, 1.0001, 0.02)
#: A window must turn: the wheels' yaw rate varies by at least this much
#: (standard deviation) [rad/s], over at least MIN_SAMPLES gyro samples.
MIN_TURN = 0.05
MIN_SAMPLES = 20
#: A window whose best shifted fit leaves more than this many times the
#: noise variance (gyro and wheels) is bent by slip.
MAX_MISFIT = 9.0
#: An offset, or a jump, is said when it is N_SIGMA sigmas from 0 and at
#: least this [s]: a wheel that slips briefly at the start of each turn
#: shifts the windows by 0.06-0.08 s (a probe's logs: slips of 0.5-1 s at
#: 22 turn starts), which no clock did.
MIN_OFFSET = 0.1
#: A window's offset sigma above this [s] says nothing...
MAX_WINDOW_SIGMA = 0.2
#: ...and none is below this: the wheels' rate is an interval mean stamped at
#: its midpoint, and clean simulated windows scattered by 0.01-0.03 s where
#: their Fisher sigma said 0.002 s.
MIN_WINDOW_SIGMA = 0.02


def _fit(g: np.ndarray, p: np.ndarray) -> tuple[float, float]:
    """(misfit: mean squared residual [rad^2/s^2], factor) of g ~ a p + c by
    least squares."""
    A = np.stack([p, np.ones_like(p)], -1)
    coef, *_ = np.linalg.lstsq(A, g, rcond=None)
    r = g - A @ coef
    return float(np.mean(r * r)), float(coef[0])


def window_offsets(log) -> list[Offset]:
    """The gyro's time offset against the wheels (positive: each sample was
    taken before its stamp) in each WINDOW-second window that turns enough
    and is not bent by slip; [] without a gyro."""
    from odomgraph.estimators.measurements import from_log
    if log.gyro is None or len(log.gyro.t) < MIN_SAMPLES:
        return []
    meas = from_log(log)
    if meas.gyro is None or len(meas.wheel.t) < 4:
        return []
    r = log.robot
    gt, g = meas.gyro
    w = meas.wheel
    om = (w.m[:, 1] - w.m[:, 0]) / r.track_width                    # the wheels' yaw rate [rad/s]
    om_sig2 = float(np.median(np.sum(w.sigma ** 2, 1))) / r.track_width ** 2
    noise2 = r.gyro_sigma ** 2 + om_sig2
    wheel_hz = 1.0 / max(float(np.median(np.diff(w.t))), 1e-6)
    lo, hi = w.t[0] + TRIALS[-1], w.t[-1] + TRIALS[0]               # every shift stays inside the wheels' span
    dom = np.gradient(om, w.t)                                      # the wheels' yaw acceleration [rad/s^2]
    out = []
    for a in np.arange(max(gt[0], lo), min(gt[-1], hi) - WINDOW + 1e-9, WINDOW):
        sel = (gt >= a) & (gt < a + WINDOW)
        if sel.sum() < MIN_SAMPLES:
            continue
        tg, gg = gt[sel], g[sel]
        if float(np.std(np.interp(tg, w.t, om))) < MIN_TURN:
            continue                                                # straight or still: no timing in it
        fits = [_fit(gg, np.interp(tg - d, w.t, om)) for d in TRIALS]
        cost = np.array([f[0] for f in fits])
        i = int(np.argmin(cost))
        if i == 0 or i == len(TRIALS) - 1:
            continue                                                # outside the range tried
        if cost[i] > MAX_MISFIT * noise2:
            continue                                                # slip bends it: no shift explains that
        if not 0.5 < abs(fits[i][1]) < 2.0:
            continue                                                # a unit or mounting mistake (analysis.mounting)
        c0, c1, c2 = cost[i - 1], cost[i], cost[i + 1]
        step = TRIALS[1] - TRIALS[0]
        curv = c0 - 2.0 * c1 + c2
        delta = float(TRIALS[i] + (0.5 * step * (c0 - c2) / curv if curv > 0 else 0.0))
        # Fisher information of the shift: the residual's sensitivity to it
        # is the factor times the wheels' yaw acceleration; the samples count
        # at most at the wheels' rate (the gyro's extra samples see the same
        # interpolated wheel rate).
        slope = fits[i][1] * np.interp(tg - delta, w.t, dom)
        n_eff = min(1.0, (WINDOW * wheel_hz) / len(tg))
        info = n_eff * float(np.sum(slope ** 2)) / max(cost[i], noise2)
        if info <= 0.0:
            continue
        sigma = max(1.0 / np.sqrt(info), MIN_WINDOW_SIGMA)
        if sigma > MAX_WINDOW_SIGMA:
            continue
        out.append(Offset(delta, float(sigma), float(a), float(a + WINDOW)))
    return out


#: How gyro_offset_warnings' lines begin (calibrate reads them back from
#: an estimate's flags rather than fitting the clock again).
SAID = ("gyro time stamps look", "the gyro clock seems to jump by")


def gyro_offset_warnings(log) -> list[str]:
    """One line for a gyro clock that is off against the wheels over the
    log, and one for a clock that jumps; [] when neither shows."""
    parts = window_offsets(log)
    whole = combine(parts)
    out = []
    found = jump(parts, MIN_OFFSET)
    # a jump's two clocks average to an offset no clock had: only the jump is said then
    if (found is None and whole is not None and abs(whole.delta) > max(N_SIGMA * whole.sigma, MIN_OFFSET)
            and len(parts) >= 2):
        out.append(f"{SAID[0]} {whole.delta:+.2f} s late (sigma {whole.sigma:.2f} s) against the wheels: "
                   "every turn then looks like slip, and the scale factors bend to explain it; re-stamp gyro.csv "
                   "(t less the offset)")
    if found is not None:
        _, a, b = found
        # the last window before may hold the jump itself
        out.append(f"{SAID[1]} {b.delta - a.delta:+.2f} s between t={a.t1 - WINDOW:.0f} and "
                   f"{b.t0 + WINDOW:.0f} s (offsets {a.delta:+.2f} s before, {b.delta:+.2f} s after) against the "
                   "wheels: the scale factors bend to explain it")
    return out


#: The GPS's and the gyro's whole-log offsets (as their lines say them).
_LATE = re.compile(r"^(GPS|gyro) time stamps look ([+-]\d+\.\d+) s late \(sigma (\d+\.\d+) s\)")
#: ...that agree within this many of their joint sigmas (plus the lines' rounding) name the wheels.
ALIKE_SIGMAS = 2.0
#: How wheels_late_lines' line begins.
WHEELS_LATE = "the GPS ("


def wheels_late_lines(lines: list[str]) -> list[str]:
    """One line when the GPS and the gyro both look late (or early) against
    the wheels by the same amount: two reference clocks off alike is far
    less likely than the wheels' own stamps off, such as an odometry
    filter's lag (diff_drive_controller's velocity_rolling_window_size
    averages the last speeds; a probe's 10-sample window at 50 Hz made both
    references look 0.10 s early, and calibrate advised --time-offset for
    the GPS, which mends neither). ``lines``: the flags gps_offset_warnings
    and gyro_offset_warnings gave (their texts are this module's and
    analysis.timing's own)."""
    found = {}
    for line in lines:
        m = _LATE.match(line)
        if m and "lever arm" not in line:
            found.setdefault(m.group(1), (float(m.group(2)), float(m.group(3))))
    if len(found) < 2:
        return []
    (dg, sg), (dw, sw) = found["GPS"], found["gyro"]
    # alike: each within ALIKE_SIGMAS of their inverse-variance mean (plus the lines' rounding)
    wg, ww = 1.0 / max(sg, 0.005) ** 2, 1.0 / max(sw, 0.005) ** 2
    mean = (wg * dg + ww * dw) / (wg + ww)
    if np.sign(dg) != np.sign(dw) or any(abs(d - mean) > ALIKE_SIGMAS * sd + 0.01 for d, sd in ((dg, sg), (dw, sw))):
        return []
    return [f"the GPS ({dg:+.2f} s, sigma {sg:.2f}) and the gyro ({dw:+.2f} s, sigma {sw:.2f}) both look late "
            f"against the wheels by about {mean:+.2f} s: the wheels' own stamps are likelier off than two clocks "
            "alike (an odometry filter's lag, such as diff_drive_controller's velocity_rolling_window_size); "
            f"re-stamp the wheels' file ({'t less' if mean < 0 else 't plus'} {abs(mean):.2f} s), not the GPS "
            "or the gyro; not trustworthy"]


def without_reference_clocks(lines: list[str]) -> list[str]:
    """``lines`` without the GPS's and the gyro's whole-log offset lines when
    wheels_late_lines names the wheels instead (their remedies, re-stamping
    the GPS or the gyro, would mend neither)."""
    if not any(w.startswith(WHEELS_LATE) for w in lines):
        return lines
    return [w for w in lines if not (_LATE.match(w) and "lever arm" not in w)]
