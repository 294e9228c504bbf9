"""The log directory of LOG_FORMAT.md: read, validate, write.

A ``Log`` holds each sensor as a small frozen dataclass of 1-D numpy arrays
sharing one clock. Reading validates everything an estimator relies on and
raises ``LogFormatError`` naming file, line and problem.
"""
from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from odomgraph.errors import LogFormatError
from odomgraph.io.csvtable import ORIGIN_ABOVE, header_of, read_text, shown, stamp_text, text_lines, write_table
from odomgraph.io.csvtable import read_table as _read_table
from odomgraph.io.geodesy import latlon_to_local
from odomgraph.io.outdir import atomic_output_dir
from odomgraph.io.robot import RobotConfig, load_robot, robot_toml


@dataclass(frozen=True)
class Encoders:
    """encoders.csv: ticks counted in (t_prev, t]; the first row only starts the count."""
    t: np.ndarray
    ticks_left: np.ndarray
    ticks_right: np.ndarray


@dataclass(frozen=True)
class WheelSpeeds:
    """wheel_speeds.csv: surface speeds converted with the nominal ticks/m [m/s]."""
    t: np.ndarray
    v_left: np.ndarray
    v_right: np.ndarray


@dataclass(frozen=True)
class Gps:
    """gps.csv in the local frame: antenna x east, y north [m]; sigma [m] or None."""
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    sigma: np.ndarray | None = None


@dataclass(frozen=True)
class Gyro:
    """gyro.csv: z rate [rad/s]."""
    t: np.ndarray
    omega: np.ndarray


@dataclass(frozen=True)
class Ranges:
    """ranges.csv: ``beacon`` indexes RobotConfig.beacons; range [m]."""
    t: np.ndarray
    beacon: np.ndarray
    range: np.ndarray


@dataclass(frozen=True)
class Velocity:
    """velocity.csv: independent body velocity, v [m/s], omega [rad/s]."""
    t: np.ndarray
    v: np.ndarray
    omega: np.ndarray


@dataclass(frozen=True)
class SensorFile:
    """One sensor's file of LOG_FORMAT.md. ``SENSOR_FILES`` is the one table
    that reading and writing a log, the stream's line format (io.stream) and
    the live estimator's buffers (odomgraph.online) read: a sensor whose
    columns are plain numbers needs its dataclass, its ``Log`` field and a
    line there, nothing more, to be read, written and streamed."""
    name: str
    """The Log field, the file's stem and a stream line's first word."""
    cls: type
    """Its dataclass: ``t``, then ``columns`` in order."""
    columns: tuple[str, ...]
    """The columns after ``t``, in LOG_FORMAT order; the last ``optional`` of them may be absent."""
    formats: tuple[str | None, ...]
    """write_table's format of each column (None: text)."""
    tie: int
    """Rank among measurements of equal stamps when a stream merges the files:
    the wheels, then the gyro, then the fixes, as estimators.sensors orders
    its codes."""
    optional: int = 0
    min_rows: tuple[int, str] = (0, "")
    """Fewest rows a file may hold, and why (said when it holds fewer)."""

    @property
    def file(self) -> str:
        return f"{self.name}.csv"

    @property
    def required(self) -> tuple[str, ...]:
        return self.columns[:len(self.columns) - self.optional]


#: Every sensor file, in the Log's field order (the wheels first: they set the clock's origin).
SENSOR_FILES = (
    SensorFile("encoders", Encoders, ("ticks_left", "ticks_right"), ("%.0f", "%.0f"), 0,
               min_rows=(2, " (the first only starts the count)")),
    SensorFile("wheel_speeds", WheelSpeeds, ("v_left", "v_right"), ("%.6f", "%.6f"), 1, min_rows=(2, "")),
    SensorFile("gps", Gps, ("x", "y", "sigma"), ("%.5f", "%.5f", "%.5f"), 3, optional=1),
    SensorFile("gyro", Gyro, ("omega",), ("%.7f",), 2),
    SensorFile("ranges", Ranges, ("beacon", "range"), (None, "%.5f"), 4),
    SensorFile("velocity", Velocity, ("v", "omega"), ("%.6f", "%.6f"), 5),
)
#: The sensors by name.
SENSOR_FILE = {s.name: s for s in SENSOR_FILES}


