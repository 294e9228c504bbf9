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


def wheel_motion(est, track_width: float) -> tuple[np.ndarray, np.ndarray]:
    """((N, 2) the ground's speed under each wheel, (N, 2) each wheel's own
    surface speed = ground speed + slip (LOG_FORMAT's error model; factors.
    encoder, paper eq. 19-24)) of ``est``'s rows, (left, right) [m/s], for
    the nominal track ``track_width`` [m] times the estimated track scale."""
    x = est.mean
    half = 0.5 * track_width * x[:, S.SCALE][:, 2]
    v, w = x[:, S.V], x[:, S.OMEGA]
    ground = np.stack([v - w * half, v + w * half], -1)
    return ground, ground + x[:, S.SLIP]


def reversed_motion_warnings(est, track_width: float) -> list[str]:
    """One line per stretch where ``est`` has the robot travelling one way
    while both wheels drive it the other (LOG_FORMAT's error model: the
    surface speed is ground speed plus slip), lasting MIN_DURATION or more;
    [] when there is none."""
    t = est.t
    if len(t) < 2:
        return []
    x = est.mean
    v = x[:, S.V]
    ground, surface = wheel_motion(est, track_width)
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


#: A wheel turning slower than the ground under it passes (a skid) by more
#: than this [m/s], by a median over the stretch of SKID_SIGMA of its own
#: sigma...
SKID_MIN = 0.03
SKID_SIGMA = 1.0
#: ...and by more than this share of the ground speed (a scale error that
#: small is left to the other checks)...
SKID_REL = 0.05
#: ...for at least this long [s]. A driven wheel skids for a moment when it
#: brakes; one that stays slower than the ground for seconds is what a
#: calibration that took up slip looks like afterwards.
SKID_DURATION = 5.0


def skid_warnings(est, track_width: float) -> list[str]:
    """One line per wheel that ``est`` (nominal track ``track_width`` [m]) has turning slower than the ground
    under it passes (slip against the ground's direction: LOG_FORMAT's
    error model, surface speed = ground speed + slip), beyond SKID_MIN,
    SKID_SIGMA of the slip's sigma and SKID_REL of the ground speed, over
    SKID_DURATION or more at once; [] when there is none.

    Why it matters: a wheel that spun while the paper's schedule forced slip
    to zero (eq. 35-36) leaves its scale factor too large by that slip's
    share of the speed. Once the spinning stops, the only way the estimate
    can explain the wheel is a slip of the opposite sign, held for as long
    as the robot drives: it never grips again. A wheel that drags for a
    while and then grips again for SKID_DURATION, or to the end of the log's
    motion, is not taken for this (yard's own 8 s drag, in a log that ends
    4 s after it, was). A probe's log (the right wheel spinning 0.1 m/s from
    3 to 80 s of a 100 s log, a 20 s window) ended with scale_right 9 %
    off at 107 sigma, status ok; its slip then read -0.08 m/s for the last
    20 s. A stall in the window is caught before the estimate
    (estimators.slipcheck); a slip that fills the window looks normal there.

    Only for logs with an absolute position or speed reference: without one
    the ground speed is the wheels' own (the common scale is not determined),
    and a skid-steer robot's real sideways skid in turns (the Jackal bag)
    reads as one wheel slower than the other."""
    t = est.t
    if len(t) < 2:
        return []
    x, sig = est.mean, est.sigma
    ground, _ = wheel_motion(est, track_width)
    slip = x[:, S.SLIP]
    against = -slip * np.sign(ground)                              # > 0: slower than the ground
    thr = np.maximum(SKID_MIN, SKID_REL * np.abs(ground))
    # over one-second means: a filter's rows jitter about the threshold
    n = min(len(t), max(1, int(round(1.0 / max(float(np.median(np.diff(t))), 1e-9)))))   # (a log under 1 s)
    mean = (lambda a: np.stack([np.convolve(a[:, j], np.ones(n) / n, "same") for j in (0, 1)], -1))
    moving = np.abs(ground) > MIN_SPEED
    skid = (mean(against - thr) > 0) & moving
    # gripping again: |slip| within the threshold while moving
    grip = (mean(np.abs(slip) - thr) < 0) & moving
    out = []
    for j, name in enumerate(("left", "right")):
        edges = np.flatnonzero(np.diff(np.concatenate([[0], skid[:, j].astype(np.int8), [0]])))
        gedges = np.flatnonzero(np.diff(np.concatenate([[0], grip[:, j].astype(np.int8), [0]])))
        t_last = float(t[np.flatnonzero(moving[:, j])[-1]]) if moving[:, j].any() else float(t[-1])
        grips = [(float(t[a]), float(t[b - 1])) for a, b in zip(gedges[::2], gedges[1::2])]
        for a, b in zip(edges[::2], edges[1::2]):
            t0, t1 = float(t[a]), float(t[b - 1])
            if t1 - t0 < SKID_DURATION:
                continue
            # A wheel that drags for a while and then grips again (a brake, a
            # rut: the simulator's yard has one) had its scale right; one
            # whose scale took up slip never grips again while it drives.
            # (or grips from the skid's end to the last moving row: a log that
            # ends soon after a drag has no room for SKID_DURATION of grip)
            if any(g0 >= t1 - 1.0 and (g1 - g0 >= SKID_DURATION or (g0 <= t1 + 1.0 and g1 >= t_last - 0.5))
                   for g0, g1 in grips):
                continue
            seg = slice(a, b)
            # a filter's slip sigma is an instant's; held for seconds, a skid
            # of one sigma is already far beyond what its random walk wanders
            if np.median(against[seg, j]) <= SKID_SIGMA * np.median(sig[seg, S.SLIP][:, j]):
                continue
            share = float(np.median(against[seg, j] / np.abs(ground[seg, j])))
            out.append(f"{est.method}: from t={t0:.1f} to {t1:.1f} s the {name} wheel turns {100 * share:.0f} % "
                       f"slower than the ground under it passes (slip {float(np.median(slip[seg, j])):+.3f} m/s): "
                       "a driven wheel does not skid that long; its scale factor is likely too large, having "
                       "taken up slip (held at zero while calibrating, or taken for rare by the slip prior), or "
                       "the scale factors are wrong; not trustworthy")
            break                                                  # one line per wheel
    return out


