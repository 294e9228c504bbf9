"""The gyro's scale factor, profiled by calibrate (analysis.gyroscale).

A probe's gyro reading 2 % high put the track width 1.2-1.4 % off at a
sigma of 0.2 % (batch -5.9 sigma, calibrate -4.2 sigma), status ok: the
model has no gyro scale. calibrate now finds the scale from the fixes,
fits on the rescaled gyro, and widens the sigmas by what the scale's own
uncertainty does to them. Seeds, scenarios and scale errors here are not
the ones the profile was written on (yard 7/9, paper 8/10; 0.97-1.02).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from odomgraph.analysis import gyroscale as G
from odomgraph.pipeline import calibrate
from odomgraph.sim.scenarios import paper, yard
from odomgraph.sim.simulate import simulate


def test_the_profile_is_the_parabola_through_the_costs():
    g = np.array([0.99, 1.0, 1.01, 1.013])
    g_hat, sigma = 1.004, 0.002
    cost = 100.0 + (g - g_hat) ** 2 / (2 * sigma**2)
    out = G.fit_profile(g, cost)
    assert out is not None
    assert out[0] == pytest.approx(g_hat, abs=1e-9) and out[1] == pytest.approx(sigma, rel=1e-6)
    assert G.fit_profile(g, 100.0 - (g - 1.0) ** 2) is None                  # opens downwards
    assert G.fit_profile(g, 100.0 + (g - 1.0) ** 2 / (2 * 0.05**2)) is None  # wider than the prior


def _gyro_times(log, g):
    return log.with_(gyro=replace(log.gyro, omega=log.gyro.omega * g))


@pytest.mark.parametrize("name,seed,g", [("paper", 44, 1.025), pytest.param("yard", 45, 0.985, marks=pytest.mark.slow), ("paper", 46, 1.0)])
def test_calibrate_finds_the_gyro_scale_and_the_true_track(name, seed, g):
    sc = paper(90.0) if name == "paper" else yard(120.0)
    log = _gyro_times(simulate(sc, seed), g)
    new, rep = calibrate(log, tune=False)
    gs = rep["gyro_scale"]
    assert gs["determined"] and abs(gs["value"] - g) < 3 * gs["sigma"], gs
    assert gs["sigma"] < 0.005
    assert gs["corrected"] == (g != 1.0), gs
    true = log.robot.track_width * log.truth_scales[2]
    tw = rep["track_width"]
    assert abs(tw["value"] - true) < 3 * tw["sigma"], (tw, true)
    assert not rep["problems"], rep["problems"]
    if g != 1.0:
        assert any("the gyro reads" in w for w in rep["warnings"]), rep["warnings"]


def test_without_fixes_the_track_carries_the_gyro_scale_prior():
    """No GPS: only the gyro says how far the robot turned, so the track
    width is as uncertain as the gyro's scale (PRIOR), whatever the fit."""
    log = simulate(paper(90.0), 47)
    log = log.with_(gps=None, robot=log.robot.with_(initial=log.robot.initial))
    new, rep = calibrate(log, tune=False)
    gs = rep["gyro_scale"]
    assert not gs["determined"] and gs["sigma"] == G.PRIOR
    # d track / d g is about 1 when the gyro alone turns the robot
    assert rep["track_width"]["sigma"] > 0.5 * G.PRIOR * log.robot.track_width, rep["track_width"]
