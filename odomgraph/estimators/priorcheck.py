"""The sparse slip prior, checked against the answer without it (batch).

After a calibration window the smoothers keep a sparse zero-slip prior: a
Cauchy loss on the joint slip norm of each keyframe interval
(graph.slip_prior_rows, GraphOptions.slip_cauchy). It keeps slip near zero
where nothing moves it, which holds the path against slowly wandering fixes
and pins the slips on clean logs to a few mm/s. It is also a model, and a
wrong one for some slips:

- a one-wheel slip s costs more than a balanced pair (+s/2, -s/2), whose
  norm is smaller; the gyro pins the difference, so the prior shrinks the
  common mode (24th session, batch: 0.034 m/s for a true 0.25);
- a common-mode slip (a snowplow pushing snow, both wheels) costs about
  log(u^2) per keyframe and wheel, so a long event is cheaper to deny.

With strong fixes the data overrule the prior. With weak fixes (0.5 m at
2 Hz, 3 m at 1 Hz) nothing does: the missing distance bends the whole path,
before the event too, and batch's rows sat 49-60 % outside 3 sigma with
status ok, where the EKF (whose slip is a free random walk) held 0-0.5 %.

The check: where the joint solution has slip after the window, solve again
without the prior there (slip a free random walk, as the EKF's), from the
joint solution, and measure how far apart the two keyframe poses are against
the prior-free covariance (a Mahalanobis distance, 3 dof; its 95th
percentile over the keyframes). The prior-free solution is the consistent
one either way; the joint one is the more precise only where the prior holds.

- Far apart (beyond CHECK_K): the data contradict the prior. The prior-free
  solution is given, and the run says so.
- Otherwise the joint mean stands, with the prior-free covariance widened by
  the two solutions' difference, Sigma_free + d d^T per keyframe (d (11,) in
  the block's tangent coordinates). Whichever model is right, its mean is
  then inside the sigma given: the prior's precision is claimed only where
  the data did not test it. (Sigma_free alone was not enough: the paper
  robot with 1 m fixes at 2 Hz and its slip events, a distance of 2.5:
  joint rows 23 % outside 3 sigma.)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from odomgraph import state as S
from odomgraph.factors._math import wrap_angle
from odomgraph.result import Estimate

#: Slip [m/s] after the window above which the prior is checked: a few times
#: what the prior leaves on clean logs (2-4 mm/s RMS, peaks near 0.02), far
#: below a slip that moves a path (a 0.15 m/s one-wheel slip for 3 s).
SLIP_SEEN = 0.05
#: The check's threshold: the 95th percentile of the keyframes' Mahalanobis
#: pose distance (3 dof) between the two solutions, in the prior-free sigma.
#: Were the prior right, the two would differ by a draw of covariance
#: Sigma_free - Sigma_joint, which is at most Sigma_free: a chi of 3 dof,
#: whose 95th percentile is 2.8 (a heuristic: the keyframes are correlated).
#: Measured (benchmarks/results/slip_prior.md): 1.4-2.7 on logs whose joint
#: mean was right or nearly (strong fixes; the paper robot with 1-3 m fixes,
#: once widened), 3.1-6.8 where it was far off (the yard with 0.5-1 m fixes
#: and its one-wheel slips) or nearly so (paper, 1 m at 1 Hz).
CHECK_K = 3.0
#: The check reads only keyframes within this much [s] of a fix or range:
#: in a gap in the fixes nothing tests the prior, and the two solutions part
#: by how each extrapolates (the prior-free slip holds its last value), not
#: by what the data say (a yard log, a slip ending 0.5 s before a 20 s GPS
#: outage: distance 4.2 over the whole log, the prior's rows right).
INFORMED_S = 1.0


@dataclass(frozen=True)
class Verdict:
    """The check of one batch run: ``p95`` the 95th percentile of the
    keyframes' pose distance [sigma]; ``prior_free``: the prior-free
    solution is given (p95 > the threshold)."""
    p95: float
    prior_free: bool


def slip_after_window(zero_slip: np.ndarray, W: np.ndarray) -> float:
    """Largest slip norm [m/s] over the keyframes that start an interval
    outside the zero-slip pseudo-prior (zero_slip (N-1,), W (N, 8))."""
    free = np.concatenate([~zero_slip, [False]])
    if not free.any():
        return 0.0
    return float(np.max(np.hypot(W[free, S.W_SLIP.start], W[free, S.W_SLIP.start + 1])))


def slips_seen(t: np.ndarray, slip: np.ndarray, t_switch: float | None) -> bool:
    """Whether an estimate's rows (t (N,) [s], slip (N, 2) [m/s]) slip by
    more than SLIP_SEEN after its calibration window ends at t_switch
    (None: no window, and no check)."""
    if t_switch is None:
        return False
    after = t > t_switch
    return bool(after.any() and np.hypot(slip[after, 0], slip[after, 1]).max() > SLIP_SEEN)


def pose_distance(d: np.ndarray, Sig: np.ndarray) -> np.ndarray:
    """(N,) Mahalanobis distance [sigma, 3 dof] of the pose part of tangent
    differences d (N, 11; tangent_difference) under the pose block of Sig
    (N, 11, 11)."""
    P, e = Sig[:, 0:3, 0:3], d[:, 0:3]
    z2 = np.einsum("ni,ni->n", e, np.linalg.solve(P, e[:, :, None])[:, :, 0])
    return np.sqrt(np.maximum(z2, 0.0))


def tangent_difference(pose_a: np.ndarray, W_a: np.ndarray, pose_b: np.ndarray, W_b: np.ndarray) -> np.ndarray:
    """(N, 11) keyframe block a minus block b in b's tangent coordinates:
    the pose part in pose_b's body frame [m, m, rad], as the covariances of
    batch.marginal_blocks; W (N, 8) as differences (state.NAMES[3:] order)."""
    d = pose_a - pose_b
    c, s = np.cos(pose_b[:, 2]), np.sin(pose_b[:, 2])
    return np.concatenate([np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1],
                                     wrap_angle(d[:, 2])], axis=1), W_a - W_b], axis=1)


def widened(Sig: np.ndarray, d: np.ndarray) -> np.ndarray:
    """(N, 11, 11) Sig + d d^T for each keyframe (d (N, 11)): the covariance
    that holds a mean d away from Sig's own (module docstring)."""
    return Sig + d[:, :, None] * d[:, None, :]


