"""Every model Jacobian against central differences, at random states and at
the edge cases (omega ~ 0 on both sides of the series branch, theta ~ +-pi,
range ~ 0, zero velocity)."""
import numpy as np
import pytest

from odomgraph.factors import encoder, gps, gyro, motion, pseudo, ranging, velocity
from odomgraph.factors._math import dsinc, sinc, wrap_angle

RNG = np.random.default_rng(7)


def numeric_jacobian(fun, args, n_out, eps=1e-6):
    """Central-difference Jacobian of fun(*args) (first output) w.r.t. each arg."""
    args = [float(a) for a in args]
    J = np.zeros((n_out, len(args)))
    for k in range(len(args)):
        hi, lo = list(args), list(args)
        hi[k] += eps
        lo[k] -= eps
        J[:, k] = (np.ravel(fun(*hi)[0]) - np.ravel(fun(*lo)[0])) / (2 * eps)
    return J


def random_states(n):
    return [
        dict(x=RNG.normal(0, 10), y=RNG.normal(0, 10), theta=RNG.uniform(-np.pi, np.pi),
             v=RNG.normal(0, 1.5), omega=RNG.normal(0, 1.0))
        for _ in range(n)
    ]


EDGE = [
    dict(x=1.0, y=-2.0, theta=np.pi - 1e-9, v=1.0, omega=0.0),
    dict(x=1.0, y=-2.0, theta=-np.pi + 1e-9, v=1.0, omega=1e-9),
    dict(x=0.0, y=0.0, theta=0.3, v=0.0, omega=0.0),
    dict(x=0.0, y=0.0, theta=0.3, v=0.0, omega=0.8),      # pivot
    dict(x=3.0, y=1.0, theta=2.0, v=1.2, omega=1.9e-4),   # just above the series switch
    dict(x=3.0, y=1.0, theta=2.0, v=1.2, omega=2.1e-4),   # and just below (dt = 1)
]


@pytest.mark.parametrize("s", random_states(20) + EDGE)
@pytest.mark.parametrize("dt", [0.05, 1.0, 7.5])
def test_motion_jacobian(s, dt):
    fun = lambda x, y, th, v, w: motion.propagate(x, y, th, v, w, dt)
    args = [s[k] for k in motion.INPUTS]
    _, J = motion.propagate(*args, dt)
    np.testing.assert_allclose(J, numeric_jacobian(fun, args, 3), atol=1e-6 * max(1, dt**2))


def test_motion_is_the_exact_arc():
    # Closed-form arc v/omega (sin(theta + a) - sin theta) for a = omega dt.
    th, v, w, dt = 0.3, 1.2, 0.9, 0.4
    pose, _ = motion.propagate(0, 0, th, v, w, dt)
    a = w * dt
    exact = [v / w * (np.sin(th + a) - np.sin(th)), -v / w * (np.cos(th + a) - np.cos(th)), th + a]
    np.testing.assert_allclose(pose, exact, atol=1e-14)
    # omega -> 0 is a straight line, continuous with the arc.
    pose0, _ = motion.propagate(0, 0, th, v, 0.0, dt)
    np.testing.assert_allclose(pose0, [v * dt * np.cos(th), v * dt * np.sin(th), th], atol=1e-15)
    pose_eps, _ = motion.propagate(0, 0, th, v, 1e-7, dt)
    np.testing.assert_allclose(pose_eps, pose0, atol=1e-7)


@pytest.mark.parametrize("s", random_states(20) + EDGE)
@pytest.mark.parametrize("dt", [0.05, 0.2, 1.0])
def test_velocity_between_inverts_the_arc(s, dt):
    """The velocity read off two poses flies the arc between them: propagate
    returns the second pose to 1e-9 (on arcs that turn less than half a turn,
    which wrap_angle can tell apart), and transition_residual is zero."""
    if abs(s["omega"] * dt) >= np.pi:
        pytest.skip("turns half a turn or more within dt")
    args = [s[k] for k in motion.INPUTS]
    p1, _ = motion.propagate(*args, dt)
    v, w = motion.velocity_between(s["x"], s["y"], s["theta"], p1[0], p1[1], wrap_angle(p1[2]), dt)
    assert v == pytest.approx(s["v"], abs=1e-9) and w == pytest.approx(s["omega"], abs=1e-9)
    e, _, _ = motion.transition_residual(s["x"], s["y"], s["theta"], v, w, dt, p1[0], p1[1], p1[2])
    np.testing.assert_allclose(e, 0.0, atol=1e-9)


