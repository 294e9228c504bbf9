"""Issue 17's second design for the EKF: its predict and update arithmetic
compiled with numba, the event loop left in Python. A prototype that the
throughput benchmark (benchmarks/ekf_throughput.py) runs beside the shipped
numpy filter and the FilterPy peer; it is not shipped, and numba is not a
dependency (the ``bench`` extra installs it).

``CompiledEKF`` is ``estimators.ekf.EKF`` with ``predict`` and ``update``
replaced by two compiled kernels each, on the same models (factors.motion's
arc, paper eq. 2-7; the Joseph-form update) and the same process noise
(``rate_noise`` and ``add_process_noise``'s pose blocks). Updates whose gain
is modified (the consider hold, the encoder update without the common-scale
gain, a heading considered) and the 3-dim scale-hold pseudo-update (eq. 37-38)
go to the numpy update: the benchmark uses the
paper's literal update and hold, where none of them occurs.
"""
from __future__ import annotations

import math

import numpy as np

from odomgraph.estimators.ekf import EKF

try:
    from numba import njit
except ImportError:          # the benchmark then says the design was not measured
    njit = None

_SMALL = 1e-4                # factors._math's series threshold


def _kernels():
    """The compiled kernels (compiled on first use; numba's cache keeps them)."""

    @njit(cache=True)
    def sinc_dsinc(a):
        if abs(a) < _SMALL:
            a2 = a * a
            return 1.0 - a2 / 6.0 + a2 * a2 / 120.0, -a / 3.0 + a ** 3 / 30.0
        return math.sin(a) / a, (a * math.cos(a) - math.sin(a)) / (a * a)

    @njit(cache=True)
    def wrap(a):
        w = np.fmod(a + math.pi, 2.0 * math.pi)      # (numba has no math.fmod; the same C fmod)
        if w < 0:
            w += 2.0 * math.pi
        w -= math.pi
        return math.pi if w == -math.pi else w

    @njit(cache=True)
    def predict(x, P, dt, rates, qv, qw):
        """x (11,), P (11, 11) in place: the arc (eq. 2-6), F P F^T (eq. 7) and the process noise."""
        half = 0.5 * x[4] * dt
        s, ds = sinc_dsinc(half)
        phi = x[2] + half
        c, sn = math.cos(phi), math.sin(phi)
        d = x[3] * dt * s
        k = x[3] * dt * 0.5 * dt
        J = np.zeros((3, 5))
        J[0, 0] = 1.0
        J[1, 1] = 1.0
        J[2, 2] = 1.0
        J[0, 2] = -d * sn
        J[1, 2] = d * c
        J[0, 3] = dt * s * c
        J[1, 3] = dt * s * sn
        J[0, 4] = k * (ds * c - s * sn)
        J[1, 4] = k * (ds * sn + s * c)
        J[2, 4] = dt
        # rows of F P, then (F P) F^T: only the pose's rows and columns change
        top = np.zeros((3, 11))
        for i in range(3):
            for j in range(11):
                acc = 0.0
                for m in range(5):
                    acc += J[i, m] * P[m, j]
                top[i, j] = acc
        for i in range(3):
            for j in range(11):
                P[i, j] = top[i, j]
        left = np.zeros((11, 3))
        for i in range(11):
            for j in range(3):
                acc = 0.0
                for m in range(5):
                    acc += P[i, m] * J[j, m]
                left[i, j] = acc
        for i in range(11):
            for j in range(3):
                P[i, j] = left[i, j]
        # process noise (ekf.add_process_noise): pose blocks, then the rates'
        for i in range(3):
            gv, gw = J[i, 3] * qv, J[i, 4] * qw
            for j in range(3):
                P[i, j] += (dt / 3.0) * (gv * J[j, 3] + gw * J[j, 4])
            P[i, 3] += (0.5 * dt) * gv
            P[i, 4] += (0.5 * dt) * gw
            P[3, i] += (0.5 * dt) * gv
            P[4, i] += (0.5 * dt) * gw
        for i in range(11):
            for j in range(11):
                P[i, j] += dt * rates[i, j]
        x[0] = x[0] + d * c
        x[1] = x[1] + d * sn
        x[2] = wrap(x[2] + x[4] * dt)

    @njit(cache=True)
    def innovate(P, y, H, idx, R):
        """(P H^T (11, m), S^-1 (m, m), NIS) of a measurement on the states idx."""
        m, n = H.shape[0], idx.shape[0]
        PHt = np.zeros((11, m))
        for i in range(11):
            for a in range(m):
                acc = 0.0
                for j in range(n):
                    acc += P[i, idx[j]] * H[a, j]
                PHt[i, a] = acc
        S = R.copy()
        for a in range(m):
            for b in range(m):
                acc = 0.0
                for j in range(n):
                    acc += H[a, j] * PHt[idx[j], b]
                S[a, b] += acc
        Si = np.empty((m, m))
        if m == 1:
            Si[0, 0] = 1.0 / S[0, 0]
        else:
            det = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
            Si[0, 0], Si[0, 1], Si[1, 0], Si[1, 1] = S[1, 1] / det, -S[0, 1] / det, -S[1, 0] / det, S[0, 0] / det
        nis = 0.0
        for a in range(m):
            for b in range(m):
                nis += y[a] * Si[a, b] * y[b]
        return PHt, Si, nis

    @njit(cache=True)
    def apply(x, P, y, PHt, Si, H, idx, R):
        """x, P in place: K = P H^T S^-1, x += K y, Joseph form P = (I-KH) P (I-KH)^T + K R K^T."""
        m, n = H.shape[0], idx.shape[0]
        K = PHt @ Si
        for i in range(11):
            for a in range(m):
                x[i] += K[i, a] * y[a]
        x[2] = wrap(x[2])
        A = np.eye(11)                    # I - K H on the full state
        for i in range(11):
            for j in range(n):
                acc = 0.0
                for a in range(m):
                    acc += K[i, a] * H[a, j]
                A[i, idx[j]] -= acc
        AP = np.zeros((11, 11))
        for i in range(11):
            for j in range(11):
                acc = 0.0
                for k in range(11):
                    acc += A[i, k] * P[k, j]
                AP[i, j] = acc
        KR = K @ R
        for i in range(11):
            for j in range(11):
                acc = 0.0
                for k in range(11):
                    acc += AP[i, k] * A[j, k]
                for a in range(m):
                    acc += KR[i, a] * K[j, a]
                P[i, j] = acc

    return predict, innovate, apply


