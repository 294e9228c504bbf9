"""Scenarios: robot, true errors, motion, sensors and their rates.

``paper`` reproduces Kreinar & Quinn sec. IV: a GPS lever arm of -0.45 m,
scale factors away from 1, a pivot early in the run (the paper's fig. 3 shows
the track-width sigma collapsing at the pivot near t = 10 s), and each wheel
slipping 0.5 m/s at a different time after the 20 s calibration window.

``yard`` is a second, independent scenario with other geometry, rates, lever
arm, error values and slip patterns (including both wheels spinning while the
robot stands still, the snowplow stuck in a drift, and a negative slip).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

from odomgraph.io.robot import Beacon, RobotConfig


@dataclass(frozen=True)
class Segment:
    """Commanded body velocity held for ``duration`` seconds."""
    duration: float
    v: float
    """Forward speed [m/s]."""
    omega: float
    """Yaw rate [rad/s]."""


@dataclass(frozen=True)
class SlipEvent:
    """A wheel spins faster than the ground passes (positive) or drags (negative)."""
    wheel: str
    """'left' or 'right'."""
    start: float
    """Start of the plateau [s]."""
    end: float
    """End of the plateau [s]."""
    speed: float
    """Slip at the plateau [m/s]."""
    ramp: float = 0.3
    """Rise and fall time [s]; real slip builds up over a fraction of a second."""

    def __post_init__(self):
        import math
        from odomgraph.errors import OptionError
        if self.wheel not in ("left", "right"):
            raise OptionError(f"slip event: wheel must be 'left' or 'right', got {self.wheel!r}")
        if not all(math.isfinite(v) for v in (self.start, self.end, self.speed, self.ramp)):
            raise OptionError("slip event: start, end, speed and ramp must be finite numbers")
        if self.end < self.start or self.start < 0 or self.ramp < 0:
            raise OptionError(f"slip event: needs 0 <= start <= end and ramp >= 0, got start {self.start:g} s, "
                              f"end {self.end:g} s, ramp {self.ramp:g} s")
        if abs(self.speed) > 20:
            raise OptionError(f"slip event: |speed| must be at most 20 m/s, got {self.speed:g}")


@dataclass(frozen=True)
class Rates:
    """Sensor rates [Hz]; 0 leaves the sensor out of the log."""
    encoders: float = 20.0
    gyro: float = 25.0
    gps: float = 10.0
    ranges: float = 0.0
    """Per beacon; beacons are polled round-robin, so the file rate is this x #beacons."""
    velocity: float = 0.0
    truth: float = 20.0
    jitter: float = 0.1
    """Timestamp jitter as a fraction of each sensor's period (uniform +-)."""


@dataclass(frozen=True)
class Scenario:
    name: str
    robot: RobotConfig
    """Nominal robot as written to robot.toml; its sigmas are also the true noise."""
    scales: tuple[float, float, float]
    """True (scale_left, scale_right, scale_track)."""
    prologue: tuple[Segment, ...]
    """Motion at the start (the calibration manoeuvres)."""
    loop: tuple[Segment, ...]
    """Motion repeated after the prologue until ``duration``."""
    duration: float
    slips: tuple[SlipEvent, ...] = ()
    gyro_bias: float = 0.0
    """Initial gyro bias [rad/s]."""
    gyro_bias_walk: float = 0.0
    """Gyro bias random walk [(rad/s)/sqrt(s)]."""
    rates: Rates = field(default_factory=Rates)
    start_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
    smoothing: float = 0.6
    """Commanded velocities are smoothed by a moving average of this width [s] (finite acceleration)."""
    calibrate_until: float = 20.0
    """The schedule this scenario was designed for [s]."""
    write_initial: bool = False
    """Write the true start pose as robot.toml [initial] (else estimators initialise from data)."""
    holds: tuple[tuple[float, float], ...] = ()
    """(start, end) windows [s] in which the robot is held still whatever the
    commands say (a stall: with slip events, the wheels spin in place)."""

    def with_(self, **changes) -> "Scenario":
        return replace(self, **changes)


