"""Stretches in which the robot stood still: both wheels turned by no more
than a tick's jitter, and no other sensor saw it move.

Outside the calibration window the slips are free (a random walk with a
sparse prior), so wheels that read zero pin nothing: a slip of -v explains
them for any v. Parked for ten minutes under 3 m fixes, every estimator let
the robot turn in place at the gyro bias's error (7.6e-3 rad/s, a 2 mm/s
differential slip the sparse prior barely charges): a probe's log came out
with the heading 3 rad off at z 38 (batch) and 7.6 m off at z 8 (EKF),
status ok. A wheel that does not turn does not skid either, so here the
paper's zero-slip pseudo-update (eq. 35-36) is applied: with zero slip the
encoder model itself (eq. 29) holds v and omega at zero within the encoder
noise, the gyro then measures its bias, and the heading stays put. This is
the zero-velocity update of inertial navigation, said through the model
every estimator already shares.

The assumption fails where the robot moves with wheels that do not turn: a
counter that froze while driving, a robot towed or sliding on locked wheels.
So a still stretch is kept only where the other sensors agree that nothing
moved: fixes (and each beacon's ranges) with no significant drift faster
than WANDER, over the stop so far or its last DRIFT_WINDOW seconds; a gyro
that stays within GYRO_TURN of its own median (a turn) and near the bias's
prior (a steady spin); and a velocity sensor near zero.
Nor is a stop taken that no robot could have made: the wheels at driving
speed in the row before and exactly still in the next (a counter freezing:
faster than MAX_DECEL), or one wheel quiet alone for LONE seconds around it
(a dead encoder). Where any of this disagrees, the stretch is dropped and
the slips stay free there as before; what the other sensors contradicted is
said (and flagged by the pipeline: moved_flags).

Wheel rows are stamped at the middle of their interval
(measurements.from_log): a row at t covers [t - dt/2, t + dt/2].
"""
from __future__ import annotations

import bisect
import math

import numpy as np

from odomgraph.estimators.sensors import GPS, GYRO, RANGE, VEL

#: Shortest stretch taken [s]: a robot reversing passes zero for a row or two.
MIN_STILL = 2.0
#: A still wheel's rows turn by at most JITTER ticks, and its count stays
#: within BAND ticks of where the stretch began (a vibrating robot's encoder
#: toggles an edge; a creeping one walks away from it).
JITTER = 1
BAND = 2
#: Hardest stop (or start) a robot makes [m/s^2], 0.5 g: the row before a stop
#: may be no faster than this allows over the half rows between them (plus a
#: tick's worth of speed). A counter that froze while driving jumps from the
#: driving speed to exactly zero in one row.
MAX_DECEL = 5.0
#: Fixes (or a beacon's ranges) whose least-squares slope is significant
#: against their sigma (MOVE_CHI2, p = 1e-6: it is tested at every fix, a
#: 10 min park's 12,000 RTK fixes twice each), over the stop so far or its
#: last DRIFT_WINDOW seconds (a robot parked, then towed: over the whole
#: stop the tow is diluted), faster than WANDER [m/s]: the stop is not taken.
#: Faster than MOVING it is motion (said and flagged); between the two it may
#: be a receiver's multipath walk (said only), which no test of the fixes
#: can tell from a robot sliding that slowly.
MOVING = 0.05
WANDER = 0.005
DRIFT_WINDOW = 10.0
MOVE_CHI2 = {1: 23.9, 2: 27.6}
#: The gyro: a one-second median more than GYRO_TURN [rad/s] (or 6 sigma of
#: such a median) from the median of the seconds is a turn; a median beyond
#: max(GYRO_SPIN, 3 sigma of the bias's prior) is a steady spin.
GYRO_TURN = 0.1
GYRO_SPIN = 0.1
#: A stretch in which one wheel had read nothing for more than LONE seconds
#: before the other stopped too (or, with hindsight, went on reading nothing
#: after the other moved again) is not taken: a dead encoder reads zero
#: whatever the robot does, and its "slip" carries the robot's motion on
#: both sides (a yard log's stop inside a dead left wheel's 35 s pulled
#: batch's scale factors to [5.4, 5.9, 0]).
LONE = 5.0
#: How a stretch the other sensors contradict is said. The pipeline flags it
#: (MOVED_SAYS) when the fixes, ranges or velocity sensor saw the robot
#: move, or the gyro turned by more than GYRO_FLAG [rad/s]: the wheels read
#: nothing while it moved, so the run's slips carry the whole motion. A
#: gyro that moved less is said only (TURNED_SAYS): a bias walking fast
#: moves its medians too.
MOVED_SAYS = "the wheels stood still over"
TURNED_SAYS = "the wheels read nothing over"
GYRO_FLAG = 0.3


