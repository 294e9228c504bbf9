"""The EKF's default hold (Hold.consider) against a textbook Schmidt-Kalman filter.

After the schedule's switch the EKF zeroes the Kalman gain rows of the three
scale factors and updates the covariance in Joseph form (ekf.EKF.update). The
reference below is written from the textbook instead, densely and without
the EKF's code: the state splits into estimated states a and considered
states b (the scale factors once the schedule holds them, none before), and
a measurement with Jacobian H = [H_a H_b] and noise R updates

    S     = H P H' + R
    K_a   = (P_aa H_a' + P_ab H_b') S^-1,         K_b = 0
    x_a  += K_a y,                                 x_b unchanged
    P_aa -= K_a S K_a'
    P_ab -= K_a (H_a P_ab + H_b P_bb),             P_ba = P_ab'
    P_bb  unchanged

(Schmidt's consider update; with b empty, the Kalman filter). Before the
switch, an encoder update considers one direction instead, the common scale
(EKFOptions.encoder_scale_gain): the same update in orthonormal coordinates
whose last axis is that direction. Its prediction
is the exact-arc motion model with the process noise of the EKF's module
docstring, built as one dense Q. Both run over the same measurements from the
same initial state, and every state and covariance they produce agree to
1e-10: a gain row of a held state left non-zero, a short-form covariance
(I - K H) P with the suboptimal gain, or a consider covariance that drops the
scale factors' uncertainty from the other states would each be far off.
"""
import numpy as np
import pytest

from odomgraph import state as S
from odomgraph.estimators.ekf import EKF
from odomgraph.estimators.measurements import slip_intensity
from odomgraph.estimators.schedule import Hold, Schedule
from odomgraph.factors import encoder, gps, gyro, pseudo, ranging, velocity
from odomgraph.factors.motion import propagate
from odomgraph.sim.scenarios import Rates, beacons_around, paper
from odomgraph.sim.simulate import simulate

SCALE = [S.SCALE_L, S.SCALE_R, S.SCALE_B]


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def schmidt_update(x, P, y, H, R, considered):
    """Dense Schmidt-Kalman update of (x, P) by innovation y (m,), H (m, n), R (m, m);
    ``considered``: the indices of the states held (gain 0)."""
    n = len(x)
    b = np.asarray(considered, int)
    a = np.setdiff1d(np.arange(n), b)
    Ha, Hb = H[:, a], H[:, b]
    Paa, Pab, Pbb = P[np.ix_(a, a)], P[np.ix_(a, b)], P[np.ix_(b, b)]
    Sm = H @ P @ H.T + R
    Ka = (Paa @ Ha.T + Pab @ Hb.T) @ np.linalg.inv(Sm)
    x = x.copy()
    x[a] += Ka @ y
    out = P.copy()
    out[np.ix_(a, a)] = Paa - Ka @ Sm @ Ka.T
    if b.size:
        out[np.ix_(a, b)] = Pab - Ka @ (Ha @ Pab + Hb @ Pbb)
        out[np.ix_(b, a)] = out[np.ix_(a, b)].T
        out[np.ix_(b, b)] = Pbb
    return x, out


def schmidt_update_along(x, P, y, H, R, u):
    """The Schmidt update with one direction u (n,) (unit) considered: in
    orthonormal coordinates whose last axis is u that axis is a considered
    state (schmidt_update), and the result is rotated back."""
    n = len(x)
    Q, _ = np.linalg.qr(np.column_stack([u, np.eye(n)]))
    T = np.roll(Q, -1, axis=1)                  # last column +-u, the rest spans its complement
    z, Pz = schmidt_update(T.T @ x, T.T @ P @ T, y, H @ T, R, [n - 1])
    return T @ z, T @ Pz @ T.T


def common_scale(x):
    """The wheels' blind direction (EKFOptions.encoder_scale_gain): ticks/m
    left and right up, the track scale down, by the same relative amount."""
    u = np.zeros(S.N)
    u[SCALE] = x[SCALE] * np.array([1.0, 1.0, -1.0])
    return u / np.linalg.norm(u)


