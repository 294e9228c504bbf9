"""Mounting and wiring mistakes that the data give away.

A gyro mounted upside down, its yaw on another axis, rates in degrees per
second, or the left and right encoders swapped all leave a log that is
valid by the contract and an estimate that is wrong with a tight sigma
(issue 12: a gyro on the wrong axis gave a track scale of 0.49 +- 0.025 and
no warning). Each check compares two sensors that must agree:

- the gyro against the wheels' turn rate (nominal parameters): the sign,
  the correlation, and a ratio near 180/pi;
- the wheels against the fixes: which way the fixes' course turns, step by
  step, against the wheels' heading. Swapped encoders (or a mirrored GPS
  frame) turn every turn the other way; with a gyro as the third witness,
  the odd one out is named.
"""
from __future__ import annotations

import numpy as np

from odomgraph.factors._math import robust_sigma

#: Turning this fast [rad/s] (standard deviation of the wheels' yaw rate) is
#: needed before the gyro can be judged against the wheels.
MIN_TURN = 0.05
#: The fewest gyro samples judged.
MIN_SAMPLES = 30
#: The gyro is judged on means over BIN seconds, and only when the wheels
#: turn through MIN_TURNED radians in all.
BIN = 0.5
MIN_TURNED = 1.5
#: Below this correlation with the wheels' yaw rate the gyro does not measure yaw.
MIN_CORRELATION = 0.3
#: Below minus this correlation, the fixes turn the other way from the wheels.
FIX_CORRELATION = 0.5
#: The fixes' speed is compared with the wheels' at lags up to this [s].
MAX_LAG = 4.0
#: ...and, when none of those agrees, up to this [s], to name a clock far off.
WIDE_LAG = 30.0


#: A wheel reading exactly 0 for this long [s] while the other moves at
#: least DEAD_OTHER_SPEED [m/s] is judged: a pivot about it, or a dead encoder.
DEAD_MIN_SPAN = 3.0
DEAD_OTHER_SPEED = 0.1


def dead_encoder_warnings(log) -> list[str]:
    """One line per wheel whose encoder reads exactly 0 for DEAD_MIN_SPAN
    seconds or more while the other wheel moves, and the gyro does not turn
    as a pivot about the still wheel would (|omega| = v_other / track).
    The estimate reads such a stretch as slip (a skid at the other wheel's
    speed), which is the right number for a wheel that really skids; for a
    disconnected encoder the calibration is built around a fault, so it is
    said. Without a gyro a pivot cannot be told from a dead encoder: both
    are named."""
    from odomgraph.estimators.measurements import from_log
    w = from_log(log).wheel
    if len(w.t) < 4:
        return []
    tw = w.t if w.dt is None else w.t - 0.5 * w.dt
    gyro = (log.gyro.t, log.gyro.omega) if log.gyro is not None and len(log.gyro.t) >= 2 else None
    out = []
    for side, name in ((0, "left"), (1, "right")):
        zero = w.m[:, side] == 0.0
        other = np.abs(w.m[:, 1 - side])
        # runs of exact zeros
        edges = np.flatnonzero(np.diff(np.concatenate([[0], zero.astype(int), [0]])))
        spans = []
        for a, b in zip(edges[::2], edges[1::2]):
            t0, t1 = tw[a], tw[b - 1]
            if t1 - t0 < DEAD_MIN_SPAN or np.median(other[a:b]) < DEAD_OTHER_SPEED:
                continue
            if gyro is not None:
                sel = (gyro[0] >= t0) & (gyro[0] <= t1)
                if sel.sum() >= 3:
                    pivot = np.median(other[a:b]) / log.robot.track_width
                    if np.median(np.abs(gyro[1][sel])) > 0.5 * pivot:
                        continue                   # the gyro turns as a pivot would: a real pivot
            if _fixes_still(log, t0, t1, float(np.median(other[a:b])) * (t1 - t0)):
                continue                           # the robot stands: the other wheel spins (slip), this one is right
            spans.append((t0, t1))
        if spans:
            total = sum(b - a for a, b in spans)
            where = ", ".join(f"{a:.0f}-{b:.0f} s" for a, b in spans[:3]) + (", ..." if len(spans) > 3 else "")
            why = ("the gyro sees no turn, so the encoder looks dead or disconnected" if gyro is not None else
                   "a pivot about that wheel, or a dead encoder (no gyro to tell)")
            out.append(f"the {name} encoder reads 0 for {total:.0f} s ({where}) while the other wheel moves: {why}; "
                       "those stretches are estimated as slip")
    return out


