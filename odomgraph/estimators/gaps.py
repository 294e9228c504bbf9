"""A gap in the fixes that the wheels slipped in: when, the log cannot say.

Between two fixes far apart (a GPS outage, a beacon out of sight) only the
wheels and the gyro speak. If the fixes after the gap say the robot went
less far than its wheels turned, the wheels slipped in the gap (a stall: held
against a drift, both wheels spinning), but the gyro cannot say when: both
wheels spinning together turn nothing. A smoother puts that slip where its
prior likes it best (the sparse slip prior: all at once, anywhere), and the
positions inside the gap are then off by up to the slip's distance along
the track, at the sigma of a robot whose slip is known. A hostile probe's
yard log (a 10 s stall inside a 14 s GPS outage) had batch 0.5-1.2 m off at
sigma 1-4 cm (z 58), status ok.

``widen_gaps`` gives the rows inside each such gap the variance of that
unknown timing, in x and in y: D^2 f (1 - f), D the common-mode slip
distance the estimate puts in the gap and f the row's fraction of it (a
Brownian bridge: nothing at the fixes either side, sigma D/2 mid-gap). Rows of a
whole-log smoother only (batch, isam2's smoothed states): a causal row
cannot know yet how the gap ends.
"""
from __future__ import annotations

import numpy as np

from odomgraph import state as S

#: A gap is at least this long [s] and GAP_INTERVALS median fix intervals...
MIN_GAP = 2.0
GAP_INTERVALS = 3.0
#: ...and the slip distance in it at least this [m], and FIX_SIGMAS of the
#: fixes' sigma, to count: less, the fix after the gap cannot have shown it
#: (a slip that ended just before an outage leaks a few centimetres into it).
MIN_DISTANCE = 0.1
FIX_SIGMAS = 3.0


def min_distance(fix_sigma, robot) -> float:
    """The slip distance [m] a gap must hold to count (MIN_DISTANCE,
    FIX_SIGMAS): the GPS fixes' median sigma (``fix_sigma`` (G,) [m]), else
    the ranges'."""
    sig = float(np.median(fix_sigma)) if fix_sigma is not None and len(fix_sigma) else float(robot.range_sigma)
    return max(MIN_DISTANCE, FIX_SIGMAS * sig)


def fix_times(kf) -> np.ndarray:
    """Sorted times [s] of the absolute fixes in the keyframe problem ``kf``
    (estimators.keyframes.Keyframes: GPS fixes at their times, ranges at
    their interval's start); empty without any. From the keyframes, not the
    measurements: a stream's problem grows its keyframes, and its
    measurements hold only the warm-up."""
    ts = []
    if kf.gps_t is not None and len(kf.gps_t):
        ts.append(np.asarray(kf.gps_t, float))
    if len(kf.rng_k):
        ts.append(np.asarray(kf.t)[np.asarray(kf.rng_k, int)])
    return np.unique(np.concatenate(ts)) if ts else np.zeros(0)


def gaps(fix_t: np.ndarray) -> list[tuple[float, float]]:
    """(start, end) [s] of the gaps between consecutive fixes longer than
    MIN_GAP and GAP_INTERVALS median intervals."""
    if len(fix_t) < 3:
        return []
    d = np.diff(fix_t)
    long = np.flatnonzero(d > max(MIN_GAP, GAP_INTERVALS * float(np.median(d))))
    return [(float(fix_t[i]), float(fix_t[i + 1])) for i in long]


def widen_gaps(t: np.ndarray, mean: np.ndarray, sigma: np.ndarray, pose_cov: np.ndarray | None,
               fix_t: np.ndarray, least: float = MIN_DISTANCE) -> list[tuple[float, float, float, bool]]:
    """Rows t (N,) [s], mean and sigma (N, 11), pose_cov (N, 3, 3) or None,
    widened in place (x and y) inside each gap of ``fix_t`` where
    the estimate's common-mode slip covers ``least`` [m] or more (module
    docstring). Returns (start, end, distance [m], whether the bridge's
    middle, D/2, exceeds the rows' median sigma in the gap) of each gap
    widened."""
    out = []
    for a, b, sel, dist, f in _slipped_gaps(t, mean, fix_t, least):
        var = dist ** 2 * f * (1.0 - f)
        # said only where it matters: the bridge's middle beyond the rows' own
        # sigma there (a slip that ended just before an outage leaks a few cm
        # into it)
        matters = bool(0.5 * dist > float(np.median(np.minimum(sigma[sel, 0], sigma[sel, 1]))))
        # In x and y alike, not only along the heading: where the path
        # curves, slip moved to another time moves the row along another
        # direction (yard, a stall in a curve: 0.14 m across the track at a
        # cross-track sigma of 0.02 m).
        add_pose_variance(sigma, pose_cov, sel, var)
        out.append((a, b, dist, matters))
    return out