def row_ticks(m, dt, robot) -> np.ndarray | None:
    """(..., 2) the ticks of wheel rows: speeds m (..., 2) [m/s] over dt (...) [s]
    at the nominal ticks/m; None for wheel_speeds.csv (dt None or 0)."""
    if dt is None or np.all(np.asarray(dt) == 0):
        return None
    tpm = np.array([robot.ticks_per_meter_left, robot.ticks_per_meter_right])
    return np.rint(np.asarray(m) * tpm * np.asarray(dt)[..., None])


def abrupt(v_before: float, gap: float, tick_speed: float) -> bool:
    """Whether a wheel speed v_before [m/s] one row away (``gap`` [s] between
    the rows' middles) from a stop is faster than MAX_DECEL allows, with
    ``tick_speed`` [m/s] (one tick over that row) to spare."""
    return abs(v_before) > MAX_DECEL * gap + tick_speed


class _Slope:
    """Weighted least-squares slopes of values z (d,) against time over the
    stretch so far and over its last DRIFT_WINDOW seconds, from running sums
    (times relative to the stretch's start). Each sample added is judged
    with the samples before it, so feeding one at a time (the filter) and
    all at once (batch) find the same."""

    def __init__(self, d: int):
        self.d = d
        self.n = 0
        self.t = np.zeros(16)                    # the samples' times (a buffer: its first n)
        self.cum = np.zeros((17, 3 + 2 * d))     # cumulative [w, w tau, w tau^2, w z (d), w tau z (d)]
        self.worst = 0.0                         # the fastest significant slope seen [m/s]

    def add(self, tau, z, sigma) -> None:
        tau = np.atleast_1d(np.asarray(tau, float))
        if tau.size == 0:
            return
        z = np.asarray(z, float).reshape(tau.size, -1)
        w = 1.0 / np.square(np.broadcast_to(np.asarray(sigma, float), tau.shape))
        ok = np.isfinite(w) & (w > 0)            # (an infinite sigma says nothing)
        tau, z, w = tau[ok], z[ok], w[ok]
        if tau.size == 0:
            return
        rows = np.column_stack([w, w * tau, w * tau**2, w[:, None] * z, (w * tau)[:, None] * z])
        n0, n1 = self.n, self.n + tau.size
        if n1 > len(self.t):                     # (grown by doubling: a long park's fixes come one by one)
            cap = max(2 * len(self.t), n1)
            self.t = np.concatenate([self.t, np.zeros(cap - len(self.t))])
            self.cum = np.vstack([self.cum, np.zeros((cap + 1 - len(self.cum), self.cum.shape[1]))])
        self.t[n0:n1] = tau
        self.cum[n0 + 1:n1 + 1] = self.cum[n0] + np.cumsum(rows, 0)
        self.n = n1
        t = self.t[:n1]
        ends = np.arange(n0 + 1, n1 + 1)                         # prefixes ending at each new sample
        starts = np.searchsorted(t, t[ends - 1] - DRIFT_WINDOW, side="left")
        for lo in (np.zeros_like(ends), starts):
            self.worst = max(self.worst, self._fastest(self.cum[ends] - self.cum[lo], ends - lo))

    def _fastest(self, S: np.ndarray, n: np.ndarray) -> float:
        """The fastest slope [m/s] among the sums S (k, 3 + 2d) of n (k,)
        samples that is significant at MOVE_CHI2 (0: none)."""
        d = self.d
        s0, s1, s2 = S[:, 0], S[:, 1], S[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            s_tt = s2 - s1 * s1 / s0
            slope = (S[:, 3 + d:] - (s1 / s0)[:, None] * S[:, 3:3 + d]) / s_tt[:, None]
            speed = np.sqrt(np.sum(slope**2, 1))
            chi2 = np.sum(slope**2, 1) * s_tt
        # (a slope from two samples, or over no time, is no drift; s_tt small against the
        # samples' span is rounding)
        ok = (n >= 3) & (s0 > 0) & (s_tt > 1e-12 * np.maximum(s2, 1e-300)) & np.isfinite(chi2) \
            & (chi2 > MOVE_CHI2.get(d, 27.6))
        return float(speed[ok].max()) if ok.any() else 0.0

    def drifts(self) -> bool:
        """A significant slope faster than WANDER has been seen."""
        return self.worst > WANDER


class Motion:
    """What the sensors other than the wheels say of a stretch that began at
    ``a`` [s]: fed in time order (arrays or single samples), ``seen()``
    names the first sensor that saw the robot move, or None."""

    def __init__(self, robot, a: float):
        self.robot, self.a = robot, a
        self.gps = _Slope(2)
        self.rng: dict[int, _Slope] = {}
        self.medians: list[float] = []             # closed seconds of gyro, sorted
        self.extremes: list[tuple[float, int]] = []  # (median, count) of the lowest and highest second
        self.open_k, self.open_g = 0, []           # the second being filled
        self.vel = np.zeros(3)                     # sum v, sum omega, count
        self.moved: str | None = None
        self.dirty: set[str] = set()               # sensors with news since the last check
        self.turn = 0.0                            # the gyro's seconds' largest move from their median [rad/s]

    def fixes(self, t, xy, sigma) -> None:
        self.gps.add(np.asarray(t) - self.a, xy, sigma)
        self.dirty.add("gps")

    def ranges(self, t, r, ids) -> None:
        t, r, ids = np.atleast_1d(t), np.atleast_1d(r), np.atleast_1d(ids)
        for i in np.unique(ids):
            s = ids == i
            self.rng.setdefault(int(i), _Slope(1)).add(t[s] - self.a, r[s], self.robot.range_sigma)
        self.dirty.add("ranges")

    def gyro(self, t, g) -> None:
        """Samples g [rad/s] at t [s] (sorted), one or many."""
        if np.ndim(t) == 0:                        # (one sample: the filter's loop)
            k = math.floor(t - self.a)
            if k != self.open_k:
                self._close()
                self.open_k = k
            self.open_g.append(float(np.ravel(g)[0]))
            return
        t, g = np.atleast_1d(t), np.atleast_1d(g)
        if t.size == 0:
            return
        k = np.floor(t - self.a).astype(int)
        keys, first = np.unique(k, return_index=True)
        for kk, part in zip(keys, np.split(g, first[1:])):
            if kk != self.open_k:
                self._close()
                self.open_k = int(kk)
            self.open_g.extend(part.tolist())

    def _close(self) -> None:
        # (a partial second's median is too noisy: seconds of fewer than 3 samples are left out)
        if len(self.open_g) >= 3:
            m, n = float(np.median(self.open_g)), len(self.open_g)
            bisect.insort(self.medians, m)
            lo, hi = (self.extremes + [(m, n), (m, n)])[:2]
            self.extremes = [min(lo, (m, n)), max(hi, (m, n))]
            self.dirty.add("gyro")
        self.open_g = []

    def velocity(self, vw) -> None:
        vw = np.asarray(vw, float).reshape(-1, 2)
        self.vel += [vw[:, 0].sum(), vw[:, 1].sum(), len(vw)]
        self.dirty.add("velocity")

    def seen(self, closing: bool = False) -> str | None:
        """The sensor that saw motion (latched), with ``closing`` the open
        gyro second counted too (the stretch has ended)."""
        if closing:
            self._close()
        if self.moved is None and self.dirty:
            # (only what changed: the filter asks at every wheel row)
            for name, seen in (("gps", self.gps.drifts), ("ranges", self._ranges), ("gyro", self._gyro),
                               ("velocity", self._velocity)):
                if name in self.dirty and seen():
                    self.moved = name
                    break
            self.dirty.clear()
        return self.moved

    def _ranges(self) -> bool:
        return any(s.drifts() for s in self.rng.values())

    @property
    def drift(self) -> float:
        """The fastest significant drift of the fixes or a beacon's ranges [m/s]."""
        return max([self.gps.worst] + [s.worst for s in self.rng.values()])

    def _gyro(self) -> bool:
        """The seconds' median beyond a spin, or their extremes a turn away
        from it (O(1) a second: the medians kept sorted)."""
        r, meds = self.robot, self.medians
        if not meds:
            return False
        k = len(meds)
        med = meds[k // 2] if k % 2 else 0.5 * (meds[k // 2 - 1] + meds[k // 2])
        self.turn = max(abs(meds[0] - med), abs(meds[-1] - med))
        if abs(med) > max(GYRO_SPIN, 3.0 * r.process.initial_bias_sigma):
            return True          # (a steady spin, or a bias that large: said, not flagged, unless it also turned)
        # (a median of n samples: 1.25 sigma / sqrt(n))
        return any(abs(m - med) > max(GYRO_TURN, 6.0 * r.gyro_sigma / math.sqrt(n)) for m, n in self.extremes)

    def _velocity(self) -> bool:
        v, w, n = self.vel
        if n < 3:
            return False
        sig = np.asarray(self.robot.velocity_sigma, float) / np.sqrt(n)
        return bool((abs(v / n) > MOVING and abs(v / n) > 4 * sig[0])
                    or (abs(w / n) > GYRO_TURN and abs(w / n) > 4 * sig[1]))


class StillWatch:
    """The causal standstill of a filter (ekf.EKF): fed every measurement in
    time order, ``wheel`` says whether that wheel row lies in a standstill
    known by then: the wheels quiet for MIN_STILL seconds with their counts
    in the band, reached no faster than MAX_DECEL, neither wheel quiet alone
    for LONE seconds before, and no other sensor seeing motion since the
    quiet began. The batch smoother sees the whole stretch at once
    (wheel_stretches, still_stretches); the rules are the same, less what
    only hindsight knows (a wheel quiet on alone, or the wheels leaping to
    speed, after the stretch). ``notes``: the stops the other sensors
    contradicted, said as still_stretches says them."""

    def __init__(self, robot):
        self.robot = robot
        self.tpm = (float(robot.ticks_per_meter_left), float(robot.ticks_per_meter_right))
        self.qa = [None, None]            # start of each wheel's own quiet run [s]
        self.run_bad: str | None = None   # the both-quiet run not taken: "abrupt", "lone" or "" (taken)
        self.a: float | None = None       # start of the current still piece (in the band) [s]
        self.cum = [0.0, 0.0]
        self.motion: Motion | None = None
        self.b = 0.0                      # end of the current piece so far [s]
        self.prev = (0.0, 0.0, 0.0)       # the previous wheel row: (t [s], dt [s], its faster wheel [m/s])
        self.notes: list[str] = []

    def wheel(self, t: float, m, dt: float) -> bool:
        """Wheel row at t [s] (the middle of its interval): speeds m (2,)
        [m/s] over dt [s] (0: wheel_speeds.csv, a sample at t)."""
        # (plain floats: this runs at every wheel row of the filter's hot loop;
        # round() is np.rint's half-to-even, as row_ticks)
        ml, mr = float(m[0]), float(m[1])
        if dt:
            tl, tr = round(ml * self.tpm[0] * dt), round(mr * self.tpm[1] * dt)
            ql, qr = abs(tl) <= JITTER, abs(tr) <= JITTER
        else:
            tl = tr = 0
            ql, qr = ml == 0.0, mr == 0.0
        start = t - 0.5 * dt
        qa = self.qa
        qa[0] = (qa[0] if qa[0] is not None else start) if ql else None
        qa[1] = (qa[1] if qa[1] is not None else start) if qr else None
        prev, self.prev = self.prev, (t, dt, max(abs(ml), abs(mr)))
        if not (ql and qr):
            self._end()
            return False
        if self.run_bad is None:                             # both quiet from this row on
            tick = 1.0 / (min(self.tpm) * prev[1]) if prev[1] else 0.0
            self.run_bad = ("lone" if start - min(qa) > LONE else
                            "abrupt" if abrupt(prev[2], t - prev[0], tick) else "")
        if self.a is not None and (abs(self.cum[0] + tl) > BAND or abs(self.cum[1] + tr) > BAND):
            bad = self.run_bad
            self._end()                                      # out of the band: a creep, a new piece from here
            self.run_bad = bad
        if self.a is None:
            self.a, self.cum = start, [0.0, 0.0]
            self.motion = Motion(self.robot, start)
        self.cum[0] += tl
        self.cum[1] += tr
        self.b = t + 0.5 * dt
        return not self.run_bad and self.b - self.a >= MIN_STILL and self.motion.seen() is None

    def idle(self) -> bool:
        """Neither wheel in a quiet run and no still piece open: a row in
        which neither wheel is quiet changes nothing here but ``prev``
        (see pass_row)."""
        return self.a is None and self.qa[0] is None and self.qa[1] is None

    def pass_row(self, t: float, dt: float, fast: float) -> None:
        """An idle watch's wheel row in which neither wheel is quiet: what
        ``wheel`` would do with it, without its arithmetic (ekf_many's many
        runs; ``fast`` is the faster wheel's |speed| [m/s])."""
        self.prev = (t, dt, fast)

    def watching(self) -> bool:
        """A still piece is open: the other sensors' measurements are checked."""
        return self.motion is not None

    def _end(self) -> None:
        """The current piece ends: say it if the other sensors contradicted it."""
        mo = self.motion
        if mo is not None and mo.moved is not None and self.run_bad != "lone" and self.b - self.a >= MIN_STILL:
            self.notes.append(moved_note(self.a, self.b, mo))
        self.a = self.motion = None
        self.run_bad = None

    def other(self, code: int, t: float, z, aux) -> None:
        """A gyro, GPS, range or velocity measurement (sensors codes), as EKF.step takes it."""
        mo = self.motion
        if mo is None or mo.moved is not None:
            return
        if code == GYRO:
            mo.gyro(t, z[0])
        elif code == GPS:
            mo.fixes(t, np.asarray(z)[None], aux[0])
        elif code == RANGE:
            mo.ranges(t, z[0], aux[1])
        elif code == VEL:
            mo.velocity(z)


def _quiet(meas, robot):
    """(K, 2) wheel rows in which each wheel turned by at most JITTER ticks
    (exactly zero speed for wheel_speeds.csv), their ticks (K, 2) and
    intervals (K,) [s] (zeros for wheel_speeds.csv)."""
    w = meas.wheel
    ticks = row_ticks(w.m, w.dt, robot)
    if ticks is None:
        return w.m == 0.0, np.zeros_like(w.m), np.zeros(len(w.t))
    return np.abs(ticks) <= JITTER, ticks, w.dt


def _run_bounds(q: np.ndarray):
    """For each row, the first and last row of its run of True in q (K,)."""
    n = len(q)
    idx = np.arange(n)
    first = np.maximum.accumulate(np.where(~q, idx + 1, 0))
    last = (n - 1 - np.maximum.accumulate(np.where(~q[::-1], idx + 1, 0)))[::-1]
    return first, last


def wheel_stretches(meas, robot) -> list[tuple[float, float]]:
    """[start, end] [s] of the runs of quiet wheel rows at least MIN_STILL
    long in which each wheel's count stays within BAND ticks, neither wheel
    was quiet alone for LONE seconds either side, and the wheels were no
    faster than MAX_DECEL allows in the rows either side (StillWatch's
    rule, with hindsight)."""
    return [(a, b) for a, b, kind in wheel_runs(meas, robot) if not kind]


def wheel_runs(meas, robot) -> list[tuple[float, float, str]]:
    """wheel_stretches, with the band's pieces of the abrupt runs too:
    (start, end, "" or "abrupt")."""
    w = meas.wheel
    qw, ticks, dt = _quiet(meas, robot)
    quiet = qw.all(axis=1)
    bounds = [_run_bounds(qw[:, k]) for k in (0, 1)]
    lo, hi = w.t - 0.5 * dt, w.t + 0.5 * dt
    speed = np.abs(w.m).max(axis=1)
    tick = np.where(dt > 0, 1.0 / (min(robot.ticks_per_meter_left, robot.ticks_per_meter_right)
                                   * np.where(dt > 0, dt, 1.0)), 0.0)
    out = []
    edges = np.flatnonzero(np.diff(np.concatenate([[0], quiet.astype(np.int8), [0]])))
    for i0, i1 in zip(edges[0::2], edges[1::2]):             # rows i0 .. i1-1
        if any(lo[i0] - lo[f[i0]] > LONE or hi[la[i1 - 1]] - hi[i1 - 1] > LONE for f, la in bounds):
            continue                                         # a wheel quiet alone: a dead encoder?
        # no robot stops (or starts) that hard: a counter froze?
        kind = "abrupt" if ((i0 > 0 and abrupt(speed[i0 - 1], w.t[i0] - w.t[i0 - 1], tick[i0 - 1])) or
                            (i1 < len(w.t) and abrupt(speed[i1], w.t[i1] - w.t[i1 - 1], tick[i1]))) else ""
        while i0 < i1:
            cum = np.abs(np.cumsum(ticks[i0:i1], axis=0)).max(axis=1)
            over = np.flatnonzero(cum > BAND)
            end = i0 + (over[0] if over.size else i1 - i0)    # rows i0 .. end-1 keep the band
            if end > i0 and hi[end - 1] - lo[i0] >= MIN_STILL:
                out.append((float(lo[i0]), float(hi[end - 1]), kind))
            i0 = max(end, i0 + 1)
    return out


def moved_flags(warnings) -> list[str]:
    """The still_stretches notes among ``warnings`` that flag a run (MOVED_SAYS)."""
    return [w for w in warnings if w.startswith(MOVED_SAYS)]


def contradicted(meas, robot, a: float, b: float) -> Motion:
    """What the other sensors saw during [a, b] [s] (Motion.moved: which saw
    the robot move, or None)."""
    mo = Motion(robot, a)

    def sel(t):
        return (t >= a) & (t <= b)
    if meas.gps is not None:
        t, xy, sg = meas.gps
        s = sel(t)
        mo.fixes(t[s], xy[s], sg[s])
    if meas.ranges is not None:
        t, _, r = meas.ranges
        ids = meas.ranges_id if meas.ranges_id is not None else np.zeros(len(t), int)
        s = sel(t)
        mo.ranges(t[s], r[s], ids[s])
    if meas.gyro is not None:
        t, g = meas.gyro
        s = sel(t)
        mo.gyro(t[s], g[s])
    if meas.velocity is not None:
        t, vw = meas.velocity
        mo.velocity(vw[sel(t)])
    mo.seen(closing=True)
    return mo


def moved_note(a: float, b: float, mo: Motion) -> str:
    """The line that says a stop [a, b] [s] which ``mo`` (its other sensors) contradicted."""
    if mo.moved == "gyro" and mo.turn < GYRO_FLAG:
        return (f"{TURNED_SAYS} {a:.1f}-{b:.1f} s while the gyro read a turn (its rate moved by {mo.turn:.2f} "
                "rad/s, or stayed far from zero: a slow turn or spin, or a gyro bias walking fast or that "
                "large): not taken as a standstill")
    if mo.moved in ("gps", "ranges") and mo.drift <= MOVING:
        return (f"{TURNED_SAYS} {a:.1f}-{b:.1f} s while the {mo.moved} drifted {mo.drift:.3f} m/s (a receiver's "
                "multipath walk, or the robot sliding that slowly): not taken as a standstill")
    return (f"{MOVED_SAYS} {a:.1f}-{b:.1f} s but the {mo.moved} saw the robot move: "
            "slip is estimated there (a frozen counter, or wheels locked while sliding)")


def still_stretches(meas, robot, t0: float, t1: float) -> tuple[list[tuple[float, float]], list[str]]:
    """[start, end] [s] of the stretches of [t0, t1] in which the robot stood
    still (the wheels' stretches no other sensor contradicts), and one note
    per stretch a sensor contradicted."""
    keep, notes = [], []
    for a, b, kind in wheel_runs(meas, robot):
        a, b = max(a, t0), min(b, t1)
        if b - a < MIN_STILL:
            continue
        mo = contradicted(meas, robot, a, b)
        if mo.moved is not None:
            notes.append(moved_note(a, b, mo))
        elif kind:
            notes.append(f"{TURNED_SAYS} {a:.1f}-{b:.1f} s, reached from driving speed within one row (faster "
                         f"than {MAX_DECEL:g} m/s^2: a counter that froze?): not taken as a standstill")
        else:
            keep.append((a, b))
    return keep, notes


def still_intervals(t: np.ndarray, stretches) -> np.ndarray:
    """(N-1,) the keyframe intervals [t_k, t_k+1] (keyframe times t (N,) [s])
    that lie inside a still stretch."""
    t = np.asarray(t, float)
    m = np.zeros(max(len(t) - 1, 0), bool)
    for a, b in stretches:
        m |= (t[:-1] >= a) & (t[1:] <= b)
    return m