def _fixes_still(log, t0: float, t1: float, wheel_travel: float) -> bool:
    """The GPS fixes over [t0, t1] moved less than a quarter of what the
    moving wheel says (and stay within a few sigma of where they were): the
    robot stood, a stuck wheel read 0 rightly while the other spun."""
    g = log.gps
    if g is None or len(g.t) < 2:
        return False
    sel = (g.t >= t0) & (g.t <= t1)
    if sel.sum() < 3:
        return False
    spread = float(np.hypot(np.ptp(g.x[sel]), np.ptp(g.y[sel])))
    sig = float(np.median(g.sigma[sel])) if g.sigma is not None else log.robot.gps_sigma
    return spread < max(0.25 * wheel_travel, 6.0 * sig)


#: A gyro reading more than this many times the wheels' turn rate, or less
#: than its inverse, is not a calibration away: a unit is wrong (cm for m is
#: 100, degrees for radians 57). A skid-steer's wheels turn faster than the
#: robot: the Jackal's 2.2x (slope 0.46), longer tracked robots more.
UNITS_OFF = 10.0
#: A gyro whose bin means vary less than this many times their own noise saw no turn.
FLAT = 3.0


def _noise_sd(x: np.ndarray) -> float:
    """The noise sigma of a smooth series x (K,), from its successive
    differences (a robust MAD; the signal's own changes between half-second
    bins are small against it)."""
    d = np.diff(x)
    return robust_sigma(d - np.median(d)) / np.sqrt(2.0)


def _bin_means(t: np.ndarray, x: np.ndarray, width: float) -> np.ndarray:
    """Means of x over consecutive ``width``-second bins of t (empty bins left out)."""
    k = np.floor((t - t[0]) / width).astype(np.int64)
    n = np.bincount(k)
    s = np.bincount(k, weights=x)
    return s[n > 0] / n[n > 0]


def unit_refusal(log) -> str | None:
    """The line for a gyro no estimate should be made from (dead, or in
    degrees per second), or None. pipeline.estimate refuses a log with it,
    naming gyro.csv; the live stream (online.Online) once its warm-up holds
    the turns to tell."""
    if log.gyro is None:
        return None
    return dead_gyro(log) or gyro_in_degrees(log)


#: The ratio of the gyro's fast turns to the wheels' [-] taken for degrees per
#: second: 57.3 times a true ratio of 0.26-1.6. A skid-steer's wheels "turn"
#: up to 2-4x faster than the robot does (their sideways scrub; a probe's read
#: 26x in deg/s); a ratio beyond 90 is no degree.
DEGREES_RATIO = (15.0, 90.0)


def gyro_in_degrees(log) -> str | None:
    """The line for a gyro that follows the wheels' turns DEGREES_RATIO
    (15-90) times over with a clear correlation (MIN_CORRELATION: the
    refusal stops the run), or None; 57.3 is degrees per second read as rad/s. Not a mounting
    mistake to warn of but a unit to fix: pipeline.estimate refuses the log
    with it (a probe's deg/s gyro ran on with 11 warnings and wrote scale
    factors of 0.1)."""
    gyro_c, slope, _ = _gyro_against_wheels(log)
    if gyro_c is not None and gyro_c > MIN_CORRELATION and _is_degrees(slope):
        return _degrees_line(slope)
    return None


