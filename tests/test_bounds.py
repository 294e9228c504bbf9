"""analysis.bounds: the track-width oracle is unbiased and its Cramer-Rao sigma matches its scatter."""
import numpy as np
import pytest

from odomgraph.analysis.bounds import track_width_bound
from odomgraph.sim.scenarios import paper
from odomgraph.sim.simulate import simulate


def test_oracle_is_unbiased_and_its_sigma_is_its_scatter():
    sc = paper()
    res = [track_width_bound(simulate(sc, seed)) for seed in range(40)]
    err = np.array([r.error for r in res])
    sig = np.array([r.sigma for r in res])
    # sigma barely changes between seeds (same motion, only the timing jitter
    # differs): measured 0.018 % spread
    assert sig.std() / sig.mean() < 5e-4
    # the scatter of 40 draws is within ~11 % (1 sigma) of it, so allow 3 sigma
    # (measured 0.87, 1.1 sigma low)
    assert abs(err.std() / sig.mean() - 1) < 0.35
    assert abs(err.mean()) < 3 * sig.mean() / np.sqrt(len(err))     # measured 1.2 sigma
    # encoder noise of eq. 41 over ~30 rad of turns: measured 0.1143 % on every seed
    assert 1.05e-3 < sig.mean() < 1.25e-3
    # the slip-free intervals: measured 1971-1975 of 2399 (the slips take ~425)
    assert all(1900 < r.intervals < 2050 for r in res)


def test_sigma_is_proportional_to_the_encoder_noise():
    """Doubling eq. 41's a and b doubles the Cramer-Rao sigma exactly (the weights
    are 1/variance, the sigma their inverse square root): measured 2.0 to rounding."""
    sc = paper(60.0)
    one = track_width_bound(simulate(sc, 0))
    noisy = sc.with_(robot=sc.robot.with_(encoder_sigma=tuple(2 * v for v in sc.robot.encoder_sigma)))
    two = track_width_bound(simulate(noisy, 0))
    assert two.intervals == one.intervals
    assert two.sigma == pytest.approx(2 * one.sigma, rel=1e-12)


def test_calibration_window_holds_less_information_than_the_log():
    log = simulate(paper(), 0)
    whole = track_width_bound(log)
    window = track_width_bound(log, t_end=log.encoders.t[0] + 20.0)
    # measured sigma ratio 1.27 (the window holds both pivots), 399 of 1973 intervals
    assert 1.15 < window.sigma / whole.sigma < 1.45
    assert 390 <= window.intervals <= 400 and window.intervals < whole.intervals / 4


def test_a_log_without_truth_is_refused():
    from dataclasses import replace
    log = replace(simulate(paper(30.0), 0), truth=None)
    with pytest.raises(ValueError, match="truth"):
        track_width_bound(log)
