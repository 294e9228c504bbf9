"""Both wheels slipping alike inside the calibration window (analysis.windowfit).

A common-mode slip of 0.2-0.25 m/s stays under the pre-fit check's 30 %,
and an estimate holding slip at zero through it was pulled off the fixes:
batch and isam2 0.5-0.85 m off at z 34-69 on a probe's logs, the scale
factors 7 sigma off, status ok. The pipeline now looks at the fit's fixes
in the window and runs again with the seconds they contradict out of it.
Seeds and slips here are not those the rule was tuned on (yard 61-62,
paper 63).
"""
from __future__ import annotations

import numpy as np
import pytest

from odomgraph.analysis.metrics import truth_errors
from odomgraph.pipeline import estimate
from odomgraph.result import status_of
from odomgraph import state as S
from odomgraph.sim.scenarios import SlipEvent, paper, yard
from odomgraph.sim.simulate import simulate

SAID = "the fixes sat more than"


def _scale_z(est, log):
    return (est.mean[-1, S.SCALE] - np.asarray(log.truth_scales)) / est.calibration_sigma


CASES = [("yard", 71, 6.0, 0.25), ("paper", 72, 4.0, 0.3), ("yard", 73, 9.0, -0.2)]


def _slipping(name, seed, start, speed):
    sc = (yard if name == "yard" else paper)()
    slips = (SlipEvent("left", start, start + 7.0, speed), SlipEvent("right", start, start + 7.0, speed))
    return simulate(sc.with_(slips=slips), seed)


@pytest.mark.parametrize("method", ["batch", "isam2"])
@pytest.mark.parametrize("name,seed,start,speed", [pytest.param(*c, marks=pytest.mark.slow) for c in CASES[:2]] + CASES[2:])
def test_common_mode_slip_in_the_window_is_found_and_estimated(method, name, seed, start, speed):
    log = _slipping(name, seed, start, speed)
    est = estimate(log, method)
    if status_of(est)[0] == "degraded":
        # isam2 may stop inside such a window and run again without it (flagged): fine, if said
        assert any("not trustworthy" in f for f in est.flags), est.flags
        return
    said = [w for w in est.warnings if SAID in w]
    assert len(said) == 1, est.warnings
    # the stretches it names cover the slip's middle
    import re
    spans = [(float(a), float(b)) for a, b in re.findall(r"(-?[0-9.]+)-(-?[0-9.]+) s", said[0].split(")")[0])]
    assert any(a <= start + 3.5 <= b for a, b in spans), spans
    z = _scale_z(est, log)
    assert np.all(np.abs(z) < 3.5), z
    e = truth_errors(est, log)
    assert e.rms_position_m < 0.05 and e.coverage_3sigma["x"] > 0.9, (e.rms_position_m, e.coverage_3sigma)


@pytest.mark.parametrize("name,seed,start,speed", CASES)
def test_the_ekf_is_right_within_sigma_or_flagged(name, seed, start, speed):
    """The EKF is not run again (its scale states take part of the slip up
    as it happens, and its fixes disagree only later): it is right within
    its sigma, or flagged. It had stopped on the drag (EKF diverged at
    14.7 s); it now runs again without the window, flagged."""
    log = _slipping(name, seed, start, speed)
    est = estimate(log, "ekf")
    z = _scale_z(est, log)
    flagged = any("not trustworthy" in f for f in est.flags)
    assert flagged or np.all(np.abs(z) < 3.5), (z, est.warnings)


@pytest.mark.parametrize("name,seed,method", [("yard", 74, "batch"), ("paper", 75, "ekf"), ("paper", 75, "isam2")])
def test_a_clean_window_is_left_alone(method, name, seed):
    """No slip in the window (each scenario's own slips come after it): no
    second look, and the estimate is the one without the check."""
    log = simulate((yard if name == "yard" else paper)(), seed)
    est = estimate(log, method)
    assert not [w for w in est.warnings if SAID in w], est.warnings
    assert status_of(est)[0] in ("ok", "recovered")