def _is_degrees(slope: float | None) -> bool:
    return slope is not None and DEGREES_RATIO[0] < slope < DEGREES_RATIO[1]


def _degrees_line(slope: float) -> str:
    return (f"the gyro reads {slope:.0f}x the wheels' turn rate: it looks like degrees per second, and the log must "
            f"hold rad/s (or the track width is {slope:.0f}x too large, or the wheel speeds that much too small)")


#: A gyro whose samples span at most this [rad/s] reads nothing (one
#: least-significant step of flicker is still dead: a probe's flickering
#: gyro passed an exact-equality test and isam2 wrote z +28)...
DEAD_SPAN = 2e-3
#: ...while the wheels' yaw rate varies by this much [rad/s] (std of half-second means).
DEAD_TURN = 0.15


def dead_gyro(log) -> str | None:
    """The line for a gyro every sample of which reads one value while the
    wheels turn (MIN_TURNED rad and more), or None: a dead sensor or a
    channel that is no yaw rate. Refused by pipeline.estimate as a unit is
    (a probe's all-zero gyro: three estimators stopped with a divergence that
    named nothing, isam2 wrote scale factors 24 sigma off)."""
    from odomgraph.analysis.holdout import wheel_yaw_rate_at_gyro
    rate = wheel_yaw_rate_at_gyro(log)
    if rate is None or len(rate[0]) < MIN_SAMPLES or np.ptp(rate[1]) > DEAD_SPAN:
        return None
    t, g, w = rate
    # The turns are the wheels' changes of yaw rate: a steady one is a
    # robot driving straight on wheels of unequal size (a probe: 1.03 and
    # 0.98 "turned" 7 rad past a deadbanded gyro reading 0).
    w = _bin_means(t, w, BIN)
    w = w - np.median(w)
    turned = float(np.sum(np.abs(w)) * BIN)
    if np.std(w) < DEAD_TURN or turned < MIN_TURNED:
        return None
    return (f"every gyro sample reads {float(np.median(g)):g} rad/s (within {float(np.ptp(g)):.2g}) while the "
            f"wheels turn {turned:.0f} rad: a dead gyro, or a channel that is no yaw rate; remove gyro.csv to "
            "estimate without it")


def _gyro_against_wheels(log) -> tuple[float | None, float | None, bool]:
    """(correlation of the gyro with the wheels' yaw rate, the ratio of their
    fast turns (gyro / wheels), whether the gyro is flat), the first two None
    when the log turns too little to tell."""
    from odomgraph.analysis.holdout import wheel_yaw_rate_at_gyro
    gyro_c, slope, gyro_flat = None, None, False
    rate = wheel_yaw_rate_at_gyro(log)
    if rate is not None:
        t, g, w = rate
        # Judged on half-second means: sample by sample, tick quantisation
        # makes the wheels' rate noise, and a log that barely turns (3 s of
        # straight driving, a probe's) then "correlates" 0.15 with the gyro.
        g, w = _bin_means(t, g, BIN), _bin_means(t, w, BIN)
        gyro_flat = len(g) > 2 and np.std(g) < FLAT * _noise_sd(g)
        turned = float(np.sum(np.abs(w)) * BIN)
        if len(g) >= MIN_SAMPLES // 3 and np.std(w) >= MIN_TURN and turned >= MIN_TURNED and np.std(g) > 0:
            gyro_c = float(np.corrcoef(g, w)[0, 1])
            # The ratio of the fast turns, gyro to wheels: slip looks like
            # turning to the wheels and not to the gyro, and pulls a
            # least-squares slope or a median ratio far down (a correct gyro
            # gave 0.64 and 0.34 on a log with slip); the top of each
            # distribution is the robot's real turns.
            slope = float(np.percentile(np.abs(g), 95) / np.percentile(np.abs(w), 95))
    return gyro_c, slope, gyro_flat