#: truth.csv columns: the LOG_FORMAT ones plus ``gyro_bias`` (an allowed extra, written by the simulator).
TRUTH_COLUMNS = ("x", "y", "theta", "v", "omega", "slip_left", "slip_right", "gyro_bias")


class Truth:
    """truth.csv: ``t`` (N,) [s] and ``values``, each present column of
    TRUTH_COLUMNS as an (N,) array (x, y [m], theta [rad], ...).

    Only the tools that score against the truth use it, so ``read_log`` reads
    truth.csv on first use (``Truth.file``), not with the sensors: an
    estimator never pays for it (an hour at 100 Hz is 40 MB of text)."""

    def __init__(self, t: np.ndarray, values: dict[str, np.ndarray]):
        self._t, self._values, self._load = t, values, None

    @classmethod
    def file(cls, load) -> "Truth":
        """A Truth whose (t, values) ``load()`` gives when first asked for."""
        out = cls(None, None)
        out._load = load
        return out

    def _loaded(self):
        if self._load is not None:
            self._t, self._values = self._load()
            self._load = None
        return self._t, self._values

    @property
    def t(self) -> np.ndarray:
        return self._loaded()[0]

    @property
    def values(self) -> dict[str, np.ndarray]:
        return self._loaded()[1]

    def at(self, name: str, t: np.ndarray) -> np.ndarray | None:
        """Column ``name`` linearly interpolated at times t (None if absent).
        Heading is interpolated on the circle."""
        if name not in self.values:
            return None
        if name == "theta":
            th = np.unwrap(self.values["theta"])
            from odomgraph.factors._math import wrap_angle
            return wrap_angle(np.interp(t, self.t, th))
        return np.interp(t, self.t, self.values[name])

    def __getstate__(self):
        # (a process pool or a checkpoint pickles it: the rows, not the reader)
        t, values = self._loaded()
        return {"_t": t, "_values": values, "_load": None}

    @property
    def loaded(self) -> bool:
        """Whether the rows have been read (see ``file``)."""
        return self._load is None

    def _then(self, f) -> "Truth":
        """This truth with ``f(t, values) -> (t, values)`` applied, read no sooner than this one."""
        if self.loaded:
            return Truth(*f(self._t, self._values))
        return Truth.file(lambda: f(*self._loaded()))

    def cut_before(self, t_end: float) -> "Truth":
        """The rows with t <= t_end [s] (Log.truncated), read no sooner than this one."""
        return self._then(lambda t, v: (t[t <= t_end], {k: a[t <= t_end] for k, a in v.items()}))

    def shifted(self, dt: float) -> "Truth":
        """The same rows with t + dt [s] (io.log.rebased), read no sooner than this one."""
        return self._then(lambda t, v: (t + dt, v))


@dataclass(frozen=True)
class Log:
    robot: RobotConfig
    encoders: Encoders | None = None
    wheel_speeds: WheelSpeeds | None = None
    gps: Gps | None = None
    gyro: Gyro | None = None
    ranges: Ranges | None = None
    velocity: Velocity | None = None
    truth: Truth | None = None
    truth_scales: tuple[float, float, float] | None = None
    """(scale_left, scale_right, scale_track) where known."""
    path: Path | None = None
    notes: tuple[str, ...] = field(default=())
    warnings: tuple[str, ...] = field(default=())
    """What reading the files repaired (duplicated rows dropped), and what
    the import that wrote them warned of (IMPORT_FILE), one line each."""
    provenance: dict | None = None
    """Where an imported log came from (IMPORT_FILE's content: importer,
    source, options, notes, warnings, odomgraph version); None otherwise."""
    t_origin: int = 0
    """Every ``t`` counts seconds from this integer second of the log's clock.
    0 for logs on a small clock; a log on a real clock (stamps near 1.7e9 s,
    where float64 keeps 0.24 us) counts from the wheels' first whole second,
    so intervals keep their full precision. Files odomgraph writes carry the
    absolute stamps again."""

    @property
    def t_start(self) -> float:
        return float(min(s.t[0] for s in self.sensors() if len(s.t)))

    @property
    def t_schedule(self) -> float:
        """When the pseudo-update schedule's clock starts [s]: Schedule's
        ``calibrate_until`` counts from here. The first sample of any sensor,
        or the wheels' first row when the others ran more than
        SCHEDULE_LEAD_S before them: a GPS receiver or an IMU logging while
        the wheel driver had not started yet (a probe's bag: 150 s) let the
        calibration window pass with no wheel row in it."""
        wheel = self.encoders if self.encoders is not None else self.wheel_speeds
        return schedule_origin(self.t_start, float(wheel.t[0]) if wheel is not None and len(wheel.t) else None)

    @property
    def t_end(self) -> float:
        return float(max(s.t[-1] for s in self.sensors() if len(s.t)))

    def sensors(self):
        return [s for s in (getattr(self, f.name) for f in SENSOR_FILES) if s is not None]

    def with_(self, **changes) -> "Log":
        return replace(self, **changes)

    def truncated(self, t_end: float) -> "Log":
        """The log as it stood at time t_end: every row with t <= t_end."""
        def cut(obj):
            if obj is None:
                return None
            if isinstance(obj, Truth):
                return obj.cut_before(t_end)
            keep = obj.t <= t_end
            kw = {k: (v[keep] if isinstance(v, np.ndarray) else v) for k, v in obj.__dict__.items()}
            return type(obj)(**kw)
        return replace(self, **{k: cut(getattr(self, k)) for k in (*SENSOR_FILE, "truth")})


