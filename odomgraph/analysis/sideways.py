"""An estimate that moved the robot sideways.

A wheeled robot, differential drive or skid-steer, does not move sideways:
its body's velocity lies along its heading, apart from a skid-steer's
instantaneous centre of rotation a few centimetres off the axle (a
sideways creep of that offset times the angle turned). The models say so
only softly (the pose's process noise), so where the fixes move sideways
together, as a GNSS multipath bias of 0.5-1 m held for seconds does, every
estimator follows them: a probe had batch and isam2 0.8 m off at z 82,
status ``ok``, because such a bias is smooth and steps by less than the
EKF's jump check (ekf.EKFOptions.jump_speed) can tell from motion.

The estimate itself shows it. ``stretches`` integrates each row step's
displacement across the row's heading (body frame, at the mean heading of
the step) and looks at it over windows of 3, 6 and 12 s: on clean
simulated logs (both scenarios, fixes at 1-20 Hz) no smoother's window
exceeded 0.06 m and no filter's 0.76 m at z 2.7, while a 0.6 m bias moved
the smoothers 0.2-0.45 m sideways at z 11-52. A window is a finding when
its sideways move exceeds both SIDE_M and Z_SIDE times what the rows' own
sigmas allow (both ends' position sigma and the heading's over the
distance driven). The pipeline flags the estimate: its rows there follow the fixes, or
the robot really was pushed sideways, or a lever arm is wrong (it moves
the body sideways in every turn). Batch and isam2 first run again with the
fixes of those stretches held out: where the held fixes sit more than 4
of their own sigma off the new path, second after second
(analysis.windowfit.stretches), they were biased, and the new rows
replace the first ones when they move nothing sideways; the flag stays
all the same (a probe: a 30 s bias seen only at its start had the good
fixes before it held out and the rows after it following the bias, 0.63 m
off at z 99; a robot really pushed sideways was taken for a bias). With
fixes below 3 a second, no second has enough of them to tell: flagged only.
"""
from __future__ import annotations

import numpy as np

from odomgraph import state as S

#: Windows over which the sideways move is summed [s]: a bias's onset is
#: spread by a smoother over several seconds, a filter's over one.
WINDOWS = (3.0, 6.0, 12.0)
#: A sideways move below this is never a finding [m]: a skid-steer robot's
#: centre of rotation sits up to ~0.1 m off the axle, which moves the axle
#: sideways by that much per radian turned.
SIDE_M = 0.15
#: ...nor below this many sigmas of the rows (clean logs: at most 9.1, at
#: 0.035 m, on a smoother inside the calibration window).
Z_SIDE = 8.0
#: A window whose rows' heading sigma exceeds this [rad] has no meaningful
#: "sideways" (a filter that does not know its heading yet).
HEADING_SIGMA_MAX = 0.1
#: At most this share of the fixes is held out to look again (more is no
#: local bias; the estimate is flagged instead).
HELD_MAX = 0.4
#: The fixes held out reach this far before and after a stretch [s]: a
#: smoother spreads the bias's onset, and the ramp's first fixes pull too.
HELD_PAD = 3.0
#: A window with a step between rows longer than this [s] is skipped: across
#: a gap or a pause the path's shape is not measured.
ROW_GAP_MAX = 2.0