def informed(t: np.ndarray, t_abs: np.ndarray, reach: float = INFORMED_S) -> np.ndarray:
    """(N,) whether each keyframe time t (N,) [s] lies within ``reach`` [s]
    of an absolute measurement (t_abs, sorted, [s]: fixes, ranges)."""
    if t_abs.size == 0:
        return np.zeros(len(t), bool)
    i = np.clip(np.searchsorted(t_abs, t), 1, t_abs.size - 1) if t_abs.size > 1 else np.zeros(len(t), int)
    near = np.minimum(np.abs(t - t_abs[i]), np.abs(t - t_abs[np.maximum(i - 1, 0)]))
    return near <= reach


def verdict(d: np.ndarray, Sig_free: np.ndarray, where: np.ndarray, k: float = CHECK_K) -> Verdict:
    """The check of the joint solution against the prior-free one, from
    their tangent difference d (N, 11) and the prior-free covariance
    Sig_free (N, 11, 11), over the keyframes ``where`` (N,) (informed;
    module docstring). No keyframe there: no disagreement seen (p95 0)."""
    if not where.any():
        return Verdict(0.0, False)
    p95 = float(np.percentile(pose_distance(d[where], Sig_free[where]), 95))
    return Verdict(p95, p95 > k)


def applied(est: Estimate) -> Estimate:
    """``est`` with batch's check of its sparse slip prior applied
    (Estimate.slip_check: the prior-free rows, or the widened covariance;
    said in its notes, and in a warning where the prior-free rows are
    given). pipeline.estimate applies it last: the checks of the fixes read
    the prior's rows, which do not follow a fault of the fixes as a
    prior-free path does (persistent GPS errors, no slip: a prior-free path
    followed them, they looked white, their sigma stayed narrow, and 23 % of
    rows fell outside 3 sigma; a sideways multipath bias: half of it taken
    as slip, and not held out)."""
    chk = est.slip_check
    if chk is None:
        return est
    for k, v in chk.fields.items():
        setattr(est, k, v)
    est.slip_check = None
    est.notes.append(chk.note)
    if chk.prior_free:
        est.warnings.append(
            f"{est.method}: the slips after the calibration window contradict the sparse zero-slip prior (the "
            f"solution with it is {chk.distance:.1f} sigma from the one without, 95th percentile near the fixes): "
            "the prior-free solution is given, slip a free random walk after the window")
    return est
