"""The simulator produces what the contract says: ticks consistent with the
scale factors and slip definition, a lever-armed GPS, unsynchronised rates."""
import numpy as np
import pytest

from odomgraph.factors.encoder import wheel_speeds
from odomgraph.factors.gps import antenna_position
from odomgraph.sim.scenarios import Rates, paper, yard
from odomgraph.sim.simulate import simulate


def test_deterministic_per_seed():
    a, b, c = simulate(paper(30), 5), simulate(paper(30), 5), simulate(paper(30), 6)
    np.testing.assert_array_equal(a.encoders.ticks_left, b.encoders.ticks_left)
    assert not np.array_equal(a.gps.x, c.gps.x)


@pytest.mark.parametrize("make", [paper, yard])
def test_encoder_ticks_follow_the_error_model(make):
    sc = make()
    log = simulate(sc, 1)
    e, r = log.encoders, sc.robot
    dt = np.diff(e.t)
    m = np.stack([e.ticks_left[1:] / (r.ticks_per_meter_left * dt), e.ticks_right[1:] / (r.ticks_per_meter_right * dt)], -1)
    tm = 0.5 * (e.t[1:] + e.t[:-1])
    tr = log.truth
    pred, _ = wheel_speeds(tr.at("v", tm), tr.at("omega", tm), tr.at("slip_left", tm), tr.at("slip_right", tm),
                           *sc.scales, r.track_width)
    res = m - pred
    # Unbiased, and as noisy as eq. 41 plus quantisation (interpolation adds a little at transitions).
    assert np.abs(res.mean(0)).max() < 2e-3
    a, b = r.encoder_sigma
    q = 1 / (np.array([r.ticks_per_meter_left, r.ticks_per_meter_right]) * dt.mean())
    expected = np.sqrt((a + b * np.abs(pred).mean(0)) ** 2 + q**2 / 6)
    np.testing.assert_allclose(res.std(0), expected, rtol=0.25)


def test_gps_has_the_lever_arm():
    sc = paper()
    log = simulate(sc, 2)
    tr, g = log.truth, log.gps
    h, _ = antenna_position(tr.at("x", g.t), tr.at("y", g.t), tr.at("theta", g.t), sc.robot.gps_lever_arm)
    res = np.stack([g.x, g.y], -1) - h
    assert np.abs(res.mean(0)).max() < 0.01
    np.testing.assert_allclose(res.std(0), sc.robot.gps_sigma, rtol=0.1)
    # ...and without the lever arm the residual would be biased by up to 0.45 m.
    h0, _ = antenna_position(tr.at("x", g.t), tr.at("y", g.t), tr.at("theta", g.t), (0.0, 0.0))
    assert np.abs(np.stack([g.x, g.y], -1) - h0).max() > 0.4


def test_sensors_are_asynchronous_at_their_rates():
    log = simulate(paper(), 0)
    r = paper().rates
    for sensor, rate in ((log.encoders, r.encoders), (log.gyro, r.gyro), (log.gps, r.gps)):
        assert np.all(np.diff(sensor.t) > 0)
        assert np.median(np.diff(sensor.t)) == pytest.approx(1 / rate, rel=0.02)
    assert len(np.intersect1d(log.gps.t, log.encoders.t)) == 0


def test_paper_scenario_has_the_papers_features():
    sc = paper()
    log = simulate(sc, 0)
    tr = log.truth
    assert sc.robot.gps_lever_arm == (-0.45, 0.0)
    assert all(abs(s - 1) > 0.01 for s in sc.scales)
    # each wheel slips 0.5 m/s at a different time, after calibration
    for w in ("left", "right"):
        s = tr.values[f"slip_{w}"]
        assert s.max() == pytest.approx(0.5)
        assert tr.t[np.argmax(s > 0.25)] > sc.calibrate_until
    assert tr.t[np.argmax(tr.values["slip_left"] > 0.25)] != tr.t[np.argmax(tr.values["slip_right"] > 0.25)]
    # a pivot (turning with no forward speed) early in the run
    pivot = (np.abs(tr.values["v"]) < 0.05) & (np.abs(tr.values["omega"]) > 0.5)
    assert pivot.any() and tr.t[pivot][0] < 10