IMPORT_FILE = "import.json"
"""Written by ``odomgraph import`` beside the sensor files (LOG_FORMAT.md
allows extra files): where the log came from and what the import noted and
warned of. Its warnings are read back into Log.warnings, so that every
estimate and calibration of the log repeats them: a fix sigma the import
assumed, an IMU it left out, are facts about the data the result rests on."""


def _provenance(path: Path) -> tuple[dict | None, tuple[str, ...]]:
    """IMPORT_FILE's content and the warnings it carries (each prefixed
    "import: "); a file that is not what import writes is ignored with a
    warning, not refused: it is not a sensor file and nothing needs it."""
    try:
        if not _optional(path):
            return None, ()
        prov = json.loads(read_text(path))
        if not isinstance(prov, dict):
            raise ValueError("not a JSON object")
        warns = prov.get("warnings", [])
        if not isinstance(warns, list) or not all(isinstance(w, str) for w in warns):
            raise ValueError("'warnings' is not a list of strings")
    except (ValueError, RecursionError, LogFormatError) as exc:
        why = exc.problem if isinstance(exc, LogFormatError) else str(exc)
        return None, (f"{path.name}: not an import record ({shown(why, 80)}); ignored",)
    return prov, tuple(f"import: {w}" for w in warns)


#: Sensors that start up to this long [s] before the wheels leave the
#: schedule's origin at the first sample (Log.t_schedule): sensors started
#: together start a fraction of a period apart, and the simulator's logs
#: and every recording shipped keep their schedule.
SCHEDULE_LEAD_S = 1.0


def schedule_origin(t_first: float, t_wheel: float | None) -> float:
    """The schedule's origin [s] (Log.t_schedule) from the first row of any
    sensor and the wheels' first row (None: no wheel row): the wheels' when
    it came over SCHEDULE_LEAD_S after the first. One rule for a read log
    and for a stream's rows so far (online.Stream)."""
    return t_wheel if t_wheel is not None and t_wheel - t_first > SCHEDULE_LEAD_S else t_first


def _optional(path: Path):
    """The path if the file is there, None if it is not; a directory (or
    anything else) by that name is refused rather than taken for no file."""
    if path.is_file():
        return path
    if path.exists():
        raise LogFormatError(path, "is not a file")
    return None