def warning(found: list[tuple[float, float, float, bool]]) -> list[str]:
    """The one line saying which gaps were widened beyond their rows' own
    sigma, or []."""
    found = [g for g in found if g[3]]
    if not found:
        return []
    parts = ", ".join(f"t={a:.1f}-{b:.1f} s ({d:.2f} m)" for a, b, d, _ in found)
    return [f"the wheels slipped inside gaps in the fixes ({parts}): when inside each gap is not known, so the "
            "positions there carry up to that distance in their sigma"]


def _slipped_gaps(t: np.ndarray, mean: np.ndarray, fix_t: np.ndarray, least: float):
    """Each gap of ``fix_t`` whose rows put ``least`` [m] or more of
    common-mode slip in it: (start, end [s], indices of its rows, the slip
    distance [m], each row's fraction f of the way through the gap)."""
    for a, b in gaps(fix_t):
        sel, dist = _slip_distance(t, mean, a, b)
        if dist >= least:
            yield a, b, sel, dist, (t[sel] - a) / (b - a)


def _slip_distance(t: np.ndarray, mean: np.ndarray, a: float, b: float) -> tuple[np.ndarray, float]:
    """(indices of the rows inside the gap (a, b), the common-mode slip
    distance [m] the rows put in it)."""
    sel = np.flatnonzero((t > a) & (t < b))
    if sel.size < 2:
        return sel, 0.0
    s_cm = 0.5 * np.abs(mean[sel][:, S.SLIP].sum(1))
    # Edges from every row, so that a row's neighbours outside the gap count (row_edges).
    e = np.concatenate([[-np.inf], row_edges(t), [np.inf]])
    lo, hi = np.maximum(e[sel], a), np.minimum(e[sel + 1], b)
    lo[0], hi[-1] = a, b
    return sel, float(np.sum(s_cm * np.maximum(hi - lo, 0.0)))


def row_edges(t: np.ndarray) -> np.ndarray:
    """(N-1,) [s] where each of the rows t (N,) hands over to the next: the
    midpoint, except next to a row that stands for a much longer interval
    (a wheel dropout's, a pause's: rows are stamped at their interval's
    midpoint), which takes all of the gap but the short row's half spacing.
    Otherwise a row's slip before a pause in the log would count for half
    the pause (a 30 min pause during a slip: 100-480 m of slip "in the
    gap" where the robot stood still). Two short rows with a long gap and
    no row between keep the midpoint."""
    g = np.diff(t)
    edges = t[:-1] + 0.5 * g
    if len(g) < 2:
        return edges
    left = np.concatenate([[np.inf], g[:-1]])        # the spacing before row i
    right = np.concatenate([g[1:], [np.inf]])        # the spacing after row i+1
    # (both short with a long gap between, no row standing for it: the midpoint)
    long_after = (g > 3.0 * left) & ~(g > 3.0 * right)    # row i short, row i+1 the long one
    long_before = (g > 3.0 * right) & ~(g > 3.0 * left)   # row i+1 short, row i the long one
    edges[long_after] = t[:-1][long_after] + 0.5 * left[long_after]
    edges[long_before] = t[1:][long_before] - 0.5 * right[long_before]
    return edges


#: The first fix after a gap, against a causal row's prediction: beyond this
#: squared Mahalanobis distance (chi-square, 2 dof, 1 - 1e-3) the rows in
#: the gap understated their error.
GAP_END_NIS = 13.8


