"""A wheel that spun through the calibration window (analysis.plausible.skid_warnings).

The paper's schedule forces slip to zero while calibrating (eq. 35-36). A
slip that fills the window is no stall the window's own check can see
(estimators.slipcheck fits the window's normal out of the window itself),
and it goes into the scale factor: a hostile probe's log (right wheel
spinning 0.1 m/s from 3 to 80 s of 100 s) came out with scale_right 107
sigma off, status ok, in every estimator. Afterwards the wheel, once it
grips, can only be explained as turning slower than the ground for as long
as the robot drives. These logs (other wheels, slips, scenarios and seeds
than the probe's) must each end right within sigma or flagged."""
import numpy as np
import pytest

from odomgraph.estimators.schedule import Schedule
from odomgraph.pipeline import estimate
from odomgraph.result import status_of
from odomgraph.sim.faults import Faults, inject
from odomgraph.sim.scenarios import SlipEvent, paper, yard
from odomgraph.state import SCALE

CASES = {
    "yard, left wheel 0.12 m/s from 2 to 70 s of 95 s, seed 41": (yard, SlipEvent("left", 2.0, 70.0, 0.12), 95.0, 41),
    "paper, right wheel 0.08 m/s from 1 to 60 s of 85 s, seed 42": (paper, SlipEvent("right", 1.0, 60.0, 0.08), 85.0,
                                                                     42),
}


#: Found by this test and not solved yet (README, Known limitations): the
#: EKF's skid on the paper log stays inside its slip sigma (0.03-0.06 m/s
#: at sigma 0.043), so it is not told from the filter's own wander.
OPEN = {("paper, right wheel 0.08 m/s from 1 to 60 s of 85 s, seed 42", "ekf")}


def _window_slip_run(make, slip, duration: float, seed: int, method: str):
    """(the estimate, z of its final scale factors against the truth, its
    status) of ``make``'s scenario with the one slip event ``slip``, a 20 s window."""
    sc = make(duration).with_(slips=(slip,))
    est = estimate(inject(sc, Faults(), seed), method, Schedule(20.0))
    z = (est.mean[-1, SCALE] - np.array(sc.scales)) / est.sigma[-1, SCALE]
    return est, z, status_of(est)[0]


@pytest.mark.parametrize("case,method", [
    pytest.param(c, m, marks=pytest.mark.xfail(reason="open: a slip through the window, not flagged", strict=False))
    if (c, m) in OPEN else (c, m)
    for c in CASES for m in ("ekf", "batch", "isam2", "fixed-lag")])
def test_a_slip_through_the_window_is_right_or_flagged(case, method):
    make, slip, duration, seed = CASES[case]
    est, z, status = _window_slip_run(make, slip, duration, seed, method)
    if np.abs(z).max() > 3.0:
        assert status == "degraded", (z, est.warnings)
        said = [w for w in est.warnings if f"the {slip.wheel} wheel turns" in w and "slower than the ground" in w]
        assert said, est.warnings
        if not said[0].startswith(f"{method}: after the calibration window"):   # (window_transfer_warnings: no time)
            t0 = float(said[0].split("from t=")[1].split(" ")[0])
            assert t0 >= slip.end - 1.0        # the skid is after the slip ends, where the wheel grips again


@pytest.mark.parametrize("make,seed", [(paper, 43), pytest.param(yard, 44, marks=pytest.mark.slow)])
def test_a_clean_log_and_its_slip_events_are_not_taken_for_a_skid(make, seed):
    """The scenarios' own slip events (0.3-0.5 m/s for 8-10 s, after the
    window) and a clean calibration: no skid said, by any estimator."""
    log = inject(make(90.0), Faults(), seed)
    for method in ("ekf", "batch", "isam2", "fixed-lag"):
        est = estimate(log, method, Schedule(20.0))
        assert not [w for w in est.warnings if "slower than the ground" in w], (method, est.warnings)