def stretches(est, chord=None) -> list[tuple[float, float, float, float]]:
    """(start [s], end [s], sideways move [m], in sigmas) of the windows of
    ``est`` (an Estimate: rows (N,) t, (N, 11) mean and sigma, state.NAMES
    order, world frame) in which the rows moved sideways, merged where they
    overlap (the largest move kept); [] when none did. ``chord``: (N-1,)
    the angle [rad] of the wheels' path between rows from its mean heading
    (estimators.shares.Shares.chord_angle; None: 0, an arc): a robot that
    drove straight and then pivoted between two rows moved along its first
    heading, not the mean."""
    t = np.asarray(est.t, float)
    if len(t) < 3:
        return []
    X, sd = est.mean, est.sigma
    th = X[:, S.THETA]
    dx, dy = np.diff(X[:, S.X]), np.diff(X[:, S.Y])
    th_mid = th[:-1] + 0.5 * np.angle(np.exp(1j * np.diff(th)))
    if chord is not None:
        th_mid = th_mid + chord
    side = np.concatenate([[0.0], np.cumsum(-np.sin(th_mid) * dx + np.cos(th_mid) * dy)])
    path = np.concatenate([[0.0], np.cumsum(np.hypot(dx, dy))])
    gap = np.concatenate([[0], np.cumsum(np.diff(t) > ROW_GAP_MAX)])
    pos_sd = np.hypot(sd[:, S.X], sd[:, S.Y])
    found: list[tuple[float, float, float, float]] = []
    for w in WINDOWS:
        j = np.searchsorted(t, t + w)
        i = np.flatnonzero(j < len(t))
        j = j[i]
        ok = (gap[j] == gap[i]) & (sd[i, S.THETA] < HEADING_SIGMA_MAX) & (sd[j, S.THETA] < HEADING_SIGMA_MAX)
        i, j = i[ok], j[ok]
        move = side[j] - side[i]
        # what the rows allow: each end's position sigma, and the heading's
        # sigma turning the distance driven into a sideways one
        allow = np.sqrt(pos_sd[i] ** 2 + pos_sd[j] ** 2
                        + ((path[j] - path[i]) * np.maximum(sd[i, S.THETA], sd[j, S.THETA])) ** 2)
        z = np.abs(move) / np.maximum(allow, 1e-9)
        hit = (np.abs(move) > SIDE_M) & (z > Z_SIDE)
        found += [(float(t[a]), float(t[b]), float(m), float(q)) for a, b, m, q in
                  zip(i[hit], j[hit], move[hit], z[hit])]
    return _merged(found)


def _merged(found):
    """Overlapping windows as one stretch, keeping the largest move's size."""
    out: list[tuple[float, float, float, float]] = []
    for a, b, m, z in sorted(found):
        if out and a <= out[-1][1]:
            a0, b0, m0, z0 = out[-1]
            big = (m, z) if abs(m) > abs(m0) else (m0, z0)
            out[-1] = (a0, max(b, b0), *big)
        else:
            out.append((a, b, m, z))
    return out


def warning(found: list[tuple[float, float, float, float]], fixes: bool = True) -> str:
    """The line naming the stretches (at most five); ``fixes``: whether the
    log has fixes or ranges to blame."""
    spans = ", ".join(f"{a:.1f}-{b:.1f} s ({abs(m):.2f} m, {z:.0f} sigma)"
                      for a, b, m, z in found[:5])
    more = f" and {len(found) - 5} more" if len(found) > 5 else ""
    why = ("its rows there follow the fixes (a GNSS multipath bias, a mocap marker that slid), or the robot "
           "skidded sideways, or a lever arm is wrong" if fixes else
           "with no fixes to pull them, the estimator's own corrections moved its rows there (through the "
           "position's correlation with the speed and scale states), or a lever arm is wrong")
    return (f"the estimate moved the robot sideways, which its wheels cannot do, at {spans}{more}: {why}; rows "
            "there may be off by that much; not trustworthy")


def recovered(found, biased, n: int) -> str:
    """The line when the run without the stretches' ``n`` fixes stood:
    ``biased`` are the seconds whose fixes sat off it (windowfit.stretches)."""
    spans = ", ".join(f"{a:.1f}-{b:.1f} s ({abs(m):.2f} m)" for a, b, m, _ in found[:5])
    off = ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in biased[:5])
    return (f"the estimate moved the robot sideways, which its wheels cannot do, at {spans}: the fixes there "
            f"pulled it; run again without them, the fixes at {off} sat more than 4 of their sigma off the "
            f"wheels' path (a GNSS multipath bias): {n} fixes held out, the rows there dead-reckoned; "
            "a bias that outlasts them, or a robot really pushed sideways, would leave rows off: not trustworthy")
