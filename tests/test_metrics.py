"""metrics.truth_errors against hand-computed cases: every accuracy bound in
the suite relies on it (issue 18)."""
import numpy as np
import pytest

from odomgraph import state as S
from odomgraph.analysis.metrics import truth_errors
from odomgraph.result import Estimate
from odomgraph.io.log import Log, Truth
from odomgraph.io.robot import RobotConfig

ROBOT = RobotConfig(ticks_per_meter_left=1000.0, ticks_per_meter_right=1000.0, track_width=0.5)


def _case():
    """Truth at 0..4 s; an estimate at 0.5..5.5 s whose last row lies outside it."""
    tt = np.arange(5.0)
    truth = Truth(tt, {"x": tt.copy(), "y": np.zeros(5), "theta": np.full(5, np.pi - 0.01),
                       "slip_left": np.zeros(5), "slip_right": np.full(5, 0.1)})
    t = np.array([0.5, 1.5, 2.5, 3.5, 5.5])
    mean = np.tile(S.NOMINAL, (5, 1))
    mean[:, S.X] = t + np.array([0.25, -0.4, 0.0, 0.0, 99.0])    # errors 0.25, -0.4, 0, 0 (and one outside)
    mean[:, S.Y] = np.array([0.2, 0.1, 0.0, 0.0, 99.0])
    mean[:, S.THETA] = -np.pi + 0.01                              # 0.02 rad past +-pi, not 2 pi - 0.02
    mean[:, S.SLIP_R] = np.array([0.1, 0.1, 0.3, 0.1, 0.0])      # error 0.2 at 2.5 s only
    mean[:, S.SCALE_L] = 1.02
    sigma = np.full((5, S.N), 0.1)
    est = Estimate("test", t, mean, sigma, t_switch=2.0)
    log = Log(robot=ROBOT, truth=truth, truth_scales=(1.0, 1.0, 1.05))
    return est, log


def test_position_rms_heading_wrap_and_truth_span():
    e = truth_errors(*_case())
    # rows at 0.5-3.5 s (5.5 s lies outside the truth): squared position
    # errors 0.25^2 + 0.2^2, 0.4^2 + 0.1^2, 0, 0
    assert e.rms_position_m == pytest.approx(np.sqrt((0.1025 + 0.17) / 4), abs=1e-12)
    # |x error| <= 3 sigma = 0.3 on 3 of 4 rows; y on all four; heading 0.02 rad across +-pi on all
    assert e.coverage_3sigma["x"] == pytest.approx(0.75)
    assert e.coverage_3sigma["y"] == pytest.approx(1.0)
    assert e.coverage_3sigma["theta"] == pytest.approx(1.0)


def test_slip_is_scored_after_the_switch_and_scales_against_truth():
    est, log = _case()
    e = truth_errors(est, log)
    # after t_switch = 2 s: rows 2.5 (error 0.2) and 3.5 (0) -> sqrt(0.04 / 2)
    assert e.rms_slip_mps["right"] == pytest.approx(np.sqrt(0.04 / 2), abs=1e-12)
    assert e.rms_slip_mps["left"] == pytest.approx(0.0, abs=1e-12)
    # scale_left 1.02 against 1.0 is inside 3 x 0.1; the track 1.0 against 1.05 too
    assert e.coverage_3sigma["scale_left"] == 1.0 and e.coverage_3sigma["scale_track"] == 1.0
    est.sigma[:, S.SCALE_B] = 0.01
    assert truth_errors(est, log).coverage_3sigma["scale_track"] == 0.0
    assert truth_errors(est, Log(robot=ROBOT)) is None
