"""Peers that the benchmarks and tests compare odomgraph against.

``FilterPyEKF`` is the paper's EKF built on FilterPy's ExtendedKalmanFilter:
the same models (factors), process noise, schedule and event loop, with
FilterPy doing every predict and update. It only supports the paper's literal
pseudo-update hold (FilterPy has no consider update) and no gating.
"""
from __future__ import annotations

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from factors._math import wrap_angle
from factors.motion import propagate
from odomgraph import state as S
from odomgraph.estimators.ekf import EKF, add_process_noise
from odomgraph.estimators.schedule import Hold, Schedule


class FilterPyEKF(EKF):
    def __init__(self, log, schedule: Schedule = Schedule(hold=Hold.pseudo), **kw):
        if schedule.hold is not Hold.pseudo:
            raise ValueError("FilterPy has no consider update: use Hold.pseudo")
        super().__init__(log, schedule, **kw)
        self.fp = ExtendedKalmanFilter(dim_x=S.N, dim_z=1)
        self.fp.x = self.x
        self.fp.P = self.P

    def predict(self, t: float) -> None:
        dt = t - self.t
        if dt <= 0.0:
            return
        fp = self.fp
        pose, J = propagate(*fp.x[:5], dt)
        F = np.eye(S.N)
        F[0:3, 0:5] = J
        Q = np.zeros((S.N, S.N))
        add_process_noise(Q, J, dt, self._q, self._q_slip)
        fp.F, fp.Q = F, Q

        def predict_x(u=0):
            fp.x[0], fp.x[1], fp.x[2] = pose[0], pose[1], wrap_angle(pose[2])
        fp.predict_x = predict_x
        fp.predict()
        self.x, self.P, self.t = fp.x, fp.P, t

    def update(self, z, h, H, idx, R, gate=None) -> float:
        assert not self.holding_scale and gate is None
        Hfull = np.zeros((H.shape[0], S.N))
        Hfull[:, idx] = H
        fp = self.fp
        fp.update(np.atleast_1d(z), lambda x: Hfull, lambda x: h, R=R)
        fp.x[2] = wrap_angle(fp.x[2])
        self.x, self.P = fp.x, fp.P
        y = np.atleast_1d(z) - h
        return float(y @ np.linalg.solve(fp.S, y))