def test_velocity_between_leaves_only_the_sideways_part():
    """Two poses no arc joins (the second moved 5 cm sideways): the heading and
    along-track residuals are zero, the lateral one is the 5 cm."""
    p1, _ = motion.propagate(1.0, 2.0, 0.4, 0.8, 0.6, 0.5)
    side = np.array([-np.sin(p1[2]), np.cos(p1[2])]) * 0.05
    v, w = motion.velocity_between(1.0, 2.0, 0.4, p1[0] + side[0], p1[1] + side[1], p1[2], 0.5)
    e, _, _ = motion.transition_residual(1.0, 2.0, 0.4, v, w, 0.5, p1[0] + side[0], p1[1] + side[1], p1[2])
    assert abs(e[0]) < 1e-12 and abs(e[2]) < 1e-12 and e[1] == pytest.approx(0.05, abs=1e-12)


@pytest.mark.parametrize("s", random_states(10) + EDGE)
@pytest.mark.parametrize("tau", [(0.05, 0.05), (0.1, 0.03), (0.0, 0.2), (0.2, 0.0)])
def test_arc_at_jacobian_and_equal_times(s, tau):
    args = [s[k] for k in motion.INPUTS]
    fun = lambda x, y, th, v, w: motion.arc_at(x, y, th, v, w, *tau)
    p, J = motion.arc_at(*args, *tau)
    np.testing.assert_allclose(J, numeric_jacobian(fun, args, 3), atol=1e-6)
    if tau[0] == tau[1]:
        p2, J2 = motion.propagate(*args, tau[0])
        np.testing.assert_allclose(p, p2, atol=1e-14)
        np.testing.assert_allclose(J, J2, atol=1e-14)
    # distance travelled v tau_v, turned omega tau_omega
    assert p[2] == pytest.approx(s["theta"] + s["omega"] * tau[1], abs=1e-12)


def test_motion_broadcasts():
    n = 50
    st = random_states(n)
    cols = [np.array([s[k] for s in st]) for k in motion.INPUTS]
    dts = RNG.uniform(0.01, 2, n)
    P, J = motion.propagate(*cols, dts)
    assert P.shape == (n, 3) and J.shape == (n, 3, 5)
    for i in (0, 17, 49):
        p1, j1 = motion.propagate(*(c[i] for c in cols), dts[i])
        np.testing.assert_array_equal(P[i], p1)
        np.testing.assert_array_equal(J[i], j1)


@pytest.mark.parametrize("x", [0.0, 1e-5, -1e-5, 9.9e-5, 1.01e-4, 0.3, -2.0, 10.0])
def test_sinc_branches_agree(x):
    ref = np.sin(x) / x if x != 0 else 1.0
    assert sinc(x) == pytest.approx(ref, rel=1e-14, abs=1e-15)
    eps = 1e-6
    ref_d = (np.sin(x + eps) / (x + eps) - np.sin(x - eps) / (x - eps)) / (2 * eps) if x != 0 else 0.0
    assert dsinc(x) == pytest.approx(ref_d, abs=1e-8)


def test_wrap_angle_convention():
    np.testing.assert_allclose(wrap_angle([np.pi, -np.pi, 3 * np.pi, 0.1 - 2 * np.pi]), [np.pi, np.pi, np.pi, 0.1])


def encoder_args():
    out = []
    for s in random_states(15):
        out.append([s["v"], s["omega"], RNG.normal(0, 0.3), RNG.normal(0, 0.3),
                    RNG.uniform(0.9, 1.1), RNG.uniform(0.9, 1.1), RNG.uniform(0.9, 1.1)])
    out.append([0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0])   # standing still
    out.append([0.0, 0.9, 0.5, 0.0, 1.02, 0.97, 1.05])  # pivot while one wheel spins
    return out


@pytest.mark.parametrize("args", encoder_args())
def test_encoder_jacobian(args):
    track = 0.6
    fun = lambda *a: encoder.wheel_speeds(*a, track)
    _, J = encoder.wheel_speeds(*args, track)
    np.testing.assert_allclose(J, numeric_jacobian(fun, args, 2), atol=1e-8)


def test_encoder_matches_log_format_convention():
    # LOG_FORMAT: m_left = scale_left * (v - omega*scale_track*track/2 + slip_left)
    v, w, sl, sr, kl, kr, kb, b = 0.8, 0.4, 0.05, -0.02, 1.03, 0.97, 1.05, 0.6
    m, _ = encoder.wheel_speeds(v, w, sl, sr, kl, kr, kb, b)
    assert m[0] == pytest.approx(kl * (v - w * kb * b / 2 + sl), rel=1e-15)
    assert m[1] == pytest.approx(kr * (v + w * kb * b / 2 + sr), rel=1e-15)
    # body_velocity inverts wheel_speeds exactly.
    v2, w2 = encoder.body_velocity(m[0], m[1], sl, sr, kl, kr, kb, b)
    assert (v2, w2) == (pytest.approx(v, abs=1e-15), pytest.approx(w, abs=1e-15))