def read_log(directory: Path | str) -> Log:
    """Read and validate a log directory. Raises LogFormatError on bad input."""
    d = Path(directory)
    if not d.is_dir():
        raise LogFormatError(d, "log directory does not exist")
    robot = load_robot(d / "robot.toml")
    truth = None
    dups: dict[str, int] = {}
    origin: list[int] = []

    def read_table(p, *a, **k):
        c = _read_table(p, *a, **k)
        dups[p.name] = int(c["_duplicates"])
        # The wheels are read first and set the origin (see Log.t_origin).
        if not origin:
            origin.append(int(c["_t_sec"][0]) if "_t_sec" in c else 0)
        if "_t_sec" in c:
            c["t"] = (c["_t_sec"] - origin[0]).astype(float) + c["_t_frac"]
        elif origin[0] and "t" in c:
            c["t"] = c["t"] - origin[0]
        return c
    if _optional(d / "encoders.csv") and _optional(d / "wheel_speeds.csv"):
        raise LogFormatError(d, "has both encoders.csv and wheel_speeds.csv; they are alternatives "
                                "(LOG_FORMAT.md): keep the one to use")
    if not _optional(d / "encoders.csv") and not _optional(d / "wheel_speeds.csv"):
        raise LogFormatError(d / "encoders.csv", "file is missing (a log needs encoders.csv or wheel_speeds.csv)")
    read: dict[str, object] = {}
    for sf in SENSOR_FILES:
        if (p := _optional(d / sf.file)):
            read[sf.name] = (_SPECIAL_READERS[sf.name](p, robot, read_table) if sf.name in _SPECIAL_READERS
                             else _read_plain(sf, p, read_table))
    if (p := _optional(d / "truth.csv")):
        wheel = read.get("encoders", read.get("wheel_speeds"))
        o = origin[0] if origin else 0
        span = (float(wheel.t[0]) + o, float(wheel.t[-1]) + o) if wheel is not None and len(wheel.t) else None
        truth = _truth_file(p, read_table, o, span)
    scales = None
    if (p := _optional(d / "truth.toml")):
        try:
            tt = tomllib.loads(read_text(p))
        except tomllib.TOMLDecodeError as exc:
            raise LogFormatError(p, f"malformed TOML: {shown(str(exc), 200)}") from None
        try:
            scales = tuple(float(tt[k]) for k in ("scale_left", "scale_right", "scale_track"))
        except KeyError as exc:
            raise LogFormatError(p, f"missing key {exc.args[0]}") from None
        except (TypeError, ValueError, OverflowError):
            raise LogFormatError(p, "scale factors must be numbers") from None
        if not all(np.isfinite(scales)) or min(scales) <= 0:
            raise LogFormatError(p, f"scale factors must be positive finite numbers, got {list(scales)}")
    warn = tuple(f"{name}: {int(n)} row(s) written twice (same stamp and values) were read once"
                 for name, n in dups.items() if n)
    if read.get("encoders") is not None:
        read["encoders"], wrapped = unwrapped_ticks(read["encoders"], robot)
        warn += tuple(wrapped)
    # A sensor file with a header and no rows is no sensor: said, as a missing
    # file is not (a probe's empty gps.csv ran as "no absolute sensor" unnamed).
    warn += tuple(f"{sf.file}: a header and no rows: the log has no {sf.name} measurements"
                  for sf in SENSOR_FILES if sf.name in read and hasattr(read[sf.name], "t")
                  and len(read[sf.name].t) == 0)
    prov, prov_warn = _provenance(d / IMPORT_FILE)
    log = Log(robot, **read, truth=truth, truth_scales=scales, path=d, warnings=prov_warn + warn,
              provenance=prov, t_origin=origin[0] if origin else 0)
    check_log(log)
    return log


#: Counter widths whose wrap-around a tick difference may carry.
COUNTER_BITS = (16, 32)
#: A row faster than this [m/s] that is within a quarter of 2^bits of a
#: counter's wrap-around, and slower than it unwrapped, is taken for one.
WRAP_SPEED = 50.0


def unwrapped_count(x: float, tpm: float, dt: float) -> tuple[float, int | None]:
    """(ticks ``x`` of a row ``dt`` [s] long without a counter's wrap-around,
    the counter's bits or None). A wrap-around is a count within a quarter of
    2^bits of it, beyond half of it, that reads a wheel speed past WRAP_SPEED
    at ``tpm`` ticks/m and one below it unwrapped: -65177 for +359 from a
    16-bit counter differenced across its wrap. The speeds keep a fine
    encoder's big counts (520k ticks/m at 10 Hz: 52k ticks a row at 1 m/s)."""
    if not dt > 0:
        return x, None
    for bits in COUNTER_BITS:
        w = float(2 ** bits)
        if abs(x) > 0.5 * w and abs(abs(x) - w) < 0.25 * w:
            y = x - np.sign(x) * w
            if abs(x) / (tpm * dt) > WRAP_SPEED > abs(y) / (tpm * dt):
                return y, bits
    return x, None


