"""estimators.shares: how far the wheels went and the gyro turned by a time
inside an interval, against closed forms on small synthetic logs."""
from __future__ import annotations

import numpy as np
import pytest

from odomgraph.estimators.shares import Shares
from odomgraph.io.log import Gyro, Log, WheelSpeeds
from odomgraph.io.robot import RobotConfig


def _log(gyro_t, gyro_w, speeds=None):
    t = np.arange(0.0, 10.0 + 1e-9, 0.01)
    v = np.ones_like(t) if speeds is None else speeds(t)
    return Log(robot=RobotConfig(1000.0, 1000.0, 0.5, gyro_sigma=1e-3), wheel_speeds=WheelSpeeds(t, v, v),
               gyro=Gyro(np.asarray(gyro_t, float), np.asarray(gyro_w, float)))


def test_the_turn_is_the_integral_of_the_linear_rate():
    """A rate ramping 0 -> 2 rad/s over [0, 4] s, sampled at 0.4 s: the turn
    by time s is s^2 / 4 exactly (linear between samples), also between
    samples; the share over [0.8, 3.2] (both samples) at 1.9 s is
    (1.9^2 - 0.8^2) / (3.2^2 - 0.8^2). Past the last sample read the rate
    is held: over [1, 3] the end is short by the ramp's 0.5 * 0.2^2 / 2."""
    gt = np.arange(0.0, 4.0 + 1e-9, 0.4)
    sh = Shares(_log(gt, 0.5 * gt))
    ts = np.array([0.13, 1.0, 1.9, 2.5, 3.99])
    np.testing.assert_allclose(sh._turned(ts, np.full(5, 4.0)) - sh._turned(np.zeros(5), np.full(5, 4.0)),
                               ts**2 / 4, rtol=0, atol=1e-12)
    got = sh.gyro_turn(np.array([0.8]), np.array([3.2]), np.array([1.9]), 0.5)
    assert got[0] == pytest.approx((1.9**2 - 0.8**2) / (3.2**2 - 0.8**2), abs=1e-12)
    got = sh.gyro_turn(np.array([1.0]), np.array([3.0]), np.array([1.9]), 0.5)
    assert got[0] == pytest.approx((1.9**2 - 1.0) / 4 / ((9.0 - 1.0) / 4 - 0.01), abs=1e-12)


def test_no_sample_after_the_interval_is_read():
    """The turn inside [t0, t1] is the same whether or not samples after t1
    exist (a stream has not seen them yet), whatever they say."""
    gt = np.arange(0.0, 6.0, 0.04)
    w = np.where(gt < 2.05, 1.0, 0.0)                       # a turn that ends inside [2.0, 2.2]
    later = np.where(gt > 2.2, 50.0, w)                     # what comes after t1 is wild
    t0, t1, ts = np.array([2.0]), np.array([2.2]), np.array([2.1])
    a = Shares(_log(gt, w)).gyro_turn(t0, t1, ts, 0.5)
    b = Shares(_log(gt, later)).gyro_turn(t0, t1, ts, 0.5)
    c = Shares(_log(gt[gt <= 2.2 + 1e-12], w[gt <= 2.2 + 1e-12])).gyro_turn(t0, t1, ts, 0.5)
    assert a[0] == b[0] == pytest.approx(c[0], abs=1e-12)
    assert a[0] > 0.9                                         # the turn was all done by 2.1 s


def test_falls_back_without_a_turn_or_samples():
    gt = np.arange(0.0, 10.0, 0.5)                           # 2 Hz: one sample in a 0.2 s interval
    sh = Shares(_log(gt, np.ones_like(gt)))
    assert sh.gyro_turn(np.array([1.1]), np.array([1.3]), np.array([1.15]), 0.5)[0] == 0.5
    gt = np.arange(0.0, 10.0, 0.01)
    still = Shares(_log(gt, 1e-4 * np.sin(37.0 * gt)))      # a turn within the noise (sigma 1e-3 rad/s)
    assert still.gyro_turn(np.array([1.0]), np.array([1.2]), np.array([1.01]), 0.5)[0] == 0.5
    no_gyro = Shares(_log(gt, gt).with_(gyro=None))
    assert no_gyro.gyro_turn(np.array([1.0]), np.array([1.2]), np.array([1.01]), 0.3)[0] == 0.3


def test_travel_share_of_an_accelerating_robot():
    """v = t m/s: travel from 2 s to 4 s is (t^2 - 4) / 12 of it by t."""
    sh = Shares(_log([0.0, 10.0], [0.0, 0.0], speeds=lambda t: t))
    ts = np.array([2.5, 3.0, 3.7])
    got = sh.travel(np.full(3, 2.0), np.full(3, 4.0), ts)
    np.testing.assert_allclose(got, (ts**2 - 4.0) / 12.0, atol=1e-4)
