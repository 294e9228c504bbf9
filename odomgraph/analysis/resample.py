"""An estimate at other times: regular (``--rate HZ``) or a sensor's
(``--at truth|gps``), for tools such as evo that associate poses by time.

The smoothers keep one state per keyframe, and evo's default association
(0.01 s) then matches almost none of them to a 100 Hz truth. Between two rows
the pose moves along the constant-curvature arc that joins them (the motion
model of eq. 2-6 with the interval's mean turn rate), corrected linearly so
that it meets both rows exactly; the other states and every sigma and
covariance are interpolated linearly. Given the log, a time's place on the
arc is the share of the wheels' travel done by then, and its heading the
share of the gyro's turn (estimators.shares, as the smoothers place their
own rows), and the position follows the path's shape dead-reckoned between
the two rows (Shares.path_between) where it is well conditioned; else the
time's share on the arc. Outside the estimate's span nothing is
extrapolated: those times are dropped.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from odomgraph import state as S
from odomgraph.result import Estimate


def _sinc(x: np.ndarray) -> np.ndarray:
    return np.sinc(x / np.pi)  # sin(x)/x, 1 at 0


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def arc_poses(t0, p0, t1, p1, t, shares=None, turn=None) -> np.ndarray:
    """(M, 3) poses (x, y, theta) [m, m, rad] at times t in [t0, t1] on the
    arc from pose p0 at t0 to p1 at t1 (arrays (M,) and (M, 3), one interval
    per row): heading turns at the constant rate that joins the two
    headings, the position follows the arc of that curvature through the
    chord's length, and the remaining difference at t1 is spread linearly.
    ``shares``: (travel, turn) (M,) each, the fractions of the arc's length
    and of its turn done by t (estimators.shares); None: the time's.
    ``turn``: (M,) the turn [rad] expected between the poses, which picks
    the heading difference's whole turns; None: the short way round."""
    dt = np.maximum(t1 - t0, 1e-12)
    s = np.clip((t - t0) / dt, 0.0, 1.0)
    s_v, s_w = (s, s) if shares is None else shares
    dth = _wrap(p1[:, 2] - p0[:, 2])
    if turn is not None:
        dth = turn + _wrap(dth - turn)
    chord = np.hypot(p1[:, 0] - p0[:, 0], p1[:, 1] - p0[:, 1])
    # arc length that gives this chord at this total turn (chord = L sinc(dth/2))
    length = chord / np.maximum(_sinc(dth / 2), 1e-6)

    def at(f_v, f_w):
        # a share f_v of the arc's length along an arc turned by a share f_w
        # of its turn, as the smoothers' own rows (motion.arc_at)
        turn = f_w * dth
        d = f_v * length * _sinc(turn / 2)
        heading = p0[:, 2] + turn / 2
        return np.column_stack([p0[:, 0] + d * np.cos(heading), p0[:, 1] + d * np.sin(heading), p0[:, 2] + turn])
    one = np.ones_like(s)
    miss = p1 - at(one, one)
    miss[:, 2] = _wrap(miss[:, 2])
    out = at(s_v, s_w) + np.column_stack([s_v, s_v, s_w]) * miss
    out[:, 2] = _wrap(out[:, 2])
    return out


def path_poses(sh, t0, p0, t1, p1, t) -> np.ndarray:
    """(M, 3) poses at times t between p0 at t0 and p1 at t1 (as arc_poses)
    on the path dead-reckoned between them (``sh``, an
    estimators.shares.Shares of the log): where the path's displacement is
    well conditioned, its shape laid on the chord (a complex ratio), else
    its own displacement with what is left at t1 spread by the share of
    the wheels' travel (a reversal or a loop between the rows). The heading
    turns as the path's did, its difference from the rows' spread by the
    same share, its whole turns picked by the path's turn (a 6 rad/s pivot
    turns more than pi between rows a second apart; the short way round put
    rows pi off). An arc bends the whole way where a robot drove straight
    and then pivoted: rows between rows a second apart 2 cm RMS off, z 8-17."""
    d_t, d_1, h_t, h_1, ok = sh.path_between(t0, t1, t)
    s_v = sh.travel(t0, t1, t)
    c0, c1 = p0[:, 0] + 1j * p0[:, 1], p1[:, 0] + 1j * p1[:, 1]
    along = c0 + np.exp(1j * p0[:, 2]) * d_t + s_v * (c1 - c0 - np.exp(1j * p0[:, 2]) * d_1)
    ratio = c0 + d_t / np.where(ok, d_1, 1.0) * (c1 - c0)
    c = np.where(ok, ratio, along)
    dth = h_1 + _wrap(p1[:, 2] - p0[:, 2] - h_1)
    th = p0[:, 2] + h_t + s_v * (dth - h_1)
    return np.column_stack([c.real, c.imag, _wrap(th)])