def mounting_warnings(log) -> list[str]:
    """One line per mounting or wiring mistake that the log shows."""
    fix_c = fix_turn_correlation(log)
    gyro_c, slope, gyro_flat = _gyro_against_wheels(log)
    units = _wheel_units_line(gyro_c, slope)
    if units:
        return [units]     # every check below reads the wheels in their units, and would blame something else
    out = []
    speed = fix_speed_correlation(log)
    if speed is not None and speed[0] < MIN_CORRELATION:
        c0, lag, c_lag = speed
        # A clock offset only when the shifted speeds agree well, at a lag
        # inside the range tried (a periodic path correlates somewhere at the
        # edge: one encoder backwards gave 0.63 at 4 s).
        if c_lag > 0.8 and 0 < abs(lag) < MAX_LAG:
            out.append(f"the fixes' speed follows the wheels' {lag:+.0f} s later (correlation {c_lag:.2f}, "
                       f"{c0:.2f} without the shift): the GPS clock is off by about that much; estimate it with "
                       "--time-offset")
        else:
            # A clock further off than the shifts tried (GPS time runs 18 s
            # ahead of UTC: a probe's log so was blamed on an encoder alone)
            # is named as the other cause, not the only one: a periodic path
            # agrees with itself a period later too.
            wide = fix_speed_correlation(log, max_lag=WIDE_LAG)
            late = wide is not None and wide[2] > 0.8 and abs(wide[1]) >= MAX_LAG
            out.append(f"the wheels' speed does not follow the fixes' (correlation {c0:.2f}): one encoder counts "
                       "backwards, or the encoders are not the wheels the log says"
                       + (f", or the GPS clock is off by about {wide[1]:+.0f} s (shifted so, the speeds agree: "
                          f"correlation {wide[2]:.2f}; GPS time runs 18 s ahead of UTC): subtract it from gps.csv's "
                          "times and run again" if late else ""))
        return out   # the turn checks below would only repeat it under other names
    fixes_against = fix_c is not None and fix_c < -FIX_CORRELATION
    # With the gyro against the wheels too, a weaker no from the fixes is enough
    # (their course is noisy at a few Hz): two witnesses against one.
    if gyro_c is not None and gyro_c < -MIN_CORRELATION and fix_c is not None and fix_c < -0.2:
        fixes_against = True
    if fixes_against:
        if gyro_c is not None and gyro_c < -MIN_CORRELATION:
            out.append(f"the fixes and the gyro both turn against the wheels (correlations {fix_c:.2f}, {gyro_c:.2f}): "
                       "the left and right encoders look swapped (or both count backwards)")
        elif gyro_c is not None and gyro_c > MIN_CORRELATION:
            out.append(f"the fixes turn against the wheels and the gyro (correlation {fix_c:.2f}): the GPS frame looks "
                       "mirrored (x and y, or lat and lon, swapped)")
        else:
            out.append(f"the fixes turn against the wheels (correlation {fix_c:.2f}): the left and right encoders are "
                       "swapped, or the GPS frame is mirrored")
    if gyro_c is None:
        return out
    if gyro_c < -MIN_CORRELATION and not fixes_against:
        sure = fix_c is not None and fix_c > 0.2      # the fixes side with the wheels
        out.append(f"the gyro turns against the wheels (correlation {gyro_c:.2f}): the gyro is mounted upside down "
                   "or its sign is flipped" + ("" if sure else ", or the left and right wheels are swapped"))
    elif abs(gyro_c) < MIN_CORRELATION:
        # A gyro that saw no turn at all, against wheels that did: either it
        # does not measure yaw, or the robot drove straight and the wheels'
        # difference was slip (a probe's straight-line log with slip events
        # was refused by calibrate so). The fixes' course breaks the tie.
        if not (gyro_flat and fix_c is not None and fix_c < MIN_CORRELATION):
            out.append(f"the gyro does not follow the wheels' turn rate (correlation {gyro_c:.2f}): its yaw is on "
                       "another axis than the log says, or it is not in rad/s"
                       + (", or the robot drove straight and the wheels' difference was slip"
                          if gyro_flat and fix_c is None else ""))
    elif gyro_c > 0 and _is_degrees(slope):
        out.append(_degrees_line(slope))
    return out


