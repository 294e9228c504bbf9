"""A log's sensor files as measurement arrays that estimators consume.

Each sensor keeps its own timestamps; nothing is resampled. Encoder counts
become average wheel speeds over their interval, stamped at the interval's
midpoint (where the average equals the instantaneous speed to second order),
with the noise of paper eq. 41 plus tick quantisation.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from odomgraph.factors._math import MAD_SIGMA
from odomgraph.factors.encoder import speed_sigma
from odomgraph.io.log import Log

#: An encoder interval longer than this many median intervals spans a dropout;
#: its average speed says less about its midpoint, and its sigma says so.
GAP_FACTOR = 5.0


@dataclass(frozen=True)
class WheelMeas:
    t: np.ndarray
    """(K,) measurement times [s]."""
    m: np.ndarray
    """(K, 2) nominal-converted (left, right) wheel speeds [m/s]."""
    sigma: np.ndarray
    """(K, 2) 1-sigma [m/s]."""
    dt: np.ndarray | None = None
    """(K,) encoder interval [s] (None for wheel_speeds.csv)."""


@dataclass(frozen=True)
class Measurements:
    t_start: float
    """The schedule's origin [s] (Log.t_schedule): the calibration window counts from it."""
    wheel: WheelMeas
    gyro: tuple[np.ndarray, np.ndarray] | None = None
    """(t, omega [rad/s])."""
    gps: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    """(t, xy (K,2) antenna [m], sigma (K,) [m])."""
    ranges: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    """(t, beacon xy (K,2) [m], range (K,) [m])."""
    velocity: tuple[np.ndarray, np.ndarray] | None = None
    """(t, (K,2) [v, omega])."""
    notes: tuple[str, ...] = field(default=())
    ranges_id: np.ndarray | None = None
    """(K,) index into robot.beacons of each range."""
    spikes: dict[str, int] = field(default_factory=dict)
    """Single-sample spikes taken out per sensor (despike)."""


#: No reading of any sensor for longer than this [s] is a pause in the log
#: (a robot parked while its logger stopped, two sessions in one file), not
#: a stretch to coast through (estimators.ekf: EKF._pause).
PAUSE_S = 10.0
#: Across a pause the wheels' net travel D (the encoder row that spans it)
#: carries the pose, but the path's shape is unknown: each position axis gets
#: this share of D as sigma, the heading this share of the turn (the EKF adds
#: a scale factor's worth of both; the smoothers' motion row across it,
#: graph.motion_sigma).
PAUSE_PATH_SHARE = 0.25
PAUSE_TURN_SHARE = 0.05


def pause_spans(meas: Measurements) -> list[tuple[float, float]]:
    """(last reading before, first reading after) [s] of every silence of all
    sensors longer than PAUSE_S. From the readings' own stamps: an encoder
    row's interval ends, not the midpoint its speed is stamped at (the
    midpoint of a row spanning the silence would halve it)."""
    w = meas.wheel
    ts = [w.t] if w.dt is None else [w.t - 0.5 * w.dt, w.t + 0.5 * w.dt]
    ts += [src[0] for src in (meas.gyro, meas.gps, meas.ranges, meas.velocity) if src is not None]
    t = np.unique(np.concatenate(ts))
    k = np.flatnonzero(np.diff(t) > PAUSE_S)
    return [(float(t[i]), float(t[i + 1])) for i in k]


#: Rows each side of a wheel_speeds row whose median speed gives its sigma (from_log).
SIGMA_HALF = 2


def local_median(x: np.ndarray, half: int) -> np.ndarray:
    """(K, ...) the median of each row of x (K, ...) and ``half`` rows each
    side of it along axis 0 (the ends repeated past the first and last)."""
    from numpy.lib.stride_tricks import sliding_window_view
    if len(x) == 0 or half <= 0:
        return np.array(x, float)
    pad = np.concatenate([np.repeat(x[:1], half, 0), x, np.repeat(x[-1:], half, 0)])
    return np.median(sliding_window_view(pad, 2 * half + 1, axis=0), -1)


