"""The GTSAM CustomFactor adapters: their linearisation against numerical
derivatives through GTSAM's own retraction, and equality with the vectorised
linearisation the smoothers use."""
import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import S, W, X

from factors import gtsam_factors as gf

RNG = np.random.default_rng(11)


def random_values():
    v = gtsam.Values()
    v.insert(X(0), gtsam.Pose2(RNG.normal(0, 5), RNG.normal(0, 5), RNG.uniform(-np.pi, np.pi)))
    v.insert(X(1), gtsam.Pose2(RNG.normal(0, 5), RNG.normal(0, 5), RNG.uniform(-np.pi, np.pi)))
    v.insert(W(0), np.array([RNG.normal(0.8, 0.5), RNG.normal(0, 0.5), 0.01, 1.02, 0.97, 1.05]))
    v.insert(S(0), RNG.normal(0, 0.2, 2))
    return v


def numeric_blocks(factor, values, eps=1e-6):
    blocks = []
    for key in factor.keys():
        dim = values.dim() if False else (3 if gtsam.Symbol(key).chr() == ord("x") else len(values.atVector(key)))
        J = np.zeros((factor.dim(), dim))
        for j in range(dim):
            d = np.zeros(dim)
            d[j] = eps
            vp, vm = gtsam.Values(values), gtsam.Values(values)
            if dim == 3 and gtsam.Symbol(key).chr() == ord("x"):
                vp.update(key, values.atPose2(key).retract(d))
                vm.update(key, values.atPose2(key).retract(-d))
            else:
                vp.update(key, values.atVector(key) + d)
                vm.update(key, values.atVector(key) - d)
            J[:, j] = (factor.whitenedError(vp) - factor.whitenedError(vm)) / (2 * eps)
        blocks.append(J)
    return blocks


def make_factors():
    n2 = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.01, 0.02]))
    return [
        gf.encoder_factor(W(0), S(0), [0.9, 1.1], n2, 0.6),
        gf.gyro_factor(W(0), 0.3, gtsam.noiseModel.Isotropic.Sigma(1, 0.01)),
        gf.velocity_factor(W(0), [0.8, 0.1], n2),
        gf.gps_factor(X(0), W(0), [1.0, 2.0], 0.07, (-0.45, 0.1), gtsam.noiseModel.Isotropic.Sigma(2, 0.05)),
        gf.range_factor(X(0), W(0), 4.0, 0.1, [3.0, -2.0], (0.2, 0.0), gtsam.noiseModel.Isotropic.Sigma(1, 0.05)),
        gf.motion_factor(X(0), W(0), X(1), 0.2, gtsam.noiseModel.Diagonal.Sigmas(np.array([1e-3, 2e-3, 1e-4]))),
        gf.zero_slip_factor(S(0), gtsam.noiseModel.Isotropic.Sigma(2, 1e-3)),
        gf.hold_scale_factor(W(0), [1.0, 1.0, 1.0], gtsam.noiseModel.Isotropic.Sigma(3, 1e-4)),
    ]


@pytest.mark.parametrize("i", range(8))
@pytest.mark.parametrize("trial", range(3))
def test_custom_factor_linearization_matches_numerical_derivatives(i, trial):
    values = random_values()
    factor = make_factors()[i]
    jf = factor.linearize(values)
    A = jf.jacobian()[0]
    num = np.hstack(numeric_blocks(factor, values))
    scale = 1 + np.abs(num).max()
    np.testing.assert_allclose(A, num, atol=2e-5 * scale, rtol=1e-5)


def test_vectorised_linearisation_equals_the_custom_factors():
    """The smoother's fast path (graph.linearize) and the straightforward
    CustomFactors give the same whitened rows for the same interval."""
    from odomgraph.estimators import batch as B
    from odomgraph.estimators.graph import linearize
    from odomgraph.estimators.schedule import Schedule
    from odomgraph.estimators.incremental import S_COLS, W_COLS, W_IDX, X_COLS, S_IDX
    from odomgraph.sim.scenarios import paper
    from odomgraph.sim.simulate import simulate
    from odomgraph.estimators.ekf import run_ekf
    log = simulate(paper(30), 4)
    prob = B.build_problem(log, Schedule(10.0), B.SmootherOptions(slip_cauchy=None, robust="none"))
    pose, Wv = B.initial_guess(prob, run_ekf(log, Schedule(10.0)))
    kf, r = prob.kf, log.robot
    k = 40
    lin = linearize(prob, pose, Wv, k, k + 1)
    values = gtsam.Values()
    for j in (k, k + 1):
        values.insert(X(j), gtsam.Pose2(*pose[j]))
        values.insert(W(j), Wv[j, W_IDX])
        values.insert(S(j), Wv[j, S_IDX])
    # encoder rows 0:2
    f = gf.encoder_factor(W(k), S(k), kf.enc_m[k], gtsam.noiseModel.Diagonal.Sigmas(kf.enc_sigma[k]), r.track_width)
    A = f.linearize(values).jacobian()[0]
    np.testing.assert_allclose(A, lin.A_u[0, 0:2][:, W_COLS + S_COLS], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(f.whitenedError(values), -lin.b_u[0, 0:2], rtol=1e-9, atol=1e-9)
    # first GPS fix of the interval
    g = int(np.searchsorted(kf.gps_k, k))
    f = gf.gps_factor(X(k), W(k), kf.gps_xy[g], kf.gps_tau_vw[g], r.gps_lever_arm,
                      gtsam.noiseModel.Isotropic.Sigma(2, kf.gps_sigma[g]))
    row = 7 + 2 * prob.gps_slot[g]
    A = f.linearize(values).jacobian()[0]
    np.testing.assert_allclose(A, lin.A_u[0, row:row + 2][:, X_COLS + W_COLS], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(f.whitenedError(values), -lin.b_u[0, row:row + 2], rtol=1e-9, atol=1e-9)
    # motion
    f = gf.motion_factor(X(k), W(k), X(k + 1), kf.dt[k], gtsam.noiseModel.Diagonal.Sigmas(1 / prob.motion_whiten[k]))
    A = f.linearize(values).jacobian()[0]
    np.testing.assert_allclose(A[:, :9], lin.A_m0[0][:, X_COLS + W_COLS], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(A[:, 9:], lin.A_m1[0], rtol=1e-9, atol=1e-9)
