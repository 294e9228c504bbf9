"""Live use: the estimate as each measurement arrives (issue 15).

    from odomgraph.online import Online
    live = Online(load_robot("robot.toml"), method="ekf", schedule=Schedule(calibrate_until=20.0))
    for sensor, t, values in feed:               # in time order, or nearly (``latency``)
        for row in live.push(sensor, t, *values):
            publish(row)                          # an OnlineRow: t, state (11,), sigma (11,)
    live.close()                                  # the rest, and the summary

Sensors and their values are those of ../shared/spec/LOG_FORMAT.md:
``encoders`` (ticks_left, ticks_right), ``wheel_speeds`` (v_left, v_right),
``gps`` (x, y[, sigma]), ``gyro`` (omega), ``ranges`` (beacon id, range) and
``velocity`` (v, omega).

**Same answer as the replay.** The filter is ``estimators.ekf.EKF``, stepped
one event at a time (``EKF.step``: the loop ``EKF.run`` runs over a whole
log), and every measurement is read through the same cleaning
(``measurements.from_log``: spikes, re-published fixes, a gyro at its rail,
dropouts). That cleaning looks a few rows ahead and behind, so the live
filter runs a little behind the newest data: it processes, in time order,
the events that no later measurement can precede or re-judge, in chunks of
``chunk`` seconds, over a window holding ``context`` seconds of what came
before. What a whole log decides once (the start pose, which scale
combinations the data determine, the slip intensity, where the wheels slipped
inside the calibration window) is decided on the first ``warmup`` seconds:
long enough to cover the calibration window (and the start-pose fit without
an ``[initial]`` pose). On a log where those decisions agree with the whole
log's, the streamed rows equal ``estimate --method ekf``'s states.csv
(tests/test_online.py holds them to 1e-9). ``estimate`` goes on to refit
noise scales from the whole log's residuals and re-runs; a live filter
cannot, and uses robot.toml as given: run ``calibrate`` first, which writes
them there.

**Order.** Measurements may arrive out of order within ``latency`` seconds of
the newest one; they are reordered. Older ones are rejected and counted.

**The smoothers.** isam2 and fixed-lag step their runners
(estimators.incremental) one keyframe at a time over a problem that grows as
the data arrive (estimators.growing). isam2 writes its causal row of each
keyframe interval (``online.csv`` of ``estimate --method isam2``) once the
next keyframe is known; fixed-lag writes each keyframe's row when it leaves
the lag window (states.csv of ``estimate --method fixed-lag``). ``close``
keeps the isam2 run's fully smoothed estimate in ``final``.
"""
from __future__ import annotations

import bisect
import heapq
import math
import pickle
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from odomgraph import state as S
from odomgraph.analysis.metrics import NIS_MIN_COUNT, NIS_WARN, nis_warning
from odomgraph.errors import EstimatorDivergedError, NotEnoughDataError, OdomgraphError, OptionError
from odomgraph.estimators.ekf import EKF, event_values
from odomgraph.estimators.initial import CONSENSUS_WINDOW
from odomgraph.estimators.measurements import from_log
from odomgraph.estimators.registry import REGISTRY, Method, check_option_names, options_for, parse_method
from odomgraph.estimators.schedule import Schedule
from odomgraph.estimators.sensors import DOF, SENSOR_NAMES, WHEEL, event_stream
from odomgraph.estimators.slipcheck import in_stretches
from odomgraph.io.csvtable import ORIGIN_ABOVE, ORIGIN_BELOW, split_stamps
from odomgraph.io.log import (MAX_COORD, MAX_RATE, MAX_SPEED, SENSOR_FILE, SENSOR_FILES, Gps, Log, Ranges, schedule_origin,
                              unwrapped_count)
from odomgraph.io.stream import SENSOR_COLUMNS
from odomgraph.io.robot import RobotConfig

#: Rows either side of a sample that the spike filter reads (measurements._spikes).
SPIKE_HALF = 3
#: Rows ahead of an EKF event that must have arrived: an encoder event sits
#: between two rows, so one more than the spike filter reads.
AHEAD_ROWS = SPIKE_HALF + 1
#: A sensor whose newest row is this much older than the newest data [s] has
#: stopped (a dropout): the filter no longer waits for its rows ahead.
STOPPED_AFTER = 1.0
#: A sensor's measurements rejected as older than the latency window this
#: many in a row (none taken between): the stream says so at once (a probe:
#: GPS lines 0.4 s behind under --latency 0.25 were every one rejected, said
#: only in the end's summary). In a row: a few late ones over hours of a
#: healthy stream are counted, not alarmed on (a second read).
LATE_SAY = 5
#: A stamp this far [s] past the newest is held, not taken as the new time,
#: until another sensor's confirm it (a whole system that paused): one stray
#: stamp (a driver's garbage, a sensor whose clock runs ahead) would else make
#: every later measurement "late".
MAX_AHEAD = 2.0
#: Encoder rows past io.log.MAX_SPEED said one by one; the rest are counted.
SAY_IMPOSSIBLE = 5
#: Per sensor, (limit, unit) of the values a line may hold (io.log.check_magnitudes's;
#: the encoders' is a speed, checked once the row before is known: Online._say_impossible_ticks).
STREAM_LIMITS = {"wheel_speeds": (MAX_SPEED, "m/s"), "gyro": (MAX_RATE, "rad/s"), "gps": (MAX_COORD, "m"),
                 "ranges": (MAX_COORD, "m"), "velocity": (MAX_SPEED, "m/s (or rad/s)")}
#: Measurements from that far ahead that confirm a new time: from two sensors,
#: or this many in a row from a stream of one.
CONFIRM_AHEAD = 3
#: The encoders may be silent this long [s] before the filter goes on without
#: them (an encoder row closes the interval since the one before, so its
#: event lies inside the gap, before everything that came meanwhile).
WHEEL_WAIT = 30.0
#: Restarts after a divergence (Online._restart) before the stream gives up and says why.
MAX_RESTARTS = 20
#: Floor [-] of the scale factors' prior 1-sigma after a restart (_restart): the
#: calibration carried over is held to what was known of it, not to a few 1e-3.
RESTART_SCALE_SIGMA = 0.005
#: Margin [s] past the calibration window (or start-pose fit) that the warm-up adds.
WARMUP_MARGIN = 5.0


def _number(v) -> float | None:
    """A float from a number or its decimal text (as read_log reads one: no
    '1_0', no hex), or None."""
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return float(v)
    text = str(v).strip()
    if "_" in text or text.lower().startswith(("0x", "-0x", "+0x")):
        return None
    try:
        return float(text)
    except ValueError:
        return None


def stamp_parts(t) -> tuple[int, float, float]:
    """(whole seconds, fraction in [0, 1), the stamp as a float) of a stamp
    given as text or a number. From text the first two are exact, as
    io.csvtable.split_stamps reads a real clock's stamps ("1700000012.345678"
    is not float-rounded); a small clock's stamp is read as float(text), as
    read_log reads it."""
    f = _number(t)
    if f is None or not math.isfinite(f):
        raise StreamInputError(f"time {t!r} is not a finite number")
    if abs(f) >= ORIGIN_BELOW:
        raise StreamInputError(f"time {t!r} is no time in seconds (nanoseconds?)")
    if isinstance(t, str):
        sec, frac = split_stamps([t.strip()])
        return int(sec[0]), float(frac[0]), f
    sec = math.floor(f)
    return int(sec), f - sec, f


