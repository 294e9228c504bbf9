"""The paper's EKF over many runs at once, vectorised over runs in numpy.

A Monte-Carlo grid point filters N logs that differ only in their noise: same
robot, same motion, same sensor timestamps (``simulate(..., timing_seed=)``).
Their event streams are then identical, so one pass over the events can
update all N states together: state (N, 11), covariance (N, 11, 11), the same
``factors`` models (they broadcast) and the same equations as ``ekf.EKF``.
Python's per-event overhead is paid once instead of N times. The result for
each run equals ``run_ekf`` on that log to rounding (a test checks 1e-9).

A run that diverges is reported as its EstimatorDivergedError and frozen;
the others go on.
"""
from __future__ import annotations

import time

import numpy as np

from odomgraph.factors import encoder, gps, gyro, pseudo, ranging, velocity
from odomgraph.factors._math import wrap_angle
from odomgraph.factors.motion import propagate
from odomgraph import state as S
from odomgraph.errors import EstimatorDivergedError
from odomgraph.estimators.ekf import (GATE_HISTORY, MAX_RECOVERIES, EKFOptions, departed, departure_note,
                                      departure_possible, departure_widening, event_values, gate_thresholds,
                                      held_directions,
                                      huber_widening, jumped, make_estimate, reacquire_widening, watch_widening)
from odomgraph.estimators.sensors import (DOF, ENC_IDX, GATED, GPS, GYRO, GYRO_IDX, POSE_IDX, RANGE, SCALE_IDX,
                                         SENSOR_NAMES, SLIP_IDX, VEL, VEL_IDX, WHEEL, event_stream)
from odomgraph.estimators.initial import initial_state
from odomgraph.estimators.measurements import from_log, slip_intensity
from odomgraph.observability import decondition, held_pins
from odomgraph.estimators.slipcheck import in_stretches, in_window
from odomgraph.estimators.standstill import JITTER, StillWatch
from odomgraph.result import Estimate
from odomgraph.estimators.schedule import Hold, Schedule
from odomgraph.io.log import Log

_I = np.eye(S.N)


def add_process_noise_many(P: np.ndarray, J: np.ndarray, dt: float, q: dict, q_slip: np.ndarray) -> None:
    """ekf.add_process_noise for a batch: P (N, 11, 11), J (N, 3, 5), one dt."""
    G = J[:, :, VEL_IDX]
    Gq = G * (q["v"], q["w"])
    P[:, POSE_IDX, POSE_IDX] += (dt / 3.0) * (Gq @ np.swapaxes(G, 1, 2))
    P[:, POSE_IDX, VEL_IDX] += (0.5 * dt) * Gq
    P[:, VEL_IDX, POSE_IDX] += (0.5 * dt) * np.swapaxes(Gq, 1, 2)
    P[:, 3, 3] += q["v"] * dt
    P[:, 4, 4] += q["w"] * dt
    P[:, 5, 5] += q["bias"] * dt
    P[:, SLIP_IDX, SLIP_IDX] += q_slip * dt
    if q["scale"]:
        P[:, SCALE_IDX, SCALE_IDX] += np.eye(3) * q["scale"] * dt


def _inv_small(A: np.ndarray) -> np.ndarray:
    """Inverse of a batch (N, m, m) of 1x1 or 2x2 matrices in closed form."""
    m = A.shape[-1]
    if m == 1:
        return 1.0 / A
    if m == 2:
        a, b, c, d = A[:, 0, 0], A[:, 0, 1], A[:, 1, 0], A[:, 1, 1]
        det = a * d - b * c
        out = np.empty_like(A)
        out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1] = d, -b, -c, a
        return out / det[:, None, None]
    return np.linalg.inv(A)


def _check_same_timing(logs: list[Log], streams) -> None:
    robot0 = logs[0].robot
    t0, c0, r0 = streams[0]
    for log, (t, c, r) in zip(logs[1:], streams[1:]):
        if log.robot != robot0:
            raise ValueError("run_ekf_many: every log must have the same robot.toml")
        if t.shape != t0.shape or not (np.array_equal(t, t0) and np.array_equal(c, c0) and np.array_equal(r, r0)):
            raise ValueError("run_ekf_many: the logs' sensor timestamps differ; simulate them with one timing_seed")


