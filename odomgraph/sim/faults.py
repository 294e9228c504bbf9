"""Faults that real logs contain, injected into any simulated scenario.

Two kinds:

* **motion faults** change what the robot does (``Faults.apply_to_scenario``):
  a *stall* (the robot held still while both wheels spin, the snowplow in a
  drift), pure rotation in place, standing still, very slow motion;
* **log faults** damage the recorded files (``Faults.apply_to_log``): GPS and
  range outliers (from the first second on, if asked), outages, a sensor that
  stops for good, dropped encoder rows whose ticks arrive summed in the next
  row (the contract allows it), duplicated rows, a clock jump in one file,
  and single-sample spikes in wheel speeds or the gyro.

Everything is seeded: the same Faults and seed give the same log. Truth is
left untouched, so a faulty log is scored against what really happened.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from odomgraph.errors import OptionError
from odomgraph.io.log import Encoders, Gps, Gyro, Log, Ranges, WheelSpeeds
from odomgraph.sim.scenarios import Scenario, Segment, SlipEvent

SENSORS = ("encoders", "gps", "gyro", "ranges", "velocity")


@dataclass(frozen=True)
class Stall:
    """The robot stands still over [start, end] while its wheels spin."""
    start: float
    """[s]"""
    end: float
    """[s]"""
    speed_left: float = 0.5
    """Left wheel surface speed during the stall, i.e. its slip [m/s]."""
    speed_right: float = 0.5


@dataclass(frozen=True)
class Faults:
    """What to inject (all off by default). Times are seconds on the scenario's
    clock (the simulated log starts at 0), as slip events and stalls are."""
    outlier_rate: float = 0.0
    """Fraction of GPS fixes and ranges replaced by outliers."""
    outlier_size: float = 5.0
    """Outlier offset [m]: GPS fixes move this far in a random direction; ranges by +-this."""
    outlier_from: float = 0.0
    """Outliers only after this time [s] (0: from the first fix on)."""
    outlier_sensors: tuple[str, ...] = ("gps", "ranges")
    outages: tuple[tuple[str, float, float], ...] = ()
    """(sensor, start, end): no data from that sensor in the window."""
    stops: tuple[tuple[str, float], ...] = ()
    """(sensor, time): the sensor stops for good."""
    stalls: tuple[Stall, ...] = ()
    motion: str | None = None
    """Replace the motion: "still" (stand still), "rotate" (pure rotation in
    place, both ways), "slow" (the scenario at 3 % of its speed)."""
    encoder_dropouts: tuple[tuple[float, float], ...] = ()
    """(start, end): encoder rows inside are lost; their ticks arrive in the next row."""
    encoder_drop_rate: float = 0.0
    """Fraction of single encoder rows lost the same way."""
    encoder_dup_rate: float = 0.0
    """Fraction of encoder rows written twice (same stamp, same ticks)."""
    clock_jumps: tuple[tuple[str, float, float], ...] = ()
    """(sensor, time, jump): stamps of that file from ``time`` on are off by ``jump`` [s]."""
    spikes: tuple[tuple[str, float, float], ...] = ()
    """(sensor, time, size): one sample at ``time`` is off by ``size``: a wheel
    speed [m/s] ("encoders": the left wheel's ticks) or a yaw rate [rad/s] ("gyro")."""
    gps_shifts: tuple[tuple[float, float, float, float], ...] = ()
    """(start, end, shift, ramp): the fixes between start and end [s] move
    ``shift`` [m] along the robot's true heading (negative: backwards), at
    once (ramp 0) or over ramps of ``ramp`` [s] at both ends: a GNSS
    multipath shift along the path, which analysis.plausible.outrun_stretches
    looks for."""

    def __post_init__(self):
        for name in ("outlier_rate", "encoder_drop_rate", "encoder_dup_rate"):
            v = getattr(self, name)
            if not 0.0 <= v <= 0.5:
                raise OptionError(f"{name} must be between 0 and 0.5, got {v:g}")
        if self.motion not in (None, "still", "rotate", "slow"):
            raise OptionError(f"motion must be still, rotate or slow, got {self.motion!r}")
        for s, *_ in (*self.outages, *self.stops, *self.clock_jumps, *self.spikes):
            if s not in SENSORS:
                raise OptionError(f"unknown sensor {s!r}; one of {', '.join(SENSORS)}")
        for st in self.stalls:
            if st.end <= st.start:
                raise OptionError(f"a stall needs start < end, got {st.start:g} to {st.end:g} s")
        for a, b, _, ramp in self.gps_shifts:
            if b <= a or ramp < 0:
                raise OptionError(f"a GPS shift needs start < end and ramp >= 0, got {a:g} to {b:g} s, ramp {ramp:g}")

    # ------------------------------------------------------------- motion
    def apply_to_scenario(self, sc: Scenario) -> Scenario:
        """The scenario with the motion faults: stalls and a replaced motion."""
        if self.motion == "still":
            sc = sc.with_(prologue=(Segment(sc.duration + 1.0, 0.0, 0.0),), loop=(), slips=())
        elif self.motion == "rotate":
            sc = sc.with_(prologue=(Segment(1.0, 0.0, 0.0),), loop=(Segment(6.0, 0.0, 0.8), Segment(6.0, 0.0, -0.8)),
                          slips=())
        elif self.motion == "slow":
            f = 0.03 / max(max(abs(s.v) for s in (*sc.prologue, *sc.loop)), 1e-9)
            slow = lambda segs: tuple(Segment(s.duration, s.v * f, s.omega * f) for s in segs)
            sc = sc.with_(prologue=slow(sc.prologue), loop=slow(sc.loop), slips=())
        if self.stalls:
            slips = list(sc.slips)
            for st in self.stalls:
                slips += [SlipEvent("left", st.start, st.end, st.speed_left),
                          SlipEvent("right", st.start, st.end, st.speed_right)]
            sc = sc.with_(holds=tuple(sc.holds) + tuple((st.start, st.end) for st in self.stalls),
                          slips=tuple(slips))
        return sc

    # ---------------------------------------------------------------- log
    def apply_to_log(self, log: Log, seed: int = 0) -> Log:
        """The log with the file faults (truth unchanged)."""
        rng = np.random.default_rng([seed, 0xFA17])
        t0 = 0.0                   # the scenario's clock, as for stalls and slip events
        changes = {}
        for name in ("encoders", "wheel_speeds", "gps", "gyro", "ranges", "velocity"):
            obj = getattr(log, name)
            if obj is None:
                continue
            key = "encoders" if name == "wheel_speeds" else name
            obj = self._outliers(obj, key, t0, rng)
            obj = self._spikes(obj, key, t0, log)
            obj = self._shifts(obj, t0, log)
            if name == "encoders":
                obj = self._encoder_rows(obj, t0, rng)
            obj = self._gaps(obj, key, t0)
            obj = self._jumps(obj, key, t0)
            changes[name] = obj
        return log.with_(**changes)

    def _outliers(self, obj, key, t0, rng):
        if self.outlier_rate <= 0 or key not in self.outlier_sensors or not isinstance(obj, (Gps, Ranges)):
            return obj
        hit = (rng.random(len(obj.t)) < self.outlier_rate) & (obj.t >= t0 + self.outlier_from)
        if isinstance(obj, Gps):
            ang = rng.uniform(0, 2 * np.pi, len(obj.t))
            return replace(obj, x=np.where(hit, obj.x + self.outlier_size * np.cos(ang), obj.x),
                           y=np.where(hit, obj.y + self.outlier_size * np.sin(ang), obj.y))
        sign = rng.choice([-1.0, 1.0], len(obj.t))
        return replace(obj, range=np.where(hit, np.abs(obj.range + sign * self.outlier_size), obj.range))

    def _spikes(self, obj, key, t0, log):
        for sensor, t, size in self.spikes:
            if sensor != key or len(obj.t) < 2:
                continue
            k = int(np.argmin(np.abs(obj.t - (t0 + t))))
            if isinstance(obj, Encoders):
                k = max(k, 1)
                dt = obj.t[k] - obj.t[k - 1]
                ticks = obj.ticks_left.copy()
                ticks[k] += np.round(size * log.robot.ticks_per_meter_left * dt)
                obj = replace(obj, ticks_left=ticks)
            elif isinstance(obj, WheelSpeeds):
                v = obj.v_left.copy()
                v[k] += size
                obj = replace(obj, v_left=v)
            elif isinstance(obj, Gyro):
                w = obj.omega.copy()
                w[k] += size
                obj = replace(obj, omega=w)
        return obj

    def _shifts(self, obj, t0, log):
        if not self.gps_shifts or not isinstance(obj, Gps) or log.truth is None:
            return obj
        amount = np.zeros(len(obj.t))
        for a, b, shift, ramp in self.gps_shifts:
            ta, tb = t0 + a, t0 + b
            if ramp > 0:
                amount += shift * np.clip(np.minimum(obj.t - ta, tb - obj.t) / ramp, 0.0, 1.0)
            else:
                amount += shift * ((obj.t >= ta) & (obj.t <= tb))
        th = log.truth.at("theta", obj.t)
        return replace(obj, x=obj.x + amount * np.cos(th), y=obj.y + amount * np.sin(th))

    def _encoder_rows(self, e: Encoders, t0, rng):
        n = len(e.t)
        lost = rng.random(n) < self.encoder_drop_rate
        for a, b in self.encoder_dropouts:
            lost |= (e.t > t0 + a) & (e.t < t0 + b)
        lost[0] = lost[-1] = False
        if lost.any():
            # A lost row's ticks arrive in the next kept row: its count is over (t_prev_kept, t].
            idx = np.flatnonzero(~lost)
            owner = idx[np.searchsorted(idx, np.arange(n))]
            e = Encoders(e.t[idx], *(np.bincount(owner, weights=c, minlength=n)[idx]
                                     for c in (e.ticks_left, e.ticks_right)))
        if self.encoder_dup_rate > 0:
            dup = rng.random(len(e.t)) < self.encoder_dup_rate
            dup[0] = False
            idx = np.sort(np.concatenate([np.arange(len(e.t)), np.flatnonzero(dup)]))
            e = Encoders(e.t[idx], e.ticks_left[idx], e.ticks_right[idx])
        return e

    def _gaps(self, obj, key, t0):
        keep = np.ones(len(obj.t), bool)
        for sensor, a, b in self.outages:
            if sensor == key:
                keep &= ~((obj.t >= t0 + a) & (obj.t <= t0 + b))
        for sensor, t in self.stops:
            if sensor == key:
                keep &= obj.t < t0 + t
        if keep.all():
            return obj
        if isinstance(obj, Encoders):
            # Lost encoder rows: the next row carries the whole count.
            raise OptionError("an encoder outage is an encoder dropout: use encoder_dropouts")
        return _select(obj, keep)

    def _jumps(self, obj, key, t0):
        for sensor, t, jump in self.clock_jumps:
            if sensor == key:
                ts = np.where(obj.t >= t0 + t, obj.t + jump, obj.t)
                if jump < 0:       # stamps stay increasing: the overlap is lost, as a real logger loses it
                    ok = np.concatenate([[True], ts[1:] > np.maximum.accumulate(ts)[:-1]])
                    obj = _select(replace(obj, t=ts), ok)
                else:
                    obj = replace(obj, t=ts)
        return obj


def _select(obj, keep):
    kw = {k: (v[keep] if isinstance(v, np.ndarray) else v) for k, v in obj.__dict__.items()}
    return type(obj)(**kw)


def parse(kind: str, text: str):
    """One CLI fault spec -> the value of a Faults field (see ``simulate --help``)."""
    parts = text.split(":")

    def nums(p, n):
        try:
            vals = [float(v) for v in p]
        except ValueError:
            vals = []
        if len(vals) != n or not all(np.isfinite(vals)):
            raise OptionError(f"--{kind}: expected {n} numbers in {text!r}")
        return vals
    if kind == "outliers":
        rate, size, *rest = nums(parts, len(parts)) if len(parts) in (2, 3) else nums(parts, 2)
        return {"outlier_rate": rate, "outlier_size": size, "outlier_from": rest[0] if rest else 0.0}
    if kind in ("outage", "clock-jump", "spike"):
        if len(parts) != 3:
            raise OptionError(f"--{kind}: expected 'sensor:a:b', got {text!r}")
        return (parts[0], *nums(parts[1:], 2))
    if kind == "stop":
        if len(parts) != 2:
            raise OptionError(f"--stop: expected 'sensor:time', got {text!r}")
        return (parts[0], nums(parts[1:], 1)[0])
    if kind == "stall":
        v = nums(parts, 4) if len(parts) == 4 else nums(parts, 2) + [0.5, 0.5]
        return Stall(*v)
    if kind == "encoder-dropout":
        return tuple(nums(parts, 2))
    raise OptionError(f"unknown fault {kind!r}")


def inject(sc: Scenario, faults: Faults, seed: int = 0) -> Log:
    """Simulate ``sc`` with ``faults``: the motion faults in the scenario, the file faults in the log."""
    from odomgraph.sim.simulate import simulate
    return faults.apply_to_log(simulate(faults.apply_to_scenario(sc), seed), seed)

