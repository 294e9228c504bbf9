"""Robot parameters and sensor noise, loaded once from ``robot.toml``.

Every table of LOG_FORMAT.md's robot.toml maps to a field here. One extra,
optional table ``[process]`` holds the estimators' process noise (the paper's
"system noise"); its defaults suit a ground robot at walking speed.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

from odomgraph.errors import LogFormatError


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
    """

    accel: float = 0.2
    """Forward acceleration noise driving v [m/s^2 /sqrt(Hz), i.e. (m/s)/sqrt(s)]."""
    yaw_accel: float = 0.3
    """Angular acceleration noise driving omega [(rad/s)/sqrt(s)]."""
    slip: float = 0.05
    """Common-mode slip random walk, of (slip_left + slip_right)/2 [(m/s)/sqrt(s)].

    Common-mode slip trades off against v and is seen only through absolute
    sensors, so a large intensity only adds noise."""
    slip_differential: float | None = None
    """Differential slip random walk, of slip_right - slip_left [(m/s)/sqrt(s)].

    None picks by the log: 1.0 when it has a yaw-rate sensor (gyro or velocity
    sensor), which pins differential slip within a few mm/s, so the estimate
    can follow a wheel that starts spinning within a few updates; 0.02 when it
    has none, because then a differential slip looks exactly like a turn and a
    large intensity lets the filter trade heading for slip."""
    gyro_bias: float = 1e-3
    """Gyro bias random walk [(rad/s)/sqrt(s)]."""
    scale: float = 0.0
    """Scale-factor random walk [1/sqrt(s)]; 0: constants, as in the paper."""
    initial_scale_sigma: float = 0.05
    """Prior 1-sigma of each scale factor about 1 [-]."""
    initial_slip_sigma: float = 0.1
    """Prior 1-sigma of each slip [m/s]."""
    initial_bias_sigma: float = 0.05
    """Prior 1-sigma of the gyro bias [rad/s]."""
    pseudo_slip_sigma: float = 1e-3
    """1-sigma of the zero-slip pseudo-measurement (paper eq. 35-36) [m/s]."""
    pseudo_scale_sigma: float = 1e-4
    """1-sigma of the hold-scale pseudo-measurement (paper eq. 37-38) [-]."""


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

    def beacon_index(self, beacon_id: str) -> int | None:
        for i, b in enumerate(self.beacons):
            if b.id == beacon_id:
                return i
        return None

    def with_(self, **changes) -> "RobotConfig":
        return replace(self, **changes)


# ----------------------------------------------------------------- reading
class _Reader:
    """Typed access to a parsed TOML table with errors that name the key."""

    def __init__(self, path: Path, data: dict):
        self.path, self.data = path, data

    def _fail(self, key: str, problem: str):
        raise LogFormatError(self.path, f"[{key}] {problem}")

    def table(self, name: str) -> dict:
        t = self.data.get(name, {})
        if not isinstance(t, dict):
            self._fail(name, "must be a table")
        return t

    def number(self, table: str, key: str, default=None, positive=False, required=False) -> float:
        t = self.table(table)
        if key not in t:
            if required:
                self._fail(f"{table}.{key}" if table else key, "is missing")
            return default
        val = t[key]
        if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val):
            self._fail(f"{table}.{key}", f"must be a finite number, got {val!r}")
        if positive and val <= 0:
            self._fail(f"{table}.{key}", f"must be positive, got {val!r}")
        return float(val)

    def vector(self, table: str, key: str, n: int, default=None, nonneg=False) -> tuple | None:
        t = self.table(table)
        if key not in t:
            return default
        val = t[key]
        if (not isinstance(val, list) or len(val) != n or
                any(isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) for v in val)):
            self._fail(f"{table}.{key}", f"must be a list of {n} finite numbers, got {val!r}")
        if nonneg and any(v < 0 for v in val):
            self._fail(f"{table}.{key}", f"must not be negative, got {val!r}")
        return tuple(float(v) for v in val)


def load_robot(path: Path | str) -> RobotConfig:
    """Parse and validate robot.toml. Raises LogFormatError naming file and key/line."""
    path = Path(path)
    if not path.is_file():
        raise LogFormatError(path, "file is missing (every log needs robot.toml)")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        # tomllib's message already carries "(at line N, column M)".
        raise LogFormatError(path, f"malformed TOML: {exc}") from None
    except UnicodeDecodeError:
        raise LogFormatError(path, "is not UTF-8 text") from None
    r = _Reader(path, data)
    beacons = []
    raw_beacons = r.table("range").get("beacons", [])
    if not isinstance(raw_beacons, list):
        r._fail("range.beacons", "must be a list of { id, x, y } tables")
    for i, b in enumerate(raw_beacons):
        if not isinstance(b, dict) or "id" not in b:
            r._fail(f"range.beacons[{i}]", "must be a table with id, x, y")
        sub = _Reader(path, {"b": b})
        bx = sub.number("b", "x", required=True)
        by = sub.number("b", "y", required=True)
        beacons.append(Beacon(str(b["id"]), bx, by))
    ids = [b.id for b in beacons]
    if len(set(ids)) != len(ids):
        r._fail("range.beacons", f"beacon ids must be unique, got {ids}")

    initial = None
    if "initial" in data:
        initial = InitialPose(
            r.number("initial", "x", required=True),
            r.number("initial", "y", required=True),
            r.number("initial", "theta", required=True),
            r.vector("initial", "sigma", 3, default=(1.0, 1.0, 0.5), nonneg=True),
        )
    pdef = ProcessNoise()
    process = ProcessNoise(**{
        k: r.number("process", k, default=getattr(pdef, k)) for k in pdef.__dataclass_fields__
    })
    origin = r.vector("gps", "origin", 2, default=None)
    if origin is None:
        origin3 = r.vector("gps", "origin", 3, default=None)
        origin = origin3[:2] if origin3 else None
    return RobotConfig(
        ticks_per_meter_left=r.number("wheels", "ticks_per_meter_left", positive=True, required=True),
        ticks_per_meter_right=r.number("wheels", "ticks_per_meter_right", positive=True, required=True),
        track_width=r.number("wheels", "track_width", positive=True, required=True),
        encoder_sigma=r.vector("encoders", "sigma", 2, default=(0.005, 0.01), nonneg=True),
        gps_lever_arm=r.vector("gps", "lever_arm", 2, default=(0.0, 0.0)),
        gps_sigma=r.number("gps", "sigma", default=0.05, positive=True),
        gps_origin=origin,
        gyro_sigma=r.number("gyro", "sigma", default=0.01, positive=True),
        range_sigma=r.number("range", "sigma", default=0.05, positive=True),
        range_lever_arm=r.vector("range", "lever_arm", 2, default=(0.0, 0.0)),
        beacons=tuple(beacons),
        velocity_sigma=r.vector("velocity", "sigma", 2, default=(0.05, 0.02), nonneg=True),
        initial=initial,
        process=process,
    )


# ----------------------------------------------------------------- writing
def _fmt(v) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
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
                **({"origin": cfg.gps_origin} if cfg.gps_origin else {})},
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