def _snake(n: int, v: float, straight: float, turn_rate: float) -> tuple[Segment, ...]:
    """A lawnmower pattern: straight rows joined by alternating 180-degree turns."""
    out = []
    for k in range(n):
        sign = 1.0 if k % 2 == 0 else -1.0
        out += [Segment(straight, v, 0.0), Segment(3.14159 / turn_rate, 0.6 * v, sign * turn_rate)]
    return tuple(out)


def paper(duration: float = 120.0) -> Scenario:
    """Kreinar & Quinn sec. IV (see module doc)."""
    robot = RobotConfig(
        ticks_per_meter_left=2000.0, ticks_per_meter_right=2000.0, track_width=0.60,
        encoder_sigma=(0.005, 0.01),   # eq. 41
        gps_lever_arm=(-0.45, 0.0), gps_sigma=0.05,  # eq. 39
        gyro_sigma=0.01,               # eq. 40
    )
    # The calibration window: straight runs for ticks/m, and early pivots both
    # ways for the track width (a gyro-bias error cancels between them).
    prologue = (
        Segment(1.0, 0.0, 0.0),        # stand still: gyro bias is visible
        Segment(4.0, 1.5, 0.0),
        Segment(3.5, 0.0, 1.2),        # the early pivot: track width and lever arm
        Segment(4.0, 1.5, 0.0),
        Segment(3.5, 0.0, -1.2),       # and back
        Segment(4.0, 1.5, 0.0),
    )
    return Scenario(
        name="paper", robot=robot, scales=(1.03, 0.98, 1.04),
        prologue=prologue, loop=_snake(2, 1.0, 8.0, 0.5), duration=duration,
        slips=(SlipEvent("left", 35.0, 45.0, 0.5), SlipEvent("right", 62.0, 72.0, 0.5)),
        gyro_bias=0.015, gyro_bias_walk=2e-4,
        # The paper's robot carries a Novatel RTK receiver, which runs at 20 Hz.
        rates=Rates(encoders=20.0, gyro=25.0, gps=20.0),
        calibrate_until=20.0,
    )


def yard(duration: float = 150.0) -> Scenario:
    """A small yard robot: other geometry, rates, lever arm and slip patterns."""
    robot = RobotConfig(
        ticks_per_meter_left=1500.0, ticks_per_meter_right=1520.0, track_width=0.42,
        encoder_sigma=(0.004, 0.008),
        gps_lever_arm=(0.25, 0.12), gps_sigma=0.02,
        gyro_sigma=0.005,
    )
    prologue = (
        Segment(1.5, 0.0, 0.0),
        Segment(5.0, 0.6, 0.0),
        Segment(6.0, 0.0, -1.1),       # pivot the other way
        Segment(4.0, 0.7, 0.25),
        Segment(6.0, -0.4, 0.0),       # reverse
        Segment(8.0, 0.7, -0.2),
    )
    loop = (Segment(10.0, 0.7, 0.0), Segment(4.0, 0.0, 0.0), Segment(5.0, 0.5, 0.6), Segment(10.0, 0.7, 0.05),
            Segment(5.0, 0.5, -0.6))
    return Scenario(
        name="yard", robot=robot, scales=(0.965, 1.02, 0.955),
        prologue=prologue, loop=loop, duration=duration,
        slips=(SlipEvent("right", 50.0, 58.0, 0.3),
               SlipEvent("left", 75.0, 79.0, 0.4), SlipEvent("right", 75.0, 79.0, 0.4),  # stuck: both spin
               SlipEvent("left", 118.0, 126.0, -0.2)),
        gyro_bias=-0.02, gyro_bias_walk=1e-4,
        rates=Rates(encoders=50.0, gyro=100.0, gps=10.0, truth=25.0),
        start_pose=(12.0, -4.0, 2.2),
        calibrate_until=30.0,
    )


def beacons_around(xmin: float, xmax: float, ymin: float, ymax: float, n: int = 3) -> tuple[Beacon, ...]:
    """n beacons spread around a box (for range scenarios)."""
    import math
    cx, cy = (xmin + xmax) / 2, (ymin + ymax) / 2
    r = 0.75 * max(xmax - xmin, ymax - ymin)
    return tuple(Beacon(chr(ord("A") + k), cx + r * math.cos(2 * math.pi * k / n + 0.3),
                        cy + r * math.sin(2 * math.pi * k / n + 0.3)) for k in range(n))


SCENARIOS = {"paper": paper, "yard": yard}