def gap_end_warnings(name: str, t: np.ndarray, mean: np.ndarray, pose_cov: np.ndarray | None, gps, lever,
                     wheel_path, lag: float = 0.0) -> list[str]:
    """For causal rows (the EKF's, isam2's online.csv; fixed-lag's with its
    ``lag`` [s]) t (N,), mean (N, 11), pose_cov (N, 3, 3): one line when the
    first GPS fix after a gap (``gps``: (t, xy (K, 2), sigma (K,)) as
    cleaned) lies further than GAP_END_NIS allows from what the last row
    that had not seen it predicts: that row (the last before the fix less
    the lag) carried on to the fix along the wheels' own path (``wheel_path``:
    measurements.dead_reckoning's times and poses), antenna at lever arm
    ``lever`` [m]. Such rows cannot be widened after the fact (they were out
    when the fix came): they are flagged. [] when none is."""
    if gps is None or pose_cov is None or len(t) < 2:
        return []
    gt, xy, sg = gps
    t_dr, P_dr = wheel_path
    bad = []
    for a, b in gaps(np.asarray(gt)):
        i = int(np.searchsorted(t, b - lag, side="left")) - 1    # the last row that had not seen the fix
        j = int(np.searchsorted(gt, b, side="left"))
        if i < 0 or t[i] <= a or j >= len(gt):
            continue
        # that row carried on to the fix's time along the wheels' path (no slip: what it believed)
        q0 = np.array([np.interp(t[i], t_dr, P_dr[:, k]) for k in range(3)])
        q1 = np.array([np.interp(b, t_dr, P_dr[:, k]) for k in range(3)])
        c0, s0 = np.cos(q0[2]), np.sin(q0[2])
        dx, dy = q1[0] - q0[0], q1[1] - q0[1]
        step = np.array([c0 * dx + s0 * dy, -s0 * dx + c0 * dy])      # in the wheels' frame at the row
        ci, si = np.cos(mean[i, 2]), np.sin(mean[i, 2])
        pos = mean[i, 0:2] + np.array([ci * step[0] - si * step[1], si * step[0] + ci * step[1]])
        th = mean[i, 2] + q1[2] - q0[2]
        c, s = np.cos(th), np.sin(th)
        lx, ly = lever
        ant = pos + np.array([c * lx - s * ly, s * lx + c * ly])
        # the row's heading turns both the step carried on and the lever arm
        J = np.array([[1.0, 0.0, -si * step[0] - ci * step[1] - s * lx - c * ly],
                      [0.0, 1.0, ci * step[0] - si * step[1] + c * lx - s * ly]])
        Sm = J @ pose_cov[i] @ J.T + sg[j] ** 2 * np.eye(2)
        d = xy[j] - ant
        nis = float(d @ np.linalg.solve(Sm, d))
        if nis > GAP_END_NIS:
            bad.append((a, b, float(np.hypot(*d)), float(np.sqrt(nis))))
    if not bad:
        return []
    parts = ", ".join(f"t={a:.1f}-{b:.1f} s: {d:.2f} m, {z:.1f} sigma" for a, b, d, z in bad)
    return [f"{name}: the first fix after a gap in the fixes lay far from what its rows predicted ({parts}): the wheels "
            "slipped (or drifted) where nothing could see it, and its rows inside the gap understate their error; "
            "not trustworthy there"]


def unwidened_gap_warnings(name: str, t: np.ndarray, mean: np.ndarray, sigma: np.ndarray, fix_t: np.ndarray,
                           least: float = MIN_DISTANCE) -> list[str]:
    """For fixed-lag's rows (out one lag after their time: those before the
    gap's end less the lag had not seen the fix after it, the others were
    smoothed over only part of the gap): one line when a gap holds slip
    whose unknown timing (widen_gaps' bridge) exceeds 3 of the rows' own
    sigma somewhere in it. [] when none does."""
    bad = []
    for a, b, sel, dist, f in _slipped_gaps(t, mean, fix_t, least):
        bridge = dist * np.sqrt(f * (1.0 - f))
        if np.any(bridge > 3.0 * np.maximum(sigma[sel, 0], sigma[sel, 1])):
            bad.append((a, b, dist))
    if not bad:
        return []
    parts = ", ".join(f"t={a:.1f}-{b:.1f} s ({d:.2f} m)" for a, b, d in bad)
    return [f"{name}: the wheels slipped inside gaps in the fixes ({parts}); when inside each gap is not known, and "
            "its rows there (out before the gap ended, or smoothed over only part of it) do not carry that in "
            "their sigma; not trustworthy there (--method batch widens them)"]


# --- A silence of every sensor: the path inside it is not known ---------------------------------

def pause_paths(meas, kf_t: np.ndarray, kf_pose: np.ndarray, track_width: float
                ) -> list[tuple[float, float, float, float]]:
    """(start, end [s], distance [m], turn [rad]) of each silence of every
    sensor longer than PAUSE_S (measurements.pause_spans) inside the
    keyframes kf_t (K,), kf_pose (K, 3). The distance is the robot's travel
    across it as far as the log says: the wheels' (the encoder row that spans
    it: its ticks, nominal parameters), or the straight line between the
    keyframe states either side when longer (a robot moved with its wheels
    silent, or a wheel_speeds.csv log, whose speeds say nothing of the
    silence); the turn, the wheels' net turn across it (a pivot in place
    drives no distance and turns)."""
    from odomgraph.estimators.measurements import pause_spans
    out = []
    w = meas.wheel

    def travel(a, b):
        """(distance [m], net turn [rad]) the wheels report over [a, b] [s]."""
        if w.dt is None:
            return 0.0, 0.0
        lo, hi = np.maximum(w.t - 0.5 * w.dt, a), np.minimum(w.t + 0.5 * w.dt, b)
        over = np.maximum(hi - lo, 0.0)
        return (float(np.sum(np.abs(w.m.mean(1)) * over)),
                float(np.sum(np.abs(w.m[:, 1] - w.m[:, 0]) * over)) / track_width)
    for a, b in pause_spans(meas):
        if not (kf_t[0] < b and kf_t[-1] > a):
            continue
        wheels, turn = travel(a, b)
        # The keyframes either side (keyframes.py gives the silence one
        # interval, from the keyframe at or before its start to the one at or
        # after its end): their straight line, less what the wheels drove
        # between them outside the silence (at 5 Hz up to 0.2 s of driving,
        # which a parked robot's silence must not be charged with).
        i = max(int(np.searchsorted(kf_t, a + 1e-9, side="right")) - 1, 0)
        j = min(int(np.searchsorted(kf_t, b - 1e-9, side="left")), len(kf_t) - 1)
        chord = float(np.hypot(*(kf_pose[j, 0:2] - kf_pose[i, 0:2])))
        outside = travel(kf_t[i], a)[0] + travel(b, kf_t[j])[0]
        out.append((float(a), float(b), max(wheels, chord - outside), turn))
    return out