def test_encoder_sigma_eq41_and_quantisation():
    assert encoder.speed_sigma(2.0, 0.005, 0.01) == pytest.approx(0.025)
    # one tick per 0.02 s at 1500 ticks/m, uniform-difference variance 1/6 tick^2
    q = encoder.speed_sigma(0.0, 0.0, 0.0, 1500.0, 0.02)
    assert q == pytest.approx(1 / (1500 * 0.02) / np.sqrt(6))


LEVERS = [(-0.45, 0.0), (0.3, 0.15), (0.0, 0.0)]


@pytest.mark.parametrize("s", random_states(10) + EDGE)
@pytest.mark.parametrize("lever", LEVERS)
def test_gps_jacobian(s, lever):
    fun = lambda x, y, th: gps.antenna_position(x, y, th, lever)
    args = [s["x"], s["y"], s["theta"]]
    h, J = gps.antenna_position(*args, lever)
    np.testing.assert_allclose(J, numeric_jacobian(fun, args, 2), atol=1e-8)
    # eq. 8: the antenna sits at the lever arm rotated into the world frame
    c, sn = np.cos(s["theta"]), np.sin(s["theta"])
    np.testing.assert_allclose(h, [s["x"] + lever[0] * c - lever[1] * sn, s["y"] + lever[0] * sn + lever[1] * c])


def test_gyro_and_velocity_and_pseudo_jacobians():
    for args in ([0.3, 0.02], [0.0, 0.0], [-1.2, -0.05]):
        _, J = gyro.yaw_rate(*args)
        np.testing.assert_allclose(J, numeric_jacobian(gyro.yaw_rate, args, 1))
        _, J = velocity.body_velocity(*args)
        np.testing.assert_allclose(J, numeric_jacobian(velocity.body_velocity, args, 2))
        _, J = pseudo.zero_slip(*args)
        np.testing.assert_allclose(J, numeric_jacobian(pseudo.zero_slip, args, 2))
    args = [1.02, 0.97, 1.05]
    _, J = pseudo.hold_scale(*args)
    np.testing.assert_allclose(J, numeric_jacobian(pseudo.hold_scale, args, 3))


@pytest.mark.parametrize("s", random_states(10) + EDGE)
@pytest.mark.parametrize("lever", LEVERS)
def test_range_jacobian(s, lever):
    beacon = np.array([4.0, -3.0])
    fun = lambda x, y, th, b: ranging.beacon_range(x, y, th, beacon, lever, b)
    args = [s["x"], s["y"], s["theta"], 0.1]
    _, J = ranging.beacon_range(*args[:3], beacon, lever, args[3])
    np.testing.assert_allclose(J, numeric_jacobian(fun, args, 1), atol=1e-7)


@pytest.mark.parametrize("r", [1e-3, 1e-6])
def test_range_jacobian_near_zero_range(r):
    # Just outside the singular branch the analytic Jacobian is still exact.
    beacon = np.array([1.0, 2.0])
    fun = lambda x, y, th, b: ranging.beacon_range(x, y, th, beacon, (0, 0), b)
    args = [1.0 + r * 0.6, 2.0 + r * 0.8, 0.4, 0.0]
    h, J = ranging.beacon_range(*args[:3], beacon)
    assert h[0] == pytest.approx(r, rel=1e-9)
    np.testing.assert_allclose(J, numeric_jacobian(fun, args, 1, eps=r * 1e-3), atol=1e-6)


def test_range_at_the_beacon_is_finite():
    h, J = ranging.beacon_range(1.0, 2.0, 0.4, np.array([1.0, 2.0]))
    assert h[0] == 0.0
    assert np.all(np.isfinite(J)) and np.allclose(J[0, :3], 0.0)


MODEL_CASES = [
    (lambda a: encoder.wheel_speeds(*a, 0.6), 7),
    (lambda a: gps.antenna_position(*a, (-0.45, 0.1)), 3),
    (lambda a: gyro.yaw_rate(*a), 2),
    (lambda a: ranging.beacon_range(a[0], a[1], a[2], np.array([3.0, -1.0]), (0.2, 0.0), a[3]), 4),
    (lambda a: velocity.body_velocity(*a), 2),
    (lambda a: pseudo.zero_slip(*a), 2),
    (lambda a: pseudo.hold_scale(*a), 3),
]


