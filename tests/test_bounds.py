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
    # sigma barely changes between seeds (same motion); the scatter of 40 draws
    # is within ~11 % (1 sigma) of it, so allow 3 sigma
    assert sig.std() / sig.mean() < 0.05
    assert abs(err.std() / sig.mean() - 1) < 0.35
    assert abs(err.mean()) < 3 * sig.mean() / np.sqrt(len(err))
    assert 1e-4 < sig.mean() < 3e-3                  # 0.01 % .. 0.3 %: encoder noise of eq. 41 over ~30 rad of turns
    assert all(r.intervals > 1500 for r in res)


def test_calibration_window_holds_less_information_than_the_log():
    log = simulate(paper(), 0)
    whole = track_width_bound(log)
    window = track_width_bound(log, t_end=log.encoders.t[0] + 20.0)
    assert window.sigma > 1.1 * whole.sigma and window.intervals < whole.intervals / 4


def test_a_log_without_truth_is_refused():
    from dataclasses import replace
    log = replace(simulate(paper(30.0), 0), truth=None)
    with pytest.raises(ValueError, match="truth"):
        track_width_bound(log)