# ------------------------------------- a calibration the rest of the log contradicts
#: After the calibration window (from TRANSFER_AFTER [s] past the schedule's
#: switch, when the slip states have settled), a wheel whose slip stays one
#: signed share of its ground speed is read as a scale factor off by that
#: share: beyond TRANSFER_SIGMA of the scale factor's sigma and TRANSFER_REL,
#: ...
TRANSFER_AFTER = 2.0
TRANSFER_SIGMA = 4.0
TRANSFER_REL = 0.005
#: ...on one side in TRANSFER_SIGN of the wheel's moving rows, over at least
#: TRANSFER_MIN_S [s] of driving. A slip is an event; a scale error is there
#: whenever the wheel turns.
TRANSFER_SIGN = 0.7
TRANSFER_MIN_S = 10.0
#: A row counts only this close [s] to an absolute measurement.
TRANSFER_SEEN = 1.0
#: The share must hold in each of this many consecutive parts of those rows.
TRANSFER_PARTS = 4


def window_transfer_warnings(est, track_width: float, seen: np.ndarray) -> list[str]:
    """One line per wheel whose slip after the calibration window (``est.t_switch``)
    is a steady share of its ground speed far beyond its scale factor's sigma;
    [] when there is none (or no window). Only rows within TRANSFER_SEEN of
    an absolute measurement (``seen``: their sorted times [s]) count: in a
    GPS outage the slips wander with nothing to hold them (a probe's 60 s
    outage read 5 % at 27 sigma, the scale factors right).

    Why: the paper's schedule holds slip at zero while it calibrates (eq.
    35-36), so a wheel that slipped by a little for part of the window (1.5-5
    cm/s, too little for estimators.slipcheck's second-by-second check or
    skid_warnings' 3 cm/s) leaves its scale factor off by that slip's share
    of the speed, at the window's tight sigma. Once the wheel grips again the
    estimate can only explain it by a slip of the same share, held for as
    long as it drives. A hostile probe's logs (one wheel slipping 1.5-5 cm/s
    for 15 of the 20 s window, then gripping for 40 s): scale factors 4-24
    sigma off, status ok, every method; the EKF's slip then read -2.2 to
    -6.5 % of the speed in 71-99 % of its rows. On clean simulated logs
    (paper and yard, 3 seeds each, with their slip events) the EKF read up
    to 1.1 % at 4.1 sigma but one side in 50-59 % of its rows, batch within
    0.1 %; on a probe's 20 clean logs and the OptiOdom runs one side in at
    most 67 % where the share passed. Batch, which weighs the rows after the
    window too, puts the error into the slips less (one of three logs in
    tests/test_skid.py: 7.6 sigma off, slip -0.1 %; README Known
    limitations). A long slip event after a clean window is no scale error:
    the share must hold in each of TRANSFER_PARTS parts of the rows (a
    probe's wheel spinning for 40 of the 58 s after the window read 9.9 % in
    87 % of them, its scale right)."""
    if est.t_switch is None or len(est.t) < 2:
        return []
    t = est.t
    dt = np.diff(t, append=t[-1])
    after = t > est.t_switch + TRANSFER_AFTER
    if len(seen) == 0:
        return []
    k = np.clip(np.searchsorted(seen, t), 1, max(len(seen) - 1, 1))
    near = np.minimum(np.abs(t - seen[k - 1]), np.abs(seen[np.minimum(k, len(seen) - 1)] - t))
    after &= near <= TRANSFER_SEEN
    ground, _ = wheel_motion(est, track_width)
    slip = est.mean[:, S.SLIP]
    out = []
    for j, (name, k_scale) in enumerate((("left", S.SCALE_L), ("right", S.SCALE_R))):
        mv = after & (np.abs(ground[:, j]) > MIN_SPEED)
        driven = float(np.sum(dt[mv]))
        if driven < TRANSFER_MIN_S:
            continue
        share = slip[mv, j] / ground[mv, j]                     # > 0: the surface outruns the ground
        k = float(np.median(share))
        one_side = max(float(np.mean(share > 0)), float(np.mean(share < 0)))
        sig = float(est.sigma[-1, k_scale])
        thr = max(TRANSFER_REL, TRANSFER_SIGMA * sig)
        if abs(k) <= thr or one_side < TRANSFER_SIGN:
            continue
        # ...and in every part of the driving after the window: a scale error
        # is there throughout, a long slip event is not (a probe: a wheel
        # spinning 0.1 m/s for 40 of the 58 s after the window, gripping
        # before and after, read 9.9 % in 87 % of the rows, its scale right).
        parts = np.array_split(share, TRANSFER_PARTS) if share.size >= 2 * TRANSFER_PARTS else [share]
        if not all(np.sign(np.median(q)) == np.sign(k) and abs(float(np.median(q))) > thr for q in parts):
            continue
        way = "faster" if k > 0 else "slower"
        out.append(f"{est.method}: after the calibration window the {name} wheel turns {100 * abs(k):.1f} % {way} "
                   f"than the ground under it passes in {100 * one_side:.0f} % of {driven:.0f} s of driving, where "
                   f"its scale factor's sigma is {100 * sig:.2f} %: that scale factor is likely off by about "
                   f"{100 * abs(k):.1f} % (the wheel slipped while the window held slip at zero?); not trustworthy: "
                   "calibrate on a log whose window the wheels grip in, or with --calibrate-until none")
    return out