def from_log(log: Log, frozen: bool = True) -> Measurements:
    """The log's measurements, after ``clean`` (``frozen``: see there)."""
    for obj, name in ((log.encoders, "encoders.csv"), (log.wheel_speeds, "wheel_speeds.csv")):
        if obj is not None and np.any(np.diff(obj.t) <= 0):
            from odomgraph.errors import LogFormatError
            raise LogFormatError((log.path / name) if log.path else name,
                                 "time does not increase (read the log with read_log, which drops rows written "
                                 "twice)")
    notes = []
    raw = log.encoders
    log, spikes = clean(log, frozen)
    if raw is not None and len(raw.t) == len(log.encoders.t):
        # rows whose ticks changed, less those despike rewrote as glitches
        n = int(np.sum((raw.ticks_left != log.encoders.ticks_left) | (raw.ticks_right != log.encoders.ticks_right)))
        n -= spikes.get("encoders", 0)
        if n > 0:
            # (no count: a stream's windows each say it, and one line stands for them all)
            notes.append("encoders: rows whose speed spiked only for their stamp (a driver stamping rows as they "
                         "arrive?) had their ticks spread over their neighbours' intervals, the total kept "
                         "(measurements.restamped)")
    r = log.robot
    a, b = r.encoder_sigma
    if log.encoders is not None:
        e = log.encoders
        dt = np.diff(e.t)
        tpm = np.array([r.ticks_per_meter_left, r.ticks_per_meter_right])
        m = np.stack([e.ticks_left[1:], e.ticks_right[1:]], -1) / (tpm * dt[:, None])
        sig = speed_sigma(m, a, b, tpm, dt[:, None])
        t = 0.5 * (e.t[1:] + e.t[:-1])
        gap = dt > GAP_FACTOR * np.median(dt)
        if gap.any():
            # A dropout whose ticks arrive in the next row (the contract allows
            # it) is still a measurement of the travel over that interval. As a
            # speed at its midpoint it is off by how much the speed varies
            # inside: for a random walk of intensity q the average over dt and
            # the midpoint value differ with variance q^2 dt / 12.
            pn = r.process
            q2 = pn.accel**2 + (0.5 * r.track_width * pn.yaw_accel) ** 2
            sig = np.where(gap[:, None], np.sqrt(sig**2 + q2 * dt[:, None] / 12.0), sig)
            notes.append(f"encoders: {int(gap.sum())} interval(s) longer than {GAP_FACTOR:g}x the median "
                         f"({np.median(dt):.3g} s) used as average speeds with the variation inside added to "
                         "their sigma")
        wheel = WheelMeas(t, m, sig, dt)
    else:
        w = log.wheel_speeds
        m = np.stack([w.v_left, w.v_right], -1)
        # Eq. 41's sigma at the rows' local median speed, not at each row's own
        # reading: a weight that follows a row's noise (smaller for a row read
        # high) biases the speeds low. Harmless at the configured noise; with
        # the wider sigma of noisy rows (analysis.noise.wheel_row_scale) a
        # probe's 200 Hz rows gave a track scale 0.04 off at z -7.3.
        wheel = WheelMeas(w.t, m, speed_sigma(local_median(m, SIGMA_HALF), a, b))
    gyro = (log.gyro.t, log.gyro.omega) if log.gyro is not None and len(log.gyro.t) else None
    gps = None
    if log.gps is not None and len(log.gps.t):
        g = log.gps
        sig = g.sigma if g.sigma is not None else np.full(len(g.t), r.gps_sigma)
        gps = (g.t, np.stack([g.x, g.y], -1), sig)
    ranges = None
    if log.ranges is not None and len(log.ranges.t):
        bxy = np.asarray([[bc.x, bc.y] for bc in r.beacons])[log.ranges.beacon]
        ranges = (log.ranges.t, bxy, log.ranges.range)
    vel = None
    if log.velocity is not None and len(log.velocity.t):
        vel = (log.velocity.t, np.stack([log.velocity.v, log.velocity.omega], -1))
    rid = None if ranges is None else np.asarray(log.ranges.beacon)
    return Measurements(log.t_schedule, wheel, gyro, gps, ranges, vel, tuple(notes), rid, spikes)


def coverage(sensor, t: np.ndarray, reach: float = 0.5) -> float:
    """Share of the times t within ``reach`` seconds of a sample of ``sensor``
    ((t, values) or None): how much of the log a rate sensor really watches.
    A gyro that sends five samples in 40 s exists, but pins nothing."""
    if sensor is None or len(sensor[0]) == 0 or len(t) == 0:
        return 0.0
    ts = sensor[0]
    i = np.clip(np.searchsorted(ts, t), 1, len(ts) - 1) if len(ts) > 1 else np.zeros(len(t), int)
    near = np.minimum(np.abs(t - ts[np.maximum(i - 1, 0)]), np.abs(t - ts[i]))
    return float(np.mean(near <= reach))