def dense_predict(x, P, dt, pn, q_slip):
    """Exact-arc prediction over dt; process noise entering uniformly inside the step:
    Q_pose,pose = dt/3 G Q_r G', Q_pose,r = dt/2 G Q_r, Q_r,r = dt Q_r for r = (v, omega),
    G = d pose / d (v, omega); random walks dt q on bias, slips and scale factors."""
    pose, J = propagate(x[0], x[1], x[2], x[3], x[4], dt)
    F = np.eye(S.N)
    F[0:3, 0:5] = J
    G = J[:, 3:5]
    Qr = np.diag([pn.accel**2, pn.yaw_accel**2])
    Q = np.zeros((S.N, S.N))
    Q[0:3, 0:3] = dt / 3 * G @ Qr @ G.T
    Q[0:3, 3:5] = dt / 2 * G @ Qr
    Q[3:5, 0:3] = Q[0:3, 3:5].T
    Q[3:5, 3:5] = dt * Qr
    Q[S.BIAS, S.BIAS] = dt * pn.gyro_bias**2
    Q[6:8, 6:8] = dt * q_slip
    Q[8:11, 8:11] = dt * pn.scale**2 * np.eye(3)
    x = x.copy()
    x[0:3] = pose[0], pose[1], _wrap(pose[2])
    return x, F @ P @ F.T + Q


def _dense(J, cols):
    H = np.zeros((J.shape[0], S.N))
    H[:, cols] = J
    return H


def reference_run(ekf: EKF, t_switch: float):
    """The textbook filter over ekf's measurements: (wheel rows' times, states, covariances)."""
    m, r, pn = ekf.meas, ekf.robot, ekf.robot.process
    q_slip = slip_intensity(pn, m)
    events = [(t, 0, i) for i, t in enumerate(m.wheel.t)]
    for code, src in ((1, m.gyro), (2, m.gps), (3, m.ranges), (4, m.velocity)):
        if src is not None:
            events += [(t, code, i) for i, t in enumerate(src[0])]
    events = sorted(e for e in events if e[0] >= ekf.init.t)   # by time, then sensor code
    x, P, t_now = ekf.init.x.copy(), ekf.init.P.copy(), ekf.init.t
    rows_t, rows_x, rows_P = [], [], []
    for t, code, i in events:
        if t > t_now:
            x, P = dense_predict(x, P, t - t_now, pn, q_slip)
            t_now = t
        held = SCALE if t >= t_switch else []
        if code == 0:
            if not held:          # calibrating: the zero-slip pseudo-measurement first (eq. 35-36)
                h, J = pseudo.zero_slip(x[6], x[7])
                x, P = schmidt_update(x, P, -h, _dense(J, [6, 7]), np.eye(2) * pn.pseudo_slip_sigma**2, held)
            h, J = encoder.wheel_speeds(*x[[3, 4, 6, 7, 8, 9, 10]], r.track_width)
            y, H, R = m.wheel.m[i] - h, _dense(J, [3, 4, 6, 7, 8, 9, 10]), np.diag(m.wheel.sigma[i] ** 2)
        elif code == 1:
            h, J = gyro.yaw_rate(x[4], x[5])
            y, H, R = m.gyro[1][i] - h, _dense(J, [4, 5]), np.array([[r.gyro_sigma**2]])
        elif code == 2:
            h, J = gps.antenna_position(x[0], x[1], x[2], r.gps_lever_arm)
            y, H, R = m.gps[1][i] - h, _dense(J, [0, 1, 2]), np.eye(2) * m.gps[2][i] ** 2
        elif code == 3:
            h, J = ranging.beacon_range(x[0], x[1], x[2], m.ranges[1][i], r.range_lever_arm)
            y, H, R = m.ranges[2][i] - h, _dense(J[:, 0:3], [0, 1, 2]), np.array([[r.range_sigma**2]])
        else:
            h, J = velocity.body_velocity(x[3], x[4])
            y, H, R = m.velocity[1][i] - h, _dense(J, [3, 4]), np.diag(np.square(r.velocity_sigma))
        if code == 0 and not held:   # the encoders say nothing along the common scale
            x, P = schmidt_update_along(x, P, y, H, R, common_scale(x))
        else:
            x, P = schmidt_update(x, P, y, H, R, held)
        x[2] = _wrap(x[2])
        if code == 0:
            rows_t.append(t)
            rows_x.append(x.copy())
            rows_P.append(P.copy())
    return np.array(rows_t), np.array(rows_x), np.array(rows_P), x, P