def unwrapped_ticks(e: Encoders, robot) -> tuple[Encoders, list[str]]:
    """``e`` with each tick count that is a counter's wrap-around
    (unwrapped_count) given back its 2^bits, and a line per wheel saying so;
    ``e`` itself and [] when there is none (a probe's wrapped rows were only
    "rejected as outliers", their ticks lost). The first row, whose ticks
    the format does not count, is left as it is."""
    from dataclasses import replace as _replace
    out, lines = {}, []
    dt = np.diff(e.t)
    for side, tpm in (("left", robot.ticks_per_meter_left), ("right", robot.ticks_per_meter_right)):
        v = np.asarray(getattr(e, f"ticks_{side}"))
        fixed, bits = v.copy(), {}
        for i in np.flatnonzero(np.abs(v[1:]) > 0.5 * 2 ** COUNTER_BITS[0]) + 1:
            y, b = unwrapped_count(float(v[i]), tpm, float(dt[i - 1]))
            if b is not None:
                fixed[i] = y
                bits.setdefault(b, []).append(int(i))
        for b, rows in bits.items():
            k = rows[0]
            lines.append(f"encoders.csv: {len(rows)} {side} tick count(s) are a {b}-bit counter's wrap-around, "
                         f"unwrapped (the first at t={float(e.t[k]):.3f} s: {v[k]:g}, read as {fixed[k]:g}): the "
                         "differences were taken across the wrap; fix the converter")
        if bits:
            out[f"ticks_{side}"] = fixed
    return (_replace(e, **out) if out else e), lines


def _truth_file(p: Path, read_table, origin: int, span: tuple[float, float] | None) -> Truth:
    """truth.csv, read when first used (see Truth). Its header is checked
    now, so that a log without the truth's columns is refused as it is read;
    the rows, and their clock against the wheels' (``span``, as written [s];
    check_clock), when read. ``origin``: the log's t_origin."""
    header = header_of(p)
    missing = [c for c in ("t", "x", "y") if c not in header]
    if missing:
        raise LogFormatError(p, f"missing column(s) {', '.join(missing)} (header is "
                                f"'{shown(','.join(header), 80)}')")

    def load():
        c = read_table(p, ("t", "x", "y"), optional=TRUTH_COLUMNS[2:])
        _check_file_clock(p, c["t"] + origin, span)
        return c["t"], {k: c[k] for k in TRUTH_COLUMNS if k in c}
    return Truth.file(load)


def check_log(log: Log) -> None:
    """The checks ``read_log`` makes beyond each file's own: one clock in
    seconds, and readings a ground robot can give. ``write_log`` makes them
    too, so that nothing odomgraph writes is refused when read back."""
    check_clock(log)
    check_magnitudes(log)


#: Values beyond these are not a sensor's reading but a broken file (a spike
#: of 50 m/s is a fault the estimators handle; 1e308 overflows them).
MAX_SPEED = 1000.0       # wheel, velocity-sensor speed [m/s]
MAX_RATE = 1000.0        # yaw rate [rad/s]
MAX_COORD = 1e8          # positions, ranges, beacons [m]


