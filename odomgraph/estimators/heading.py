"""When the heading is not known yet: a robot that has neither driven nor turned.

Without an [initial] pose the start heading comes from the first motion
(initial.consensus_pose). A robot that stands still gives none: GPS fixes the
antenna, and with a lever arm l the centre lies anywhere on the circle of
radius |l| around it. No estimator may then report a heading, or a centre
tighter than that circle, however its linearisation reads the data:

- the EKF, relinearising each fix at a heading that wanders with the fix
  noise, gathered heading information that is not there (sigma 0.1 rad with
  0.4 rad of error after 150 s standing still: a 0.55 coverage);
- Gauss-Newton took the nonholonomic link between the heading and the fixes'
  slow wander as information (batch: heading 1.5 rad off at sigma 0.43).

``HeadingWatch`` says, causally, when the motion has shown the heading: the
wheels' dead-reckoned antenna has moved, and so have the fixes (a trailing
median, so that noise and outliers do not count as motion). Until then the
EKF takes fixes with the heading considered, not estimated (Schmidt), and its
position covariance floored at the circle's; the smoothers' rows before that
time (after it, for batch, only when it never comes) are widened by
``widen_rows``.

The circle. Weak fixes pin where the wheels' path lies (the mean of the
antenna points they saw) long before they pin which way it points. With the
heading anywhere, the centre at time t lies on the circle of radius
``|q(t) - a_bar(t)|`` around that point: q the wheels' dead-reckoned centre,
a_bar the mean of their dead-reckoned antenna at the fixes so far
(``HeadingWatch.arm``). Standing still that is the lever-arm circle, |l|. A
robot that drives a few metres between 2 m fixes at 1 Hz before they show
its heading is on a circle of metres: with the lever-arm circle alone the
rows held 57-87 % of positions inside +-3 sigma (EKF, isam2's causal rows and
fixed-lag; yard, no [initial], seeds 11, 12, 15), with errors of 3-5 m at
sigma 0.6 m.
"""
from __future__ import annotations

import bisect
import math
from collections import deque

import numpy as np

from odomgraph.estimators.gaps import add_pose_variance

#: Trailing window of fixes whose median tells motion from noise: this many at
#: least, and at least FIX_WINDOW_S seconds of them.
FIX_MEDIAN_N = 5
FIX_WINDOW_S = 2.0


def motion_threshold(fix_sigma: float) -> float:
    """Displacement that shows a heading [m]: the consensus fit's ``the antenna
    hardly moved`` test (initial.consensus_pose), 3 fix sigmas or 5 cm."""
    return max(3.0 * float(fix_sigma), 0.05)


def circle_variance(radius):
    """Per-axis variance [m^2] the unknown heading leaves the centre, a point
    of a circle of radius ``radius`` [m] (scalar or array): standing still,
    the centre is antenna - R(theta) l with theta anywhere, radius |l|
    (HeadingWatch.arm otherwise). Per-axis variance r^2 / 2; 3 sigma = 2.1 r,
    more than the circle's diameter, so any heading estimate is covered."""
    return 0.5 * np.asarray(radius, float) ** 2