def _wheel_units_line(gyro_c: float | None, slope: float | None) -> str | None:
    """The line for wheels whose turn rate is UNITS_OFF or more times off the
    gyro's (which follows them: gyro_c > MIN_CORRELATION), or None. A probe:
    JointState positions in degrees, and a wheel radius in cm, passed the
    import, and estimate blamed an encoder counting backwards (the path
    dead-reckoned from such wheels follows nothing). A gyro in degrees per
    second is mounting_warnings' own line."""
    if gyro_c is None or gyro_c < MIN_CORRELATION or slope is None or slope <= 0:
        return None
    if 35.0 < 1.0 / slope < 90.0:
        return (f"the wheels turn {1.0 / slope:.0f}x faster than the gyro: their speeds look like degrees, not "
                "radians, times the wheel radius (or the radius, ticks per metre or track are off that much)")
    if not 1.0 / UNITS_OFF < slope < UNITS_OFF and not _is_degrees(slope):
        return (f"the gyro reads {slope:.3g}x the wheels' turn rate: the wheel speeds, or the track width, are off "
                "by that factor (a unit: cm or mm for m?), far beyond any calibration or skid")
    return None


#: A grid step is compared only when the fixes around both its ends are at
#: most this many steps apart: across a dropout the fixes' straight line is
#: no path (a 60 s outage read as "one encoder counts backwards").
MAX_FIX_GAP = 2.0


def _fix_grid(log, step: float):
    """(grid times, fix x, fix y on the grid, wheel path (t, pose), fix sigma,
    (grid-1,) mask of the steps the fixes cover) or None."""
    from odomgraph.estimators.measurements import clean, dead_reckoning, from_log
    if log.gps is None or len(log.gps.t) < 20:
        return None
    log = clean(log)[0]
    g = log.gps
    if len(g.t) < 20:
        return None
    t_dr, dr = dead_reckoning(from_log(log), log.robot.track_width)
    lo, hi = max(g.t[0], t_dr[0]), min(g.t[-1], t_dr[-1])
    if hi - lo < 10 * step or np.median(np.diff(g.t)) > step:
        return None
    grid = np.arange(lo, hi, step)
    sig = float(np.median(g.sigma)) if g.sigma is not None else log.robot.gps_sigma
    # the span of the two fixes around each grid time
    j = np.clip(np.searchsorted(g.t, grid), 1, len(g.t) - 1)
    ok = (g.t[j] - g.t[j - 1]) <= MAX_FIX_GAP * step
    covered = ok[:-1] & ok[1:]
    return grid, np.interp(grid, g.t, g.x), np.interp(grid, g.t, g.y), t_dr, dr, sig, covered


#: fix_speed_correlation leaves out steps whose fix and wheel speeds differ
#: beyond this many robust sigmas of the rest, if they are at most this share.
OUTLIER_MADS = 8.0
OUTLIER_SHARE = 0.1