_K = None


def kernels():
    global _K
    if _K is None:
        _K = _kernels()
    return _K


def _as_index(idx) -> np.ndarray:
    if isinstance(idx, slice):
        return np.arange(idx.start, idx.stop, dtype=np.int64)
    return np.asarray(idx, dtype=np.int64)


class CompiledEKF(EKF):
    """EKF whose predict and unmodified-gain updates run as compiled kernels."""

    def predict(self, t: float) -> None:
        dt = t - self.t
        if dt <= 0.0:
            return
        if self._in_pause(t):
            self._pause(t)
            return
        kernels()[0](self.x, self.P, dt, self._rates, self._q["v"], self._q["w"])
        self.t = t

    def update(self, z, h, H, idx, R, gate=None, ref=None, no_gain=None, huber=False) -> float:
        if self.holding_scale or no_gain is not None or self.consider_heading or np.shape(H)[0] > 2:
            # (a modified gain, or the 3-dim scale-hold pseudo-update: the numpy update)
            return super().update(z, h, H, idx, R, gate, ref, no_gain, huber)
        _, innovate, apply = kernels()
        y = np.atleast_1d(np.asarray(z - h, dtype=float))
        self.last_y = y
        ix = _as_index(idx)
        H = np.ascontiguousarray(H, dtype=float)
        R = np.ascontiguousarray(R, dtype=float)
        PHt, Si, nis = innovate(self.P, y, H, ix, R)
        if gate is not None and nis > gate:
            d = y if ref is None else y - ref
            if ref is None or float(d @ Si @ d) > gate:
                return -nis
            if huber:       # rescued, at a Huber weight: the numpy update (rare)
                return super().update(z, h, H, idx, R, gate, ref, no_gain, huber)
        apply(self.x, self.P, y, PHt, Si, H, ix, R)
        return nis