def yaw_rate_sensed(meas: Measurements) -> bool:
    """Whether a yaw-rate sensor (a gyro, or a velocity sensor's yaw rate)
    covers at least half the log (``coverage``): then the heading does not
    hang on the wheels' difference alone, and by default the slips'
    differential is free to step (slip_intensity) and batch's common-mode
    steps are Huber (batch.build_problem; whatever ProcessNoise.slip_differential says)."""
    return max(coverage(meas.gyro, meas.wheel.t), coverage(meas.velocity, meas.wheel.t)) >= 0.5


def slip_intensity(process, meas: Measurements, sensed: bool | None = None) -> np.ndarray:
    """(2, 2) slip random-walk intensity in (left, right) [(m/s)^2/s], for the EKF and the smoothers.

    Built in common-mode c = (sL+sR)/2 and differential d = sR-sL coordinates,
    mapped by (sL, sR) = (c - d/2, c + d/2). The differential default depends
    on the log: see ProcessNoise.slip_differential; a yaw-rate sensor counts
    only where it covers at least half the log (``coverage``); ``sensed``
    is that answer when the caller already has it (``yaw_rate_sensed``).
    """
    q_d = process.slip_differential
    if q_d is None:
        q_d = 1.0 if (yaw_rate_sensed(meas) if sensed is None else sensed) else 0.02
    return process.slip**2 * np.ones((2, 2)) + 0.25 * q_d**2 * np.array([[1.0, -1.0], [-1.0, 1.0]])


#: A single sample further than this many robust sigmas (1.4826 MAD) from the
#: median of its neighbours is a spike...
SPIKE_MADS = 8.0
#: ...and further than a ground robot's speed can change in that time:
SPIKE_ACCEL = 20.0        # wheel speed [m/s^2]
SPIKE_YAW_ACCEL = 50.0    # yaw rate [rad/s^2]
SPIKE_FLOOR = (0.3, 0.3)  # and at least this far [m/s, rad/s]
#: An encoder row is never a spike for being this many ticks off its
#: neighbours: with coarse encoders sampled fast (20 ticks/m at 50 Hz) one
#: tick is 2.5 m/s, and a slow robot's rows read 0, 0, 1, 0, ... ticks. Read
#: as spikes, every tick was rewritten to 0 and the wheels said the robot
#: stood still (a probe's log: the whole 60 s).
SPIKE_TICKS = 3.0


def _spikes(t: np.ndarray, x: np.ndarray, accel: float, floor: float | np.ndarray, half: int = 3) -> np.ndarray:
    """(K,) mask of single-sample spikes in a sampled signal x (K,): a Hampel
    filter over +-half neighbours (the sample itself left out), with the
    physical bound ``accel`` times twice the gap to its neighbours as a floor. A step (a
    slip starting, a pivot) is not a spike: half its window agrees with it."""
    return _hampel(t, x, accel, floor, half)[0]


def _hampel(t, x, accel, floor, half: int = 3):
    """_spikes' (mask, neighbours' median, threshold), each (K,)."""
    from numpy.lib.stride_tricks import sliding_window_view
    K = len(x)
    if K < 2 * half + 1:
        return np.zeros(K, bool), np.asarray(x, float), np.full(K, np.inf)
    pad = np.concatenate([np.full(half, x[0]), x, np.full(half, x[-1])])
    win = sliding_window_view(pad, 2 * half + 1)
    nb = np.delete(win, half, axis=1)                                  # neighbours only
    med = np.median(nb, 1)
    mad = MAD_SIGMA * np.median(np.abs(nb - med[:, None]), 1)          # (factors._math.robust_sigma per row)
    # how far the signal can move between this sample and its nearest neighbours
    gap = np.maximum(np.diff(t, prepend=t[0]), np.diff(t, append=t[-1]))
    thr = np.maximum(np.maximum(SPIKE_MADS * mad, accel * 2.0 * gap), floor)
    return np.abs(x - med) > thr, med, thr


#: At most this many intervals are merged into one (restamped): a row stamped
#: late past its neighbour's slot distorts two neighbours.
MERGE_MAX = 3
#: restamped passes at most (despike).
MERGE_PASSES = 4
#: A merged speed within this share of the spike test's threshold of the
#: neighbours' median is the neighbours' (restamped). Not the whole threshold,
#: whose floor is what the robot could do (20 m/s^2): a 2 cm counter glitch
#: in a 20 ms row passed over two rows at 0.63 of it and kept its ticks.
MERGE_WITHIN = 0.5