def check_magnitudes(log: Log) -> None:
    """Refuse readings no ground robot produces, naming file and line."""
    d = log.path or Path(".")
    checks = []
    r = log.robot
    if log.encoders is not None:
        e = log.encoders
        dt = np.diff(e.t)
        tpm = min(r.ticks_per_meter_left, r.ticks_per_meter_right)
        ticks = np.maximum(np.abs(e.ticks_left[1:]), np.abs(e.ticks_right[1:]))
        # dt = 0 only for a row written twice, which reading drops
        speed = np.where(dt > 0, ticks / (tpm * np.where(dt > 0, dt, 1.0)), 0.0)
        checks.append(("encoders.csv", np.concatenate([[0.0], speed]), MAX_SPEED, "a wheel speed of", "m/s"))
    if log.wheel_speeds is not None:
        w = log.wheel_speeds
        checks.append(("wheel_speeds.csv", np.maximum(np.abs(w.v_left), np.abs(w.v_right)), MAX_SPEED,
                       "a wheel speed of", "m/s"))
    if log.gyro is not None:
        checks.append(("gyro.csv", np.abs(log.gyro.omega), MAX_RATE, "a yaw rate of", "rad/s"))
    if log.velocity is not None:
        checks.append(("velocity.csv", np.maximum(np.abs(log.velocity.v), np.abs(log.velocity.omega) / MAX_RATE
                                                  * MAX_SPEED), MAX_SPEED, "a speed of", "m/s (or rad/s)"))
    if log.gps is not None:
        checks.append(("gps.csv", np.maximum(np.abs(log.gps.x), np.abs(log.gps.y)), MAX_COORD, "a coordinate of",
                       "m"))
    if log.ranges is not None:
        checks.append(("ranges.csv", log.ranges.range, MAX_COORD, "a range of", "m"))
    for name, values, limit, what, unit in checks:
        bad = values > limit
        if bad.any():
            k = int(np.argmax(bad))
            line = _line_of_row(d / name, k)
            raise LogFormatError(d / name, f"{what} {float(values[k]):.4g} {unit} is not a reading a ground robot "
                                           f"gives (limit {limit:g})", line)
    for b in r.beacons:
        if max(abs(b.x), abs(b.y)) > MAX_COORD:
            raise LogFormatError(d / "robot.toml", f"beacon {b.id} lies {max(abs(b.x), abs(b.y)):.4g} m away")


def _line_of_row(path: Path, k: int) -> int | None:
    """File line of data row k (0-based), counting as read_table does."""
    if not path.is_file():
        return None
    seen = -1
    for lineno, raw in text_lines(read_text(path)):
        s = raw.strip()
        if not s or s.startswith("#"):
            continue
        if seen >= k:
            return lineno
        seen += 1
    return None


#: A time stamp beyond this many seconds is not seconds (1e10 s after 1970 is the year 2286).
MAX_ABS_TIME = 1e10
#: Longest plausible log [s] (a year).
MAX_DURATION = 3.2e7
#: Longest plausible median wheel-odometry interval [s]: 5 s is 0.2 Hz.
MAX_WHEEL_INTERVAL = 5.0

_FILES = {**{sf.name: sf.file for sf in SENSOR_FILES}, "truth": "truth.csv"}


def _unit_guess(value: float, lo: float, hi: float, interval: float | None = None) -> str:
    """Which unit turns ``value`` into [lo, hi] seconds, and the file's median
    sample ``interval`` (same unit) into a sensor's plausible 0.1 ms to
    MAX_WHEEL_INTERVAL, in words ('' if none). The interval tells apart
    units that both give a plausible length (90 s in microseconds read as
    25 h in milliseconds)."""
    for unit, f in (("milliseconds", 1e3), ("microseconds", 1e6), ("nanoseconds", 1e9)):
        if lo <= value / f <= hi and (interval is None or 1e-4 <= interval / f <= MAX_WHEEL_INTERVAL):
            return f"; it looks like {unit}"
    return ""


def check_clock(log: Log) -> None:
    """Refuse time stamps that cannot be seconds on one shared clock (LOG_FORMAT.md).

    Milliseconds or nanoseconds pass every per-file check (they increase), and
    then give plausible-looking nonsense: a track scale of 0.0015, or an
    allocation of hundreds of GiB. Checks, each naming the likely unit:
    absolute stamps beyond MAX_ABS_TIME, a log longer than MAX_DURATION, a
    median wheel interval beyond MAX_WHEEL_INTERVAL, and a sensor file whose
    times do not overlap the wheels' (a different clock). A truth.csv not
    read yet is checked when it is (``_truth_file``).
    """
    d = log.path or Path(".")
    wheel = "encoders" if log.encoders is not None else "wheel_speeds"
    wt = getattr(log, wheel).t
    if len(wt) > 1:
        med = float(np.median(np.diff(wt)))
        if med > MAX_WHEEL_INTERVAL:
            raise LogFormatError(d / _FILES[wheel], f"median sample interval is {med:.4g} s, implausible for "
                                                   f"wheel odometry{_unit_guess(med, 1e-4, MAX_WHEEL_INTERVAL)} "
                                                   "(LOG_FORMAT.md: t is in seconds)")
    span = _wheel_span(log)
    for key, name in _FILES.items():
        obj = getattr(log, key)
        if obj is None or (isinstance(obj, Truth) and not obj.loaded):
            continue
        _check_file_clock(d / name, obj.t + log.t_origin, span if key != wheel else None)