def test_the_skid_check_reads_the_wheels_direction_and_its_sigma():
    """Unit check on a synthetic estimate: a wheel slower than the ground
    backwards, to the end, is a skid too; a skid within one sigma, shorter
    than SKID_DURATION, below SKID_REL of the speed, or followed by
    SKID_DURATION of grip (a drag that ended), is not."""
    from types import SimpleNamespace

    from odomgraph.analysis.plausible import SKID_DURATION, skid_warnings
    t = np.arange(0.0, 30.0, 0.05)
    mean = np.zeros((t.size, 11))
    mean[:, 8:11] = 1.0
    mean[:, 3] = -1.0                                    # reversing at 1 m/s
    sigma = np.full((t.size, 11), 0.01)
    on = t >= 10.0
    mean[on, 7] = +0.1                                   # right wheel's surface speed -0.9: slower than the ground
    est = SimpleNamespace(t=t, mean=mean, sigma=sigma, method="m")
    out = skid_warnings(est, 0.5)
    assert len(out) == 1 and "the right wheel turns 10 % slower" in out[0], out
    assert float(out[0].split("from t=")[1].split(" ")[0]) == pytest.approx(10.0, abs=0.6)
    sigma[:, 7] = 0.2                                    # within its sigma
    assert skid_warnings(est, 0.5) == []
    sigma[:, 7] = 0.01
    mean[on, 7] = 0.04                                   # 4 %: below SKID_REL
    assert skid_warnings(est, 0.5) == []
    mean[on, 7] = -0.1                                   # faster than the ground: slip, not a skid
    assert skid_warnings(est, 0.5) == []
    mean[:, 7] = 0.0
    mean[(t >= 10.0) & (t < 10.0 + SKID_DURATION - 1.5), 7] = 0.1      # too short
    assert skid_warnings(est, 0.5) == []
    mean[:, 7] = 0.0
    mean[(t >= 10.0) & (t < 10.0 + SKID_DURATION + 3.0), 7] = 0.1      # a drag, then grip to the end
    assert skid_warnings(est, 0.5) == []
    mean[t >= 10.0 + SKID_DURATION + 3.0 + SKID_DURATION - 1.0, 7] = 0.1   # grip too short to count
    assert len(skid_warnings(est, 0.5)) == 1


def test_a_smoother_that_diverges_after_its_window_runs_again_without_it():
    """The yard case above stopped isam2 and fixed-lag 2 s after the window
    (the fixes 12-13 sigma off and a 60 s re-solve could not bring them
    back: the window's zero-slip priors cannot be undone). They now run
    again with slip estimated throughout, say so, and are flagged."""
    make, slip, duration, seed = CASES["yard, left wheel 0.12 m/s from 2 to 70 s of 95 s, seed 41"]
    log = inject(make(duration).with_(slips=(slip,)), Faults(), seed)
    for method in ("isam2", "fixed-lag"):
        est = estimate(log, method, Schedule(20.0))
        said = [w for w in est.warnings if "run again with slip estimated throughout" in w]
        assert len(said) == 1 and said[0].startswith(f"{method} diverged at t="), est.warnings
        assert status_of(est)[0] == "degraded"
        assert est.t_switch is None                       # the run that finished had no window


@pytest.mark.parametrize("make,seed,duration,drag", [
    (yard, 291, 130.0, None),                                       # yard's own 118-126 s drag, 4 s before the end
    (paper, 241, 120.0, SlipEvent("left", 110.0, 118.0, -0.2)),
    (paper, 242, 121.0, SlipEvent("right", 112.0, 119.5, -0.15))])
def test_a_drag_near_the_end_of_the_log_is_not_a_skid(make, seed, duration, drag):
    """A second probe's false alarms: a real drag that ends a few seconds
    before the log does left no room for SKID_DURATION of grip after it, and
    was taken for a wheel that never grips again (the scale factors were
    exact)."""
    sc = make(duration) if drag is None else make(duration).with_(slips=(drag,))
    log = inject(sc, Faults(), seed)
    for method in ("ekf", "batch"):
        est = estimate(log, method, Schedule(20.0))
        assert not [w for w in est.warnings if "slower than the ground" in w], (method, est.warnings)


def test_an_estimate_shorter_than_a_second_is_read():
    """A review found the one-second means broke on fewer rows than a
    second holds (a 0.8 s log raised in every estimator)."""
    from types import SimpleNamespace

    from odomgraph.analysis.plausible import skid_warnings
    t = np.arange(0.0, 0.25, 0.05)
    mean = np.zeros((t.size, 11))
    mean[:, 8:11] = 1.0
    mean[:, 3] = 1.0
    est = SimpleNamespace(t=t, mean=mean, sigma=np.full((t.size, 11), 0.01), method="m")
    assert skid_warnings(est, 0.5) == []


#: A small slip of one wheel for part of the calibration window, then grip
#: (window_transfer_warnings): a probe's logs (1.5-5 cm/s, seeds 26-81, a
#: 0.6 m track, GPS at 5-10 Hz) ended 4-24 sigma off, status ok. These have
#: other scenarios, wheels, slips, spans and seeds.
SMALL = {
    "yard, left 0.04 m/s from 4 to 17 s, seed 61": (yard, SlipEvent("left", 4.0, 17.0, 0.04), 70.0, 61),
    "paper, right 0.05 m/s from 2 to 15 s, seed 62": (paper, SlipEvent("right", 2.0, 15.0, 0.05), 75.0, 62),
    "paper, left 0.03 m/s from 6 to 19 s, seed 63": (paper, SlipEvent("left", 6.0, 19.0, 0.03), 80.0, 63),
}


#: Not caught yet (README Known limitations): batch leaves the slip's share
#: in its scale factor (z 7.6) without the slip after the window showing it.
OPEN_SMALL = {("paper, left 0.03 m/s from 6 to 19 s, seed 63", "batch")}


@pytest.mark.parametrize("case,method", [
    pytest.param(c, m, marks=pytest.mark.xfail(reason="open: batch's small slip in the window", strict=False))
    if (c, m) in OPEN_SMALL else (c, m) for c in SMALL for m in ("ekf", "batch")])