#: A silence whose wheels turned the robot this much [rad] (or drove it
#: MIN_DISTANCE) leaves its heading unknown inside.
MIN_TURN = 0.1


def pause_variance(t: np.ndarray, pauses) -> tuple[np.ndarray, np.ndarray]:
    """(x and y variance [m^2], heading variance [rad^2]) (N,) that the
    unknown path through each of ``pauses`` (pause_paths) adds at the times
    t (N,): a bridge pinned at the silence's ends, D^2 f (1 - f) in x and
    in y (D/2 mid-silence), D the distance, f the fraction of the silence
    gone; and, where the robot moved or turned at all (MIN_DISTANCE,
    MIN_TURN), a heading as unknown as a start's with no heading (pi,
    estimators.heading) mid-silence. The gyro was silent too: no turn inside
    is known, only the net one."""
    pos, th = np.zeros(len(t)), np.zeros(len(t))
    for a, b, dist, turn in pauses:
        sel = (t > a) & (t < b)
        f = (t[sel] - a) / (b - a)
        pos[sel] += dist ** 2 * f * (1.0 - f)
        if turns_unknown(dist, turn):
            th[sel] += np.pi ** 2 * 4.0 * f * (1.0 - f)
    return pos, th


def widen_pauses(t: np.ndarray, sigma: np.ndarray, pose_cov: np.ndarray | None, pauses) -> int:
    """Rows t (N,), sigma (N, 11), pose_cov (N, 3, 3) or None widened in place
    by pause_variance. Returns the number of rows widened."""
    pos, th = pause_variance(t, pauses)
    sel = (pos > 0) | (th > 0)
    add_pose_variance(sigma, pose_cov, sel, pos[sel], th[sel])
    return int(sel.sum())


def add_pose_variance(sigma: np.ndarray, pose_cov: np.ndarray | None, sel, xy, theta=None) -> None:
    """Add variance ``xy`` [m^2] to x and to y, and ``theta`` [rad^2] to the
    heading, of the rows ``sel`` (a mask or indices) of sigma (N, 11) and
    pose_cov (N, 3, 3) or None, in place: independent errors the rows'
    covariance did not hold (a gap's slip, a silence's path, the circle of
    an unknown heading). ``xy`` and ``theta`` are scalars or one per row."""
    sigma[sel, S.X] = np.sqrt(sigma[sel, S.X] ** 2 + xy)
    sigma[sel, S.Y] = np.sqrt(sigma[sel, S.Y] ** 2 + xy)
    if theta is not None:
        sigma[sel, S.THETA] = np.sqrt(sigma[sel, S.THETA] ** 2 + theta)
    if pose_cov is not None:
        pose_cov[sel, 0, 0] += xy
        pose_cov[sel, 1, 1] += xy
        if theta is not None:
            pose_cov[sel, 2, 2] += theta


def pause_note(method: str, pauses) -> list[str]:
    """The line naming each silence whose rows were widened, or []."""
    if not pauses:
        return []
    turned = [turns_unknown(d, r) for _, _, d, r in pauses]
    parts = ", ".join(f"t={a:.1f}-{b:.1f} s ({b - a:.4g} s, {d:.2f} m" + (", heading unknown" if u else "") + ")"
                      for (a, b, d, _), u in zip(pauses, turned))
    return [f"{method}: no sensor spoke during {parts}: the rows inside are drawn between the states either side, "
            "and carry the unknown path's shape in their sigma (up to half the distance"
            + (", and the heading where it says so)" if any(turned) else ")")]


def turns_unknown(dist: float, turn: float) -> bool:
    """Whether a silence's heading is widened (pause_variance): the robot
    moved ``dist`` [m] or turned ``turn`` [rad] through it at all."""
    return dist >= MIN_DISTANCE or turn >= MIN_TURN
