"""A GNSS receiver that freezes: it repeats its last fix while the robot
drives (measurements.frozen_fixes). A probe's 20 s freeze (paper, seed 812)
was read as a robot standing while its wheels spin, and every estimator
ended 2.4-4 m off at z 197-404, the mirror heading after it, no line naming
the receiver. Here other seeds, rates and spans; and a robot that really
stands while its wheels spin, its fixes held, is no freeze."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from odomgraph import state as S
from odomgraph.estimators.measurements import frozen_fixes, repeat_notes
from odomgraph.estimators.schedule import Schedule
from odomgraph.pipeline import estimate
from odomgraph.sim.faults import Faults, Stall, inject
from odomgraph.sim.scenarios import paper, yard


def _frozen(log, a: float, b: float):
    """``log`` with every fix in (a, b) [s] replaced by the last one before a."""
    g = log.gps
    i = np.searchsorted(g.t, a) - 1
    m = (g.t > a) & (g.t < b)
    return log.with_(gps=replace(g, x=np.where(m, g.x[i], g.x), y=np.where(m, g.y[i], g.y)))


CASES = [(paper, 91, 10.0, 45.0, 62.0), (yard, 93, 5.0, 22.0, 34.0)]


@pytest.mark.parametrize("make,seed,hz,a,b", CASES)
def test_a_frozen_receiver_is_found_said_and_left_out(make, seed, hz, a, b):
    base = make(100.0)
    clean = inject(base.with_(rates=replace(base.rates, gps=hz)), Faults(), seed)
    log = _frozen(clean, a, b)
    found = frozen_fixes(log)
    assert len(found) == 1, found
    first, last, travel, turn = found[0]
    g = log.gps
    assert g.t[first] <= a < g.t[first + 1] and g.t[last] < b <= g.t[last + 1]
    assert travel > 5.0 and turn > 0.5
    said = [n for n in repeat_notes(log) if "frozen receiver" in n]
    assert len(said) == 1 and f"from t={g.t[first]:.2f} to {g.t[last]:.2f} s" in said[0], said
    # the estimate is the one without those fixes, row for row (its first kept)
    keep = np.ones(len(g.t), bool)
    keep[first + 1:last + 1] = False
    gap = log.with_(gps=replace(g, t=g.t[keep], x=g.x[keep], y=g.y[keep]))
    est, ref = (estimate(lg, "ekf", Schedule(20.0)) for lg in (log, gap))
    np.testing.assert_array_equal(est.mean, ref.mean)
    # and the smoother, no longer pulled to a standstill, stays on the path
    sm = estimate(log, "batch", Schedule(20.0))
    err = np.hypot(sm.mean[:, S.X] - log.truth.at("x", sm.t), sm.mean[:, S.Y] - log.truth.at("y", sm.t))
    assert err.max() < 0.3, err.max()


@pytest.mark.parametrize("seed", [95, 96])
def test_a_robot_standing_while_its_wheels_spin_keeps_its_fixes(seed):
    """The paper's own case: the fixes held while the wheels spin are the evidence of slip."""
    log = inject(paper(80.0), Faults(stalls=(Stall(40.0, 50.0, 0.6, 0.4),)), seed)
    g = log.gps
    held = (g.t > 40.0) & (g.t < 50.0)
    i = np.searchsorted(g.t, 40.0)
    log = log.with_(gps=replace(g, x=np.where(held, g.x[i], g.x), y=np.where(held, g.y[i], g.y)))
    assert frozen_fixes(log) == []
    assert frozen_fixes(inject(yard(60.0), Faults(motion="still"), seed)) == []


def test_a_freeze_on_a_steady_arc_is_found_and_look_alikes_are_not():
    """The gyro's bias is taken against the wheels, so a freeze on a circle
    (a steady turn) is still a turn; a pivot in place with the antenna on
    the axle (held fixes are right there) drives no distance; a gyro that
    turns while the wheels do not is no rolling robot."""
    from odomgraph.sim.scenarios import Segment
    base = yard(80.0)
    arc = base.with_(prologue=(Segment(2.0, 0.0, 0.0),), loop=(Segment(30.0, 0.8, 0.25),), slips=())
    log = _frozen(inject(arc, Faults(), 97), 40.0, 55.0)
    (first, last, travel, turn), = frozen_fixes(log)
    g = log.gps
    # the run: the last fresh fix before 40 s, then its copies up to 55 s
    assert (first, last) == (np.searchsorted(g.t, 40.0) - 1, np.searchsorted(g.t, 55.0) - 1)
    span = g.t[last] - g.t[first]
    assert travel == pytest.approx(0.8 * span, rel=0.05)     # 0.8 m/s for the run's span
    # 0.25 rad/s commanded: on a circle the gyro's bias, taken against the
    # wheels' rate over the whole log, also takes in the wheels' track error
    # (this robot's wheels read the turn 1.5x the gyro), so the turn counted
    # is nearer the wheels' (5.1 rad here; the gyro's own reading 3.4 rad)
    assert 0.25 * span < turn < 1.5 * 0.25 * span
    pivot = base.with_(robot=base.robot.with_(gps_lever_arm=(0.0, 0.0)))
    log = inject(pivot, Faults(motion="rotate"), 98)
    g = log.gps
    held = (g.t > 30.0) & (g.t < 45.0)
    i = np.searchsorted(g.t, 30.0)
    log = log.with_(gps=replace(g, x=np.where(held, g.x[i], g.x), y=np.where(held, g.y[i], g.y)))
    assert frozen_fixes(log) == []
    straight = base.with_(prologue=(Segment(2.0, 0.0, 0.0),), loop=(Segment(30.0, 1.0, 0.0),), slips=())
    log = _frozen(inject(straight, Faults(), 99), 40.0, 55.0)
    gy = log.gyro
    pushed = (gy.t > 40.0) & (gy.t < 55.0)
    log = log.with_(gyro=replace(gy, omega=gy.omega + np.where(pushed, 0.4 * np.sin(gy.t), 0.0)))
    assert frozen_fixes(log) == []
