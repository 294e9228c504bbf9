"""isam2 from an uncertain start heading (no [initial], weak fixes: 2 m GPS
at 1 Hz). Its linear factors keep the heading they were linearised at; before
ISAM2Runner._settle_start the online heading sat 30-45 sigma off, the
position 20-150 m, and a 300 s log stopped or ended with scale factors 70 %
off. Scenarios, rates and seeds other than the benchmark's (weak_gps LONG)."""
from dataclasses import replace

import numpy as np
import pytest

from odomgraph.estimators.schedule import Schedule
from odomgraph.pipeline import estimate
from odomgraph.result import status_of
from odomgraph.sim.faults import Faults, inject
from odomgraph.sim.scenarios import paper, yard
from odomgraph.state import SCALE

CASES = {
    "yard, 2 m at 1 Hz, seed 2": (yard, 2.0, 1.0, 2),
    "yard, 2 m at 1 Hz, seed 4": (yard, 2.0, 1.0, 4),
    "paper, 1.5 m at 2 Hz, seed 7": (paper, 1.5, 2.0, 7),
}


@pytest.mark.parametrize("case", list(CASES))
def test_isam2_online_heading_is_honest_from_an_uncertain_start(case):
    make, sigma, hz, seed = CASES[case]
    base = make(60.0).with_(slips=())
    sc = base.with_(robot=base.robot.with_(gps_sigma=sigma), rates=replace(base.rates, gps=hz))
    log = inject(sc, Faults(), seed)
    assert log.robot.initial is None
    est = estimate(log, "isam2", Schedule(20.0), fit_noise=False)
    on = est.online
    dth = (on.mean[:, 2] - log.truth.at("theta", on.t) + np.pi) % (2 * np.pi) - np.pi
    z = np.abs(dth) / on.sigma[:, 2]
    pos = np.hypot(on.mean[:, 0] - log.truth.at("x", on.t), on.mean[:, 1] - log.truth.at("y", on.t))
    assert np.mean(z < 3.0) >= 0.97, f"online heading inside 3 sigma: {np.mean(z < 3.0):.2f}"
    assert pos[on.t > 20.0].max() < 3.0 * sigma, f"online position error after 20 s: {pos[on.t > 20].max():.1f} m"
    assert est.recoveries == []
    assert any("re-solved from its prior" in n for n in est.notes)
    e = est.mean[-1, SCALE] / np.array(sc.scales) - 1.0
    assert np.all(np.abs(e / est.sigma[-1, SCALE]) < 4.0), f"scale factors' error / sigma {e / est.sigma[-1, SCALE]}"


def _run(make, sigma, hz, seed, segment, duration=60.0):
    base = make(duration).with_(slips=())
    sc = base.with_(robot=base.robot.with_(gps_sigma=sigma), rates=replace(base.rates, gps=hz))
    log = inject(sc, Faults(), seed)
    return sc, log, estimate(log, "isam2", Schedule(20.0), fit_noise=False, segment=segment)


def test_the_first_segment_stays_open_until_its_heading_settles_and_says_when_it_could_not():
    """A --segment shorter than the time the fixes take to pin the heading:
    the first segment is kept open (it alone can be re-solved) up to
    FIRST_SEGMENT_CAP segments, re-solved once more as it closes, and a
    warning says the heading was still uncertain then. Before, the settle
    stopped silently at the first hand-over (t = 6 s here)."""
    from odomgraph.estimators.incremental import FIRST_SEGMENT_CAP
    sc, log, est = _run(paper, 2.0, 1.0, 3, segment=6.0)
    said = [w for w in est.warnings if "still uncertain" in w]
    assert len(said) == 1, est.warnings
    assert status_of(est)[0] == "degraded"                # flagged, not only said
    close = float(said[0].split("closed at t=")[1].split(" s")[0])
    assert FIRST_SEGMENT_CAP * 6.0 <= close < FIRST_SEGMENT_CAP * 6.0 + 0.5
    sig_deg = float(said[0].split("(sigma ")[1].split(" deg")[0])
    assert sig_deg > 2.9                                   # above SETTLE_HEADING_DONE, as said
    on = est.online
    dth = (on.mean[:, 2] - log.truth.at("theta", on.t) + np.pi) % (2 * np.pi) - np.pi
    assert np.mean(np.abs(dth) / on.sigma[:, 2] < 3.0) >= 0.97
    e = est.mean[-1, SCALE] / np.array(sc.scales) - 1.0
    assert np.all(np.abs(e / est.sigma[-1, SCALE]) < 3.0), e / est.sigma[-1, SCALE]


def test_a_heading_that_settles_inside_a_short_first_segment_gives_no_warning():
    """Precise fixes (0.5 m at 5 Hz) pin the heading within the first 6 s
    segment: no warning, the segments close on time (60 s / 6 s)."""
    sc, log, est = _run(paper, 0.5, 5.0, 3, segment=6.0)
    assert not [w for w in est.warnings if "still uncertain" in w]
    n_seg = int(next(n for n in est.notes if "segment(s)" in n).split(", ")[-1].split(" ")[0])
    assert n_seg == 10
    e = est.mean[-1, SCALE] / np.array(sc.scales) - 1.0
    assert np.all(np.abs(e / est.sigma[-1, SCALE]) < 3.0)


# (seed 84 runs weekly, with the slow tests: suite time)
@pytest.mark.parametrize("seed", [83, pytest.param(84, marks=pytest.mark.slow)])
def test_an_overshooting_update_is_caught_between_sparse_fixes(seed):
    """10 m fixes at 0.2 Hz, no [initial]: the heading stays unknown, and one
    ISAM2 step from linearisations at a guessed heading carried the online
    estimate away between two fixes, doubling its error every keyframe (2-20
    km off at sigma 5-11 m; the watch on fixes saw nothing, the next fix
    being gated). _Runner._overshot tripped at the first implausible step and
    the recovery brought it back to within tens of metres. Since the start
    is settled from the first fix on (no gate while unsettled, a re-solve
    from the prior at once: ISAM2Runner._settle_start), the step no longer
    comes: 12 m at most, every row inside 2.6 sigma (seed 83)."""
    base = yard(150.0)
    sc = base.with_(robot=base.robot.with_(gps_sigma=10.0), rates=replace(base.rates, gps=0.2))
    log = inject(sc, Faults(), seed)
    est = estimate(log, "isam2", Schedule(), fit_noise=False)
    on = est.online
    ex = on.mean[:, 0] - log.truth.at("x", on.t)
    ey = on.mean[:, 1] - log.truth.at("y", on.t)
    pos = np.hypot(ex, ey)
    assert pos.max() < 50.0, f"online position error {pos.max():.0f} m"      # was 2.3-18 km, then tens of m
    z = np.maximum(np.abs(ex) / on.sigma[:, 0], np.abs(ey) / on.sigma[:, 1])
    assert z.max() < 4.0 or est.flags, z.max()


@pytest.mark.parametrize("segment", [1.0, 2.0])
def test_a_short_segment_on_weak_fixes_is_right_or_flagged(segment):
    """A probe: 1-2 s segments on 5 m GPS at 0.5 Hz ended 4-7 sigma off
    with status ok (the warning said it, the status did not)."""
    sc, log, est = _run(paper, 5.0, 0.5, 45, segment=segment)
    z = np.abs((est.mean[-1, SCALE] / np.array(sc.scales) - 1.0) / est.sigma[-1, SCALE]).max()
    assert z < 3.0 or status_of(est)[0] == "degraded", (z, status_of(est))
