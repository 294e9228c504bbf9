"""Issue 14: one vocabulary of state blocks and of the smoothers' row layout.

The 11-vector (state.py), the smoothers' per-interval W (the state after the
pose) and the unary factor's rows each had raw slices (``[8:11]``,
``w[:, 3:5]`` meaning slips where ``x[3:5]`` means (v, omega), ``7 + 2 *
slot``) written out in several modules. These tests hold the names to
what they index, and keep the raw state slices out."""
import re
from pathlib import Path

import numpy as np

from odomgraph import state as S
from odomgraph.estimators import graph
from odomgraph.estimators.keyframes import W_NAMES

ROOT = Path(__file__).resolve().parents[1]


def test_the_blocks_select_the_states_they_name():
    names = np.array(S.NAMES)
    assert list(names[S.POSE_S]) == ["x", "y", "theta"]
    assert list(names[S.VEL_S]) == ["v", "omega"]
    assert list(names[S.SLIP_S]) == ["slip_left", "slip_right"]
    assert list(names[S.SCALE_S]) == ["scale_left", "scale_right", "scale_track"]
    assert list(names[S.WHEEL_SCALE_S]) == ["scale_left", "scale_right"]
    # the slices agree with the index arrays
    for sl, idx in ((S.POSE_S, S.POSE), (S.SLIP_S, S.SLIP), (S.SCALE_S, S.SCALE)):
        assert list(range(S.N)[sl]) == list(idx)


def test_w_is_the_state_after_the_pose():
    assert W_NAMES == S.NAMES[S.W_OFFSET:]
    w = np.array(W_NAMES)
    assert list(w[S.W_VEL]) == ["v", "omega"]
    assert list(w[S.W_SLIP]) == ["slip_left", "slip_right"]
    assert list(w[S.W_SCALE]) == ["scale_left", "scale_right", "scale_track"]
    assert list(w[S.W_WHEEL_SCALE]) == ["scale_left", "scale_right"]
    # a smoother's tangent block [pose, W] has the state's indices
    assert (graph.V, graph.SL, graph.KB) == (S.V, S.SLIP_L, S.SCALE_B) and graph.NB == S.N


def test_the_unary_rows_of_each_sensor_do_not_overlap():
    """A problem with fixes and ranges: every row named once, none past the end."""
    from odomgraph.estimators.batch import GraphOptions, build_problem
    from odomgraph.estimators.schedule import Schedule
    from odomgraph.sim.scenarios import Rates, beacons_around, paper
    from odomgraph.sim.simulate import simulate
    sc = paper(30.0)
    sc = sc.with_(robot=sc.robot.with_(beacons=beacons_around(-10.0, 10.0, -10.0, 10.0)),
                  rates=Rates(encoders=20, gyro=25, gps=10, ranges=10))
    prob = build_problem(simulate(sc, 3), Schedule(10.0), GraphOptions())
    assert prob.g_max >= 1 and prob.r_max >= 1
    assert prob.rows_unary == graph.unary_rows(prob.g_max, prob.r_max)
    rows = list(range(prob.rows_unary))
    taken = rows[graph.ROW_ENC] + [graph.ROW_GYRO] + rows[graph.ROW_VEL] + rows[graph.ROW_SLIP]
    for s in range(prob.g_max):
        taken += [int(prob.gps_rows(s)), int(prob.gps_rows(s)) + 1]
    taken += [int(prob.range_rows(s)) for s in range(prob.r_max)]
    assert sorted(taken) == rows


def test_no_raw_slices_of_the_state_blocks():
    """The scale, slip, velocity and W blocks are named, not written as
    numbers (``3:5`` is (v, omega) of the state but the slips of W)."""
    raw = re.compile(r"\[[^\]\n]*\b(8:11|6:8|5:8|5:7|6:11|3:5)\]")
    found = []
    for p in sorted((ROOT / "odomgraph").rglob("*.py")):
        for i, line in enumerate(p.read_text().splitlines(), 1):
            code = line.split("#", 1)[0]
            if raw.search(code):
                found.append(f"{p.relative_to(ROOT)}:{i}: {line.strip()}")
    assert not found, "\n".join(found)
