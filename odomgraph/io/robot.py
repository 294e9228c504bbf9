"""Robot parameters and sensor noise, loaded once from ``robot.toml``.

Every table of LOG_FORMAT.md's robot.toml maps to a field here. One extra,
optional table ``[process]`` holds the estimators' process noise (the paper's
"system noise"); its defaults suit a ground robot at walking speed.
"""
from __future__ import annotations

import math
import json
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

from odomgraph.checks import bounded, check_fields, field_ranges, unknown_names, value_problem, value_text
from odomgraph.errors import LogFormatError, OptionError
from odomgraph.io.csvtable import read_text, shown


@dataclass(frozen=True)
class Beacon:
    id: str
    """Beacon name as used in ranges.csv."""
    x: float
    """World-frame x [m]."""
    y: float
    """World-frame y [m]."""


@dataclass(frozen=True)
class InitialPose:
    x: float
    y: float
    theta: float
    """Heading [rad]."""
    sigma: tuple[float, float, float]
    """1-sigma of (x [m], y [m], theta [rad])."""


@dataclass(frozen=True)
class ProcessNoise:
    """Continuous-time random-walk intensities, as 1-sigma growth per sqrt(second).

    A state with intensity q grows its variance by q^2 dt over dt seconds.
    Every intensity and sigma must be positive (a zero one makes the
    covariance singular); only ``scale`` may be 0.
    """

    accel: float = bounded(0.2, ge=1e-9, le=1e3)
    """Forward acceleration noise driving v [m/s^2 /sqrt(Hz), i.e. (m/s)/sqrt(s)]."""
    yaw_accel: float = bounded(0.3, ge=1e-9, le=1e3)
    """Angular acceleration noise driving omega [(rad/s)/sqrt(s)]."""
    slip: float = bounded(0.05, ge=1e-9, le=1e3)
    """Common-mode slip random walk, of (slip_left + slip_right)/2 [(m/s)/sqrt(s)].

    Common-mode slip trades off against v and is seen only through absolute
    sensors, so a large intensity only adds noise."""
    slip_differential: float | None = bounded(None, ge=1e-9, le=1e3, optional=True)
    """Differential slip random walk, of slip_right - slip_left [(m/s)/sqrt(s)].

    None picks by the log: 1.0 when it has a yaw-rate sensor (gyro or velocity
    sensor), which pins differential slip within a few mm/s, so the estimate
    can follow a wheel that starts spinning within a few updates; 0.02 when it
    has none, because then a differential slip looks exactly like a turn and a
    large intensity lets the filter trade heading for slip."""
    gyro_bias: float = bounded(1e-3, ge=1e-9, le=1e3)
    """Gyro bias random walk [(rad/s)/sqrt(s)]."""
    scale: float = bounded(0.0, ge=0, le=1.0)
    """Scale-factor random walk [1/sqrt(s)]; 0: constants, as in the paper."""
    initial_scale_sigma: float = bounded(0.05, ge=1e-6, le=1.0)
    """Prior 1-sigma of each scale factor about 1 [-]."""
    initial_slip_sigma: float = bounded(0.1, ge=1e-6, le=100.0)
    """Prior 1-sigma of each slip [m/s]."""
    initial_bias_sigma: float = bounded(0.05, ge=1e-6, le=100.0)
    """Prior 1-sigma of the gyro bias [rad/s]."""
    pseudo_slip_sigma: float = bounded(1e-3, ge=1e-6, le=1.0)
    """1-sigma of the zero-slip pseudo-measurement (paper eq. 35-36) [m/s]."""
    pseudo_scale_sigma: float = bounded(1e-4, ge=1e-6, le=1.0)
    """1-sigma of the hold-scale pseudo-measurement (paper eq. 37-38) [-]."""

    def __post_init__(self):
        check_fields(self)