class HeadingWatch:
    """Causal test: has the motion shown the heading yet?

    Feed it, in time order, the wheel measurements (``wheel``: nominal left
    and right speeds [m/s] over dt [s]) and the absolute fixes (``fix``:
    antenna x, y [m] with sigma [m]). ``known`` turns True, at time
    ``t_known`` [s], once both the wheels' dead-reckoned antenna (lever arm
    ``lever`` (2,) in the body frame [m], track ``track`` [m]) and the
    trailing median of the fixes have moved ``motion_threshold`` from where
    they started. Without fixes (``fixes=False``: ranges, whose single
    measurements fix no point) the wheels alone decide.
    """

    def __init__(self, track: float, lever, fix_sigma: float, fixes: bool = True, record: bool = True):
        self.track = float(track)
        self.lever = np.asarray(lever, float)
        self.thr = motion_threshold(fix_sigma)
        self.pose = np.zeros(3)
        self._a0 = self._antenna()
        self.wheels_moved = False
        self.fixes_moved = not fixes
        self._fixes: deque = deque()
        self._fix0: np.ndarray | None = None
        self.t_known = math.inf
        # when the wheels moved, and the first fix [s]: which of them the heading waited for (warning)
        self.t_wheels = self.t_first_fix = math.inf
        # the dead-reckoned antenna summed over the fixes so far, and how many
        self._a_sum, self._n_fix = np.zeros(2), 0
        # arm(): its value from each event on where it moved (arm_at), until the
        # heading is known; a filter that reads only arm() now records nothing
        self._record_on = bool(record)
        self._hist_t: list[float] = []
        self._hist_arm: list[float] = []
        # the fixes' world positions summed, and their mean at each history entry (centre_at)
        self._xy_sum = np.zeros(2)
        self._hist_c: list[tuple[float, float]] = []

    def __setstate__(self, state: dict) -> None:
        # a checkpoint written before the circle (odomgraph.online) has none of it
        self.__dict__.update(state)
        for name, value in (("_a_sum", np.zeros(2)), ("_n_fix", 0), ("_record_on", True), ("_hist_t", []),
                            ("_hist_arm", []), ("t_wheels", math.inf), ("t_first_fix", math.inf), ("_xy_sum", np.zeros(2)),
                            ("_hist_c", [])):
            self.__dict__.setdefault(name, value)

    @property
    def known(self) -> bool:
        return self.t_known < math.inf

    def _antenna(self) -> np.ndarray:
        c, s = math.cos(self.pose[2]), math.sin(self.pose[2])
        lx, ly = self.lever
        return np.array([self.pose[0] + c * lx - s * ly, self.pose[1] + s * lx + c * ly])

    def _done(self, t: float) -> None:
        if self.wheels_moved and self.fixes_moved and not self.known:
            self.t_known = float(t)

    def arm(self) -> float:
        """Radius [m] of the circle the centre lies on now while the heading
        is unknown: the dead-reckoned centre's distance from the mean
        dead-reckoned antenna of the fixes so far (module docstring), at
        least the lever arm |l| (all there is before the first fix)."""
        lever = float(np.hypot(*self.lever))
        if not self._n_fix:
            return lever
        return max(lever, float(np.hypot(*(self.pose[0:2] - self._a_sum / self._n_fix))))

    def arm_at(self, t) -> np.ndarray:
        """``arm()`` as it was at times t (N,) [s] (the last event at or
        before each; |l| before the first); after the heading is known, its
        last value. One time (a stream's row) is a bisection of the history,
        not a copy of it."""
        t = np.atleast_1d(np.asarray(t, float))
        lever = float(np.hypot(*self.lever))
        if t.size == 1:
            i = bisect.bisect_right(self._hist_t, float(t[0])) - 1
            return np.array([self._hist_arm[i] if i >= 0 else lever])
        if not self._hist_t:
            return np.full(t.shape, lever)
        i = np.searchsorted(np.asarray(self._hist_t), t, side="right") - 1
        vals = np.concatenate([[lever], self._hist_arm])
        return vals[i + 1]

    def centre_at(self, t) -> np.ndarray:
        """(N, 2) the mean of the fixes [m, world frame] as it was at times t
        (N,) [s] (the last history entry at or before each); NaN before the
        first fix or without the history."""
        t = np.atleast_1d(np.asarray(t, float))
        out = np.full((t.size, 2), np.nan)
        if len(self._hist_c) != len(self._hist_t) or not self._hist_t:
            return out
        i = np.searchsorted(np.asarray(self._hist_t), t, side="right") - 1
        c = np.asarray(self._hist_c, float)
        ok = i >= 0
        out[ok] = c[i[ok]]
        return out

    def _record(self, t: float) -> None:
        if not self._record_on:
            return
        a = self.arm()
        c = (tuple(self._xy_sum / self._n_fix) if self._n_fix else (math.nan, math.nan))
        if self._hist_arm and abs(a - self._hist_arm[-1]) < 1e-3 and (not self._n_fix or c == self._hist_c[-1]):
            return                        # standing still: the history stays one entry, not one per event
        self._hist_t.append(float(t))
        self._hist_arm.append(a)
        self._hist_c.append(c)

    def wheel(self, t: float, v_left: float, v_right: float, dt: float) -> None:
        if self.known:
            return
        v, w = 0.5 * (v_left + v_right), (v_right - v_left) / self.track
        th = self.pose[2] + 0.5 * w * dt
        self.pose += (v * dt * math.cos(th), v * dt * math.sin(th), w * dt)
        self._record(t)
        if not self.wheels_moved and float(np.hypot(*(self._antenna() - self._a0))) >= self.thr:
            self.wheels_moved = True
            self.t_wheels = float(t)
            self._done(t)

    def fix(self, t: float, xy, sigma: float | None = None) -> None:
        if self.known:
            return
        self._a_sum += self._antenna()
        self._xy_sum += np.asarray(xy, float)[:2]
        self._n_fix += 1
        self.t_first_fix = min(self.t_first_fix, float(t))
        self._record(t)
        if self.fixes_moved:
            return
        q = self._fixes
        q.append((float(t), float(xy[0]), float(xy[1])))
        while len(q) > FIX_MEDIAN_N and q[-1][0] - q[1][0] >= FIX_WINDOW_S:
            q.popleft()
        if len(q) < FIX_MEDIAN_N:
            return
        med = np.median(np.array([(x, y) for _, x, y in q]), 0)
        if self._fix0 is None:
            self._fix0 = med
        elif float(np.hypot(*(med - self._fix0))) >= self.thr:
            self.fixes_moved = True
            self._done(t)


def known_from(meas, robot) -> float:
    """``HeadingWatch.t_known`` over a whole log's measurements
    (estimators.measurements.Measurements): the time [s] the motion first
    shows the heading, math.inf if it never does. Causal: the same time a
    watch fed live would give."""
    return watch_log(meas, robot).t_known