def restamped(e, robot) -> tuple:
    """(encoders, intervals re-spread): encoder rows whose speed spikes only
    for a stamp off (the driver stamped the row when it arrived, late by a
    few ms), their ticks spread over the intervals around them.

    Such a row's ticks are right and its interval wrong, and so is its
    neighbour's, the other way: over the two intervals together the speed
    is the neighbours'. Rewritten as a counter glitch, its ticks were lost
    (a probe's rows late by |N(0, 10 ms)| at 50 Hz: 826 of 7498 rewritten,
    wheel scales 5 % low at z -73, status ok). A spike interval and the one
    before or after it (or two, MERGE_MAX) whose speed together, both
    wheels, is within MERGE_WITHIN / (n - 1) of the spike test's threshold
    of its neighbours' median (the fewest intervals, then the closest) get
    the group's ticks in proportion to their durations (rounded on the
    running count, so the total stays). Rows and stamps stay: the live
    smoothers key their keyframes to the rows (a second read: merging rows
    away broke them). No group holds an interval longer than GAP_FACTOR
    median periods: a stamp error does not make a dropout, and over one a
    counter glitch's extra ticks look like travel. A counter glitch stays a
    spike over two intervals too, and is rewritten by despike."""
    from dataclasses import replace
    tpm = (robot.ticks_per_meter_left, robot.ticks_per_meter_right)
    dt = np.diff(e.t)
    if dt.size < 3:
        return e, 0
    long = dt > GAP_FACTOR * np.median(dt)
    t = 0.5 * (e.t[1:] + e.t[:-1])
    ticks = (np.asarray(e.ticks_left, float), np.asarray(e.ticks_right, float))
    tests = [_hampel(t, tk[1:] / (c * dt), SPIKE_ACCEL, np.maximum(SPIKE_FLOOR[0], SPIKE_TICKS / (c * dt)))
             for tk, c in zip(ticks, tpm)]
    used = np.zeros(dt.size, bool)           # intervals in a group already
    groups = []
    for i in np.flatnonzero(tests[0][0] | tests[1][0]):
        if used[i]:
            continue
        best = None
        for n in range(2, MERGE_MAX + 1):     # the fewest intervals that explain it
            for j in range(i - n + 1, i + 1):     # intervals j .. j + n - 1
                if j < 0 or j + n > dt.size or used[j:j + n].any() or long[j:j + n].any():
                    continue
                span = e.t[j + n] - e.t[j]
                # a glitch's extra ticks spread over n intervals shrink as 1/n; a stamp's
                # error is gone once its neighbours are in: the bound shrinks alike
                dev = max(abs(tk[j + 1:j + n + 1].sum() / (c * span) - med[i]) / thr[i]
                          for tk, c, (_, med, thr) in zip(ticks, tpm, tests))
                if dev <= MERGE_WITHIN / (n - 1) and (best is None or dev < best[0]):
                    best = (dev, j, n)
            if best is not None:
                break
        if best is not None:
            _, j, n = best
            used[j:j + n] = True
            groups.append((j, n))
    if not groups:
        return e, 0
    new = {}
    for name, tk in zip(("ticks_left", "ticks_right"), ticks):
        c = np.cumsum(tk)
        for j, n in groups:
            # the running count at the group's inner rows, in proportion to time
            share = (e.t[j + 1:j + n] - e.t[j]) / (e.t[j + n] - e.t[j])
            c[j + 1:j + n] = np.round(c[j] + share * (c[j + n] - c[j]))
        out = np.concatenate([tk[:1], np.diff(c)])
        new[name] = out.astype(np.asarray(getattr(e, name)).dtype)
    return replace(e, **new), len(groups)