@dataclass(frozen=True)
class RobotConfig:
    ticks_per_meter_left: float
    """Nominal (possibly wrong) left ticks per metre."""
    ticks_per_meter_right: float
    track_width: float
    """Nominal track width [m]."""
    encoder_sigma: tuple[float, float] = (0.005, 0.01)
    """Wheel-speed noise a + b|v| [m/s, -] (paper eq. 41)."""
    gps_lever_arm: tuple[float, float] = (0.0, 0.0)
    """Antenna position in the robot frame [m]."""
    gps_sigma: float = 0.05
    """Per-axis GPS 1-sigma [m] where gps.csv has no sigma column (paper eq. 39)."""
    gps_origin: tuple[float, float] | None = None
    """(lat, lon) [deg] of the local east/north origin; None: the first fix."""
    gps_time_offset: float = 0.0
    """How late the GPS stamps are [s]: a fix stamped t was taken at t - offset
    (receiver latency; ``estimate --time-offset`` measures it)."""
    gyro_sigma: float = 0.01
    """Gyro 1-sigma [rad/s] (paper eq. 40)."""
    range_sigma: float = 0.05
    """Range 1-sigma [m]."""
    range_lever_arm: tuple[float, float] = (0.0, 0.0)
    """Ranging antenna position in the robot frame [m]."""
    beacons: tuple[Beacon, ...] = ()
    velocity_sigma: tuple[float, float] = (0.05, 0.02)
    """Velocity-sensor 1-sigma of (v [m/s], omega [rad/s])."""
    initial: InitialPose | None = None
    process: ProcessNoise = field(default_factory=ProcessNoise)

    def __post_init__(self):
        # The same ranges as robot.toml's SCHEMA, for configs built in code
        # (importers, the simulator): a bad one fails here, not deep in an estimator.
        for name in ("ticks_per_meter_left", "ticks_per_meter_right", "track_width", "gps_sigma", "gyro_sigma",
                     "range_sigma"):
            problem = value_problem(getattr(self, name), {"gt": 0})
            if problem:
                raise OptionError(f"RobotConfig.{name} {problem}, got {value_text(getattr(self, name))}")
        if not (self.encoder_sigma[0] > 0 and self.encoder_sigma[1] >= 0):
            raise OptionError(f"RobotConfig.encoder_sigma must be (a > 0, b >= 0), got {self.encoder_sigma}")
        if not all(v > 0 for v in self.velocity_sigma):
            raise OptionError(f"RobotConfig.velocity_sigma must be positive, got {self.velocity_sigma}")
        if self.initial is not None and not all(v > 0 for v in self.initial.sigma):
            raise OptionError(f"RobotConfig.initial.sigma must be positive, got {self.initial.sigma}")

    def beacon_index(self, beacon_id: str) -> int | None:
        for i, b in enumerate(self.beacons):
            if b.id == beacon_id:
                return i
        return None

    def with_(self, **changes) -> "RobotConfig":
        return replace(self, **changes)


# ----------------------------------------------------------------- reading
def _number(gt=None, ge=None, le=None, required=False):
    return {"kind": "number", "range": {"gt": gt, "ge": ge, "le": le}, "required": required}


def _vector(n, gt=None, ge=None, le=None):
    return {"kind": "vector", "n": n, "range": {"gt": gt, "ge": ge, "le": le}}


#: A sensor sigma below this [m, rad, m/s] is not a noise level but a typo (its
#: square underflows the filter's arithmetic); above SIGMA_MAX it is no sensor.
SIGMA_MIN, SIGMA_MAX = 1e-6, 1e6


#: robot.toml, table by table: every key a reader accepts and its range.
#: ``[calibration]`` is the record ``calibrate`` writes; readers ignore it.
SCHEMA: dict[str, dict | None] = {
    "wheels": {"ticks_per_meter_left": _number(ge=1e-3, le=1e9, required=True),
               "ticks_per_meter_right": _number(ge=1e-3, le=1e9, required=True),
               "track_width": _number(ge=1e-3, le=100.0, required=True)},
    "encoders": {"sigma": _vector(2, ge=0, le=SIGMA_MAX)},
    "gps": {"lever_arm": _vector(2, ge=-100.0, le=100.0), "sigma": _number(ge=SIGMA_MIN, le=SIGMA_MAX),
            "origin": _vector((2, 3)), "time_offset": _number(ge=-10.0, le=10.0)},
    "gyro": {"sigma": _number(ge=SIGMA_MIN, le=SIGMA_MAX)},
    "range": {"sigma": _number(ge=SIGMA_MIN, le=SIGMA_MAX), "lever_arm": _vector(2, ge=-100.0, le=100.0),
              "beacons": {"kind": "beacons"}},
    "velocity": {"sigma": _vector(2, ge=SIGMA_MIN, le=SIGMA_MAX)},
    "initial": {"x": _number(ge=-1e8, le=1e8, required=True), "y": _number(ge=-1e8, le=1e8, required=True),
                "theta": _number(ge=-100.0, le=100.0, required=True),
                "sigma": _vector(3, ge=SIGMA_MIN, le=SIGMA_MAX)},
    "process": {name: {"kind": "number", "range": meta, "required": False}
                for name, meta in field_ranges(ProcessNoise).items()},
    "calibration": None,
}


