"""The sensor configurations of the paper's Monte-Carlo study (sec. VI).

1. GPS with a 0.45 m lever arm, plus a gyro (table II, fig. 8);
2. GPS plus a body-velocity sensor (visual odometry) at 5 Hz (table III, fig. 9);
3. three range beacons at 20 Hz each plus a gyro, no GPS (table IV, fig. 10).

Each configuration sweeps two sensor noise levels (the two axes). The paper's
tables are garbled in our copy; the ranges below follow its text: GPS from
0.05 m to 1.5 m ("as GPS standard deviation degrades from 0.05 m to 1.5 m"),
ranges from 1 cm to 2 m ("between 1 cm and 2 m"), and rate sensors up to
0.25 rad/s (gyro; the track width "degrades once gyroscope standard deviation
increases above approximately 0.05 rad/s") or 0.5 m/s and rad/s (velocity
sensor; errors stay low "as long as velocity standard deviation is less than
0.2"). The noise values of a grid are spread uniformly over these ranges, as
the paper's are.

The run is the paper's sec. IV simulation shortened to the study's length:
pivots and straight runs during a 20 s calibration window, then each wheel
slipping 0.5 m/s in turn. The start pose is known (robot.toml [initial]), as
in the paper's simulations, so every run of a grid point starts together.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from odomgraph.sim.scenarios import Rates, Scenario, SlipEvent, paper


@dataclass(frozen=True)
class Axis:
    name: str
    """Robot parameter the axis sets (a RobotConfig field)."""
    label: str
    lo: float
    hi: float

    def values(self, n: int) -> np.ndarray:
        return np.linspace(self.lo, self.hi, n)


@dataclass(frozen=True)
class SensorConfig:
    number: int
    title: str
    x: Axis
    """First swept noise (the position sensor)."""
    y: Axis
    """Second swept noise (the rate sensor)."""
    rates: Rates


_GPS = Axis("gps_sigma", "GPS σ [m]", 0.05, 1.5)
_GYRO = Axis("gyro_sigma", "gyro σ [rad/s]", 0.005, 0.25)

CONFIGS = {
    1: SensorConfig(1, "GPS (0.45 m lever arm) + gyro", _GPS, _GYRO,
                    Rates(encoders=20.0, gyro=25.0, gps=10.0)),
    2: SensorConfig(2, "GPS + body-velocity sensor at 5 Hz", _GPS,
                    Axis("velocity_sigma", "velocity σ [m/s, rad/s]", 0.01, 0.5),
                    Rates(encoders=20.0, gyro=0.0, gps=10.0, velocity=5.0)),
    3: SensorConfig(3, "3 range beacons at 20 Hz + gyro, no GPS",
                    Axis("range_sigma", "range σ [m]", 0.01, 2.0), _GYRO,
                    Rates(encoders=20.0, gyro=25.0, gps=0.0, ranges=20.0)),
}


def study_scenario(config: int, x_sigma: float, y_sigma: float, duration: float = 60.0) -> Scenario:
    """The Monte-Carlo run of ``config`` at one grid point (noise x_sigma, y_sigma)."""
    cfg = CONFIGS[config]
    base = paper(duration)
    # Both slips inside the run: after the 20 s window, one wheel at a time.
    t_slip = [20.0 + 0.2 * (duration - 20.0), 20.0 + 0.55 * (duration - 20.0)]
    width = 0.15 * (duration - 20.0)
    slips = (SlipEvent("left", t_slip[0], t_slip[0] + width, 0.5),
             SlipEvent("right", t_slip[1], t_slip[1] + width, 0.5))
    robot = base.robot
    values = {cfg.x.name: x_sigma, cfg.y.name: y_sigma}
    if "velocity_sigma" in values:
        values["velocity_sigma"] = (values["velocity_sigma"],) * 2
    robot = robot.with_(**values)
    if cfg.rates.ranges > 0:
        from odomgraph.sim.simulate import beacons_around_path
        robot = robot.with_(beacons=beacons_around_path(base))
    return base.with_(robot=robot, slips=slips, rates=cfg.rates, write_initial=True)