def despike(log: Log, restamp: bool = True) -> tuple[Log, dict[str, int]]:
    """The log without single-sample spikes in wheel speeds and yaw rate, and
    how many were taken out per sensor.

    A 50 m/s wheel-speed spike in one encoder row (a counter glitch) would
    otherwise be one measurement no slip or scale can explain; the estimators
    would bend a whole calibration around it. An encoder row that spikes gets
    the neighbours' median speed (its ticks are rewritten so that the
    interval semantics hold); a gyro or wheel-speed sample that spikes is
    dropped. Every estimator reads the log through this (one model, one
    cleaning)."""
    from dataclasses import replace
    counts = {}
    r = log.robot
    if log.encoders is not None and len(log.encoders.t) > 8:
        e = log.encoders
        for _ in range(MERGE_PASSES if restamp else 0):
            # a group settles its neighbours' windows, which may then show another
            e, merged = restamped(e, r)
            if not merged:
                break
        if e is not log.encoders:
            log = log.with_(encoders=e)
        dt = np.diff(e.t)
        t = 0.5 * (e.t[1:] + e.t[:-1])
        out = {}
        n = 0
        for side, tpm in (("ticks_left", r.ticks_per_meter_left), ("ticks_right", r.ticks_per_meter_right)):
            ticks = getattr(e, side).astype(float).copy()
            speed = ticks[1:] / (tpm * dt)
            bad = _spikes(t, speed, SPIKE_ACCEL, np.maximum(SPIKE_FLOOR[0], SPIKE_TICKS / (tpm * dt)))
            if bad.any():
                idx = np.flatnonzero(bad)
                good = np.flatnonzero(~bad)
                fill = np.interp(t[idx], t[good], speed[good]) if good.size else np.zeros(idx.size)
                ticks[idx + 1] = np.round(fill * tpm * dt[idx])
                n += int(bad.sum())
            out[side] = ticks
        if n:
            log = log.with_(encoders=replace(e, **out))
            counts["encoders"] = n
    if log.wheel_speeds is not None and len(log.wheel_speeds.t) > 8:
        w = log.wheel_speeds
        bad = _spikes(w.t, w.v_left, SPIKE_ACCEL, SPIKE_FLOOR[0]) | _spikes(w.t, w.v_right, SPIKE_ACCEL,
                                                                             SPIKE_FLOOR[0])
        if bad.any():
            log = log.with_(wheel_speeds=replace(w, t=w.t[~bad], v_left=w.v_left[~bad], v_right=w.v_right[~bad]))
            counts["encoders"] = int(bad.sum())
    if log.gyro is not None and len(log.gyro.t) > 8:
        g = log.gyro
        bad = _spikes(g.t, g.omega, SPIKE_YAW_ACCEL, SPIKE_FLOOR[1])
        if bad.any():
            log = log.with_(gyro=replace(g, t=g.t[~bad], omega=g.omega[~bad]))
            counts["gyro"] = int(bad.sum())
    return log, counts


#: Fixes are re-published copies when the distinct positions come at least
#: this many times slower than the rows (1 Hz fixes sent at 10 Hz: 10x).
REPUBLISH_RATIO = 1.5


def repeated_fixes(gps) -> np.ndarray:
    """(K,) mask of the rows that re-publish an earlier fix: a receiver driver
    that sends its last fix at its own rate (1 Hz fixes at 10 Hz). Each copy
    carries a new stamp and an old position; read as ten fixes it says the
    robot stood still nine tenths of the time (a probe's log: scale factors
    5-7 sigma off, status ok).

    A row repeating the one before exactly (x, y and sigma) is a copy only
    when the log re-publishes: its distinct positions come REPUBLISH_RATIO
    times slower than its rows. A receiver that sends each fix once can
    still repeat a position exactly, at a standstill (quantised output, a
    static-hold mode), and those fixes are the evidence that the robot
    stands while its wheels spin: they are all kept. In a re-publishing log
    a run longer than a fix interval holds fresh fixes too: one row per 1.5
    fix intervals of it is kept."""
    same = (gps.x[1:] == gps.x[:-1]) & (gps.y[1:] == gps.y[:-1])
    if gps.sigma is not None:
        same &= gps.sigma[1:] == gps.sigma[:-1]
    mask = np.concatenate([[False], same])
    if not mask.any() or mask.sum() == len(mask) - 1:
        return np.zeros(len(mask), bool)       # no repeats, or a single position (nothing moves at all)
    t = np.asarray(gps.t, float)
    dt_rows = float(np.median(np.diff(t)))
    dt_fix = float(np.median(np.diff(t[~mask])))
    if not dt_fix >= REPUBLISH_RATIO * dt_rows:
        return np.zeros(len(mask), bool)
    kept = 0.0
    for k in np.flatnonzero(mask):
        if not mask[k - 1]:
            kept = t[k - 1]                    # the run's first row, a distinct fix
        # Copies come about dt_fix after their fix at most (the receiver's
        # jitter stretches some intervals); a run that lasts longer holds the
        # receiver's later fixes, repeating the position at a standstill:
        # one row per 1.5 dt_fix is kept as such.
        if t[k] - kept >= 1.5 * dt_fix:
            mask[k], kept = False, t[k]
    return mask