def test_a_small_slip_in_the_window_is_right_or_flagged(case, method):
    make, slip, duration, seed = SMALL[case]
    est, z, status = _window_slip_run(make, slip, duration, seed, method)
    if method == "ekf":
        # each of these slips bends the EKF's calibration (z 9-21): the flag
        # below is what holds it, not a calibration that came out right
        assert np.abs(z).max() > 5.0, z
    if np.abs(z).max() > 3.0:
        assert status == "degraded", (z, est.warnings)
        assert any(f"the {slip.wheel} wheel turns" in w for w in est.flags), (z, est.flags)


def test_the_window_transfer_check_reads_a_steady_share_beyond_sigma():
    """Unit check on a synthetic estimate (reversing at 1 m/s, window until
    20 s): a wheel whose slip stays -3 % of its ground speed after the
    window, with a 0.3 % scale sigma, is said with its share; within
    TRANSFER_SIGMA sigmas, below TRANSFER_REL, on one side in fewer than
    TRANSFER_SIGN of its rows (slip events), or with no window, it is not."""
    from types import SimpleNamespace

    from odomgraph.analysis.plausible import window_transfer_warnings
    t = np.arange(0.0, 60.0, 0.05)
    mean = np.zeros((t.size, 11))
    mean[:, 8:11] = 1.0
    mean[:, 3] = -1.0
    sigma = np.full((t.size, 11), 0.003)
    mean[t > 20.0, 6] = 0.03                  # left surface -0.97 m/s: 3 % slower than the ground
    est = SimpleNamespace(t=t, mean=mean, sigma=sigma, method="m", t_switch=20.0)
    seen = np.arange(0.0, 60.0, 0.5)          # fixes at 2 Hz throughout
    out = window_transfer_warnings(est, 0.5, seen)
    assert len(out) == 1 and "the left wheel turns 3.0 % slower than the ground under it passes in 100 % of " \
        "38 s of driving, where its scale factor's sigma is 0.30 %" in out[0], out
    sigma[:, 8] = 0.01                        # 3 sigma
    assert window_transfer_warnings(est, 0.5, seen) == []
    sigma[:, 8] = 0.0005
    mean[t > 20.0, 6] = 0.004                 # 0.4 %: below TRANSFER_REL
    assert window_transfer_warnings(est, 0.5, seen) == []
    mean[t > 20.0, 6] = np.where(np.sin(t[t > 20.0]) > -0.1, 0.03, -0.03)    # one side in ~53 %
    assert window_transfer_warnings(est, 0.5, seen) == []
    mean[t > 20.0, 6] = -0.03                 # faster than the ground, steadily: said too
    assert "3.0 % faster" in window_transfer_warnings(est, 0.5, seen)[0]
    seen = seen[(seen < 25.0) | (seen > 52.0)]  # an outage from 25 to 52 s: 12 s of driving seen
    assert len(window_transfer_warnings(est, 0.5, seen)) == 1
    seen = seen[(seen < 25.0) | (seen > 54.0)]  # just under TRANSFER_MIN_S seen: too few
    assert window_transfer_warnings(est, 0.5, seen) == []
    est.t_switch = None
    assert window_transfer_warnings(est, 0.5, np.arange(0.0, 60.0, 0.5)) == []


@pytest.mark.parametrize("make,seed", [(yard, 73), (paper, 72)])   # yard 73: said, before rows were judged so
def test_slips_wandering_in_a_gps_outage_are_not_a_calibration_off(make, seed):
    """In a GPS outage nothing holds the EKF's slips (a probe's 60 s outage
    with a slip inside read 5 % at 27 sigma, its scale factors right): only
    rows near an absolute measurement count, and no transfer line is said."""
    log = inject(make(110.0), Faults(outages=(("gps", 30.0, 85.0),)), seed)
    est = estimate(log, "ekf", Schedule(20.0))
    assert not [w for w in est.warnings if "after the calibration window" in w], est.warnings


@pytest.mark.parametrize("make,slip,duration,seed", [
    (paper, SlipEvent("right", 28.0, 70.0, 0.12), 85.0, 81),       # 42 of the 63 s after the window
    (yard, SlipEvent("left", 35.0, 72.0, -0.08), 95.0, 82)])       # a long drag
@pytest.mark.parametrize("method", ["ekf", "batch"])
def test_a_long_slip_event_after_the_window_is_not_a_calibration_off(make, slip, duration, seed, method):
    """A wheel spinning (or dragging) for most of the driving after the
    window, gripping before and after, with the window clean (a probe: 40 of
    58 s at 0.1 m/s read "9.9 % faster", degraded, its scale right): the
    share must hold in every part of the rows after the window."""
    log = inject(make(duration).with_(slips=(slip,)), Faults(), seed)
    est = estimate(log, method, Schedule(20.0))
    assert not [w for w in est.warnings if "after the calibration window" in w], est.warnings