class _Reader:
    """Typed access to a parsed robot.toml, checked against SCHEMA, with errors
    that name the key and, where it can be found, its line."""

    def __init__(self, path: Path, data: dict, text: str):
        self.path, self.data, self.text = path, data, text

    def _line(self, table: str, key: str | None = None) -> int | None:
        """Line of ``key`` inside ``[table]`` (or of the table header), if it can be found."""
        import re
        current = ""
        for lineno, raw in enumerate(self.text.split("\n"), start=1):
            s = raw.strip()
            m = re.match(r"^\[\s*([^\]]+?)\s*\]", s)
            if m and not s.startswith("[["):
                current = m.group(1)
                if key is None and current == table:
                    return lineno
                continue
            if key is not None and current == table and re.match(rf"^[\"']?{re.escape(key)}[\"']?\s*=", s):
                return lineno
        return None

    def fail(self, table: str, key: str | None, problem: str):
        where = f"[{table}.{key}]" if key and table else (f"[{table}]" if table else f"'{key}'")
        raise LogFormatError(self.path, f"{where} {problem}", self._line(table, key))

    def check_keys(self) -> None:
        """Unknown tables and keys are errors (a typo would otherwise be ignored)."""
        for name, body in self.data.items():
            if name not in SCHEMA:
                if not isinstance(body, dict):
                    tables = [t for t, keys in SCHEMA.items() if keys and name in keys]
                    hint = f" (it belongs in [{tables[0]}])" if tables else ""
                    raise LogFormatError(self.path, f"unknown top-level key '{shown(name)}'{hint}",
                                         self._line("", name))
                msg = unknown_names([name], SCHEMA, "table")
                raise LogFormatError(self.path, shown(msg, 200), self._line(name))
            keys = SCHEMA[name]
            if keys is None:
                continue
            if not isinstance(body, dict):
                self.fail(name, None, "must be a table")
            msg = unknown_names(list(body), keys, f"key in [{name}]")
            if msg:
                bad = next(k for k in body if k not in keys)
                raise LogFormatError(self.path, shown(msg, 200), self._line(name, bad))

    def table(self, name: str) -> dict:
        return self.data.get(name, {})

    def get(self, table: str, key: str, default=None):
        spec = SCHEMA[table][key]
        t = self.table(table)
        if key not in t:
            if spec.get("required"):
                self.fail(table, key, "is missing")
            return default
        val = t[key]
        if spec["kind"] == "number":
            problem = value_problem(val, spec["range"])
            if problem:
                self.fail(table, key, f"{problem}, got {shown(repr(val))}")
            return float(val)
        sizes = spec["n"] if isinstance(spec["n"], tuple) else (spec["n"],)
        if (not isinstance(val, list) or len(val) not in sizes or
                any(isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) for v in val)):
            n = " or ".join(map(str, sizes))
            self.fail(table, key, f"must be a list of {n} finite numbers, got {shown(repr(val))}")
        for v in val:
            problem = value_problem(v, spec["range"])
            if problem:
                self.fail(table, key, f"entries {problem}, got {shown(repr(val))}")
        return tuple(float(v) for v in val)

    def beacons(self) -> tuple[Beacon, ...]:
        raw = self.table("range").get("beacons", [])
        if not isinstance(raw, list):
            self.fail("range", "beacons", "must be a list of { id, x, y } tables")
        out = []
        for i, b in enumerate(raw):
            if not isinstance(b, dict) or "id" not in b:
                self.fail("range", "beacons", f"entry {i + 1} must be a table with id, x, y")
            msg = unknown_names(list(b), ("id", "x", "y"), f"key in beacon {i + 1}")
            if msg:
                self.fail("range", "beacons", shown(msg, 200))
            if not isinstance(b["id"], (str, int)) or isinstance(b["id"], bool) or str(b["id"]).strip() == "":
                self.fail("range", "beacons", f"entry {i + 1}: id must be a non-empty string or an integer")
            xy = []
            for c in ("x", "y"):
                if c not in b:
                    self.fail("range", "beacons", f"entry {i + 1} has no {c}")
                problem = value_problem(b[c], {})
                if problem:
                    self.fail("range", "beacons", f"entry {i + 1}: {c} {problem}")
                xy.append(float(b[c]))
            out.append(Beacon(str(b["id"]), *xy))
        ids = [b.id for b in out]
        if len(set(ids)) != len(ids):
            self.fail("range", "beacons", f"beacon ids must be unique, got {ids}")
        return tuple(out)