#: A run of fixes at one exact position is judged frozen when it lasts at
#: least this long [s] ...
FROZEN_MIN_S = 5.0
#: ... while the gyro turns through at least this much [rad] (after its
#: bias, taken against the wheels' rate over the whole log: a bias is no
#: turn) ...
FROZEN_TURN = 0.5
#: ... the wheels' turn rate follows the gyro's (their 0.5 s means correlate
#: by this much, or differ by less than FROZEN_DISAGREE of the turn, summed:
#: a steady arc has no variation to correlate; the wheels roll, they do not
#: spin in place) ...
FROZEN_CORRELATION = 0.8
FROZEN_DISAGREE = 0.3
#: ... and the wheels drive at least this far [m] (nominal parameters).
FROZEN_TRAVEL = 2.0


def frozen_fixes(log: Log) -> list[tuple[int, int, float, float]]:
    """Runs of fixes that repeat one position while the robot drove: a
    receiver that froze (holding its last fix when it lost lock), as
    (first, last) row indices and the wheels' travel [m] and the gyro's turn
    [rad] over the run.

    A position held exactly is also what a robot standing still gives (a
    quantised or static-hold receiver), and that is the evidence of slip
    that the paper is about: a snowplow whose wheels spin in a drift. So a
    run is frozen only when the wheels and the gyro agree the robot turned,
    FROZEN_TURN at least, at the rates the wheels say (FROZEN_CORRELATION, FROZEN_DISAGREE): wheels that spin
    while the robot stands do not turn it as the gyro sees (the gyro's
    turn counted after its bias, taken against the wheels' rate over the
    whole log). On a probe's
    log a 20 s freeze, taken for a standstill, left every estimator 2.4-4 m
    off (the mirror solution) once the fixes came back."""
    g = log.gps
    if g is None or len(g.t) < 3 or log.gyro is None or len(log.gyro.t) < 10:
        return []
    same = np.concatenate([[False], (g.x[1:] == g.x[:-1]) & (g.y[1:] == g.y[:-1])])
    if same[1:].all():
        return []            # one position throughout: no fix to keep in its place (repeated_fixes alike)
    if not same.any():
        return []
    # The gyro's bias against the wheels' rate over the whole log (a median:
    # slip and stalls are the exception). Not over the run: its own median
    # takes a steady turn out with it, and one against the wheels there makes
    # a stall's scale mismatch (spinning wheels read a slow turn) a turn the
    # gyro "agrees" with.
    ww_all = wheel_yaw_rate(log, log.gyro.t)
    if ww_all is None:
        return []
    bias = float(np.median(log.gyro.omega - ww_all))
    out = []
    for a, b in runs_of(same):
        first = a - 1                      # the run's own fix, then its copies
        t0, t1 = float(g.t[first]), float(g.t[b])
        if t1 - t0 < FROZEN_MIN_S:
            continue
        gy = log.gyro
        sel = (gy.t >= t0) & (gy.t <= t1)
        if sel.sum() < 10:
            continue
        tg = gy.t[sel]
        ww = ww_all[sel]
        wg = gy.omega[sel] - bias
        turn = float(np.sum(np.abs(wg[:-1]) * np.diff(tg)))
        bins = np.floor((tg - tg[0]) / 0.5).astype(int)
        n = np.bincount(bins)
        mg, mw = (np.bincount(bins, v)[n > 0] / n[n > 0] for v in (wg, ww))
        if turn < FROZEN_TURN or len(mg) < 4:
            continue
        alike = np.sum(np.abs(mg - mw)) <= FROZEN_DISAGREE * np.sum(np.abs(mg))
        if not alike and not (np.std(mg) > 0 and np.std(mw) > 0
                              and np.corrcoef(mg, mw)[0, 1] >= FROZEN_CORRELATION):
            continue
        travel = _wheel_travel(log, t0, t1)
        if travel >= FROZEN_TRAVEL:
            out.append((first, int(b), travel, turn))
    return out


def runs_of(mask: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) index of each run of True in ``mask`` (K,)."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1))