def watch_log(meas, robot) -> HeadingWatch:
    """A ``HeadingWatch`` fed a whole log's measurements in time order until
    the heading is known (or the log ends): its ``t_known`` and ``arm_at``
    are what a watch fed live gives."""
    from odomgraph.estimators.sensors import GPS, WHEEL, event_stream
    if meas.gps is not None:
        lever, sig, fixes = robot.gps_lever_arm, float(np.median(meas.gps[2])), True
    else:
        lever, sig, fixes = robot.range_lever_arm, robot.range_sigma, False
    hw = HeadingWatch(robot.track_width, lever, sig, fixes)
    w = meas.wheel
    dt = w.dt if w.dt is not None else np.append(np.diff(w.t), np.median(np.diff(w.t)) if len(w.t) > 1 else 0.0)
    t_ev, code_ev, row_ev = event_stream(meas, w.t[0])
    for t, code, i in zip(t_ev, code_ev, row_ev):
        if code == WHEEL:
            hw.wheel(t, w.m[i, 0], w.m[i, 1], dt[i])
        elif code == GPS:
            hw.fix(t, meas.gps[1][i])
        if hw.known:
            break
    return hw


def widen_rows(t: np.ndarray, sigma: np.ndarray, pose_cov: np.ndarray | None, until: float, watch,
               mean: np.ndarray | None = None) -> int:
    """Rows before ``until`` [s] (t (N,), sigma (N, 11), pose_cov (N, 3, 3) or
    None, in place): heading sigma at least pi, and x, y widened by the
    circle the centre lies on at each row's time (circle_variance of
    ``watch.arm_at(t)``, a HeadingWatch fed at least that far) on top of what
    they had. With the rows' ``mean`` (N, 11), the circle is at least as wide
    as the row's own distance from the fixes' mean then (watch.centre_at): an
    estimate linearised at a heading that was a guess need not lie on the
    wheels' circle (a probe: isam2's causal rows on 10 m fixes at 0.2 Hz 47 m
    off at sigma 7-10 m, the circle 10-14 m). Returns the number of rows
    widened."""
    sel = np.asarray(t) < until
    n = int(sel.sum())
    if not n:
        return 0
    radius = watch.arm_at(np.asarray(t)[sel])
    if mean is not None:
        d = np.hypot(*(np.asarray(mean)[sel, 0:2] - watch.centre_at(np.asarray(t)[sel])).T)
        radius = np.where(np.isfinite(d), np.maximum(radius, d), radius)
    add_pose_variance(sigma, pose_cov, sel, circle_variance(radius))
    sigma[sel, 2] = np.maximum(sigma[sel, 2], math.pi)
    if pose_cov is not None:
        pc = pose_cov[sel]
        th = np.sqrt(np.maximum(pc[:, 2, 2], 1e-300))
        f = np.maximum(math.pi / th, 1.0)          # scale theta's row and column: stays positive semi-definite
        pc[:, 2, :] *= f[:, None]
        pc[:, :, 2] *= f[:, None]
        pose_cov[sel] = pc
    return n


def warning(until: float, watch: HeadingWatch | None = None) -> str:
    """The one-line warning of a stretch with the heading unknown; with the
    ``watch`` that decided, it names what the heading waited for: the robot
    to move, or the fixes (which came late, or showed no motion yet). Times
    are the log's, as the rows' and every other warning's (they counted from
    the schedule's origin, seconds off the rows where other sensors led)."""
    if watch is not None and until < math.inf and watch.t_wheels < until:
        first = (f"the first fix came at t={watch.t_first_fix:.1f} s" if watch.t_first_fix < math.inf
                 else "no fix came")
        return (f"heading not observable until t={until:.1f} s, when the fixes first showed the motion "
                f"({first}; the wheels had moved from t={watch.t_wheels:.1f} s): before it, heading sigma is "
                "pi and x, y sigma include the circle the centre can lie on (the wheels' path's around the fixes' "
                "mean)")
    if until == math.inf:
        return ("heading not observable: no motion showed which way the robot points (the wheels' path, or the "
                "fixes' trailing median, never moved 3 fix sigmas, at least 5 cm, from where it started); heading "
                "sigma is pi, and x, y sigma include the circle the centre can lie on (the GPS lever arm's, or "
                "the wheels' path's around the fixes' mean)")
    # (not "when the robot first moved": under 3 m fixes the robot had driven
    # for a minute by the time its path moved 3 fix sigmas; a probe's read t=67 s)
    return (f"heading not observable until t={until:.1f} s, when the motion first showed it (the wheels' path, or "
            "the fixes' trailing median, had moved 3 fix sigmas, at least 5 cm, from where it started): before it, "
            "heading sigma is pi and x, y sigma include the circle the centre can lie on (the lever arm's standing "
            "still, the wheels' path's around the fixes' mean once it drove)")