def fix_speed_correlation(log, step: float = 2.0, max_lag: float | None = None):
    """(correlation between the fixes' speed and the wheels' speed (nominal)
    over ``step``-second steps, the lag [s] of the fixes that correlates
    best within +-max_lag, that correlation); None when the robot's speed
    varies too little (against the fix noise) to tell."""
    grid_data = _fix_grid(log, step)
    if grid_data is None:
        return None
    grid, x, y, t_dr, dr, sig, covered = grid_data
    fix_speed = (np.hypot(np.diff(x), np.diff(y)) / step)[covered]
    max_lag = MAX_LAG if max_lag is None else max_lag

    # The antenna on the wheels' path: on a pivot the robot's centre stands
    # while the antenna sweeps its lever arm round (a probe's pivot-only log
    # read as "one encoder counts backwards").
    lx, ly = log.robot.gps_lever_arm
    c, s_ = np.cos(dr[:, 2]), np.sin(dr[:, 2])
    ax, ay = dr[:, 0] + c * lx - s_ * ly, dr[:, 1] + s_ * lx + c * ly

    def wheel_speed(lag):
        px, py = np.interp(grid - lag, t_dr, ax), np.interp(grid - lag, t_dr, ay)
        return (np.hypot(np.diff(px), np.diff(py)) / step)[covered]
    w0 = wheel_speed(0.0)
    if fix_speed.size < 10:
        return None
    lags = np.arange(-max_lag, max_lag + 1e-9, 0.5)
    # A wild fix (a probe's first fix 5-17 m off) makes the steps either side
    # of it disagree with the wheels by far more than the rest do; at a
    # near-constant speed those one or two steps decide the correlation
    # alone, and read as "one encoder counts backwards" they refused good
    # logs. They are left out: beyond OUTLIER_MADS robust sigmas of the
    # steps' disagreement at every lag tried (a late clock's speed changes
    # agree at its lag, and stay), and only a few (OUTLIER_SHARE: a
    # backwards encoder makes most steps disagree, and is kept whole).
    sane = np.zeros(fix_speed.size, bool)
    for lag in lags:
        r = fix_speed - wheel_speed(lag)
        sane |= np.abs(r - np.median(r)) <= max(OUTLIER_MADS * robust_sigma(r - np.median(r)), 4.0 * sig / step)
    if np.mean(~sane) > OUTLIER_SHARE:
        sane[:] = True
    fix_speed = fix_speed[sane]
    if fix_speed.size < 10 or np.std(fix_speed) < 4.0 * sig / step or np.std(w0[sane]) == 0:
        return None

    def corr_at(lag):
        w = wheel_speed(lag)[sane]
        return float(np.corrcoef(fix_speed, w)[0, 1]) if np.std(w) > 0 else None
    corr = {lag: c for lag in lags if (c := corr_at(lag)) is not None}
    best = max(corr, key=corr.get)
    return corr.get(0.0, float(np.corrcoef(fix_speed, w0[sane])[0, 1])), float(best), corr[best]


def fix_turn_correlation(log, step: float | None = None) -> float | None:
    """Correlation between how the fixes' course turns and how the wheels'
    heading turns, over ``step``-second steps [-1..1]; None when the fixes are
    too few or the robot turns too little to tell. Independent of the scale
    factors (they change how much, not which way), and of driving backwards
    (the course is then off by pi, its changes are not). ``step`` defaults
    to four fix intervals, at least 1 s: a course from two noisy fixes a
    fraction of a second apart is mostly noise."""
    if step is None:
        if log.gps is None or len(log.gps.t) < 2:
            return None
        step = max(1.0, 4.0 * float(np.median(np.diff(log.gps.t))))
    grid_data = _fix_grid(log, step)
    if grid_data is None:
        return None
    grid, x, y, t_dr, dr, sig, covered = grid_data
    dx, dy = np.diff(x), np.diff(y)
    moving = (np.hypot(dx, dy) > max(6.0 * sig, 0.05)) & covered
    course = np.arctan2(dy, dx)
    ok = moving[:-1] & moving[1:]
    d_course = np.angle(np.exp(1j * np.diff(course)))[ok]
    mid = 0.5 * (grid[:-1] + grid[1:])
    heading = np.interp(mid, t_dr, dr[:, 2])
    d_heading = np.diff(heading)[ok]
    if d_course.size < MIN_SAMPLES // 2 or np.std(d_heading) < MIN_TURN * step or np.std(d_course) == 0:
        return None
    return float(np.corrcoef(d_course, d_heading)[0, 1])