def run_ekf_many(logs: list[Log], schedule: Schedule = Schedule(), options: EKFOptions = EKFOptions(),
                 progress=None) -> list[Estimate | EstimatorDivergedError]:
    """Filter N logs that share robot and timestamps; one result per log, in order."""
    wall0 = time.perf_counter()
    n = len(logs)
    meas = [from_log(log) for log in logs]
    inits = [initial_state(log.robot, m, dict(options.pin)) for log, m in zip(logs, meas)]
    if any(i.heading_unknown for i in inits):
        # (the EKF's heading watch, estimators.heading, is not vectorised)
        raise ValueError("run_ekf_many: a run starts with no heading (standing still, no [initial] pose); "
                         "filter it with ekf.EKF")
    if any(i.anchor is not None for i in inits):
        # (nor is the anchor of a late first fix, ekf.EKF._take_anchor)
        raise ValueError("run_ekf_many: a run's first fix or range comes after the robot drove off (no [initial] "
                         "pose), and its start is anchored there; filter it with ekf.EKF")
    if len({i.t for i in inits}) != 1:
        raise ValueError("run_ekf_many: the runs start at different times (give robot.toml an [initial] pose)")
    streams = [event_stream(m, inits[0].t) for m in meas]
    _check_same_timing(logs, streams)
    t_ev, code_ev, row_ev = streams[0]
    obs = inits[0].observability
    pins = held_pins(obs)          # (ekf.held_directions)
    # As ekf.EKF, with the first run's slipping stretches (the runs share their motion); each
    # run's own standstill (StillWatch: its fixes may see a motion another run's do not).
    r, m0, sch, opt = logs[0].robot, meas[0], schedule, options

    # Measurements stacked over runs: (N, K, ...).
    wheel_m = np.stack([m.wheel.m for m in meas])
    wheel_s2 = np.stack([m.wheel.sigma for m in meas]) ** 2
    gyro_z = np.stack([m.gyro[1] for m in meas])[..., None] if m0.gyro is not None else None
    gps_z = np.stack([m.gps[1] for m in meas]) if m0.gps is not None else None
    gps_s2 = np.stack([m.gps[2] for m in meas]) ** 2 if m0.gps is not None else None
    rng_b = m0.ranges[1] if m0.ranges is not None else None
    rng_z = np.stack([m.ranges[2] for m in meas])[..., None] if m0.ranges is not None else None
    vel_z = np.stack([m.velocity[1] for m in meas]) if m0.velocity is not None else None

    x = np.stack([i.x for i in inits])
    P = np.stack([i.P for i in inits])
    pn = r.process
    q = dict(v=pn.accel**2, w=pn.yaw_accel**2, bias=pn.gyro_bias**2, scale=pn.scale**2)
    q_slip = slip_intensity(pn, m0)
    if not opt.slip_states:
        q_slip = np.zeros((2, 2))
        x[:, SLIP_IDX] = 0.0
        P[:, SLIP_IDX, :] = 0.0
        P[:, :, SLIP_IDX] = 0.0
    R_slip = np.eye(2) * pn.pseudo_slip_sigma**2
    R_scale = np.eye(3) * pn.pseudo_scale_sigma**2
    R_gyro = np.array([[r.gyro_sigma**2]])
    R_vel = np.diag(np.square(r.velocity_sigma))
    R_rng = np.array([[r.range_sigma**2]])
    track, lever_gps, lever_rng = r.track_width, r.gps_lever_arm, r.range_lever_arm
    gates = gate_thresholds(opt)
    t_switch = sch.switch_time(m0.t_start)
    slip_ev = in_stretches(t_ev, in_window(schedule.slip_stretches(inits[0].slipping), m0.t_start, t_switch)[0])
    watches = [StillWatch(r) for _ in range(n)]     # (fed each run's measurements, as ekf.EKF.step is)
    tpm = np.array([r.ticks_per_meter_left, r.ticks_per_meter_right])
    switch_sigma = None
    holding = False
    rows = int(np.sum(code_ev == WHEEL))
    out_x = np.empty((rows, n, S.N))
    out_var = np.empty((rows, n, S.N))
    out_pose = np.empty((rows, n, 3, 3))
    out_t = np.empty(rows)
    nis_t = {k: [] for k in range(5)}
    nis_v = {k: [] for k in range(5)}
    nis_ema = np.tile(np.asarray(DOF, float), (n, 1))
    nis_clip = np.array([10.0 * opt.max_mean_nis * d for d in DOF])
    seen_run = np.zeros((n, 5), int)
    failed: list[EstimatorDivergedError | None] = [None] * n
    dead = np.zeros(n, bool)
    frozen_x, frozen_P = x.copy(), P.copy()
    t_now = inits[0].t
    row = 0

    run = {}                                     # gated sensor -> (N, reacquire_after, m) innovations of the runs
    run_len = {c: np.zeros(n, int) for c in GATED}
    recoveries: list[list[str]] = [[] for _ in range(n)]
    departures: list[list[str]] = [[] for _ in range(n)]
    last_y = None

    hist: dict[tuple, list] = {}                 # (sensor, beacon) -> list of (N, m) innovations, newest last
    jump_on: dict[tuple, np.ndarray] = {}        # (sensor, beacon) -> (N,) held out after a jump (EKF.run)
    jump_t0: dict[tuple, np.ndarray] = {}
    jump_y: dict[tuple, np.ndarray] = {}         # (N, m) the innovation before the jump
    last_t: dict[tuple, float] = {}
    rearm: dict[tuple, np.ndarray] = {}          # (N,) hold expired: no new jump until one is accepted
    held_t: list[dict[str, list]] = [{} for _ in range(n)]
    last2: dict[tuple, list] = {}                # (sensor, beacon) -> its last two (t, (N, m) innovations, (N,) |NIS|)
    last_departure = np.full(n, -np.inf)         # per run (EKF.last_departure)

    def reference(key):
        """(N, m) median of the recent innovations (ekf.gate_reference), or None."""
        hk = hist.get(key, [])
        return None if len(hk) < 3 else np.median(np.stack(hk), 0)

    def update(z, h, H, idx, R, gate=None, ref=None, no_ref=None, no_gain=None, huber=False, skip=None):
        """Batched Kalman update (see EKF.update); returns (N,) NIS, negative where gated.
        no_ref: (N,) runs that get no rescue from ``ref`` (held out after a jump);
        skip: (N,) runs the update leaves alone (zero gain: exactly no update)."""
        nonlocal x, P, last_y
        Ht = np.swapaxes(H, 1, 2)
        PHt = P[:, :, idx] @ Ht
        Sm = H @ PHt[:, idx, :] + R
        y = z - h
        last_y = y
        Sinv = _inv_small(Sm)
        nis = np.einsum("ni,nij,nj->n", y, Sinv, y)
        if gate is not None:
            rej = nis > gate
            if ref is not None:
                d = y - ref
                far = np.einsum("ni,nij,nj->n", d, Sinv, d) > gate
                rej &= far if no_ref is None else (far | no_ref)
            rescued = (nis > gate) & ~rej
            if huber and rescued.any():
                # a range taken at a Huber weight, its NIS the gate's (EKF.update)
                R, Sinv = huber_widening(R, Sm, Sinv, np.where(rescued, nis, gate), gate)
        K = PHt @ Sinv
        if skip is not None:
            K[skip] = 0.0
        if gate is not None:
            K[rej] = 0.0
            nis = np.where(rej, -nis, nis)
        if holding:
            K[:, SCALE_IDX, :] = 0.0
        elif no_gain is not None and no_gain.ndim == 2:       # (N, 11) unit directions (EKF.update)
            K = K - no_gain[:, :, None] * np.einsum("ni,nij->nj", no_gain, K)[:, None, :]
        elif no_gain is not None:       # (N, 11, m) orthonormal columns: with pins (ekf.held_directions)
            K = K - no_gain @ (np.swapaxes(no_gain, 1, 2) @ K)
        x = x + np.einsum("nij,nj->ni", K, y)
        x[:, 2] = wrap_angle(x[:, 2])
        IKH = np.broadcast_to(_I, P.shape).copy()
        IKH[:, :, idx] -= K @ H
        P = IKH @ P @ np.swapaxes(IKH, 1, 2) + K @ R @ np.swapaxes(K, 1, 2)
        return nis

    def kill(i: int, msg: str):
        failed[i] = EstimatorDivergedError(msg)
        dead[i] = True
        frozen_x[i], frozen_P[i] = x[i], P[i]

    stride = max(1, len(t_ev) // 200)
    with np.errstate(all="ignore"):  # frozen (diverged) runs may overflow; they are reset below
        for k in range(len(t_ev)):
            t, code, i = t_ev[k], code_ev[k], row_ev[k]
            if code == WHEEL:
                # (the runs share their stamps: a wheel row quiet in no run, with no
                # run's watch in a quiet stretch, leaves every watch as it finds it)
                dt_i = float(m0.wheel.dt[i]) if m0.wheel.dt is not None else 0.0
                quiet = (np.abs(np.rint(wheel_m[:, i] * tpm * dt_i)) <= JITTER if dt_i
                         else wheel_m[:, i] == 0.0)                          # (either wheel: its own run)
                if quiet.any() or not all(w.idle() for w in watches):
                    still_k = np.array([w.wheel(t, wheel_m[j, i], dt_i) for j, w in enumerate(watches)])
                else:
                    still_k = None
                    for w, fast in zip(watches, np.abs(wheel_m[:, i]).max(axis=1).tolist()):
                        w.pass_row(t, dt_i, fast)
            elif any(w.watching() for w in watches):
                for j, w in enumerate(watches):
                    ev = event_values(meas[j], code, i)
                    w.other(code, t, ev[0], ev[1:])
            dt = t - t_now
            if dt > 0.0:
                pose, J = propagate(x[:, 0], x[:, 1], x[:, 2], x[:, 3], x[:, 4], dt)
                # F P F' with F = I except rows 0:3 = J (on the first 5 states)
                P[:, 0:3, :] = J @ P[:, 0:5, :]
                P[:, :, 0:3] = P[:, :, 0:5] @ np.swapaxes(J, 1, 2)
                add_process_noise_many(P, J, dt, q, q_slip)
                x[:, 0], x[:, 1], x[:, 2] = pose[:, 0], pose[:, 1], wrap_angle(pose[:, 2])
                t_now = t
            if switch_sigma is None and t_switch is not None and t >= t_switch:
                switch_sigma = P[:, SCALE_IDX, SCALE_IDX].copy()
                holding = sch.hold is Hold.consider
            if code == WHEEL:
                window = (switch_sigma is None and t_switch is not None and not slip_ev[k]) or not obs.slip_observable
                if window or (still_k is not None and still_k.any()):
                    h, H = pseudo.zero_slip(x[:, 6], x[:, 7])                        # eq. 35-36
                    update(np.zeros((n, 2)), h, H, SLIP_IDX, R_slip, skip=None if window else ~still_k)
                if not window and switch_sigma is not None and sch.hold is Hold.pseudo:
                    h, H = pseudo.hold_scale(x[:, 8], x[:, 9], x[:, 10])             # eq. 37-38
                    update(h.copy(), h, H, SCALE_IDX, R_scale)
                h, H = encoder.wheel_speeds(x[:, 3], x[:, 4], x[:, 6], x[:, 7], x[:, 8], x[:, 9], x[:, 10],
                                            track)                                    # eq. 29-34
                s2 = wheel_s2[:, i]
                Rw = np.zeros((n, 2, 2))
                Rw[:, 0, 0], Rw[:, 1, 1] = s2[:, 0], s2[:, 1]
                nis = update(wheel_m[:, i], h, H, ENC_IDX, Rw,
                             no_gain=None if opt.encoder_scale_gain else held_directions(x, *pins))
                d = np.diagonal(P, 0, 1, 2)
                bad = ~(np.isfinite(x).all(1) & np.isfinite(d).all(1)) | (d < -1e-12).any(1)
                far = (np.abs(x[:, S.SCALE] - 1.0).max(1) > opt.max_scale_error) | (x[:, S.SCALE].min(1) < 0.05)
                for j in np.nonzero((bad | far) & ~dead)[0]:
                    kill(j, f"EKF diverged at t={t:.3f} s: " + (
                        "non-finite state or covariance" if bad[j] else
                        f"scale factors {np.round(x[j, S.SCALE], 3).tolist()} are not physical (outside 0.05 to "
                        f"{1 + opt.max_scale_error:g})"))
                out_t[row] = t
                out_x[row] = x
                Pr = P if not obs.unobservable else decondition(P, obs, S.SCALE, obs.prior_sigma)  # as ekf.EKF
                out_var[row] = np.diagonal(Pr, 0, 1, 2)
                out_pose[row] = Pr[:, 0:3, 0:3]
                row += 1
            elif code == GYRO:
                h, H = gyro.yaw_rate(x[:, 4], x[:, 5])                               # eq. 10-11
                nis = update(gyro_z[:, i], h, H, GYRO_IDX, R_gyro)
            elif code == GPS:
                h, H = gps.antenna_position(x[:, 0], x[:, 1], x[:, 2], lever_gps)    # eq. 8-9
                Rg = np.eye(2) * gps_s2[:, i, None, None]
                key = (GPS, 0)
                R_k = Rg
                nis = update(gps_z[:, i], h, H, POSE_IDX, Rg, gates[GPS], reference(key), jump_on.get(key))
            elif code == RANGE:
                h, H = ranging.beacon_range(x[:, 0], x[:, 1], x[:, 2], rng_b[i], lever_rng)  # eq. 12-16
                key = (RANGE, int(m0.ranges_id[i]))
                R_k = np.broadcast_to(R_rng, (n, 1, 1))
                nis = update(rng_z[:, i], h, H[:, :, :3], POSE_IDX, R_rng, gates[RANGE], reference(key),
                             jump_on.get(key), huber=True)
            else:
                h, H = velocity.body_velocity(x[:, 3], x[:, 4])                      # sec. VI-B
                key = (VEL, 0)
                nis = update(vel_z[:, i], h, H, VEL_IDX, R_vel, gates[VEL], reference(key))
            nis_t[code].append(t)
            nis_v[code].append(nis)
            rejected = nis < 0
            if code in run_len:
                hk = hist.setdefault(key, [])
                # Jumps held out, per run, as in EKF.run.
                t_prev, last_t[key] = last_t.get(key), t
                on = jump_on.setdefault(key, np.zeros(n, bool))
                ra = rearm.setdefault(key, np.zeros(n, bool))
                if code != VEL and hk and rejected.any():
                    onset = rejected & ~on & ~ra & jumped(last_y, hk[-1], R_k, t - t_prev, opt.jump_speed,
                                                          gates[code])
                    if onset.any():
                        jump_t0.setdefault(key, np.zeros(n))[onset] = t
                        jump_y.setdefault(key, np.zeros_like(last_y))[onset] = hk[-1][onset]
                        on |= onset
                # A departure: the rate states' variances floored, per run, as in EKF.run (EKF._departure).
                l2 = last2.setdefault(key, [])
                if code != VEL and gates[code] is not None and len(l2) == 2 and t > l2[1][0] > l2[0][0]:
                    (t0, y0, _), (t1, y1, n1) = l2
                    dep = departure_possible(np.abs(nis), n1, gates[code], DOF[code]) & ~on   # (mostly none)
                    if dep.any():
                        dep &= departed((y0, y1, last_y), np.abs(nis), n1, gates[code], DOF[code],
                                        (t1 - t0, t - t1), R_k, opt.jump_speed)
                    for j in np.flatnonzero(dep):
                        idx, floor = departure_widening(last_y[j], y1[j], t - t1, opt.slip_states)
                        P[j, idx, idx] += np.maximum(floor - np.diagonal(P[j])[idx], 0.0)
                        note = departure_note(t, code, float(floor), float(last_departure[j]), opt.slip_states)
                        if note:
                            departures[j].append(note)
                        last_departure[j] = t
                l2.append((t, last_y.copy(), np.abs(nis)))
                if len(l2) > 2:
                    del l2[0]
                expire = on & rejected & (t - jump_t0[key] > opt.jump_hold) if on.any() else np.zeros(n, bool)
                for j in np.flatnonzero(expire):
                    recoveries[j].append(f"t={t:.2f} s: {SENSOR_NAMES[code]} jumped at t={jump_t0[key][j]:.2f} s "
                                         f"and did not come back in {opt.jump_hold:g} s; re-acquiring it")
                    for e in hk:                 # the jump is the sensor's new level (EKF.run)
                        e[j] = last_y[j]
                on &= ~expire
                ra |= expire
                held = on & rejected
                for j in np.flatnonzero(held):
                    held_t[j].setdefault(SENSOR_NAMES[code], []).append(t)
                hk.append(np.where(held[:, None], jump_y[key], last_y) if held.any() else last_y.copy())
                if len(hk) > GATE_HISTORY:
                    del hk[0]
                on &= rejected           # back where the state expects it: the jump is over
                ra &= rejected
                # Re-acquisition after a run of rejections, per run, as in EKF.run.
                rl = run_len[code]
                if code not in run:
                    run[code] = np.zeros((n, opt.reacquire_after, last_y.shape[1]))
                counted = rejected & ~held
                run[code][counted, rl[counted]] = last_y[counted]
                rl[:] = np.where(counted, rl + 1, np.where(held, rl, 0))
                for j in np.flatnonzero(rl >= opt.reacquire_after):
                    blk, add = reacquire_widening(code, run[code][j])
                    P[j, blk, blk] += np.diag(add)
                    recoveries[j].append(f"t={t:.2f} s: {rl[j]} {SENSOR_NAMES[code]} measurements in a row rejected; "
                                         "covariance widened to re-acquire")
                    rl[j] = 0
            # Divergence watch on the accepted NIS, per run, as in EKF.run.
            nk = np.minimum(np.where(rejected, nis_ema[:, code], nis), nis_clip[code])
            nis_ema[:, code] = np.where(rejected, nis_ema[:, code], 0.98 * nis_ema[:, code] + 0.02 * nk)
            seen_run[:, code] += ~rejected
            lost = (seen_run[:, code] > 100) & (nis_ema[:, code] > opt.max_mean_nis * DOF[code])
            for j in np.nonzero(lost & ~dead)[0]:
                what = f"the running mean NIS of {SENSOR_NAMES[code]} is {nis_ema[j, code]:.0f} (expected {DOF[code]})"
                widen = watch_widening(code, np.atleast_1d(last_y[j]))
                if widen is None or len(recoveries[j]) >= MAX_RECOVERIES:
                    kill(j, f"EKF diverged at t={t:.3f} s: {what}; the model no longer explains the data")
                    continue
                blk, add = widen                                   # as EKF.run
                P[j, blk, blk] += np.diag(add)
                nis_ema[j, code], seen_run[j, code] = float(DOF[code]), 0
                recoveries[j].append(f"t={t:.2f} s: {what}; its states' covariance widened")
            if dead.any():
                x[dead], P[dead] = frozen_x[dead], frozen_P[dead]
            if progress is not None and k % stride == 0:
                progress(k, len(t_ev))
    if progress is not None:
        progress(len(t_ev), len(t_ev))

    wall = (time.perf_counter() - wall0) / n
    n_up = len(t_ev)
    nis_arr = {c: np.asarray(v) for c, v in nis_v.items() if v}
    out: list[Estimate | EstimatorDivergedError] = []
    for j in range(n):
        if failed[j] is not None:
            out.append(failed[j])
            continue
        nis_j = {c: list(zip(nis_t[c], nis_arr[c][:, j])) for c in nis_arr}
        est = make_estimate("ekf" if opt.slip_states else "ekf-no-slip", out_t, out_x[:, j], out_var[:, j],
                            out_pose[:, j], nis_j, list(meas[j].notes) + [inits[j].note], wall, n_up,
                            t_switch, None if switch_sigma is None else switch_sigma[j], sch.hold,
                            P[j, SCALE_IDX, SCALE_IDX].copy(), inits[j])
        est.recoveries, est.departures = recoveries[j], departures[j]
        est.held_out = {k: np.asarray(v) for k, v in held_t[j].items()}
        for key, v in meas[j].spikes.items():
            est.rejected[key] = est.rejected.get(key, 0) + v
        out.append(est)
    return out