def _wheel_span(log: Log) -> tuple[float, float] | None:
    """(first, last) wheel stamp as written [s], None without rows."""
    wt = (log.encoders if log.encoders is not None else log.wheel_speeds).t
    return (float(wt[0]) + log.t_origin, float(wt[-1]) + log.t_origin) if len(wt) else None


def _check_file_clock(p: Path, t: np.ndarray, wheel_span: tuple[float, float] | None) -> None:
    """check_clock for one file's stamps ``t`` (as written [s]) against the
    wheels' (first, last) stamps (None: this is the wheels' file)."""
    if len(t) == 0:
        return
    big = np.abs(t) > MAX_ABS_TIME
    if big.any():
        k = int(np.argmax(big))
        v = float(t[k])
        raise LogFormatError(p, f"time stamp {v:.4g} is not seconds{_unit_guess(abs(v), 1e8, 1e10)} "
                                "(LOG_FORMAT.md: t is in seconds)", _line_of_row(p, k))
    s0, s1 = float(t[0]), float(t[-1])
    if s1 - s0 > MAX_DURATION:
        step = float(np.median(np.diff(t))) if len(t) > 1 else None
        raise LogFormatError(p, f"spans {s1 - s0:.4g} s, more than a year: the time stamps are "
                                f"not seconds{_unit_guess(s1 - s0, 1.0, MAX_DURATION, step)}")
    if wheel_span is None:
        return
    w0, w1 = wheel_span
    if s1 < w0 or s0 > w1:
        raise LogFormatError(p, f"its times ({s0:.6g} to {s1:.6g} s) do not overlap the wheel "
                                f"odometry's ({w0:.6g} to {w1:.6g} s): the files of a log share "
                                "one clock", _line_of_row(p, 0))
    if s1 - s0 > 10 * (w1 - w0) + 60:
        raise LogFormatError(p, f"spans {s1 - s0:.4g} s, the wheel odometry only {w1 - w0:.4g} s: "
                                "the files of a log share one clock and unit (seconds)")


def _read_plain(sf: SensorFile, p: Path, read_table):
    """A sensor file whose columns are plain numbers, as its dataclass."""
    c = read_table(p, ("t", *sf.required), optional=sf.columns[len(sf.required):])
    n, why = sf.min_rows
    if len(c["t"]) < n:
        raise LogFormatError(p, f"needs at least {'two' if n == 2 else n} rows{why}")
    if sf.cls is Encoders:
        for k in ("ticks_left", "ticks_right"):
            frac = c[k] != np.round(c[k])
            if frac.any():
                i = int(np.argmax(frac))
                raise LogFormatError(p, f"{k} {float(c[k][i]):g} is not a whole number of ticks (LOG_FORMAT.md: "
                                        "ticks counted; wheel_speeds.csv takes speeds)", int(c["_line"][i]))
    return sf.cls(c["t"], *(c.get(k) for k in sf.columns))


def _read_ranges(p: Path, robot: RobotConfig, read_table=_read_table) -> Ranges:
    """ranges.csv: beacon ids (text) become indices into robot.toml's beacons."""
    c = read_table(p, ("t", "beacon", "range"), text_columns=("beacon",), equal_times=True)
    idx = np.empty(len(c["t"]), dtype=np.int64)
    known = {b.id: i for i, b in enumerate(robot.beacons)}
    for k, (b, ln) in enumerate(zip(c["beacon"], c["_line"])):
        if b not in known:
            raise LogFormatError(p, f"unknown beacon '{shown(b)}' (robot.toml [range].beacons has "
                                    f"{shown(str(sorted(known)), 120) if known else 'none'})", int(ln))
        idx[k] = known[b]
    neg = c["range"] < 0
    if neg.any():
        raise LogFormatError(p, "negative range", int(c["_line"][np.argmax(neg)]))
    return Ranges(c["t"], idx, c["range"])