def resampled(est: Estimate, times: np.ndarray, log=None) -> Estimate:
    """``est`` at ``times`` [s, est's clock] inside its span (others dropped).
    Rows of ``est`` at the same time are kept as they are. ``log`` (on est's
    clock): place each time on its arc by the wheels' travel and the gyro's
    turn, read from the cleaned log as the smoothers read it (a fast
    robot's rows resampled by time were 1.9 cm off along the track, 93-94 %
    inside 3 sigma). The result has no innovations or online
    estimate of its own; every other field is est's."""
    times = np.asarray(times, dtype=float)
    times = times[(times >= est.t[0]) & (times <= est.t[-1])]
    k = np.clip(np.searchsorted(est.t, times, side="right") - 1, 0, max(len(est.t) - 2, 0))
    if len(est.t) == 1:
        k1 = k
        w = np.zeros_like(times)
    else:
        k1 = k + 1
        w = (times - est.t[k]) / np.maximum(est.t[k1] - est.t[k], 1e-12)
    w = np.clip(w, 0.0, 1.0)
    lin = (1 - w)[:, None] * est.mean[k] + w[:, None] * est.mean[k1]
    p0, p1 = est.mean[k][:, S.POSE], est.mean[k1][:, S.POSE]
    if log is not None and len(est.t) > 1:
        from odomgraph.estimators.measurements import clean
        from odomgraph.estimators.shares import Shares
        sh = Shares(clean(log)[0])     # an encoder spike moved a 20 Hz row 2.4 cm (a second read)
        pose = path_poses(sh, est.t[k], p0, est.t[k1], p1, times)
    else:
        # the turn between the rows from their yaw rates, not the short way
        # round (a 6 rad/s pivot turns more than pi in a second)
        turn = 0.5 * (est.mean[k, S.OMEGA] + est.mean[k1, S.OMEGA]) * (est.t[k1] - est.t[k])
        pose = arc_poses(est.t[k], p0, est.t[k1], p1, times, turn=turn)
    lin[:, S.POSE] = pose
    sigma = (1 - w)[:, None] * est.sigma[k] + w[:, None] * est.sigma[k1]
    cov = None
    if est.pose_cov is not None:
        cov = (1 - w)[:, None, None] * est.pose_cov[k] + w[:, None, None] * est.pose_cov[k1]
    if est.pauses:
        # Inside a silence of every sensor the arc between two rows is a
        # guess: at least the unknown path's variance there (est.pauses), not
        # the rows' interpolated (a row mid-silence and one at its edge would
        # give a straight line from the bridge's middle to nothing).
        from odomgraph.estimators.gaps import pause_variance
        pos, th = pause_variance(times, est.pauses)
        for col, add in ((S.X, pos), (S.Y, pos), (S.THETA, th)):
            sigma[:, col] = np.maximum(sigma[:, col], np.sqrt(add))
        if cov is not None:
            for i, add in ((0, pos), (1, pos), (2, th)):
                cov[:, i, i] = np.maximum(cov[:, i, i], add)
    return replace(est, t=times, mean=lin, sigma=sigma, pose_cov=cov, innovations={}, online=None,
                   update_times=None)


#: Highest --rate [Hz], and most rows it may write: beyond, the request is a typo, not a plan.
MAX_RATE_HZ = 1000.0
MAX_ROWS = 10_000_000


def regular_times(est: Estimate, rate_hz: float) -> np.ndarray:
    """Times at ``rate_hz`` inside the estimate's span, on whole multiples of
    1/rate of the log's clock (t_origin is a whole second), so that they meet
    a truth or a reference sampled at the same rate (evo associates within
    0.01 s)."""
    from odomgraph.errors import OdomgraphError
    if not (np.isfinite(rate_hz) and 0 < rate_hz <= MAX_RATE_HZ):
        raise OdomgraphError(f"--rate must be between 0 and {MAX_RATE_HZ:g} Hz, got {rate_hz!r}")
    k0, k1 = np.ceil(est.t[0] * rate_hz - 1e-9), np.floor(est.t[-1] * rate_hz + 1e-9)
    if k1 - k0 + 1 > MAX_ROWS:
        raise OdomgraphError(f"--rate {rate_hz:g} Hz would write {k1 - k0 + 1:.3g} rows (at most {MAX_ROWS:g})")
    return np.arange(k0, k1 + 1) / rate_hz