def load_robot(path: Path | str) -> RobotConfig:
    """Parse and validate robot.toml. Raises LogFormatError naming file, key and line.

    Every key is checked against SCHEMA: unknown tables and keys are errors,
    with the nearest valid name suggested."""
    path = Path(path)
    if not path.is_file() and not path.exists():
        raise LogFormatError(path, "file is missing (every log needs robot.toml)")
    text = read_text(path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        # tomllib's message already carries "(at line N, column M)".
        raise LogFormatError(path, f"malformed TOML: {shown(str(exc), 200)}") from None
    r = _Reader(path, data, text)
    r.check_keys()
    beacons = r.beacons()
    initial = None
    if "initial" in data:
        initial = InitialPose(r.get("initial", "x"), r.get("initial", "y"), r.get("initial", "theta"),
                              r.get("initial", "sigma", default=(1.0, 1.0, 0.5)))
    pdef = ProcessNoise()
    process = ProcessNoise(**{k: r.get("process", k, default=getattr(pdef, k)) for k in pdef.__dataclass_fields__})
    origin = r.get("gps", "origin")
    enc = r.get("encoders", "sigma", default=(0.005, 0.01))
    if enc[0] < SIGMA_MIN:
        r.fail("encoders", "sigma", f"needs a positive constant part a (sigma = a + b|v|, a >= {SIGMA_MIN:g}), "
                                    f"got {list(enc)}")
    return RobotConfig(
        ticks_per_meter_left=r.get("wheels", "ticks_per_meter_left"),
        ticks_per_meter_right=r.get("wheels", "ticks_per_meter_right"),
        track_width=r.get("wheels", "track_width"),
        encoder_sigma=enc,
        gps_lever_arm=r.get("gps", "lever_arm", default=(0.0, 0.0)),
        gps_sigma=r.get("gps", "sigma", default=0.05),
        gps_origin=origin[:2] if origin else None,
        gps_time_offset=r.get("gps", "time_offset", default=0.0),
        gyro_sigma=r.get("gyro", "sigma", default=0.01),
        range_sigma=r.get("range", "sigma", default=0.05),
        range_lever_arm=r.get("range", "lever_arm", default=(0.0, 0.0)),
        beacons=beacons,
        velocity_sigma=r.get("velocity", "sigma", default=(0.05, 0.02)),
        initial=initial,
        process=process,
    )


# ----------------------------------------------------------------- writing
def _fmt(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        # A JSON string is a valid TOML basic string: quotes, backslashes,
        # newlines and control characters come out escaped.
        return json.dumps(v, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(v, (tuple, list)):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_fmt(x)}" for k, x in v.items()) + " }"
    return repr(float(v))


def dump_toml(tables: dict[str, dict]) -> str:
    """Write nested {table: {key: value}} as TOML (numbers, strings, lists, inline tables)."""
    out = []
    for name, body in tables.items():
        if not body:
            continue
        out.append(f"[{name}]")
        out.extend(f"{k} = {_fmt(v)}" for k, v in body.items())
        out.append("")
    return "\n".join(out)


def robot_toml(cfg: RobotConfig, extra: dict[str, dict] | None = None) -> str:
    """robot.toml text for ``cfg``; ``load_robot`` reads it back to an equal config.

    ``extra`` tables (e.g. a [calibration] record) are appended; readers ignore them.
    """
    tables = {
        "wheels": {"ticks_per_meter_left": cfg.ticks_per_meter_left,
                   "ticks_per_meter_right": cfg.ticks_per_meter_right,
                   "track_width": cfg.track_width},
        "encoders": {"sigma": cfg.encoder_sigma},
        "gps": {"lever_arm": cfg.gps_lever_arm, "sigma": cfg.gps_sigma,
                **({"origin": cfg.gps_origin} if cfg.gps_origin else {}),
                **({"time_offset": cfg.gps_time_offset} if cfg.gps_time_offset else {})},
        "gyro": {"sigma": cfg.gyro_sigma},
        "range": {"sigma": cfg.range_sigma, "lever_arm": cfg.range_lever_arm,
                  **({"beacons": [{"id": b.id, "x": b.x, "y": b.y} for b in cfg.beacons]} if cfg.beacons else {})},
        "velocity": {"sigma": cfg.velocity_sigma},
    }
    if cfg.initial is not None:
        i = cfg.initial
        tables["initial"] = {"x": i.x, "y": i.y, "theta": i.theta, "sigma": i.sigma}
    if cfg.process != ProcessNoise():
        tables["process"] = {k: getattr(cfg.process, k) for k in cfg.process.__dataclass_fields__
                             if getattr(cfg.process, k) is not None}
    tables.update(extra or {})
    return dump_toml(tables)
