"""The smoother's vectorised linearisation against numerical derivatives of
its own residuals (through the Pose2 retraction), factor by factor."""
import math

import numpy as np
import pytest

from odomgraph.estimators import batch as B
from odomgraph.estimators.graph import NB, linearize
from odomgraph.estimators.schedule import Schedule
from odomgraph.sim.scenarios import Rates, beacons_around, paper
from odomgraph.sim.simulate import simulate


def residuals(prob, pose, W):
    lin = linearize(prob, pose, W)
    return {"u": -lin.b_u, "m": -lin.b_m, "w": -lin.b_w, "p": -lin.b_p}, lin


@pytest.fixture(scope="module")
def problem():
    sc = paper(30).with_(rates=Rates(gps=20, ranges=5, velocity=5))
    sc = sc.with_(robot=sc.robot.with_(beacons=beacons_around(0, 15, -5, 5)))
    log = simulate(sc, 1)
    prob = B.build_problem(log, Schedule(10.0), B.SmootherOptions(keyframe_hz=5, slip_cauchy=None, robust="none",
                                                                         slip_step_k=math.inf))
    prob.speed_ref = np.array([0.97, 1.02, 1.05])      # wheel-speed units in the window (graph.linearize)
    rng = np.random.default_rng(0)
    from odomgraph.estimators.ekf import run_ekf
    pose, W = B.initial_guess(prob, run_ekf(log, Schedule(10.0)))
    pose = pose + rng.normal(0, [0.05, 0.05, 0.02], pose.shape)   # off the optimum: residuals nonzero
    W = W + rng.normal(0, 0.01, W.shape)
    return prob, pose, W


@pytest.mark.parametrize("k", [0, 7, 40, 90])
def test_linearization_matches_numerical_derivatives(problem, k):
    prob, pose, W = problem
    r0, lin = residuals(prob, pose, W)
    eps = 1e-6
    for j in range(NB):
        d = np.zeros((prob.kf.n, NB))
        d[k, j] = eps
        rp, _ = residuals(prob, *B.retract(pose, W, d))
        rm, _ = residuals(prob, *B.retract(pose, W, -d))
        num = {key: (rp[key] - rm[key]) / (2 * eps) for key in r0}
        # unary rows of interval k act on block k
        np.testing.assert_allclose(lin.A_u[k][:, j], num["u"][k], rtol=1e-5, atol=1e-5 * (1 + np.abs(num["u"][k]).max()))
        # motion rows: interval k (block k) and interval k-1 (pose of block k)
        np.testing.assert_allclose(lin.A_m0[k][:, j], num["m"][k], rtol=1e-5, atol=1e-4)
        if k > 0 and j < 3:
            np.testing.assert_allclose(lin.A_m1[k - 1][:, j], num["m"][k - 1], rtol=1e-5, atol=1e-4)
        if j >= 3:
            # random-walk rows: interval k (W_k) and interval k-1 (W_k as its later end)
            np.testing.assert_allclose(lin.A_w0[k][:, j - 3], num["w"][k], rtol=1e-6, atol=1e-6)
            if k > 0:
                np.testing.assert_allclose(lin.A_w1[k - 1][:, j - 3], num["w"][k - 1], rtol=1e-6, atol=1e-6)
        if k == 0:
            np.testing.assert_allclose(lin.A_p[:, j], num["p"], rtol=1e-5, atol=1e-5)


def test_robust_slip_rows_have_the_gradient_of_the_cauchy_cost():
    # IRLS rows must descend the cost the line search evaluates.
    sc = paper(30)
    log = simulate(sc, 2)
    prob = B.build_problem(log, Schedule(10.0), B.SmootherOptions(keyframe_hz=5, slip_cauchy=0.01))
    from odomgraph.estimators.ekf import run_ekf
    pose, W = B.initial_guess(prob, run_ekf(log, Schedule(10.0)))
    W[:, 3:5] += np.random.default_rng(3).normal(0, 0.02, (len(W), 2))
    lin = linearize(prob, pose, W)
    k = int(np.argmax(~prob.zero_slip)) + 3
    for j in (6, 7):  # slip_left, slip_right columns
        d = np.zeros((prob.kf.n, NB))
        d[k, j] = 1e-7
        cp = linearize(prob, *B.retract(pose, W, d)).cost
        cm = linearize(prob, *B.retract(pose, W, -d)).cost
        grad_num = (cp - cm) / 2e-7
        # gradient of 0.5 ||A d - b||^2 at d = 0 is -A^T b, summed over every row touching block k
        A1, A2, b = B.factor_arrays(prob, lin)
        grad = -(A1[k][:, j] @ b[k]) - (A2[k - 1][:, j] @ b[k - 1])
        assert grad == pytest.approx(grad_num, rel=1e-4, abs=1e-6)