# ------------------------------------------- a robot that outran its wheels
#: A stretch where the ground passed under both wheels further than they
#: turned is a finding beyond this distance [m]...
OUTRUN_M = 0.08
#: ...with its largest speed excess beyond this many of the rows' slip sigma.
OUTRUN_Z = 4.0
#: Rows further apart than this [s] end a stretch: across a gap the motion is not measured.
OUTRUN_GAP = 2.0


def outrun_excess(est, track_width: float) -> tuple[np.ndarray, np.ndarray]:
    """((N,) how much faster the ground passed under *both* wheels than they
    turned: the smaller of the two wheels' drags [m/s]; (N,) its sigma, the
    larger slip sigma [m/s]) of ``est``'s rows (outrun_stretches).

    A wheel drags when its surface turns slower than the ground under it
    passes (slip against the ground's direction). One wheel may drag for a
    while (a brake, a rut: the yard scenario's left wheel, -0.2 m/s for 8 s);
    a driven wheel otherwise spins (the robot moves less than it turns) or
    stalls. Both at once is a skid (wheels locked while the robot slides, or
    pushed), or encoders that lost ticks, or fixes that pulled the rows
    ahead. Each drag is at most the ground's own speed under that wheel: a
    wheel spinning against a robot that barely moves counts by that motion,
    so the sign of a standing robot's v does not matter (a yard log's stuck
    robot, v -0.01 m/s with both wheels spinning 0.4 m/s forward, read 0.4
    without it). Per wheel, not against the faster wheel: in a turn the
    outer wheel turns faster than the centre moves, and a forward shift of
    the fixes there (a helper's probe: batch 0.36 m off at z 30) never
    outran it."""
    ground, surface = wheel_motion(est, track_width)
    along = np.where(ground >= 0.0, 1.0, -1.0)
    drag = np.clip(along * (ground - surface), 0.0, np.abs(ground))
    return np.min(drag, axis=1), np.max(est.sigma[:, S.SLIP], axis=1)


