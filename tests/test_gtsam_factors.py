"""The GTSAM CustomFactor adapters: their linearisation against numerical
derivatives through GTSAM's own retraction, and equality with the vectorised
linearisation the smoothers use."""
import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import S, W, X

from odomgraph.factors import gtsam_factors as gf

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
        # bent to a path's shape (motion.bend): a factor and an offset
        gf.gps_factor(X(0), W(0), [1.0, 2.0], (0.05, 0.09), (-0.45, 0.1), gtsam.noiseModel.Isotropic.Sigma(2, 0.05),
                      q=(0.9, -0.3, 0.04, -0.02)),
        gf.range_factor(X(0), W(0), 4.0, (0.1, 0.02), [3.0, -2.0], (0.2, 0.0), gtsam.noiseModel.Isotropic.Sigma(1, 0.05),
                        q=(1.2, 0.4, -0.03, 0.05)),
        gf.motion_factor(X(0), W(0), X(1), 0.2, gtsam.noiseModel.Diagonal.Sigmas(np.array([1e-3, 2e-3, 1e-4])),
                         q=(0.95, 0.2, 0.01, 0.03)),
    ]


@pytest.mark.parametrize("i", range(11))
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
                      gtsam.noiseModel.Isotropic.Sigma(2, kf.gps_sigma[g]), q=kf.gps_bend[g])
    row = 7 + 2 * prob.gps_slot[g]
    A = f.linearize(values).jacobian()[0]
    np.testing.assert_allclose(A, lin.A_u[0, row:row + 2][:, X_COLS + W_COLS], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(f.whitenedError(values), -lin.b_u[0, row:row + 2], rtol=1e-9, atol=1e-9)
    # motion
    f = gf.motion_factor(X(k), W(k), X(k + 1), kf.dt[k], gtsam.noiseModel.Diagonal.Sigmas(1 / prob.motion_whiten[k]),
                         q=kf.trans_bend[k])
    A = f.linearize(values).jacobian()[0]
    np.testing.assert_allclose(A[:, :9], lin.A_m0[0][:, X_COLS + W_COLS], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(A[:, 9:], lin.A_m1[0], rtol=1e-9, atol=1e-9)


# ------------------------------------------------------------ edge-case states
# Each: the poses of X(0), X(1), W(0) = (v, omega, gyro_bias, scale_left, scale_right,
# scale_track), S(0), the interval dt, the fix's time tau after X(0), the lever arm,
# and where the beacon sits relative to the antenna at tau (None: 4 m away).
EDGE_STATES = {
    # heading just below +pi, turning left: X(1) is across the wrap at -pi + 0.1
    "heading_at_plus_pi": dict(x0=(2.0, -1.0, np.pi - 1e-9), w=(1.0, 0.5, 0.01, 1.02, 0.97, 1.05), s=(0.01, -0.02),
                               dt=0.2, tau=0.1),
    # just above -pi, turning right: X(1) is across the wrap at +pi - 0.1
    "heading_at_minus_pi": dict(x0=(2.0, -1.0, -np.pi + 1e-9), w=(1.0, -0.5, 0.0, 1.0, 1.0, 1.0), s=(0.0, 0.0),
                                dt=0.2, tau=(0.15, 0.05)),
    # standing still: zero velocity, zero yaw rate, zero slip, zero bias (series branches)
    "standstill": dict(x0=(0.0, 0.0, 0.3), w=(0.0, 0.0, 0.0, 1.0, 1.0, 1.0), s=(0.0, 0.0), dt=0.2, tau=0.1),
    # a pivot: turning on the spot
    "pivot": dict(x0=(1.0, 1.0, -2.0), w=(0.0, 1.2, 0.0, 1.0, 1.0, 1.0), s=(0.0, 0.0), dt=0.2, tau=0.2),
    # scale factors at the divergence limits of the EKF (0.05 and 1 + max_scale_error = 6)
    "scales_low": dict(x0=(5.0, 3.0, 1.0), w=(0.8, 0.4, 0.02, 0.05, 0.05, 0.05), s=(0.3, -0.1), dt=0.2, tau=0.1),
    "scales_high": dict(x0=(5.0, 3.0, 1.0), w=(0.8, -0.4, -0.02, 6.0, 6.0, 6.0), s=(-0.3, 0.2), dt=0.2, tau=0.1),
    # very small steps (a 1 us encoder interval, a fix 1 us after the keyframe)
    "tiny_dt": dict(x0=(-3.0, 4.0, 2.5), w=(1.5, 0.9, 0.0, 1.0, 1.0, 1.0), s=(0.0, 0.0), dt=1e-6, tau=1e-6),
    # a GPS / ranging antenna 5.8 m from the origin
    "large_lever": dict(x0=(1.0, 2.0, 0.7), w=(1.2, 0.6, 0.0, 1.0, 1.0, 1.0), s=(0.0, 0.0), dt=0.2, tau=0.12,
                        lever=(5.0, -3.0)),
    # a beacon 1.1 mm from the antenna
    "beacon_at_antenna": dict(x0=(1.0, 2.0, 0.7), w=(1.2, 0.6, 0.0, 1.0, 1.0, 1.0), s=(0.0, 0.0), dt=0.2,
                              tau=0.12, lever=(0.3, -0.2), beacon_offset=(1e-3, -5e-4)),
}


def _body(theta):
    """d world (x, y, theta) / d body tangent of a Pose2 at heading theta."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


W_NAMES = ("v", "omega", "gyro_bias", "scale_left", "scale_right", "scale_track")


def _w_block(J, inputs):
    """A model Jacobian (m, len(inputs)) as the block on W(k), column by state name."""
    out = np.zeros((J.shape[0], 6))
    for j, name in enumerate(W_NAMES):
        if name in inputs:
            out[:, j] = J[:, inputs.index(name)]
    return out


def _edge_case(name):
    """(values, [(factor, its error by the numpy model, its Jacobian blocks by the numpy
    model with pose blocks in the body-frame tangent)]) of one edge state, in FACTOR_NAMES order."""
    from odomgraph.factors import encoder, gps, gyro, motion, pseudo, ranging, velocity
    c = EDGE_STATES[name]
    lever = c.get("lever", (-0.45, 0.1))
    w, s = np.array(c["w"], float), np.array(c["s"], float)
    tv, tw = (c["tau"], c["tau"]) if np.ndim(c["tau"]) == 0 else c["tau"]
    values = gtsam.Values()
    values.insert(X(0), gtsam.Pose2(*c["x0"]))
    x0, y0, th0 = (values.atPose2(X(0)).x(), values.atPose2(X(0)).y(), values.atPose2(X(0)).theta())
    # X(1): the flown arc, off by a few mm and mrad (its residual is small, not 2 pi)
    p1, _ = motion.propagate(x0, y0, th0, w[0], w[1], c["dt"])
    values.insert(X(1), gtsam.Pose2(p1[0] + 3e-3, p1[1] - 2e-3, p1[2] + 1e-3))
    values.insert(W(0), w)
    values.insert(S(0), s)
    x1 = values.atPose2(X(1))
    unit = gtsam.noiseModel.Unit.Create
    cases = []
    # encoder
    z = np.array([0.7, 0.9])
    h, J = encoder.wheel_speeds(w[0], w[1], s[0], s[1], w[3], w[4], w[5], 0.6)
    cases.append((gf.encoder_factor(W(0), S(0), z, unit(2), 0.6), h - z,
                  [_w_block(J, encoder.INPUTS), J[:, [encoder.INPUTS.index("slip_left"),
                                                      encoder.INPUTS.index("slip_right")]]]))
    # gyro, velocity sensor
    h, J = gyro.yaw_rate(w[1], w[2])
    cases.append((gf.gyro_factor(W(0), 0.25, unit(1)), h - 0.25, [_w_block(J, gyro.INPUTS)]))
    z = np.array([0.5, -0.2])
    h, J = velocity.body_velocity(w[0], w[1])
    cases.append((gf.velocity_factor(W(0), z, unit(2)), h - z, [_w_block(J, velocity.INPUTS)]))
    # GPS at tau on the arc from X(0)
    pa, Ja = motion.arc_at(x0, y0, th0, w[0], w[1], tv, tw)
    z = np.array([x0 + 0.3, y0 - 0.4])
    h, Jh = gps.antenna_position(pa[0], pa[1], pa[2], lever)
    # the antenna by hand: the arc's end plus the rotated lever arm
    np.testing.assert_allclose(h, pa[:2] + _body(pa[2])[:2, :2] @ np.array(lever), rtol=0, atol=1e-12)
    Jt = Jh @ Ja
    cases.append((gf.gps_factor(X(0), W(0), z, c["tau"], lever, unit(2)), h - z,
                  [Jt[:, 0:3] @ _body(th0), _w_block(Jt[:, 3:5], ("v", "omega"))]))
    # range from the antenna at tau
    off = c.get("beacon_offset")
    beacon = h + (np.array(off) if off is not None else np.array([4.0, 0.0]))
    hr, Jr = ranging.beacon_range(pa[0], pa[1], pa[2], beacon, lever)
    np.testing.assert_allclose(hr[0], np.hypot(*(h - beacon)), rtol=1e-12)
    Jt = Jr[:, 0:3] @ Ja
    zr = 0.5 if off is None else 0.0
    cases.append((gf.range_factor(X(0), W(0), zr, c["tau"], beacon, lever, unit(1)), hr - zr,
                  [Jt[:, 0:3] @ _body(th0), _w_block(Jt[:, 3:5], ("v", "omega"))]))
    # motion X(0) -> X(1); its residual is GTSAM's own Pose2.between of the prediction and X(1)
    e, J0, J1 = motion.transition_residual(x0, y0, th0, w[0], w[1], c["dt"], x1.x(), x1.y(), x1.theta())
    between = gtsam.Pose2(*motion.propagate(x0, y0, th0, w[0], w[1], c["dt"])[0]).between(x1)
    np.testing.assert_allclose(e, [between.x(), between.y(), between.theta()], rtol=0, atol=1e-12)
    cases.append((gf.motion_factor(X(0), W(0), X(1), c["dt"], unit(3)), e,
                  [J0[:, 0:3] @ _body(th0), _w_block(J0[:, 3:5], ("v", "omega")), J1 @ _body(x1.theta())]))
    # the pseudo-updates
    h, J = pseudo.zero_slip(s[0], s[1])
    cases.append((gf.zero_slip_factor(S(0), unit(2)), h, [J]))
    held = np.array([1.0, 0.5, 2.0])
    h, J = pseudo.hold_scale(w[3], w[4], w[5])
    cases.append((gf.hold_scale_factor(W(0), held, unit(3)), h - held, [_w_block(J, pseudo.HOLD_SCALE_INPUTS)]))
    return values, cases


FACTOR_NAMES = ("encoder", "gyro", "velocity", "gps", "range", "motion", "zero_slip", "hold_scale")


@pytest.mark.parametrize("name", list(EDGE_STATES))
def test_custom_factors_at_edge_states_equal_the_numpy_models(name):
    """At each edge state every adapter's error and Jacobian are the pure-numpy
    model's (pose blocks in GTSAM's body-frame tangent), to rounding, and the
    Jacobian is the numerical derivative through GTSAM's retraction."""
    values, cases = _edge_case(name)
    for fname, (factor, err, blocks) in zip(FACTOR_NAMES, cases):
        e = factor.unwhitenedError(values)
        assert np.all(np.isfinite(e)), (name, fname, e)
        np.testing.assert_allclose(e, np.ravel(err), rtol=1e-12, atol=1e-12, err_msg=f"{name} {fname}")
        A, b = factor.linearize(values).jacobian()
        np.testing.assert_allclose(b, -np.ravel(err), rtol=1e-12, atol=1e-12, err_msg=f"{name} {fname}")
        np.testing.assert_allclose(A, np.hstack(blocks), rtol=1e-12, atol=1e-12, err_msg=f"{name} {fname}")
        num = np.hstack(numeric_blocks(factor, values, eps=1e-7 if name == "beacon_at_antenna" else 1e-6))
        scale = 1 + np.abs(num).max()
        np.testing.assert_allclose(A, num, rtol=1e-6, atol=2e-7 * scale, err_msg=f"{name} {fname}")
    if name.startswith("heading"):
        # the motion residual's heading is wrapped: mrad, not 2 pi
        e = cases[FACTOR_NAMES.index("motion")][0].unwhitenedError(values)
        assert abs(e[2]) < 5e-3, e


def test_range_factor_at_the_beacon_is_finite():
    """A beacon exactly at the antenna: the range model's subgradient 0, not NaN."""
    from odomgraph.factors import motion, ranging
    values, _ = _edge_case("beacon_at_antenna")
    c = EDGE_STATES["beacon_at_antenna"]
    p = values.atPose2(X(0))
    w = values.atVector(W(0))
    pa, _ = motion.arc_at(p.x(), p.y(), p.theta(), w[0], w[1], c["tau"], c["tau"])
    lx, ly = c["lever"]
    cth, sth = np.cos(pa[2]), np.sin(pa[2])
    beacon = np.array([pa[0] + lx * cth - ly * sth, pa[1] + lx * sth + ly * cth])
    h, J = ranging.beacon_range(pa[0], pa[1], pa[2], beacon, c["lever"])
    assert h[0] < 1e-12 and np.all(J[0, 0:3] == 0)
    f = gf.range_factor(X(0), W(0), 0.02, c["tau"], beacon, c["lever"], gtsam.noiseModel.Unit.Create(1))
    np.testing.assert_allclose(f.unwhitenedError(values), h - 0.02, atol=1e-12)
    A, _ = f.linearize(values).jacobian()
    assert np.all(np.isfinite(A)) and np.all(A == 0)
