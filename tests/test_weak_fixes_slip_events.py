"""Weak fixes and one-wheel slip events (README, Known limitations: "Weak
fixes and slip events: the smoothers' rows are overconfident").

The yard scenario with consumer GNSS (0.5 m at 2 Hz), and the paper's
with 3 m fixes at 1 Hz, each with its own slip events: the EKF's rows are
within their sigma, batch's are not (49 % and 56 % of them outside 3 sigma,
position z 17 and 5, status ok, measured in the 24th session): its sparse slip prior on the joint slip norm shrinks a one-wheel
slip's common mode, and the weak fixes do not pull it back. The batch case
is a strict xfail on each log: it passes, and so fails the suite, the day
the smoother is mended; the README item goes then."""
from dataclasses import replace

import numpy as np
import pytest

from odomgraph import state as S
from odomgraph.estimators.schedule import Schedule
from odomgraph.pipeline import estimate
from odomgraph.sim.faults import Faults, inject
from odomgraph.sim.scenarios import paper, yard

#: (scenario, GPS sigma [m], GPS rate [Hz], seed): consumer GNSS on the yard
#: robot, and a weaker receiver on the paper's (batch 56 % outside 3 sigma).
LOGS = [pytest.param(yard, 0.5, 2.0, 11, id="yard-0.5m-2Hz"), pytest.param(paper, 3.0, 1.0, 12, id="paper-3m-1Hz")]


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


@pytest.mark.parametrize("make,gps_sigma,gps_hz,seed", LOGS)
def test_the_ekf_holds_its_sigma_through_the_slip_events(make, gps_sigma, gps_hz, seed):
    log = _log(make, gps_sigma, gps_hz, seed)
    assert _outside(estimate(log, "ekf", Schedule(20.0)), log) < 0.01


@pytest.mark.xfail(strict=True, raises=AssertionError,
                   reason="README Known limitations: weak fixes and slip events (joint-norm slip prior)")
@pytest.mark.parametrize("make,gps_sigma,gps_hz,seed", LOGS)
def test_batch_holds_its_sigma_through_the_slip_events(make, gps_sigma, gps_hz, seed):
    log = _log(make, gps_sigma, gps_hz, seed)
    assert _outside(estimate(log, "batch", Schedule(20.0)), log) < 0.05