def _read_gps(p: Path, robot: RobotConfig, read_table=_read_table) -> Gps:
    cols = header_of(p)
    if ("lat" in cols or "lon" in cols) and ("x" in cols or "y" in cols):
        line = next((n for n, raw in text_lines(read_text(p)) if raw.strip() and not raw.strip().startswith("#")), None)
        raise LogFormatError(p, "has both x,y and lat,lon columns: keep the one to use (LOG_FORMAT.md)", line)
    if "lat" in cols or "lon" in cols:
        c = read_table(p, ("t", "lat", "lon"), optional=("sigma",))
        if len(c["t"]) == 0:
            return Gps(c["t"], c["lat"], c["lon"], None)
        bad = (np.abs(c["lat"]) > 90) | (np.abs(c["lon"]) > 180)
        if bad.any():
            raise LogFormatError(p, "latitude/longitude out of range", int(c["_line"][np.argmax(bad)]))
        o = robot.gps_origin or (c["lat"][0], c["lon"][0])
        x, y = latlon_to_local(c["lat"], c["lon"], o[0], o[1])
    else:
        c = read_table(p, ("t", "x", "y"), optional=("sigma",))
        x, y = c["x"], c["y"]
    sigma = c.get("sigma")
    if sigma is not None and (sigma <= 0).any():
        raise LogFormatError(p, "sigma must be positive", int(c["_line"][np.argmax(sigma <= 0)]))
    return Gps(c["t"], x, y, sigma)


#: Sensors read by their own function (p, robot, read_table): GPS in either
#: coordinate form, ranges naming their beacons.
_SPECIAL_READERS = {"gps": _read_gps, "ranges": _read_ranges}


def rebased(log: Log) -> Log:
    """``log`` counting from an integer origin when its stamps are on a real
    clock (see Log.t_origin); unchanged when they are small or already are.
    Subtracting a nearby whole second is exact in float64, so this loses
    nothing; it keeps later differences of large stamps from losing more."""
    if not log.sensors() or abs(log.t_start) < ORIGIN_ABOVE:
        return log
    o = int(np.floor(log.t_start))

    def shift(obj):
        if obj is None:
            return None
        return obj.shifted(-o) if isinstance(obj, Truth) else replace(obj, t=obj.t - o)
    return replace(log, t_origin=log.t_origin + o,
                   **{k: shift(getattr(log, k)) for k in (*_FILES,)})


def write_log(log: Log, directory: Path | str, inputs=()) -> Path:
    """Write ``log`` as a log directory (atomically; ``inputs`` are paths the
    output must not touch, see io.outdir). Returns the path."""
    check_log(log)
    log = rebased(log)
    o = log.t_origin

    def T(t):  # absolute stamps, exact in the whole seconds
        return stamp_text(t, o)
    with atomic_output_dir(directory, inputs, kind="log") as d:
        (d / "robot.toml").write_text(robot_toml(log.robot), encoding="utf-8")
        for sf in SENSOR_FILES:
            obj = getattr(log, sf.name)
            if obj is None:
                continue
            cols, fmts = {"t": T(obj.t)}, {"t": "%.6f"}
            for k, f in zip(sf.columns, sf.formats):
                v = getattr(obj, k)
                if sf.name == "ranges" and k == "beacon":
                    v = np.asarray([log.robot.beacons[i].id for i in v], dtype=str)
                if v is not None:          # an optional column left out (gps' sigma)
                    cols[k] = v
                if f is not None:
                    fmts[k] = f
            write_table(d / sf.file, cols, fmts)
        if log.truth is not None:
            write_table(d / "truth.csv", {"t": T(log.truth.t), **log.truth.values}, {"t": "%.6f"})
        if log.provenance is not None:
            (d / IMPORT_FILE).write_text(json.dumps(log.provenance, indent=2) + "\n", encoding="utf-8")
        if log.truth_scales is not None:
            sl, sr, sb = log.truth_scales
            (d / "truth.toml").write_text(f"scale_left = {float(sl)!r}\nscale_right = {float(sr)!r}\n"
                                          f"scale_track = {float(sb)!r}\n",
                                          encoding="utf-8")
    return Path(directory)
