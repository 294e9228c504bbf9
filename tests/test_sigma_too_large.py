"""A GPS sigma configured too large is said.

The noise model widens a sigma the data say is too small; one too large was
never said (a probe: 10x too large, and calibrate's process-noise tuning made
up for it at its grid's edge, x40, unflagged). Its estimate's sigmas are then
pessimistic and the fixes count for less than they should: not a confident
wrong answer, but a wrong robot.toml that nothing named. Logs here: the yard
scenario at other seeds and factors than the probe's.
"""
from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest

from odomgraph.pipeline import Method, Schedule, calibrate, estimate
from odomgraph.sim.scenarios import yard
from odomgraph.sim.simulate import simulate


@pytest.fixture(scope="module")
def log():
    return simulate(yard(90.0), 51)


def too_large(warnings):
    return [w for w in warnings if "too large, so this estimate's sigmas are pessimistic" in w]


@pytest.mark.parametrize("method", [Method.ekf, Method.batch, Method.isam2])
def test_said_with_the_factor_and_not_for_a_right_sigma(log, method):
    assert too_large(estimate(log, method, Schedule(20.0)).warnings) == []
    wide = log.with_(robot=log.robot.with_(gps_sigma=5.0 * log.robot.gps_sigma))
    est = estimate(wide, method, Schedule(20.0))
    (line,) = too_large(est.warnings)
    looks = float(re.search(r"looks (\S+)x too large", line).group(1))
    assert 3.5 < looks < 6.0, line          # measured 3.9 (EKF, persistence credited) and 4.8
    assert "robot.toml's sigma (0.1 m)" in line
    # a filter's innovations carry its prediction's spread: both are named
    assert ("or the process noise" in line) == (method is Method.ekf)
    # said, not acted on: the sigma in force is the configured one
    assert est.noise_scales["gps"]["applied"] == 1.0


def test_the_fixes_own_sigmas_are_named(log):
    g = log.gps
    own = log.with_(gps=replace(g, sigma=np.full(len(g.t), 3.0 * log.robot.gps_sigma)))
    (line,) = too_large(estimate(own, Method.batch, Schedule(20.0)).warnings)
    assert "the fixes' own sigmas (median 0.06 m)" in line and "set the sigma in gps.csv" in line


@pytest.mark.parametrize("method", [Method.ekf, Method.batch])
def test_not_said_for_errors_that_persist(log, method):
    """GPS errors that persist from fix to fix (AR(1), rho 0.99 at 10 Hz) at a
    right sigma: the estimate follows them and their scatter about it is
    small, but its sigmas are not pessimistic (a second read: 1-69 % inside
    3 sigma while the line said 3.6-11x too large)."""
    g = log.gps
    rng = np.random.default_rng(7)
    rho, sd = 0.99, log.robot.gps_sigma
    e = np.zeros((len(g.t), 2))
    e[0] = rng.normal(0.0, sd, 2)
    for i in range(1, len(g.t)):
        e[i] = rho * e[i - 1] + rng.normal(0.0, sd * np.sqrt(1 - rho**2), 2)
    tr = log.truth
    x, y = (np.interp(g.t, tr.t, tr.values[c]) for c in ("x", "y"))
    th = np.interp(g.t, tr.t, np.unwrap(tr.values["theta"]))
    lx, ly = log.robot.gps_lever_arm
    ax, ay = x + lx * np.cos(th) - ly * np.sin(th), y + lx * np.sin(th) + ly * np.cos(th)
    slow = log.with_(gps=replace(g, x=ax + e[:, 0], y=ay + e[:, 1]))
    est = estimate(slow, method, Schedule(20.0))
    assert too_large(est.warnings) == []


def test_calibrate_says_the_grid_edge(log):
    """EKF, sigma 10x too large: held-out fixes chose x40, the grid's top."""
    wide = log.with_(robot=log.robot.with_(gps_sigma=10.0 * log.robot.gps_sigma))
    _, rep = calibrate(wide, Schedule(20.0), Method.ekf, tune=True)
    assert rep["process_noise"]["chosen_factor"] == 40.0
    assert sum(w.startswith("process noise chosen at the top of the range tried (x40") for w in rep["warnings"]) == 1
    assert len(too_large(rep["warnings"])) == 1