def test_slip_split_is_the_common_mode_and_differential_steps_whitened_alone():
    """RandomWalkSteps.slip_split rotates the slips' whitened rows into c =
    (sL + sR)/2 over its sigma and d = sR - sL over its: orthogonal (the cost
    unchanged), and each row one of the two steps (slip_intensity's p = 0.05,
    q_d = 0.02 m/s per sqrt s without a gyro)."""
    from odomgraph.estimators.graph import WSL
    from odomgraph.io.robot import ProcessNoise
    from odomgraph.estimators.graph import RandomWalkSteps
    p, qd = 0.05, 0.02
    q = p**2 * np.ones((2, 2)) + 0.25 * qd**2 * np.array([[1.0, -1.0], [-1.0, 1.0]])
    rw = RandomWalkSteps.of(ProcessNoise(), q, np.array([0.2]))
    R = rw.slip_split
    np.testing.assert_allclose(R @ R.T, np.eye(2), atol=1e-12)
    rows = R @ rw.unit_whiten[WSL, WSL]
    np.testing.assert_allclose(rows, [[0.5 / p, 0.5 / p], [-1 / qd, 1 / qd]], rtol=1e-12)


def test_robust_curvature_is_the_second_derivative_of_the_loss():
    """The covariance's weights (graph.robust_curvature) against a numerical
    second derivative of robust_weight's loss, floored at LAPLACE_FLOOR."""
    from odomgraph.estimators.graph import LAPLACE_FLOOR, robust_curvature, robust_weight
    u = np.array([0.1, 0.9, 1.3, 1.9, 2.1, 2.5, 4.0, 30.0])
    for kind, k in (("huber", 2.0), ("cauchy", 2.385)):
        h = 1e-4
        rho = lambda x: robust_weight(x, kind, k)[1]
        num = (rho(u + h) - 2 * rho(u) + rho(u - h)) / h**2
        np.testing.assert_allclose(robust_curvature(u, kind, k) ** 2, np.maximum(num, LAPLACE_FLOOR**2),
                                   rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("units", [False, True])
def test_huber_slip_steps_have_the_gradient_of_their_cost(units):
    """batch's default Huber on the common-mode slip step (graph.SLIP_STEP_K):
    its IRLS rows descend the cost the line search evaluates, with steps far
    beyond k (a stall's) at every block tested, and the cost is the Huber loss
    of the common-mode step plus the Gaussian differential's; with plain
    walks and in wheel-speed units."""
    log = simulate(paper(30), 2)
    prob = B.build_problem(log, Schedule(10.0), B.SmootherOptions(keyframe_hz=5, slip_cauchy=None))
    assert prob.slip_step_k == 2.0
    from odomgraph.estimators.ekf import run_ekf
    from odomgraph.estimators.graph import WSL, walk_rows
    pose, W = B.initial_guess(prob, run_ekf(log, Schedule(10.0)))
    if units:
        prob.speed_ref = np.array([0.97, 1.02, 1.05])      # wheel-speed units in the window (graph.linearize)
    assert prob.wheel_speed_units == units
    W[:, 3:5] += np.random.default_rng(4).normal(0, 0.3, (len(W), 2))     # steps of ~10 sigma
    A0, A1, bw, extra = walk_rows(prob, W, 0, prob.kf.n - 1)
    gauss = B.build_problem(log, Schedule(10.0), B.SmootherOptions(keyframe_hz=5, slip_cauchy=None,
                                                                    slip_step_k=math.inf))
    gauss.speed_ref = prob.speed_ref
    _, _, bg, zero = walk_rows(gauss, W, 0, prob.kf.n - 1)
    assert zero == 0.0
    u = (bg[:, WSL] @ prob.rw.slip_split.T)                 # (common, differential) whitened steps
    huber = np.where(np.abs(u[:, 0]) <= 2, 0.5 * u[:, 0] ** 2, 2 * (np.abs(u[:, 0]) - 1))
    assert np.mean(np.abs(u[:, 0]) > 2) > 0.5
    assert 0.5 * np.sum(bw[:, WSL] ** 2) + extra == pytest.approx(np.sum(huber + 0.5 * u[:, 1] ** 2), rel=1e-12)
    lin = linearize(prob, pose, W)
    A1f, A2f, b = B.factor_arrays(prob, lin)
    for k in (5, 60, 120):
        for j in (3, 6, 7, 8, 9):        # v, the slips, the wheels' scales
            d = np.zeros((prob.kf.n, NB))
            d[k, j] = 1e-7
            num = (linearize(prob, *B.retract(pose, W, d)).cost - linearize(prob, *B.retract(pose, W, -d)).cost) / 2e-7
            grad = -(A1f[k][:, j] @ b[k]) - (A2f[k - 1][:, j] @ b[k - 1])
            assert grad == pytest.approx(num, rel=1e-4, abs=1e-5)


@pytest.mark.parametrize("kind", ["huber", "cauchy"])
def test_robust_measurement_rows_have_the_gradient_of_their_loss(kind):
    sc = paper(30).with_(rates=Rates(gps=20, ranges=5))
    sc = sc.with_(robot=sc.robot.with_(beacons=beacons_around(0, 15, -5, 5)))
    log = simulate(sc, 1)
    prob = B.build_problem(log, Schedule(10.0), B.SmootherOptions(slip_cauchy=None, robust=kind, robust_k=1.0))
    from odomgraph.estimators.ekf import run_ekf
    pose, W = B.initial_guess(prob, run_ekf(log, Schedule(10.0)))
    pose = pose + np.random.default_rng(5).normal(0, [0.1, 0.1, 0.03], pose.shape)  # many rows beyond k
    lin = linearize(prob, pose, W)
    A1, A2, b = B.factor_arrays(prob, lin)
    for k in (5, 60):
        for j in (0, 1, 2, 3):
            d = np.zeros((prob.kf.n, NB))
            d[k, j] = 1e-7
            num = (linearize(prob, *B.retract(pose, W, d)).cost - linearize(prob, *B.retract(pose, W, -d)).cost) / 2e-7
            grad = -(A1[k][:, j] @ b[k]) - (A2[k - 1][:, j] @ b[k - 1])
            assert grad == pytest.approx(num, rel=1e-4, abs=1e-5)


def test_graph_built_in_chunks_equals_the_whole_stack(monkeypatch):
    """gaussian_graph stacks GRAPH_CHUNK intervals at a time (memory): the
    step it solves is the one from the whole stack, exactly, also with a chunk
    that does not divide the intervals and with range biases (a second key)."""
    sc = paper(30).with_(rates=Rates(gps=0, ranges=5))
    sc = sc.with_(robot=sc.robot.with_(beacons=beacons_around(0, 15, -5, 5)))
    log = simulate(sc, 4)
    prob = B.build_problem(log, Schedule(10.0), B.SmootherOptions(range_bias=True))
    from odomgraph.estimators.ekf import run_ekf
    pose, W = B.initial_guess(prob, run_ekf(log, Schedule(10.0)))
    lin = linearize(prob, pose, W, range_bias=np.zeros(prob.n_bias) if prob.n_bias else None)
    order = B.time_ordering(prob.kf.n, 1 if prob.n_bias else 0)
    whole = B.gaussian_graph(prob, lin)
    step = whole.optimize(order, B.gtsam.EliminateQR)
    monkeypatch.setattr(B, "GRAPH_CHUNK", 7)
    chunked = B.gaussian_graph(prob, lin)
    assert prob.n_bias and chunked.size() == whole.size() and (prob.kf.n - 1) % 7 != 0
    step7 = chunked.optimize(order, B.gtsam.EliminateQR)
    for k in range(prob.kf.n + (1 if prob.n_bias else 0)):
        assert np.array_equal(step.at(k), step7.at(k))
    A1, A2, b = B.factor_arrays(prob, lin)
    a1, a2, bb = B.factor_arrays(prob, lin, slice(10, 17))
    assert np.array_equal(A1[10:17], a1) and np.array_equal(A2[10:17], a2) and np.array_equal(b[10:17], bb)