class StreamInputError(OdomgraphError):
    """A measurement the stream cannot read (unknown sensor, wrong count, not a number)."""


@dataclass(frozen=True)
class OnlineRow:
    """One estimate, as a states.csv row: ``t`` [s since ``t_origin``],
    ``mean`` (11,) and ``sigma`` (11,) in state.NAMES order (m, rad, m/s,
    rad/s, scale factors unitless), ``pose_cov`` (3, 3) of x, y, theta
    (None for isam2's causal rows, whose marginals are per variable)."""
    t: float
    mean: np.ndarray
    sigma: np.ndarray
    pose_cov: np.ndarray
    t_origin: int = 0

    def named(self) -> dict[str, float]:
        """{state name: value, sigma_<name>: sigma}."""
        out = {n: float(v) for n, v in zip(S.NAMES, self.mean)}
        out.update({f"sigma_{n}": float(v) for n, v in zip(S.NAMES, self.sigma)})
        return out


@dataclass
class _Counts:
    accepted: dict[str, int] = field(default_factory=dict)
    rejected: dict[str, int] = field(default_factory=dict)   # by the filter's gate
    late: dict[str, int] = field(default_factory=dict)       # older than the latency window
    repeated: dict[str, int] = field(default_factory=dict)   # a stamp the sensor sent already
    ahead: dict[str, int] = field(default_factory=dict)      # stamped far past the newest, not followed
    impossible: dict[str, int] = field(default_factory=dict)  # encoder rows past io.log.MAX_SPEED

    @staticmethod
    def add(d: dict, key: str, n: int = 1) -> None:
        d[key] = d.get(key, 0) + n