def _wheel_travel(log: Log, t0: float, t1: float) -> float:
    """Distance the wheels report between t0 and t1 [s] [m], nominal parameters."""
    r = log.robot
    if log.encoders is not None and len(log.encoders.t) > 1:
        e = log.encoders
        sel = (e.t > t0) & (e.t <= t1)
        return float(np.sum(np.abs(0.5 * (e.ticks_left[sel] / r.ticks_per_meter_left
                                           + e.ticks_right[sel] / r.ticks_per_meter_right))))
    ws = log.wheel_speeds
    if ws is None or len(ws.t) < 2:
        return 0.0
    sel = (ws.t >= t0) & (ws.t <= t1)
    tt, v = ws.t[sel], 0.5 * (ws.v_left[sel] + ws.v_right[sel])
    return float(np.sum(np.abs(v[:-1]) * np.diff(tt))) if len(tt) > 1 else 0.0


def repeat_notes(log: Log) -> list[str]:
    """One line when gps.csv repeats fixes (``repeated_fixes``), [] otherwise."""
    if log.gps is None or len(log.gps.t) < 2:
        return []
    n = int(repeated_fixes(log.gps).sum())
    out = [] if not n else [
        f"gps: {n} of {len(log.gps.t)} fixes repeat the fix before them exactly (a receiver re-publishing its "
        "last fix): each position was read once, at its first stamp"]
    g = log.gps
    for a, b, travel, turn in frozen_fixes(log):
        out.append(f"gps: the {b - a + 1} fixes from t={g.t[a]:.2f} to {g.t[b]:.2f} s hold one position while "
                   f"the wheels and the gyro agree the robot drove {travel:.1f} m and turned {turn:.1f} rad: a "
                   "frozen receiver; all but the first were left out, the wheels carry the path there")
    return out


#: A gyro rail: at least this many samples in a row at the largest |rate| of
#: the log (to within RAIL_TOL of it), beyond RAIL_MIN rad/s.
RAIL_RUN = 3
RAIL_TOL = 1e-6
RAIL_MIN = 0.3
#: ...where the wheels turn faster than this multiple of the rail.
RAIL_WHEELS = 1.05


def saturated(gyro, wheel_rate: np.ndarray | None = None) -> np.ndarray:
    """(K,) mask of gyro samples at the sensor's rail: a saturated gyro
    clips every faster turn to its range, and those samples say only "at
    least this fast". Read as rates they tell the estimators the robot turns
    slower than its wheels say (a probe's gyro clipped at 0.8 rad/s on
    1.2 rad/s pivots: the EKF stopped, batch put the track 26 % off and
    blamed the lever arm). A rail is a value the log's largest |rate|
    repeats exactly RAIL_RUN times in a row; real rates are never that still
    at speed, and the wheels must turn faster there (a quantised gyro
    holding its top value through a steady spin is not clipped).
    ``wheel_rate``: the wheels' yaw rate [rad/s] at the gyro's times (nominal
    parameters), or None to skip that test."""
    w = np.asarray(gyro.omega, float)
    if len(w) < RAIL_RUN:
        return np.zeros(len(w), bool)
    top = float(np.max(np.abs(w)))
    if top < RAIL_MIN:
        return np.zeros(len(w), bool)
    at = np.abs(np.abs(w) - top) <= RAIL_TOL * top
    # runs of RAIL_RUN or more
    edges = np.flatnonzero(np.diff(np.concatenate([[0], at.astype(np.int8), [0]])))
    mask = np.zeros(len(w), bool)
    for a, b in zip(edges[::2], edges[1::2]):
        if b - a >= RAIL_RUN and (wheel_rate is None or np.median(np.abs(wheel_rate[a:b])) > RAIL_WHEELS * top):
            mask[a:b] = True
    return mask


def wheel_yaw_rate(log: Log, t: np.ndarray) -> np.ndarray | None:
    """The wheels' yaw rate [rad/s] at times t, nominal parameters, from the
    raw encoder rows (interval means at their midpoints) or wheel speeds."""
    r = log.robot
    if log.encoders is not None and len(log.encoders.t) > 1:
        e = log.encoders
        dt = np.diff(e.t)
        w = (e.ticks_right[1:] / r.ticks_per_meter_right - e.ticks_left[1:] / r.ticks_per_meter_left) / (
            dt * r.track_width)
        return np.interp(t, 0.5 * (e.t[1:] + e.t[:-1]), w)
    if log.wheel_speeds is not None and len(log.wheel_speeds.t) > 1:
        ws = log.wheel_speeds
        return np.interp(t, ws.t, (ws.v_right - ws.v_left) / r.track_width)
    return None