def outrun_stretches(est, track_width: float) -> list[tuple[float, float, float, float]]:
    """(start [s], end [s], distance beyond the wheels [m], peak in sigmas)
    of each run of ``est``'s rows ((N,) t, (N, 11) mean and sigma) in which
    the ground passed under both wheels faster than they turned (outrun_excess) by more than OUTRUN_M
    in all, at more than OUTRUN_Z sigma at its peak; [] when none did.

    Why: where the fixes shift along the direction of travel (a GNSS
    multipath shift of 0.3-1 m held for seconds), every estimator follows
    them with a slip against the travel, which no driven wheel makes: a
    helper's probe (fourteenth session) had batch 0.5 m off at z 80, status
    ok. The sideways check (analysis.sideways) cannot see it: the move is
    along the path. The thresholds were set (fifteenth session) on clean
    paper and yard logs (seeds 1-8, GPS 1-10 Hz, ranges alone, repeated
    stalls, a stuck robot whose wheels spin: at most 0.076 m, at most z 3.0)
    and the real runs (OptiOdom, libRSF: at most 0.054 m at z 0.5; the
    Jackal bag has no reference and is not checked); benchmarks/outrun.py
    measures them on other logs (results/outrun.md: the margins of clean
    logs, shifted fixes, and the misses: a shift while a wheel spins, which
    the estimate reads as that wheel spinning less and the other dragging,
    and a shift backwards inside a turn, taken for one wheel's slip).
    """
    return [r for r in outrun_runs(est, track_width) if r[2] > OUTRUN_M and r[3] > OUTRUN_Z]


def outrun_runs(est, track_width: float) -> list[tuple[float, float, float, float]]:
    """(start [s], end [s], distance beyond the wheels [m], peak in sigmas)
    of every run of ``est``'s rows in which the ground passed under both
    wheels faster than they turned, however small (outrun_stretches keeps
    the findings; benchmarks/outrun.py measures the margins)."""
    t = np.asarray(est.t, float)
    if len(t) < 2:
        return []
    e, s = outrun_excess(est, track_width)
    dt = np.diff(t)
    # an interval counts when both its rows outran the wheels and no gap lies between them
    step = (e[:-1] > 0) & (e[1:] > 0) & (dt <= OUTRUN_GAP)
    part = np.where(step, 0.5 * (e[:-1] + e[1:]) * dt, 0.0)
    z = e / np.maximum(s, 1e-12)
    edges = np.diff(np.concatenate([[0], step.astype(np.int8), [0]]))
    # intervals i..j-1: rows i..j
    return [(float(t[i]), float(t[j]), float(part[i:j].sum()), float(z[i:j + 1].max()))
            for i, j in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1))]