class Online:
    """A live estimator over one robot (see the module doc).

    robot: RobotConfig (io.robot.load_robot). method: "ekf", "isam2" or
    "fixed-lag". schedule: as ``estimate``'s. latency
    [s]: how far out of order measurements may arrive. warmup [s]: data
    held before the filter starts (None: the calibration window, or the
    start-pose fit without [initial], plus WARMUP_MARGIN; at least 2 s).
    chunk [s]: how much new data each EKF step takes. options: the
    method's options (EKFOptions, IncrementalOptions), as ``estimate``'s.
    """

    # (an EKF checkpoint pickled before these existed loads without them)
    _frame_free = False
    _placed_by: frozenset = frozenset()     # the absolute sensors a frame-free run had (_frame_check)
    _revised = None
    _rev_prev = None

    def __init__(self, robot: RobotConfig, method="ekf", schedule: Schedule = Schedule(), latency: float = 0.25,
                 warmup: float | None = None, chunk: float = 0.1, context: float = 2.0, journal: bool = False,
                 **options):
        self._args = dict(robot=robot, method=method, schedule=schedule, latency=latency, warmup=warmup, chunk=chunk,
                          context=context, journal=journal, **options)
        method = parse_method(method)
        if method is Method.batch:
            raise OptionError("batch smooths a whole log and cannot stream; stream with --method isam2, "
                              "fixed-lag or ekf")
        for name, v in (("latency", latency), ("chunk", chunk), ("context", context),
                        ("warmup", 0.0 if warmup is None else warmup)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise OptionError(f"{name} must be seconds >= 0, got {v!r}")
        if method is Method.ekf and schedule.calibrate_until is None:
            raise OptionError("the EKF needs a schedule: --calibrate-until none (slip and scale together) is for "
                              "the smoothers; use a number of seconds (0 = slip only)")
        check_option_names(options)
        self.options = REGISTRY[method].options_type()(**options_for(method, options))
        self.robot, self.schedule, self.method = robot, schedule, method
        self.latency, self.chunk, self.context = float(latency), max(float(chunk), 1e-6), float(context)
        self._warmup_given = warmup is not None
        self.warmup = float(warmup) if warmup is not None else self._default_warmup()
        # scale factors of robot (after a restart: the calibration carried) against robot.toml's
        self._base = np.ones(3)
        self._scale_sigma = self.robot.process.initial_scale_sigma   # robot.toml's, whatever restarts set
        self._beacons = {b.id: i for i, b in enumerate(robot.beacons)}
        self._heap: list = []                          # (t, seq, sensor, values) not yet released
        self._seq = 0
        self._raw: dict[str, list] = {s: [] for s in SENSOR_COLUMNS}   # released (t, values), in time order
        self.t_origin: int | None = None
        self.t_newest = -math.inf                       # newest stamp pushed
        self.t_released = -math.inf                     # every row older than this is released
        self.t_first: float | None = None
        self.t_done = -math.inf                         # every event before this is filtered
        self.ekf: EKF | None = None
        self.smoother: _Smoother | None = None
        self.final = None            # isam2: the fully smoothed Estimate, after close()
        self._wheel_rows = 0         # wheel rows released so far (the keyframes are every step-th)
        self.last: OnlineRow | None = None
        self.counts = _Counts()
        self.notes: list[str] = []
        self.closed = False
        self.lines_read = 0         # input lines consumed (odomgraph stream keeps it for --resume)
        self.restarts: list[str] = []   # divergences the estimator did not recover from itself
        self._ahead: list = []              # (sensor, t, values) held: stamped far past the newest
        self._sensors_seen: set[str] = set()
        self._gyro_top: tuple | None = None  # (t, omega) of the largest |rate| so far (the rail test's)
        self._nis = {}                      # sensor -> [sum of accepted NIS, count, dimension]
        self.alerts: list[str] = []         # warnings said as they arise (odomgraph stream prints them)
        self._late_by: dict[str, list] = {}     # sensor -> [late in a row, the most [s] behind, said]
        self._settle_said = 0
        self._fail_t = None                 # time of the event being filtered (a divergence's)
        # The estimator started with no absolute measurement and no [initial]
        # pose: its frame is the start's own (the origin, heading 0) until the
        # first fix or range, which starts it again in theirs (_anchor).
        self._frame_free = False
        # Rows that jumped further than the row before allowed (analysis.plausible.revision_jumps):
        # [count, first t, last t, worst beyond [m], its z], and the row the next is judged against.
        self._revised: list | None = None
        self._rev_prev = None
        # A smoother's GTSAM state cannot be pickled: its checkpoint is every
        # measurement pushed so far, replayed on load (deterministic, so equal).
        self.journal: list | None = [] if journal else None

    def _default_warmup(self) -> float:
        """The calibration window, or the start-pose fit without [initial], plus WARMUP_MARGIN; at least 2 s."""
        w = 2.0
        if self.schedule.calibrate_until is not None:
            w = max(w, self.schedule.calibrate_until + WARMUP_MARGIN)
        if self.robot.initial is None:
            w = max(w, CONSENSUS_WINDOW + WARMUP_MARGIN)
        return w

    def _late(self, sensor: str, t: float) -> None:
        """Count a measurement older than the latency window, and say it once
        per sensor when LATE_SAY have come in a row (how far behind the newest)."""
        _Counts.add(self.counts.late, sensor)
        by = getattr(self, "_late_by", None)       # (a checkpoint written before it existed)
        if by is None:
            by = self._late_by = {}
        run = by.setdefault(sensor, [0, 0.0, False])
        run[0] += 1
        run[1] = max(run[1], self.t_newest - t)
        if run[0] >= LATE_SAY and not run[2]:
            run[2] = True
            self.alerts.append(
                f"{sensor}: {LATE_SAY} measurements in a row came older than the {self.latency:g} s latency window "
                f"(up to {run[1]:.2f} s behind the newest stamp) and were rejected; the rest are counted in the "
                "summary: a sensor this late needs a larger --latency, or its clock is behind")

    def _on_time(self, sensor: str) -> None:
        """A measurement taken: the sensor's run of late ones ends."""
        run = getattr(self, "_late_by", {}).get(sensor)
        if run is not None:
            run[0], run[1] = 0, 0.0

    def _row(self, t: float, mean: np.ndarray, sigma: np.ndarray, pose_cov) -> OnlineRow:
        """An output row; its scale factors against robot.toml's (a restart carries them in the robot)."""
        if not np.all(self._base == 1.0):
            mean, sigma = mean.copy(), sigma.copy()
            mean[S.SCALE_S] *= self._base
            sigma[S.SCALE_S] *= self._base
        return OnlineRow(float(t), mean, sigma, pose_cov, self.t_origin or 0)

    # ------------------------------------------------------------ input
    def push(self, sensor: str, t: float, *values) -> list[OnlineRow]:
        """One measurement at stamp t [s, the log's clock]. Returns the rows
        that became final (none while warming up or waiting for data)."""
        if self.closed:
            raise OdomgraphError("push after close()")
        vals = self._values(sensor, values)
        try:
            sec, frac, f = stamp_parts(t)
        except StreamInputError as exc:
            raise StreamInputError(f"{sensor}: {exc}") from None
        if self.journal is not None:
            self.journal.append((sensor, t, values))
        if self.t_origin is None:
            self.t_origin = sec if abs(sec) >= ORIGIN_ABOVE else 0
        # as read_log reads a stamp: on a real clock, whole seconds from the origin, then the fraction (exact)
        t = float(sec - self.t_origin) + frac if self.t_origin else f
        self._sensors_seen.add(sensor)
        if self.t_newest > -math.inf and t > self.t_newest + MAX_AHEAD:
            return self._hold_ahead(sensor, t, vals)
        if self._ahead:
            self._drop_ahead()
        return self._accept(sensor, t, vals)

    def _accept(self, sensor: str, t: float, vals: tuple) -> list[OnlineRow]:
        if t < self.t_released:
            self._late(sensor, t)
            return []
        self._on_time(sensor)
        heapq.heappush(self._heap, (t, self._seq, sensor, vals))
        self._seq += 1
        if t > self.t_newest:
            self.t_newest = t
        self._release(self.t_newest - self.latency)
        return self._advance(final=False)

    def _hold_ahead(self, sensor: str, t: float, vals: tuple) -> list[OnlineRow]:
        """A stamp far past the newest: held until others confirm the new time."""
        self._ahead.append((sensor, t, vals))
        sensors = {s for s, _, _ in self._ahead}
        if len(sensors) >= 2 or (len(self._sensors_seen) == 1 and len(self._ahead) >= CONFIRM_AHEAD):
            held, self._ahead = self._ahead, []
            self.alerts.append(f"the clock jumped {held[0][1] - self.t_newest:.3g} s ahead at t={held[0][1]:.3f} s "
                               f"({', '.join(sorted(sensors))} agree); going on from there")
            out = []
            for s_, t_, v_ in held:
                out += self._accept(s_, t_, v_)
            return out
        return []

    def _drop_ahead(self) -> None:
        """Held stamps that the stream did not follow: rejected and counted."""
        for s_, t_, _ in self._ahead:
            if not self.counts.ahead.get(s_):
                self.alerts.append(f"{s_}: a measurement stamped t={t_:.3f} s, {t_ - self.t_newest:.3g} s past "
                                   "the newest, rejected (a clock ahead?); such are counted")
            _Counts.add(self.counts.ahead, s_)
        self._ahead = []

    def encoders(self, t: float, ticks_left: float, ticks_right: float) -> list[OnlineRow]:
        return self.push("encoders", t, ticks_left, ticks_right)

    def wheel_speeds(self, t: float, v_left: float, v_right: float) -> list[OnlineRow]:
        return self.push("wheel_speeds", t, v_left, v_right)

    def gps(self, t: float, x: float, y: float, sigma: float | None = None) -> list[OnlineRow]:
        return self.push("gps", t, x, y, *(() if sigma is None else (sigma,)))

    def gyro(self, t: float, omega: float) -> list[OnlineRow]:
        return self.push("gyro", t, omega)

    def ranges(self, t: float, beacon: str, range_m: float) -> list[OnlineRow]:
        return self.push("ranges", t, beacon, range_m)

    def velocity(self, t: float, v: float, omega: float) -> list[OnlineRow]:
        return self.push("velocity", t, v, omega)

    def _values(self, sensor: str, values) -> tuple:
        names = SENSOR_COLUMNS.get(sensor)
        if names is None:
            raise StreamInputError(f"unknown sensor {sensor!r}; one of {', '.join(SENSOR_COLUMNS)}")
        sf = SENSOR_FILE[sensor]
        want = tuple(range(len(sf.required), len(names) + 1))     # its optional columns may be left out
        if len(values) not in want:
            raise StreamInputError(f"{sensor}: expected {' or '.join(map(str, want))} values "
                                   f"({', '.join(names[:max(want)])}), got {len(values)}")
        out = []
        for name, v in zip(names, values):
            if sensor == "ranges" and name == "beacon":
                key = str(v).strip()
                if key not in self._beacons:
                    raise StreamInputError(f"ranges: unknown beacon {key!r} (robot.toml [range].beacons has "
                                           f"{', '.join(self._beacons) or 'none'})")
                out.append(self._beacons[key])
                continue
            f = _number(v)
            if f is None:
                raise StreamInputError(f"{sensor}: {name} {v!r} is not a number")
            if not math.isfinite(f):
                raise StreamInputError(f"{sensor}: {name} is {f!r}")
            out.append(f)
        if sensor == "gps" and len(out) == 3 and not out[2] > 0:
            raise StreamInputError(f"gps: sigma must be > 0, got {out[2]!r}")
        if sensor == "ranges" and not out[1] >= 0:
            raise StreamInputError(f"ranges: range must be >= 0, got {out[1]!r}")
        # read_log refuses a file with such a row (io.log.check_magnitudes); a
        # stream cannot stop for one line, so the line is skipped and said
        limit = STREAM_LIMITS.get(sensor)
        if limit is not None:
            size = max(abs(v) for v in (out[1:2] if sensor == "ranges" else out[:2]))
            if size > limit[0]:
                raise StreamInputError(f"{sensor}: {size:.4g} {limit[1]} is not a reading a ground robot gives "
                                       f"(limit {limit[0]:g})")
        return tuple(out)

    def _release(self, until: float) -> None:
        """Rows older than ``until`` leave the reorder buffer for good."""
        if until <= self.t_released:
            return
        self.t_released = until
        heap, raw = self._heap, self._raw
        while heap and heap[0][0] < until:
            t, _, sensor, vals = heapq.heappop(heap)
            rows = raw[sensor]
            # a stamp sent twice (read_log drops such rows too); ranges may share stamps
            if rows and sensor != "ranges" and t <= rows[-1][0]:
                _Counts.add(self.counts.repeated, sensor)
                continue
            rows.append((t, vals))
            if self.t_first is None or t < self.t_first:
                self.t_first = t
            if sensor == "gyro" and (self._gyro_top is None or abs(vals[0]) > abs(self._gyro_top[1][0])):
                self._gyro_top = (t, vals)
            if sensor == "encoders" and len(rows) >= 2:
                self._unwrap(rows)
                self._say_impossible_ticks(rows)
            if sensor in ("encoders", "wheel_speeds"):
                if sensor == "encoders" and len(rows) >= 2 and rows[-2][0] + 1e-9 < self.t_done \
                        and 0.5 * (rows[-2][0] + t) < self.t_done:
                    # the encoders were silent past WHEEL_WAIT: the filter went on, and this
                    # row's interval (its event mid-gap) lies behind it
                    _Counts.add(self.counts.late, sensor)
                    self.alerts.append(f"encoders: silent from t={rows[-2][0]:.2f} to {t:.2f} s; the filter went "
                                       "on without them, and the row that ended the gap was dropped")
                if self.smoother is not None:
                    self.smoother.wheel_row(self._wheel_rows, t)
                self._wheel_rows += 1

    def _unwrap(self, rows: list) -> None:
        """The encoder row just appended to ``rows`` without a counter's
        wrap-around (io.log.unwrapped_count, as read_log unwraps
        encoders.csv), said."""
        (t0, _), (t, vals) = rows[-2], rows[-1]
        fixed = list(vals)
        for i, tpm in enumerate((self.robot.ticks_per_meter_left, self.robot.ticks_per_meter_right)):
            y, bits = unwrapped_count(vals[i], tpm, t - t0)
            if bits is not None:
                fixed[i] = y
                self.alerts.append(f"encoders: a tick count of {vals[i]:g} at t={t:.3f} s is a {bits}-bit "
                                   f"counter's wrap-around; read as {y:g} (the differences were taken across it)")
        if fixed != list(vals):
            rows[-1] = (t, tuple(fixed))

    def _say_impossible_ticks(self, rows: list) -> None:
        """Count and say an encoder row (the last of ``rows``) that reads a
        wheel speed past io.log.MAX_SPEED over its interval, for which
        read_log refuses a file (a probe's 99,999,999-tick row went unsaid).
        It stays in: the cleaning (measurements.despike) takes it for the
        counter glitch it is, from its neighbours, and dropping it would hand
        its interval to the next row, whose ticks do not cover it."""
        (t0, _), (t, vals) = rows[-2], rows[-1]
        tpm = min(self.robot.ticks_per_meter_left, self.robot.ticks_per_meter_right)
        speed = max(abs(vals[0]), abs(vals[1])) / (tpm * (t - t0))
        if speed > MAX_SPEED:
            seen = self.counts.__dict__.setdefault("impossible", {})    # (older checkpoints lack it)
            _Counts.add(seen, "encoders")
            if seen["encoders"] > SAY_IMPOSSIBLE:
                return                      # a broken counter: the count at the end says the rest
            self.alerts.append(f"encoders: the row at t={t:.3f} s reads a wheel speed of {speed:.4g} m/s, not a "
                               f"reading a ground robot gives (limit {MAX_SPEED:g}); taken for a counter glitch")

    # ----------------------------------------------------------- filter
    def _log(self, t_lo: float) -> Log:
        """The released rows from t_lo on, as a Log."""
        def arrays(sensor):
            rows = self._raw[sensor]
            i = bisect.bisect_left(rows, (t_lo,))                 # (t_lo,) sorts before (t_lo, values)
            if sensor in ("encoders", "wheel_speeds"):
                # the rows the cleaning reads before the window's first, however old: an
                # encoder row's interval starts at the row before it (a dropout's too)
                i = max(i - SPIKE_HALF - 1, 0)
            rows = rows[i:]
            if sensor == "gyro" and rows and self._gyro_top is not None and self._gyro_top[0] < rows[0][0]:
                # The rail test (measurements.saturated) takes the largest |rate| of the log as the
                # rail: a window's own largest is no rail. The largest so far, at its own time before
                # the window, stands in; it lies before every event the window is read for.
                rows = [self._gyro_top] + rows
            if not rows:
                return None
            return np.array([r[0] for r in rows]), [np.array(c) for c in zip(*(r[1] for r in rows))]
        kw = {}
        for sf in SENSOR_FILES:
            if (a := arrays(sf.name)) is None:
                continue
            if sf.name == "gps":
                rows = self._raw["gps"][bisect.bisect_left(self._raw["gps"], (t_lo,)):]
                # fixes with and without a sigma: the configured one for those without (LOG_FORMAT)
                sig = (None if all(len(r[1]) == 2 for r in rows)
                       else np.array([r[1][2] if len(r[1]) == 3 else self.robot.gps_sigma for r in rows]))
                kw["gps"] = Gps(a[0], a[1][0], a[1][1], sig)
            elif sf.name == "ranges":
                kw["ranges"] = Ranges(a[0], a[1][0].astype(int), a[1][1])     # beacon indices
            else:
                kw[sf.name] = sf.cls(a[0], *a[1])
        return Log(self.robot, **kw)

    def _final_before(self, ahead: int = AHEAD_ROWS) -> float:
        """Events before this time [s] can no longer change: every row they
        depend on, and ``ahead`` rows after them, have been released."""
        b = self.t_released
        off = self.robot.gps_time_offset
        if off > 0:
            b -= off                          # a later fix is stamped late: it belongs earlier
        for sensor in ("encoders", "wheel_speeds", "gyro"):
            rows = self._raw[sensor]
            wait = WHEEL_WAIT if sensor == "encoders" else STOPPED_AFTER
            if not rows or rows[-1][0] < self.t_released - wait:
                continue
            if len(rows) <= ahead:
                return -math.inf
            # encoder events sit midway between two rows: the next row's event
            # lies after the newest row, ``ahead`` rows back is final
            b = min(b, rows[-1 - ahead][0])
        return b

    def _advance(self, final: bool) -> list[OnlineRow]:
        kept: list[OnlineRow] = []
        while True:
            try:
                return kept + self._advance_once(final)
            except EstimatorDivergedError as exc:
                # the rows a live stream would have given before the failing chunk (_filter)
                done = getattr(exc, "rows_before", [])
                if done:
                    self._check_revisions(done)
                    self.last = done[-1]
                kept += done
                if len(self.restarts) >= MAX_RESTARTS:
                    # giving up: the rows of this call so far go with the error (livestream
                    # writes them before it stops; a second divergence while closing lost them)
                    exc.rows_before = kept
                    raise
                self._restart(exc)
                if not final:
                    return kept
            except NotEnoughDataError:
                if not (final and self.restarts):
                    raise
                # closing right after a restart with too few rows left to start on: the
                # rows so far stand, and the restart says where they end
                self.restarts[-1] += "; too few rows were left after it to start again"
                return kept
            # Closing (the stream's end, or a short log's whole run at close): no more
            # rows will come to warm up on, so the restarted estimator runs on the rest
            # now (a probe: a 25 s replay whose window slipped stopped with exit 1 where
            # estimate gave flagged rows).

    def _frame_check(self, init, log: Log) -> None:
        """A run that starts in the wheels' own frame (initial.InitialState
        .frame_free) waits for an absolute sensor it did not have (_anchor)."""
        if init.frame_free:
            self._frame_free = True
            self._placed_by = {name for name in ("gps", "ranges") if getattr(log, name) is not None}

    def _anchor(self) -> None:
        """The first fix or range came after the estimator had started in the
        start's own frame (no absolute measurement in the warm-up, no
        [initial] pose): nothing ties that frame to theirs, and an estimator
        that took them anyway bent its scale factors to join the two (a
        probe: the first fix 35 s in, isam2's wheel scales 12 sigma off,
        status ok). The stream starts again from the last row on, as at a
        fresh start: a warm-up that fits the start to the fixes. The rows so
        far stay in the start's own frame, and the restart says so."""
        from odomgraph.errors import OdomgraphError
        firsts = [(rows[0][0], name) for name, rows in self._raw.items()
                  if name in ("gps", "ranges") and name not in self._placed_by and rows]
        t_abs, name = min(firsts)
        self._frame_free = False
        self._restart(OdomgraphError(
            f"the first {'GPS fix' if name == 'gps' else 'range'} came at t={t_abs:.2f} s, after the estimator had "
            "started without any absolute measurement or [initial] pose: the rows before are in the start's own "
            "frame (the origin, heading 0), not theirs"), anchor=True)

    def _restart(self, exc: Exception, anchor: bool = False) -> None:
        """The estimator diverged beyond its own recoveries: a robot still
        needs an estimate, so start again on the data from the failing event
        on, at the last row's pose with a wide sigma (or as at the start,
        before any row). The calibration so far is kept (the last row's
        scale factors, where they are plausible: within 10 % of nominal):
        the EKF holds them (slip only: calibrate_until 0, a short warm-up),
        a smoother calibrates again around them. Rows still give the scale
        factors against robot.toml's. ``anchor`` (_anchor): neither pose nor
        scale factors carry over, and the schedule stays: a fresh start."""
        from dataclasses import replace as dc_replace
        from odomgraph.io.robot import InitialPose
        # from the failing event on (the rows of the chunk that failed are the diverging ones)
        t_r = max(self.last.t if self.last is not None else self.t_first, self._fail_t or -math.inf)
        if anchor:
            # a fresh start: robot.toml and the schedule as given, no row to go on from
            self.robot = self._args["robot"].with_(initial=None)
            self.schedule = self._args["schedule"]
            self._base = np.ones(3)
        elif self.last is not None:
            x, y, th = (float(v) for v in self.last.mean[:3])
            sx, sy, sth = (float(v) for v in self.last.sigma[:3])
            sc = self.last.mean[S.SCALE_S]
            if np.all(np.abs(sc - 1.0) < 0.1):
                r = self.robot
                # Kept with what was known of them (3 sigma, at least RESTART_SCALE_SIGMA): a
                # restart wide in pose, in the middle of a slip, otherwise trades the
                # scale factors against the unknowns of its first seconds, and frozen
                # linearisations from then kept a track scale 6 % off at 15 sigma.
                sig = float(min(getattr(self, "_scale_sigma", r.process.initial_scale_sigma),
                                max(RESTART_SCALE_SIGMA, 3.0 * float(np.max(self.last.sigma[S.SCALE_S] / self._base)))))
                self.robot = r.with_(ticks_per_meter_left=r.ticks_per_meter_left * float(sc[0] / self._base[0]),
                                     ticks_per_meter_right=r.ticks_per_meter_right * float(sc[1] / self._base[1]),
                                     track_width=r.track_width * float(sc[2] / self._base[2]),
                                     process=dc_replace(r.process, initial_scale_sigma=sig))
                self._base = np.array(sc, float)
            else:                                   # not carried over: robot.toml's sigma again
                self.robot = self.robot.with_(process=dc_replace(self.robot.process,
                                                                 initial_scale_sigma=getattr(
                                                                     self, "_scale_sigma",
                                                                     self.robot.process.initial_scale_sigma)))
            self.robot = self.robot.with_(initial=InitialPose(x, y, th, (max(3 * sx, 1.0), max(3 * sy, 1.0),
                                                                         max(3 * sth, 0.5))))
        if self.method is Method.ekf and not anchor:
            # the EKF holds them from the start (slip only); a smoother has no hold, and calibrates again
            # with them as its prior's centre
            self.schedule = dc_replace(self.schedule, calibrate_until=0.0)
        if not self._warmup_given:
            self.warmup = self._default_warmup()
        for rows in self._raw.values():
            del rows[:bisect.bisect_left(rows, (t_r,))]                 # (t_r,) sorts before (t_r, values)
        g = self._raw["gyro"]
        self._gyro_top = max(g, key=lambda r: abs(r[1][0])) if g else None    # the rail test's, from here on
        firsts = [rows[0][0] for rows in self._raw.values() if rows]
        self.t_first = min(firsts) if firsts else None
        self.ekf = self.smoother = None
        self._rev_prev = None            # a new run's rows are not judged against the last one's
        if anchor:
            self.last = None             # (estimate() gives no row of the old frame, nor does a later restart)
        self._settle_said = 0            # the new runner's settle warnings start from none
        self.t_done = -math.inf
        self.restarts.append(f"t={t_r:.2f} s: {' '.join(str(exc).split())}; " + (
            f"started again in their frame, warming up for {self.warmup:g} s" if anchor else
            f"restarted from the last estimate's pose (sigma widened) and scale factors, warming up again for "
            f"{self.warmup:g} s"))

    def _advance_once(self, final: bool) -> list[OnlineRow]:
        if self.t_first is None:
            return []
        if self.ekf is None and self.smoother is None:
            if not self._warmup_given and self.robot.initial is None and self.method is not Method.ekf:
                # The start is fitted to the fixes (or ranges) of CONSENSUS_WINDOW
                # seconds from the first: a first fix late in the warm-up
                # extends it (one fix 35 s in fitted a start 17 m off only on
                # the circle its path allows, and isam2 bent its scale factors
                # to that prior). Streams whose fixes begin with them are not
                # held longer. The EKF takes such a start as one with no heading
                # (estimators.heading), which it handles causally; the fit on
                # the late fixes, carried back, gives it a heading of sigma pi
                # that it took as a Gaussian (a mirror solution, 1 m off at z 89).
                firsts = [rows[0][0] for name in ("gps", "ranges") if (rows := self._raw[name])]
                if firsts:
                    self.warmup = max(self.warmup, min(firsts) - self.t_first + CONSENSUS_WINDOW + WARMUP_MARGIN)
            # the warm-up covers the calibration window, which counts from the
            # schedule's origin (Log.t_schedule): with references that ran
            # before the wheels, from the wheels' first row (a second read: the
            # stream started before the replay's window ended, and missed the
            # slip inside it that the replay found)
            origin = self._schedule_origin()
            if not final and (origin is None or self.t_released < origin + self.warmup):
                return []
            self._start(final)
        if final:
            b = math.inf
        elif self.smoother is not None:
            # the smoother's intervals end on a wheel row: the cleaning reads SPIKE_HALF rows past it
            b = self._final_before(SPIKE_HALF)
        else:
            b = self._final_before()
        if self._frame_free and any(self._raw[name] for name in ("gps", "ranges") if name not in self._placed_by):
            self._anchor()
            if not final:
                return []
            return self._advance_once(final)     # closing: the rest of the stream in the new frame
        if self.smoother is not None:
            out = self.smoother.feed(self, b, final)
            said = getattr(self.smoother.runner, "settle_warnings", [])   # isam2's start heading (incremental.py)
            for msg in said[self._settle_said:]:
                self.alerts.append(msg)
            self._settle_said = len(said)
        elif not final and b - self.t_done < self.chunk:
            return []
        else:
            out = self._filter(b)
        if out:
            self._check_revisions(out)
            self.last = out[-1]
        self._prune()
        return out

    def _check_revisions(self, out: list[OnlineRow]) -> None:
        """Flag rows that jumped further from the row before than the robot
        could drive, by many of that row's sigma: the row before was far off
        at a small sigma (analysis.plausible.revision_warnings, as a whole
        run's causal rows are judged). Said once as an alert, counted in
        summary()["flags"]."""
        from odomgraph.analysis.plausible import revision_jumps, revision_line
        rows = ([self._rev_prev] if self._rev_prev is not None else []) + out
        self._rev_prev = out[-1]
        if len(rows) < 2:
            return
        t = np.array([r.t for r in rows])
        bad, beyond, z = revision_jumps(t, np.stack([r.mean for r in rows]), np.stack([r.sigma for r in rows]))
        for i in bad:
            if self._revised is None:
                self._revised = [0, float(t[i]), float(t[i + 1]), 0.0, 0.0]
                self.alerts.append(revision_line(f"{self.method.value} (stream)", 1, float(t[i]), float(t[i + 1]),
                                                 float(beyond[i]), float(z[i])))
            r = self._revised
            r[0] += 1
            r[2] = float(t[i + 1])
            if beyond[i] > r[3]:
                r[3], r[4] = float(beyond[i]), float(z[i])

    def flags(self) -> list[str]:
        """What makes rows so far not trustworthy: rows that jumped
        (_check_revisions), and at close a smoother's own flags."""
        from odomgraph.analysis.plausible import revision_line
        out = []
        if self._revised is not None:
            out.append(revision_line(f"{self.method.value} (stream)", *self._revised))
        if self.final is not None:
            out += [f for f in self.final.flags if f not in out]
        if self.ekf is not None:
            # a stop the fixes contradicted: the wheels read nothing while the robot moved
            from odomgraph.estimators.standstill import moved_flags
            out += [f for f in moved_flags(list(self.ekf.init.warnings) + self.ekf.still_watch.notes) if f not in out]
        return out

    def _schedule_origin(self) -> float | None:
        """The schedule's origin as the stream knows it (Log.t_schedule on
        the rows so far): the first row of any sensor, or the wheels' first
        when it came over SCHEDULE_LEAD_S later; None before a wheel row."""
        firsts = [rows[0][0] for name in ("encoders", "wheel_speeds") if (rows := self._raw[name])]
        if not firsts or self.t_first is None:
            return None
        return schedule_origin(self.t_first, min(firsts))

    def _start(self, final: bool = False) -> None:
        """Warm-up done: the whole-log decisions on the rows so far (see the module doc)."""
        log = self._log(-math.inf)
        wheel = log.encoders if log.encoders is not None else log.wheel_speeds
        if wheel is None or len(wheel.t) < 3:
            raise NotEnoughDataError(f"{0 if wheel is None else len(wheel.t)} encoder or wheel_speeds rows in the "
                                     f"first {self.warmup:g} s of the stream (or all of it): nothing to estimate "
                                     "from")
        from odomgraph.analysis.mounting import unit_refusal
        line = unit_refusal(log)
        if line:
            # as estimate refuses such a gyro.csv: no row from it is worth publishing
            raise OdomgraphError(f"the gyro lines of the first {log.t_end - log.t_start:.0f} s: {line}")
        if self.method is not Method.ekf:
            self.smoother = _Smoother(self, log, final)
            self._frame_check(self.smoother.runner.prob.init, log)
            return
        self.ekf = EKF(log, self.schedule, self.options)
        self._frame_check(self.ekf.init, log)
        self.ekf.begin()
        self.t_done = self.ekf.init.t
        self.notes.append(self.ekf.init.note)

    def _filter(self, b: float) -> list[OnlineRow]:
        """Filter the events in [t_done, b)."""
        ekf = self.ekf
        meas = from_log(self._log(self.t_done - self.context), frozen=False)
        t_ev, code_ev, row_ev = event_stream(meas, self.t_done)
        n = int(np.searchsorted(t_ev, b, side="left"))
        slip = in_stretches(t_ev[:n], ekf.slipping)
        out = []
        counts = self.counts
        for k in range(n):
            code = int(code_ev[k])
            self._fail_t = float(t_ev[k])
            try:
                nis = ekf.step(t_ev[k], code, *event_values(meas, code, row_ev[k]), in_slip=bool(slip[k]))
            except EstimatorDivergedError as exc:
                # A long span filtered at once (a short log's whole run at close, the warm-up)
                # keeps the rows a live stream in chunks would have given before the failing
                # chunk: failing at a log's last event lost every row of it.
                exc.rows_before = [r for r in out if r.t < self._fail_t - self.chunk]
                raise
            name = SENSOR_NAMES[code]
            _Counts.add(counts.accepted if nis >= 0 else counts.rejected, name)
            if nis >= 0:
                acc = self._nis.setdefault(name, [0.0, 0, DOF[code], False])
                acc[0] += nis
                acc[1] += 1
                # the filter's own running mean (its divergence watch's): said once per sensor when the
                # rows' sigma stop covering what the sensor sees, well before the watch gives up
                ema = ekf._nis_ema[code]
                if not acc[3] and ekf._n_seen[code] > NIS_MIN_COUNT and ema > NIS_WARN * DOF[code]:
                    acc[3] = True
                    self.alerts.append(f"{name}: the running mean NIS is {ema:.0f} (expected {DOF[code]}) at "
                                       f"t={t_ev[k]:.2f} s: the rows' sigma understate their error from here")
            if code == WHEEL:
                x, var, pc = ekf.row()
                out.append(self._row(t_ev[k], x, np.sqrt(np.maximum(var, 0.0)), pc))
        for note in [*meas.notes, *([ekf.anchored] if ekf.anchored else [])]:
            if note not in self.notes:
                self.notes.append(note)
        self.t_done = b
        return out

    def _prune(self) -> None:
        """Memory stays flat: rows older than the cleaning's context go."""
        keep_from = (self.smoother.keep_from(self) if self.smoother is not None else self.t_done) - self.context
        for sensor, rows in self._raw.items():
            i = 0
            while i < len(rows) - AHEAD_ROWS - 2 and rows[i][0] < keep_from:
                i += 1
            if i:
                del rows[:i]
        if self.ekf is not None:
            # the filter's own lists of held-out times: the last thousand per sensor are plenty
            for k, v in self.ekf.held_t.items():
                del v[:-1000]

    # ----------------------------------------------------------- output
    def estimate(self) -> OnlineRow | None:
        """The newest estimate (None before the filter starts)."""
        return self.last

    def close(self) -> list[OnlineRow]:
        """No more data: filter everything that is left. Returns those rows."""
        if self.closed:
            return []
        self._release(math.inf)
        out = self._advance(final=True)
        self.closed = True
        return out

    def summary(self) -> dict:
        """Counts, recoveries and notes so far, for a log line or summary.json."""
        c = self.counts
        eng = self.ekf if self.ekf is not None else (self.smoother.runner if self.smoother is not None else None)
        rejected = dict(c.rejected) if self.smoother is None else dict(self.smoother.runner.graph.gated)
        warnings = []
        if self.ekf is not None:
            warnings = list(self.ekf.init.warnings) + list(self.ekf.window_warnings) + self.ekf.heading_warnings()
            # the stops after the warm-up that the other sensors contradicted (standstill.StillWatch)
            warnings += [w for w in self.ekf.still_watch.notes if w not in warnings]
        elif self.smoother is not None:
            warnings = list(self.smoother.runner.prob.init.warnings) + list(
                getattr(self.smoother.runner, "settle_warnings", []))
            if self.smoother.watch is not None:
                from odomgraph.estimators.heading import warning
                warnings.append(warning(self.smoother.watch.t_known, self.smoother.watch))
        warnings += self._pinned_lines()
        for k, v in self._nis.items():
            line = nis_warning(k, v[0], v[1], v[2])
            if line:
                warnings.append(line)
        accepted = dict(c.accepted)
        if self.smoother is not None:
            from odomgraph.estimators.batch import measurement_counts
            accepted = measurement_counts(self.smoother.runner.prob)
        return {"method": self.method.value, "t_origin": self.t_origin or 0, "accepted": accepted,
                "rejected_by_gate": rejected, "rejected_late": dict(c.late),
                "repeated_stamps": dict(c.repeated), "recoveries": list(eng.recoveries) if eng else [],
                "departures": list(getattr(eng, "departures", [])),
                "restarts": list(self.restarts), "rejected_ahead": dict(c.ahead),
                "impossible_rows": dict(getattr(c, "impossible", {})),
                "mean_nis": {k: {"mean": v[0] / v[1], "dof": v[2], "n": v[1]} for k, v in self._nis.items() if v[1]},
                "warnings": warnings, "flags": self.flags(),
                "notes": list(self.notes), "warmup_s": self.warmup, "latency_s": self.latency}

    def _pinned_lines(self) -> list[str]:
        """A line per scale combination the warm-up did not determine: held at
        nominal for the whole stream, its rows carrying the prior sigma (a
        probe's isam2 stream of a slow snowplow that drove straight through
        its warm-up gave the track scale at nominal, silently; estimate says
        the same of a whole log, pipeline.warnings_of)."""
        init = (self.ekf.init if self.ekf is not None
                else self.smoother.runner.prob.init if self.smoother is not None else None)
        obs = None if init is None else init.observability
        if obs is None:
            return []
        return [f"{name} is not determined by the warm-up's first {self.warmup:.0f} s (held at nominal for the whole "
                f"stream, reported with its prior sigma): {reason}; a --warmup that holds straight driving and "
                "turns, or calibrate first, determines it" for name, reason in obs.unobservable.items()]

    # ------------------------------------------------------ checkpoints
    def save(self, path: Path | str) -> None:
        """Checkpoint: everything needed to go on as if never stopped,
        written atomically (a crash mid-write leaves the previous one)."""
        path = Path(path)
        if self.method is Method.ekf:
            data = {"format": "odomgraph-online-1", "online": self}
        elif self.journal is None:
            raise OdomgraphError(f"{self.method.value}: a checkpoint replays the measurements so far; make the "
                                 "Online with journal=True")
        else:
            data = {"format": "odomgraph-online-1", "args": self._args, "journal": self.journal,
                    "lines_read": self.lines_read}
        # through a fresh temporary beside it; only a checkpoint is ever replaced
        from odomgraph.io.outdir import atomic_output_file
        with atomic_output_file(path, is_ours=Online.is_checkpoint) as tmp:
            with open(tmp, "wb") as f:
                pickle.dump(data, f, protocol=pickle.HIGHEST_PROTOCOL)

    @staticmethod
    def is_checkpoint(path: Path | str) -> bool:
        """Whether the file at ``path`` is one ``save`` wrote (its format
        tag near the start), so that a checkpoint path never replaces a file
        odomgraph did not write (a log's gps.csv, a robot.toml)."""
        try:
            with open(path, "rb") as f:
                return b"odomgraph-online-1" in f.read(256)
        except OSError:
            return False

    @staticmethod
    def load(path: Path | str) -> "Online":
        """An Online from ``save``'s checkpoint. A checkpoint is a pickle:
        load only your own (unpickling a foreign file can run its code)."""
        path = Path(path)
        try:
            with open(path, "rb") as f:
                data = pickle.load(f)
        except FileNotFoundError:
            raise OdomgraphError(f"{path}: no such checkpoint") from None
        except Exception as exc:   # a truncated or foreign file
            raise OdomgraphError(f"{path}: not an odomgraph checkpoint ({type(exc).__name__})") from None
        if not isinstance(data, dict) or data.get("format") != "odomgraph-online-1":
            raise OdomgraphError(f"{path}: not an odomgraph checkpoint")
        if "online" in data:
            if not isinstance(data["online"], Online):
                raise OdomgraphError(f"{path}: not an odomgraph checkpoint")
            return data["online"]
        if not isinstance(data.get("args"), dict) or not isinstance(data.get("journal"), list):
            raise OdomgraphError(f"{path}: not an odomgraph checkpoint")
        try:
            live = Online(**data["args"])
            for sensor, t, values in data["journal"]:
                live.push(sensor, t, *values)
        except (TypeError, ValueError, OdomgraphError) as exc:
            raise OdomgraphError(f"{path}: the checkpoint does not replay ({' '.join(str(exc).split())})") from None
        live.lines_read = data["lines_read"]
        return live


class _Smoother:
    """isam2 or fixed-lag, one keyframe at a time (see the module doc)."""

    def __init__(self, online: Online, log: Log, final: bool = False):
        from odomgraph.estimators.batch import build_problem
        from odomgraph.estimators.growing import GrowingProblem
        from odomgraph.estimators.incremental import FixedLagRunner, ISAM2Runner
        from odomgraph.estimators.keyframes import keyframe_step
        opt, sch = online.options, online.schedule
        self.isam2 = online.method is Method.isam2
        wheel = log.encoders if log.encoders is not None else log.wheel_speeds
        self.step = keyframe_step(wheel.t, opt.keyframe_hz)
        prob = build_problem(log, sch, opt, causal=True)
        self.first = int(np.searchsorted(wheel.t, prob.init.t, side="left"))
        # the stream's wheel row number of this log's first row (a restart starts a new log)
        self.offset = online._wheel_rows - len(wheel.t)
        # the keyframes of the whole log are every step-th wheel row from `first` on
        self.kf_times = [float(t) for t in wheel.t[self.first::self.step]]
        self.t_start = log.t_schedule          # the schedule's origin, as the replay's (Log.t_schedule)
        b = math.inf if final else online._final_before(SPIKE_HALF)
        # final: interval j ends at t_{j+1} <= b, and keyframe j+2 is one of the log's
        m = 0
        while m + 2 < len(self.kf_times) and self.kf_times[m + 1] <= b and m + 1 < prob.kf.n - 1:
            m += 1
        if m < 2:
            raise NotEnoughDataError(f"{online.method.value}: fewer than 3 keyframes in the warm-up "
                                     f"({online.warmup:g} s); give a longer --warmup")
        cut, t_next = GrowingProblem.cut(prob, m)
        cls = ISAM2Runner if self.isam2 else FixedLagRunner
        self.runner = r = cls(log, sch, opt, prob=cut)
        r.last_k = math.inf             # a stream's last keyframe is known when it ends
        self.grow = GrowingProblem([r.prob, r.graph.lin_prob, r.graph.lin_first], t_next, sch, self.step,
                                   opt.keyframe_hz)
        online.notes.append(prob.init.note)
        self.wall0 = time.perf_counter()
        self._emitted = 0               # fixed-lag: keyframes whose row was written
        r.begin()
        self.next_k = 1                 # the next keyframe to advance to
        self.no_walk: list[int] = []    # intervals appended whose random walk waits for the next keyframe
        # A start with no heading: the rows before the motion shows one are widened, as the replay's
        # (batch.smoother_estimate); the watch reads the cleaned events in time order as they become final.
        self.watch, self._watch_t = None, -math.inf
        if prob.init.heading_unknown:
            from odomgraph.estimators.heading import HeadingWatch
            rb = online.robot
            gps_first = prob.meas.gps is not None
            lever = rb.gps_lever_arm if gps_first else rb.range_lever_arm
            self.watch = HeadingWatch(rb.track_width, lever, float(np.median(prob.meas.gps[2])) if gps_first
                                      else rb.range_sigma, fixes=gps_first)

    def wheel_row(self, i: int, t: float) -> None:
        """Wheel row i (of the whole stream) was released at t [s]."""
        i -= self.offset
        if i > self.first + (len(self.kf_times) - 1) * self.step and (i - self.first) % self.step == 0:
            self.kf_times.append(t)

    def keep_from(self, online: Online) -> float:
        """The oldest time [s] a later window reads."""
        from odomgraph.estimators.growing import WINDOW_BACK
        j = self.runner.prob.kf.n - 1              # the next interval to append
        return self.kf_times[max(j - WINDOW_BACK, 0)]

    def feed(self, online: Online, b: float, final: bool) -> list[OnlineRow]:
        """Append every interval whose data are final (their end t_{j+1} <= b),
        then advance every keyframe whose interval and random walk are ready
        (the walk needs the next keyframe's time, which comes a row or so
        later: the two halves of the work fall on different measurements).
        Returns the new rows."""
        from odomgraph.estimators.growing import WINDOW_BACK, window_piece
        r, kt = self.runner, self.kf_times
        if final:
            wheel = online._raw["encoders"] or online._raw["wheel_speeds"]
            if wheel and wheel[-1][0] > kt[-1]:
                kt = kt + [wheel[-1][0]]        # the whole log's last keyframe: its last wheel row
        j0 = r.prob.kf.n - 1                     # intervals j0.. are not in the problem yet
        j1 = j0
        while j1 + 1 < len(kt) and (final or kt[j1 + 1] <= b):
            j1 += 1
        if j1 > j0:
            w0 = max(j0 - WINDOW_BACK, 0)
            piece = window_piece(online._log(kt[w0] - online.context), kt[w0], kt[j1], r.options.keyframe_hz,
                                 self.step)
            for j in range(j0, j1):
                self.grow.append(piece, j - w0, None, self.t_start)
                self.no_walk.append(j)
        while self.no_walk and (final or self.no_walk[0] + 2 < len(kt)):
            j = self.no_walk.pop(0)
            self.grow.set_walk(j, kt[j + 2] if j + 2 < len(kt) else kt[j + 1])
        if final:
            r.last_k = r.prob.kf.n - 1
        self._watch_heading(online, math.inf if final else b)
        out = []
        ready = r.prob.kf.n - 1 - len(self.no_walk)       # keyframes up to here have their interval
        while self.next_k <= ready:
            online._fail_t = float(r.prob.kf.t[self.next_k])
            r.advance(self.next_k)
            if self.isam2:
                out.append(self._online_row(self.next_k, online))
            self.next_k += 1
        if not self.isam2:
            out += self._harvested(online, final)
        if self.watch is not None:
            until = self.watch.t_known - (0.0 if self.isam2 else r.options.lag)
            out = [self._widen(row, until) if row.t < until else row for row in out]
        if final:
            r.trim()
            if self.watch is not None:
                r.heading_watch = self.watch      # the final smoothing's, from the whole stream
            self.final = r.finish(self.wall0)
            online.final = self.final
        return out

    def _watch_heading(self, online: Online, b: float) -> None:
        """Feed the heading watch the cleaned events up to b [s] (only while
        it waits: a start with no heading that has not moved yet)."""
        from odomgraph.estimators.sensors import GPS, WHEEL, event_stream
        w = self.watch
        if w is None or w.known:
            return
        meas = from_log(online._log(self._watch_t - online.context if self._watch_t > -math.inf else -math.inf),
                        frozen=False)
        wh = meas.wheel
        t_ev, code_ev, row_ev = event_stream(meas, wh.t[0])
        dt = wh.dt if wh.dt is not None else np.append(np.diff(wh.t), np.median(np.diff(wh.t)) if len(wh.t) > 1
                                                       else 0.0)
        for t, code, i in zip(t_ev, code_ev, row_ev):
            if t <= self._watch_t or t > b:
                continue
            if code == WHEEL:
                w.wheel(t, wh.m[i, 0], wh.m[i, 1], dt[i])
            elif code == GPS:
                w.fix(t, meas.gps[1][i])
            self._watch_t = float(t)
            if w.known:
                return

    def _widen(self, row: OnlineRow, until: float) -> OnlineRow:
        from dataclasses import replace as dc_replace
        from odomgraph.estimators.heading import widen_rows
        sig = row.sigma[None].copy()
        pc = None if row.pose_cov is None else row.pose_cov[None].copy()
        widen_rows(np.array([row.t]), sig, pc, until, self.watch, row.mean[None])
        return dc_replace(row, sigma=sig[0], pose_cov=None if pc is None else pc[0])

    def _online_row(self, k: int, online: Online) -> OnlineRow:
        r = self.runner
        t = r.prob.kf.t
        return online._row(t[k - 1] + 0.5 * (t[k] - t[k - 1]), r.online[k].copy(), r.online_sigma[k].copy(), None)

    def _harvested(self, online: Online, final: bool) -> list[OnlineRow]:
        """fixed-lag: the rows of the keyframes that left the window (all, at the end)."""
        from odomgraph.estimators.batch import honest_blocks, keyframe_rows
        r = self.runner
        n = r.prob.kf.n
        if final:
            r.end_hold()
            est = r.smoother.calculateEstimate()
            for j in np.nonzero(~r.done[:n])[0]:
                r._harvest(int(j), est)
        k1 = self._emitted
        while k1 < n - 1 and r.done[k1]:        # row k describes interval k: keyframe k's final state
            k1 += 1
        if k1 <= self._emitted:
            return []
        Sig = r.Sig[:n]
        if r.prob.init.observability.unobservable:
            # pinned scale combinations: their prior sigma given back, on the harvested keyframes only
            # (the others' blocks are still zero); honest_blocks is the identity otherwise
            Sig = Sig.copy()
            Sig[self._emitted:k1] = honest_blocks(r.prob, Sig[self._emitted:k1])
        rows = keyframe_rows(r.prob, r.pose[:n], r.W[:n], Sig, r.method, slice(self._emitted, k1))
        self._emitted = k1
        return [online._row(rows.t[i], rows.mean[i], rows.sigma[i], rows.pose_cov[i]) for i in range(len(rows.t))]