def saturation_notes(log: Log) -> list[str]:
    """One line when gyro.csv holds samples at a rail (``saturated``), [] otherwise."""
    if log.gyro is None or len(log.gyro.t) < RAIL_RUN:
        return []
    m = saturated(log.gyro, wheel_yaw_rate(log, log.gyro.t))
    if not m.any():
        return []
    top = float(np.max(np.abs(log.gyro.omega)))
    return [f"gyro: {int(m.sum())} of {len(m)} samples sit at +-{top:.4g} rad/s, the gyro's range (it saturates "
            "on faster turns): they were left out, the wheels carry the heading there"]


def clean(log: Log, frozen: bool = True) -> tuple[Log, dict[str, int]]:
    """The log as every estimator reads it: GPS fixes that repeat the one
    before dropped (``repeated_fixes``; the first copy is kept, its stamp
    nearest the fix), and those of a frozen receiver (``frozen_fixes``), gyro samples at the gyro's rail dropped
    (``saturated``), GPS stamps moved back by the configured
    ``[gps] time_offset`` (a fix stamped t was taken at t - offset; the
    returned robot's offset is then 0: spent), then
    ``despike``. Returns it with the spikes taken out per sensor (the
    repeated fixes and the rail are not rejections: ``repeat_notes`` and
    ``saturation_notes`` say them, and pipeline.estimate makes those warnings).
    ``frozen``: False leaves a frozen receiver's fixes in (the live
    estimator's windows: a few seconds of a freeze look like a stall, and a
    window starting inside one would keep a stale copy as its first fix),
    and arrival-stamped encoder rows as they are (restamped)."""
    from dataclasses import replace
    if log.gps is not None and len(log.gps.t) > 1:
        rep = repeated_fixes(log.gps)
        for a, b, _, _ in (frozen_fixes(log) if frozen else []):
            rep[a + 1:b + 1] = True
        if rep.any():
            g = log.gps
            keep = ~rep
            log = log.with_(gps=replace(g, t=g.t[keep], x=g.x[keep], y=g.y[keep],
                                        sigma=None if g.sigma is None else g.sigma[keep]))
    if log.gyro is not None and len(log.gyro.t) >= RAIL_RUN:
        sat = saturated(log.gyro, wheel_yaw_rate(log, log.gyro.t))
        if sat.any():
            g = log.gyro
            log = log.with_(gyro=replace(g, t=g.t[~sat], omega=g.omega[~sat]))
    off = log.robot.gps_time_offset
    if off and log.gps is not None:
        # The stamps corrected, the offset is spent: a log cleaned again, or
        # a check that corrects the stamps itself (metrics.gps_times), must
        # not apply it twice.
        log = log.with_(gps=replace(log.gps, t=log.gps.t - off), robot=log.robot.with_(gps_time_offset=0.0))
    # Arrival stamps (restamped) on the whole log only: its groups reach up to
    # (SPIKE_HALF + MERGE_MAX - 1) x MERGE_PASSES rows ahead, past what a live
    # window waits for (online.AHEAD_ROWS), and a window deciding otherwise
    # than the next counts an interval's ticks twice or not at all.
    return despike(log, restamp=frozen)


def dead_reckoning(meas: Measurements, track: float, scales=(1.0, 1.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """The wheels' own path from the first measurement (pose 0): times (K+1,)
    and poses (K+1, 3), heading not wrapped, with the scale factors taken out
    of the nominal wheel speeds (LOG_FORMAT: m = scale u).

    Encoder speeds are averages over their interval: each is integrated over
    its own interval, so the nodes sit at the interval ends (integrating from
    the midpoints instead would lag the path by half an interval, which a
    time-offset check then reads as a 25 ms late GPS at 20 Hz). Wheel speeds
    already in m/s stand for their instant, each held to the next."""
    from odomgraph.factors.encoder import body_velocity
    from odomgraph.factors.motion import integrate
    w = meas.wheel
    v, om = body_velocity(w.m[:, 0], w.m[:, 1], 0.0, 0.0, *scales, track)
    if w.dt is not None:
        dt = w.dt
        t = np.concatenate([[w.t[0] - 0.5 * dt[0]], w.t + 0.5 * dt])
    else:
        dt = np.append(np.diff(w.t), np.median(np.diff(w.t)) if len(w.t) > 1 else 0.0)
        t = np.append(w.t, w.t[-1] + dt[-1])
    return t, integrate(v, om, dt)