def outrun_warning(found: list[tuple[float, float, float, float]]) -> str:
    """The line naming outrun_stretches' ``found`` (at most five)."""
    spans = ", ".join(f"{a:.1f}-{b:.1f} s ({m:.2f} m, {z:.0f} sigma)" for a, b, m, z in found[:5])
    more = f" and {len(found) - 5} more" if len(found) > 5 else ""
    return (f"the estimate moved the robot further than its wheels turned at {spans}{more}: its rows there "
            "follow the fixes or ranges (a GNSS multipath shift along the path), or the robot skidded (wheels "
            "locked while it slid, or pushed), or the encoders lost ticks; rows there may be off by that much; "
            "not trustworthy")


#: A causal row (the EKF's, isam2's online.csv, fixed-lag's) that lands
#: further from the row before it than the robot could drive in between
#: (its speed times the interval) by more than this many of that row's
#: position sigma (x and y together)...
REVISION_SIGMAS = 6.0
#: ...and by at least this much [m], was a revision the row before could
#: not have allowed for.
REVISION_MIN = 0.2


def revision_jumps(t: np.ndarray, mean: np.ndarray, sigma: np.ndarray):
    """(i (M,), beyond (N-1,) [m], z (N-1,)): the rows i whose next row, of
    causal rows t (N,) [s], mean, sigma (N, 11), landed ``beyond`` metres
    further than the robot could drive in between (the larger |v| of the two
    times the interval), ``z`` of row i's position sigma (x and y together),
    both beyond REVISION_SIGMAS and REVISION_MIN (revision_warnings)."""
    dt = np.diff(t)
    d = np.hypot(np.diff(mean[:, S.X]), np.diff(mean[:, S.Y]))
    reach = np.maximum(np.abs(mean[:-1, S.V]), np.abs(mean[1:, S.V])) * dt
    beyond = d - reach
    s = np.hypot(sigma[:-1, S.X], sigma[:-1, S.Y])
    z = beyond / np.maximum(s, 1e-12)
    return np.flatnonzero((beyond > REVISION_MIN) & (z > REVISION_SIGMAS) & (dt > 0)), beyond, z


def revision_line(name: str, n: int, t0: float, t1: float, beyond: float, z: float) -> str:
    """The flag of n revisions between t0 and t1 [s], the worst ``beyond`` [m] at ``z`` sigma."""
    return (f"{name}: {n} time(s) from t={t0:.1f} to {t1:.1f} s a row landed further from the one before than "
            f"the robot could drive (at most {beyond:.1f} m beyond it, {z:.0f} sigma of the row before; allowed "
            f"{REVISION_SIGMAS:g}): the rows before such a jump were far off at a small sigma there; not trustworthy")


def revision_warnings(name: str, t: np.ndarray, mean: np.ndarray, sigma: np.ndarray) -> list[str]:
    """One line when causal rows t (N,) [s], mean, sigma (N, 11) jump: a row
    revised further than REVISION_SIGMAS of the position sigma of the row
    before it, beyond the distance the robot could have driven between them
    (revision_jumps). [] when none does.

    Why: each causal row is an estimate from the data up to its time; the
    next one knows more. For a consistent estimator the revision has
    covariance (earlier covariance - later covariance), smaller than the
    earlier row's own, so a revision many of its sigma long says the
    earlier row was far off at a small sigma. A causal estimator cannot take
    such rows back (they were out when the data came): they are flagged. A
    probe's yard log with 10 m fixes at 0.2 Hz had isam2's online.csv jump
    100 m between keyframes 0.2 s apart at sigma 7-9 m, up to 194 m off at
    33 sigma, while its overshoot check waited for a jump beyond any fix's
    reach (303 m)."""
    if len(t) < 2:
        return []
    bad, beyond, z = revision_jumps(t, mean, sigma)
    if not bad.size:
        return []
    worst = bad[np.argmax(beyond[bad])]
    return [revision_line(name, bad.size, float(t[bad[0]]), float(t[bad[-1] + 1]), float(beyond[worst]),
                          float(z[worst]))]