def test_optional_sensors_and_beacons():
    """Each optional sensor reads the truth plus noise of its own configured sigma
    (distinct values, so that one sensor drawing with another's sigma shows)."""
    from odomgraph.factors.ranging import beacon_range
    from odomgraph.sim.scenarios import beacons_around
    sc = paper(60).with_(rates=Rates(gps=0, gyro=0, ranges=20, velocity=20))
    sc = sc.with_(robot=sc.robot.with_(beacons=beacons_around(0, 20, -10, 10), range_sigma=0.03,
                                       range_lever_arm=(0.3, -0.2), velocity_sigma=(0.04, 0.015)))
    log = simulate(sc, 0)
    assert log.gps is None and log.gyro is None
    assert set(np.unique(log.ranges.beacon)) == {0, 1, 2}
    assert log.ranges.t.size == pytest.approx(3600, abs=3)        # 3 beacons x 20 Hz x 60 s
    assert log.velocity.t.size == pytest.approx(1200, abs=2)
    # the ranges are the true ranges from the lever-armed antenna plus the configured
    # noise: mean within 4 standard errors, std within 10 % overall and per beacon
    # (1200 each: 2 % is one standard error). Measured std/sigma 1.003; 1.033, 0.988,
    # 0.987 per beacon, means 1.1 (0.9, -0.4, 1.5) standard errors off; without the
    # lever arm the std would be 8.1 sigma.
    r, tr, rb = log.ranges, log.truth, sc.robot
    x, y, th = (tr.at(k, r.t) for k in ("x", "y", "theta"))
    b = np.array([[bc.x, bc.y] for bc in rb.beacons])[r.beacon]
    res = r.range - beacon_range(x, y, th, b, rb.range_lever_arm)[0][:, 0]
    assert abs(res.mean()) < 4 * rb.range_sigma / np.sqrt(res.size)
    assert res.std() == pytest.approx(rb.range_sigma, rel=0.1)
    for i in range(3):
        ri = res[r.beacon == i]
        assert abs(ri.mean()) < 4 * rb.range_sigma / np.sqrt(ri.size), i
        assert ri.std() == pytest.approx(rb.range_sigma, rel=0.1), i
    # the velocity sensor reads the true body velocity plus its noise (measured
    # std/sigma 0.968 on v, 1.012 on omega; means 0.1 and 0.45 standard errors off)
    ev = log.velocity.v - tr.at("v", log.velocity.t)
    ew = log.velocity.omega - tr.at("omega", log.velocity.t)
    sv, sw = rb.velocity_sigma
    assert abs(ev.mean()) < 4 * sv / np.sqrt(ev.size) and ev.std() == pytest.approx(sv, rel=0.1)
    assert abs(ew.mean()) < 4 * sw / np.sqrt(ew.size) and ew.std() == pytest.approx(sw, rel=0.1)


def test_gyro_reads_rate_plus_bias_plus_its_noise():
    """The gyro (optional too) reads the true yaw rate plus the drifting bias of
    truth.csv plus white noise of gyro_sigma: measured std/sigma 0.984, mean 1.3
    standard errors off, over 3000 samples."""
    sc = paper(60).with_(rates=Rates(gps=0, gyro=50))
    sc = sc.with_(robot=sc.robot.with_(gyro_sigma=0.007))
    log = simulate(sc, 0)
    g, tr = log.gyro, log.truth
    assert g.t.size == pytest.approx(3000, abs=2)
    res = g.omega - tr.at("omega", g.t) - tr.at("gyro_bias", g.t)
    sigma = sc.robot.gyro_sigma
    assert abs(res.mean()) < 4 * sigma / np.sqrt(res.size)
    assert res.std() == pytest.approx(sigma, rel=0.1)
    # the bias is there: measured mean 0.016 rad/s (configured 0.015, walking 2e-4/sqrt(s))
    bias = tr.at("gyro_bias", g.t)
    assert bias.mean() == pytest.approx(sc.gyro_bias, abs=0.003)
    assert np.abs(g.omega - tr.at("omega", g.t)).mean() > 0.01      # measured 0.016 rad/s