@pytest.mark.parametrize("fun,n_args", MODEL_CASES)
def test_every_model_broadcasts_and_matches_its_scalar_path(fun, n_args):
    # The EKF uses the scalar fast paths, the smoother and Monte-Carlo the array
    # paths: both must give identical numbers.
    cols = [RNG.normal(1.0, 0.5, 40) for _ in range(n_args)]
    H, J = fun(cols)
    assert H.shape[0] == 40 and J.shape[0] == 40
    for i in (0, 13, 39):
        h1, j1 = fun([float(c[i]) for c in cols])
        np.testing.assert_allclose(H[i], h1, rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(J[i], j1, rtol=1e-14, atol=1e-15)


@pytest.mark.parametrize("s", random_states(10) + EDGE)
@pytest.mark.parametrize("dt", [0.05, 0.4])
def test_transition_residual_jacobians(s, dt):
    x1 = [s["x"] + 0.3, s["y"] - 0.2, s["theta"] + 0.1]
    args0 = [s[k] for k in motion.INPUTS]
    e, J0, J1 = motion.transition_residual(*args0, dt, *x1)
    f0 = lambda *a: (motion.transition_residual(*a, dt, *x1)[0],)
    f1 = lambda *a: (motion.transition_residual(*args0, dt, *a)[0],)
    np.testing.assert_allclose(J0, numeric_jacobian(f0, args0, 3), atol=1e-6)
    np.testing.assert_allclose(J1, numeric_jacobian(f1, x1, 3), atol=1e-6)
    # exactly on the arc, the residual is zero
    p, _ = motion.propagate(*args0, dt)
    e0, _, _ = motion.transition_residual(*args0, dt, *p)
    np.testing.assert_allclose(e0, 0.0, atol=1e-12)


def test_pose2_retract_and_body_jacobian_match_gtsam():
    import gtsam
    from odomgraph.factors import pose2
    for _ in range(20):
        x, y, th = RNG.normal(0, 5), RNG.normal(0, 5), RNG.uniform(-np.pi, np.pi)
        d = RNG.normal(0, 0.3, 3)
        ref = gtsam.Pose2(x, y, th).retract(d)
        got = pose2.retract(x, y, th, d)
        np.testing.assert_allclose([got[0], got[1], np.angle(np.exp(1j * got[2]))],
                                   [ref.x(), ref.y(), ref.theta()], atol=1e-12)
    # body Jacobian of the GPS model against a numerical derivative through gtsam's retract
    x, y, th, lever = 2.0, -1.0, 2.5, (-0.45, 0.2)
    _, Jw = gps.antenna_position(x, y, th, lever)
    Jb = pose2.to_body(Jw, th)
    num = np.zeros((2, 3))
    for k in range(3):
        d = np.zeros(3); d[k] = 1e-6
        hp = gtsam.Pose2(x, y, th).retract(d); hm = gtsam.Pose2(x, y, th).retract(-d)
        num[:, k] = (gps.antenna_position(hp.x(), hp.y(), hp.theta(), lever)[0]
                     - gps.antenna_position(hm.x(), hm.y(), hm.theta(), lever)[0]) / 2e-6
    np.testing.assert_allclose(Jb, num, atol=1e-7)


def test_robust_sigma_is_a_gaussians_sigma_unmoved_by_outliers():
    """factors._math.robust_sigma: 1.4826 median |x| is the sigma of zero-mean
    Gaussian samples (within 2 % at 20 000 of them). With 20 % of them
    replaced by outliers 50 sigma out it grows to 1.32 sigma (the median of
    |x| is then the kept samples' 62.5th percentile, 0.887 sigma), where the
    mean absolute value grows 12-fold."""
    from odomgraph.factors._math import MAD_SIGMA, robust_sigma
    rng = np.random.default_rng(5)
    x = 0.3 * rng.standard_normal(20_000)
    assert abs(robust_sigma(x) / 0.3 - 1.0) < 0.02
    assert robust_sigma(x) == MAD_SIGMA * float(np.median(np.abs(x)))
    y = x.copy()
    y[: 4_000] = 15.0 * rng.choice([-1.0, 1.0], 4_000)
    assert abs(robust_sigma(y) / 0.3 - 1.315) < 0.04, robust_sigma(y) / 0.3
    assert np.mean(np.abs(y)) > 10 * np.mean(np.abs(x))
