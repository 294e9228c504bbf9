"""Weak fixes and slip events: the smoothers' sparse slip prior, checked
(estimators.priorcheck).

The yard scenario with consumer GNSS (0.5-1 m at 1-2 Hz), and the paper's
with 1-3 m fixes at 1-2 Hz, each with its own slip events. Unchecked, the
smoothers' sparse prior on the joint slip norm shrinks a one-wheel slip's
common mode and the weak fixes do not pull it back: batch's rows were 49 %
and 56 % outside 3 sigma (position z 17 and 5, status ok; 24th session),
isam2's and fixed-lag's 26-56 %. The EKF, whose slip is a free random walk,
held its sigma. Checked, batch gives the prior-free solution where the two
part far (the yard), and the joint mean with a covariance that holds both
elsewhere (the paper robot); isam2 and fixed-lag, whose rows were given
live, are flagged where batch switches."""
from dataclasses import replace

import numpy as np
import pytest

from odomgraph import state as S
from odomgraph.estimators.batch import run_batch
from odomgraph.estimators.schedule import Schedule
from odomgraph.pipeline import estimate
from odomgraph.result import status_of
from odomgraph.sim.faults import Faults, inject
from odomgraph.sim.scenarios import paper, yard

#: (scenario, GPS sigma [m], GPS rate [Hz], seed, batch gives the prior-free
#: solution): measured distances between the two solutions 6.1 (yard), 2.6
#: and 2.5 (paper: the joint mean kept, its sigma widened).
LOGS = [pytest.param(yard, 0.5, 2.0, 12, True, id="yard-0.5m-2Hz"),
        pytest.param(paper, 3.0, 1.0, 12, False, id="paper-3m-1Hz"),
        pytest.param(paper, 1.0, 2.0, 18, False, id="paper-1m-2Hz")]
PRIOR_FREE = "the prior-free solution is given"


def _log(make, gps_sigma, gps_hz, seed):
    sc = make(180.0)
    sc = sc.with_(robot=sc.robot.with_(gps_sigma=gps_sigma), rates=replace(sc.rates, gps=gps_hz))
    # (a one-wheel slip among its events: the case the joint-norm prior reads as a balanced pair)
    assert any(s.speed > 0 and not any(o.start == s.start and o.wheel != s.wheel for o in sc.slips)
               for s in sc.slips)
    return inject(sc, Faults(), seed)


def _outside(est, log) -> float:
    """Share of rows with x, y or heading more than 3 sigma off the truth."""
    z = []
    for k in (S.X, S.Y, S.THETA):
        e = est.mean[:, k] - log.truth.at(S.NAMES[k], est.t)
        if k == S.THETA:
            e = np.angle(np.exp(1j * e))
        z.append(np.abs(e) / est.sigma[:, k])
    return float(np.mean(np.max(z, axis=0) > 3.0))


@pytest.mark.parametrize("make,gps_sigma,gps_hz,seed,free", LOGS[:2])
def test_the_ekf_holds_its_sigma_through_the_slip_events(make, gps_sigma, gps_hz, seed, free):
    log = _log(make, gps_sigma, gps_hz, seed)
    assert _outside(estimate(log, "ekf", Schedule(20.0)), log) < 0.01


@pytest.mark.parametrize("make,gps_sigma,gps_hz,seed,free", LOGS)
def test_batch_holds_its_sigma_through_the_slip_events(make, gps_sigma, gps_hz, seed, free):
    log = _log(make, gps_sigma, gps_hz, seed)
    est = estimate(log, "batch", Schedule(20.0))
    # measured: 1.8 % (yard), 0 % and 0 % outside 3 sigma
    assert _outside(est, log) < 0.03
    assert any(PRIOR_FREE in w for w in est.warnings) == free, est.warnings
    assert status_of(est)[0] == "ok"           # a model replaced is said, and the answer is right: not degraded
    assert any("slip prior checked" in n for n in est.notes), est.notes


def test_the_check_is_what_mends_batch():
    """The same yard log through the same pipeline with the prior
    unchecked: batch is overconfident (so the check, not some other change,
    holds the sigma above); and run_batch alone leaves the check's outcome
    for priorcheck.applied, which gives the pipeline's rows."""
    from odomgraph.estimators.priorcheck import applied
    log = _log(yard, 0.5, 2.0, 12)
    est = estimate(log, "batch", Schedule(20.0), slip_check=False)
    assert _outside(est, log) > 0.3            # measured 60 %
    raw = run_batch(log, Schedule(20.0))
    assert raw.slip_check is not None and raw.slip_check.prior_free
    assert _outside(raw, log) > 0.3            # unchecked rows until applied...
    assert _outside(applied(raw), log) < 0.03  # ...and within sigma after


@pytest.mark.parametrize("method", ["isam2", "fixed-lag"])
def test_the_incremental_smoothers_are_flagged(method):
    """isam2 and fixed-lag keep the prior's rows (given as they came, live)
    and are flagged where batch gives the prior-free solution (measured:
    48 % and 42 % of rows outside 3 sigma, status ok before the check)."""
    log = _log(yard, 0.5, 2.0, 11)
    est = estimate(log, method, Schedule(20.0))
    assert _outside(est, log) > 0.3            # the rows stand as they came...
    assert status_of(est)[0] == "degraded"     # ...and are flagged
    assert any("contradict the sparse zero-slip prior" in f for f in est.flags), est.flags


@pytest.mark.parametrize("make,seed", [(paper, 15), (yard, 16)])
def test_a_log_without_slip_events_is_not_checked(make, seed):
    """Nothing slips after the window: no second solve, and batch's answer
    is the prior's, unchanged (estimate's whole pipeline)."""
    sc = make(120.0).with_(slips=())
    sc = sc.with_(robot=sc.robot.with_(gps_sigma=0.5), rates=replace(sc.rates, gps=2.0))
    log = inject(sc, Faults(), seed)
    a = estimate(log, "batch", Schedule(20.0))
    b = estimate(log, "batch", Schedule(20.0), slip_check=False)
    assert not any("slip prior checked" in n for n in a.notes), a.notes
    np.testing.assert_array_equal(a.mean, b.mean)
    np.testing.assert_array_equal(a.sigma, b.sigma)