def _gps_gyro_log():
    return simulate(paper(30), 2).truncated(9.0)


def _ranges_velocity_log():
    sc = paper(30).with_(rates=Rates(gyro=0, gps=0, ranges=10, velocity=10))
    sc = sc.with_(robot=sc.robot.with_(beacons=beacons_around(0, 20, -6, 12), range_sigma=0.05,
                                       range_lever_arm=(0.2, -0.1)))
    return simulate(sc, 2).truncated(9.0)


@pytest.mark.parametrize("make_log", [_gps_gyro_log, _ranges_velocity_log])
def test_consider_hold_equals_a_textbook_schmidt_kalman_filter(make_log):
    log = make_log()
    ekf = EKF(log, Schedule(calibrate_until=4.0, hold=Hold.consider))
    # the plain case: nothing pinned, no slip stretches in the window, no gating
    assert not ekf.init.observability.unobservable and not ekf.init.slipping
    est = ekf.run()
    assert est.rejected == {} and est.recoveries == []
    t_ref, x_ref, P_ref, x_end, P_end = reference_run(ekf, est.t_switch)
    np.testing.assert_array_equal(est.t, t_ref)
    after = est.t >= est.t_switch
    assert after.sum() > 80 and (~after).sum() > 60        # ~100 wheel updates either side (5 s at 20 Hz)
    # every state after every wheel update, and the covariance, to 1e-10 (measured:
    # states 4e-14 / 2e-13 apart, sigma 7e-14 / 8e-14, the final covariance 2e-13 / 7e-12
    # of its standard deviations, on the two logs; a gain row left on, the short form
    # (I - K H) P, or the scale cross-covariance dropped: 1e-3 .. 1 off)
    np.testing.assert_allclose(est.mean, x_ref, rtol=0, atol=1e-10)
    np.testing.assert_allclose(est.sigma, np.sqrt(np.diagonal(P_ref, axis1=1, axis2=2)), rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(est.pose_cov, P_ref[:, 0:3, 0:3], rtol=0, atol=1e-12)
    # the full final covariance, entry by entry relative to its standard deviations
    d = np.sqrt(np.diag(P_end))
    np.testing.assert_allclose(ekf.x, x_end, rtol=0, atol=1e-10)
    np.testing.assert_allclose(ekf.P / np.outer(d, d), P_end / np.outer(d, d), rtol=0, atol=1e-10)
    # held means held: after the switch the scale factors and their covariance stay
    # those of the first row after it (no scale random walk by default)
    k = int(np.argmax(after))
    np.testing.assert_array_equal(est.mean[after][:, SCALE], np.broadcast_to(est.mean[k, SCALE], (after.sum(), 3)))
    np.testing.assert_array_equal(P_ref[after][:, 8:11, 8:11], np.broadcast_to(P_ref[k, 8:11, 8:11],
                                                                               (after.sum(), 3, 3)))
    assert np.abs(est.mean[k, SCALE] - est.mean[0, SCALE]).max() > 1e-4   # ...and they did move before it
    # ...while the considered uncertainty still reaches the estimated states:
    # the scale-slip cross-covariance is alive after the switch
    assert np.abs(P_end[6:8, 8:11]).max() > 1e-3 * d[6:8].max() * d[8:11].max()
