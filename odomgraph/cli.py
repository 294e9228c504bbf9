"""The ``odomgraph`` command line: a thin layer over ``odomgraph.pipeline``.

Heavy imports happen inside the commands so that ``--help`` is instant.
Known errors, bad option values included, become one line on stderr,
``odomgraph: error: ...``, and exit code 1. SIGTERM is handled as Ctrl-C:
outputs are written atomically, so either stops leaves nothing half-written.
"""
from __future__ import annotations

import functools
import signal
import sys
from enum import Enum
from pathlib import Path
from typing import Annotated, Optional

import typer
from typer.core import TyperGroup

try:                                   # typer >= 0.20 carries its own copy of click
    from typer._click import exceptions as _click_exc
except ImportError:                    # pragma: no cover - older typer on real click
    from click import exceptions as _click_exc


class _OneLineErrors(TyperGroup):
    """Usage errors (a bad option value, an unknown option) as one line and exit 1,
    like every other error, instead of click's boxed usage text and exit 2."""

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        try:
            rv = super().main(args=args, prog_name=prog_name, complete_var=complete_var, standalone_mode=False,
                              **extra)
        except _click_exc.NoArgsIsHelpError as exc:
            typer.echo(exc.ctx.get_help() if exc.ctx else exc.format_message())
            rv = 0
        except _click_exc.ClickException as exc:
            msg = " ".join(exc.format_message().split())
            if isinstance(exc, _click_exc.UsageError) and exc.ctx is not None and exc.ctx.parent is not None:
                msg = f"{exc.ctx.command_path}: {msg}"
            typer.echo(f"odomgraph: error: {msg}", err=True)
            rv = 1
        except typer.Abort:
            typer.echo("odomgraph: interrupted; nothing was written", err=True)
            rv = 130
        if not standalone_mode:
            return rv
        sys.exit(rv if isinstance(rv, int) else 0)


def _version(value: bool):
    if value:
        from odomgraph import __version__
        _out(f"odomgraph {__version__}")
        raise typer.Exit()


app = typer.Typer(
    cls=_OneLineErrors,
    help="Wheel-odometry error estimation (scale factors + per-wheel slip) for differential-drive robots.\n\n"
         "Logs and outputs follow LOG_FORMAT.md. Start with `odomgraph demo`.",
    no_args_is_help=True, add_completion=False, pretty_exceptions_enable=False,
    # Plain help text: rich markup would eat units written as [m] or [s].
    rich_markup_mode=None, context_settings={"help_option_names": ["-h", "--help"]},
)


#: 0: -q (errors and warnings only), 1: default, 2: -v (also what was used, rejected and recovered).
_VERBOSITY = [1]


def _warn(warnings) -> None:
    """Each warning on one line of the error stream (never quieted by -q)."""
    for w in warnings:
        typer.echo(f"odomgraph: warning: {' '.join(str(w).split())}", err=True)


def _out(message: str = "", level: int = 1) -> None:
    """An informational line on stdout, shown at verbosity ``level`` or above
    (errors and warnings go to stderr whatever -q says)."""
    if _VERBOSITY[0] >= level:
        typer.echo(message)


@app.callback()
def _root(version: Annotated[bool, typer.Option("--version", callback=_version, is_eager=True,
                                                help="Print the version and exit.")] = False,
          quiet: Annotated[bool, typer.Option("--quiet", "-q", help="Only errors and warnings (on stderr); "
                                                                   "no progress bars.")] = False,
          verbose: Annotated[bool, typer.Option("--verbose", "-v", help="Also print the measurements used, "
                                                                       "rejected and down-weighted per sensor, "
                                                                       "recoveries and fitted noise scales.")]
          = False):
    """Wheel-odometry error estimation (scale factors + per-wheel slip) for differential-drive robots.

    Logs and outputs follow LOG_FORMAT.md. Start with `odomgraph demo`."""
    if quiet and verbose:
        raise _click_exc.UsageError("give -q or -v, not both")
    _VERBOSITY[0] = 0 if quiet else 2 if verbose else 1


class ScenarioName(str, Enum):
    paper = "paper"
    yard = "yard"


class MethodName(str, Enum):
    ekf = "ekf"
    batch = "batch"
    isam2 = "isam2"
    fixed_lag = "fixed-lag"


class RobustName(str, Enum):
    huber = "huber"
    cauchy = "cauchy"
    none = "none"


class ImportKind(str, Enum):
    optiodom = "optiodom"
    librsf = "librsf"
    rosbag = "rosbag"


class Numbers:
    """Parser of ``n`` comma-separated finite numbers ("0.005,0.01"), run as
    the option is read: a bad value is a usage error naming the option,
    before any work starts."""

    def __init__(self, n: int, what: str):
        self.n, self.what = n, what
        self.__name__ = what

    def __call__(self, value):
        import math
        if isinstance(value, tuple):
            return value
        try:
            vals = tuple(float(v) for v in str(value).split(","))
        except ValueError:
            vals = ()
        if len(vals) != self.n or not all(math.isfinite(v) for v in vals):
            raise typer.BadParameter(f"expected {self.n} comma-separated finite numbers ({self.what}), "
                                     f"got {value!r}")
        return vals


def slip_spec(value):
    """Parser of a slip event "left|right:start:end:speed" [s, s, m/s]."""
    from odomgraph.sim.scenarios import SlipEvent
    if not isinstance(value, str):
        return value
    parts = value.split(":")
    if len(parts) != 4 or parts[0] not in ("left", "right"):
        raise typer.BadParameter(f"expected 'left|right:start:end:speed', got {value!r}")
    from odomgraph.errors import OdomgraphError
    try:
        return SlipEvent(parts[0], float(parts[1]), float(parts[2]), float(parts[3]))
    except ValueError:
        raise typer.BadParameter(f"expected numbers in {value!r}") from None
    except OdomgraphError as exc:  # the event's own checks (start <= end, ...)
        raise typer.BadParameter(str(exc)) from None


def _names(value, n: int, what: str) -> tuple:
    if isinstance(value, tuple):
        return value
    parts = tuple(v.strip() for v in str(value).split(","))
    if len(parts) != n or not all(parts):
        raise typer.BadParameter(f"expected {what}, got {value!r}")
    return parts


def _one_or_two(value) -> tuple:
    """One positive number or two ("2000" or "2000,2010"), as (left, right)."""
    if isinstance(value, tuple):
        return value
    vals = Numbers(2, "left,right")(value) if "," in str(value) else Numbers(1, "one value")(value) * 2
    if not all(v > 0 for v in vals):
        raise typer.BadParameter(f"ticks per metre must be positive, got {value!r}")
    return vals


class AtName(str, Enum):
    truth = "truth"
    gps = "gps"


class HoldName(str, Enum):
    consider = "consider"
    pseudo = "pseudo"


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that every cleanup (temporary output
    directories, worker pools) runs."""


def _on_sigterm(signum, frame):
    raise Terminated()


def _user_errors(fn):
    """Turn the project's known errors, and any failure to read or write a
    file, into one line and exit 1."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        from odomgraph.errors import OdomgraphError
        try:
            return fn(*args, **kwargs)
        except OdomgraphError as exc:
            typer.echo(f"odomgraph: error: {' '.join(str(exc).split())}", err=True)
            raise typer.Exit(code=1)
        except KeyboardInterrupt as exc:
            typer.echo("odomgraph: interrupted; nothing was written", err=True)
            raise typer.Exit(code=143 if isinstance(exc, Terminated) else 130)
        except OSError as exc:
            where = f"{exc.filename}: " if exc.filename else ""
            typer.echo(f"odomgraph: error: {where}{exc.strerror or exc}", err=True)
            raise typer.Exit(code=1)
    return wrapper


class _Progress:
    """A rich progress bar on stderr, fed by an estimator's progress(done, total)."""

    def __init__(self, label: str):
        # Only on a terminal: piped into a file, a bar is noise (and rich
        # leaves an empty line behind).
        self._on = sys.stderr.isatty() and _VERBOSITY[0] > 0
        if not self._on:
            return
        from rich.console import Console
        from rich.progress import BarColumn, Progress, TimeElapsedColumn, TimeRemainingColumn, TextColumn
        self._p = Progress(TextColumn(label), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                           TimeElapsedColumn(), TimeRemainingColumn(), console=Console(stderr=True),
                           transient=True)
        self._task = None

    def __enter__(self):
        if self._on:
            self._p.__enter__()
        return self

    def __exit__(self, *exc):
        return self._p.__exit__(*exc) if self._on else None

    def __call__(self, done: int, total: int):
        if not self._on:
            return
        if self._task is None:
            self._task = self._p.add_task("", total=total)
        self._p.update(self._task, completed=done)


class _MultiProgress(_Progress):
    """One bar per run: called with a label, returns that run's progress(done, total)."""

    def __init__(self):
        super().__init__("{task.description:<18}")

    def __call__(self, label: str):
        if not self._on:
            return None
        task = self._p.add_task(label, total=1)

        def update(done: int, total: int):
            self._p.update(task, completed=done, total=total)
        return update


def _columns(rows: list[list[str]], keep: list[int]) -> None:
    widths = [max(len(r[i]) for r in rows) for i in keep]
    for r in rows:
        _out("  ".join(r[i].ljust(w) for i, w in zip(keep, widths)))


def _print_comparison(m: dict, determined: dict | None = None) -> None:
    from odomgraph.analysis.report import metrics_table_rows, scale_table_rows
    _columns(metrics_table_rows(m), [0, 1, 2, 3, 4, 6])  # the columns that fit a terminal
    _out("")
    _columns(scale_table_rows(m, determined or {}), list(range(7)))
    _out(f"reference: {m['reference_note']}")
    for label, e in m["estimators"].items():
        if "failed" in e and label != "isam2-online":
            _out(f"{label}: {e['failed']}")
        for b, v in (e.get("range_bias") or {}).items():
            _out(f"{label}: range bias {b:<8} {v['value']:+.3f} ± {v['sigma']:.3f} m")


def _parse_schedule(calibrate_until: str, hold: HoldName):
    from odomgraph.errors import OdomgraphError
    from odomgraph.estimators.schedule import Hold, Schedule
    if calibrate_until.strip().lower() == "none":
        return Schedule(calibrate_until=None, hold=Hold(hold.value))
    try:
        T = float(calibrate_until)
    except ValueError:
        raise OdomgraphError(f"--calibrate-until: expected seconds or 'none', got {calibrate_until!r}") from None
    if T < 0:
        raise OdomgraphError("--calibrate-until must not be negative")
    return Schedule(calibrate_until=T, hold=Hold(hold.value))


def _print_summary(s: dict) -> None:
    cal = s["calibration"]
    _out(f"{s['method']}: {s['n_steps']} rows, {s['n_updates']} updates in {s['wall_time_s']:.2f} s "
               f"({s['updates_per_second']:.0f} updates/s)")
    truth = s.get("truth_scales", {})
    for k, v in cal.items():
        tv = f"   truth {truth[k]:.4f}" if k in truth else ""
        _out(f"  {k:<12} {v['value']:.4f} ± {v['sigma']:.4f}{tv}")
    for key, label in (("errors", ""), ("errors_online", " (online)")):
        if key in s:
            e = s[key]
            slip = ", ".join(f"{w} {v:.3f}" for w, v in e["rms_slip_mps"].items())
            _out(f"  RMS position error{label} {e['rms_position_m']:.3f} m; RMS slip error after calibration: "
                       f"{slip} m/s")
    if "update_time_ms" in s:
        u = s["update_time_ms"]
        _out(f"  update time: mean {u['mean']:.2f} ms, first 10% {u['first_10pct']:.2f} ms, "
                   f"last 10% {u['last_10pct']:.2f} ms")
    for b, v in s.get("range_bias", {}).items():
        _out(f"  range bias {b:<8} {v['value']:+.3f} ± {v['sigma']:.3f} m")
    for n in s["notes"]:
        _out(f"  note: {n}")
    for sensor, n in s.get("used", {}).items():
        _out(f"  {sensor}: {n} used, {s.get('rejected', {}).get(sensor, 0)} rejected, "
             f"{s.get('downweighted', {}).get(sensor, 0)} down-weighted", level=2)
    for r in s.get("recoveries", []):
        _out(f"  recovery: {r}", level=2)
    for r in s.get("departures", []):
        _out(f"  departure: {r}", level=2)
    for sensor, v in s.get("noise_scales", {}).items():
        _out(f"  noise scale {sensor}: measured {v['measured']:.2f}, applied {v['applied']:.2f}", level=2)
    why = "; ".join(s.get("status_reasons", []))
    _out(f"  status: {s['status']}" + (f" ({why})" if why else ""))
    _warn(s.get("warnings", []))


@app.command()
@_user_errors
def simulate(
    output: Annotated[Path, typer.Option("--output", "-o", help="Log directory to write.")],
    scenario: Annotated[ScenarioName, typer.Option(help="paper: Kreinar & Quinn sec. IV; yard: a second robot.")]
    = ScenarioName.paper,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    duration: Annotated[Optional[float], typer.Option(help="Length of the log [s] (scenario default if unset).")]
    = None,
    encoder_hz: Annotated[Optional[float], typer.Option(help="Encoder rate [Hz].")] = None,
    gyro_hz: Annotated[Optional[float], typer.Option(help="Gyro rate [Hz]; 0 = no gyro.")] = None,
    gps_hz: Annotated[Optional[float], typer.Option(help="GPS rate [Hz]; 0 = no GPS.")] = None,
    range_hz: Annotated[Optional[float], typer.Option(help="Range rate per beacon [Hz]; >0 adds 3 beacons.")] = None,
    velocity_hz: Annotated[Optional[float], typer.Option(help="Body-velocity sensor rate [Hz].")] = None,
    gps_sigma: Annotated[Optional[float], typer.Option(help="GPS noise 1-sigma [m] (eq. 39).")] = None,
    gyro_sigma: Annotated[Optional[float], typer.Option(help="Gyro noise 1-sigma [rad/s] (eq. 40).")] = None,
    range_sigma: Annotated[Optional[float], typer.Option(help="Range noise 1-sigma [m].")] = None,
    encoder_sigma: Annotated[Optional[tuple], typer.Option(
        parser=Numbers(2, "a,b"), metavar="A,B", help="Wheel-speed noise 'a,b': a + b|v| m/s (eq. 41).")] = None,
    scales: Annotated[Optional[tuple], typer.Option(
        parser=Numbers(3, "left,right,track"), metavar="L,R,T", help="True scale factors 'left,right,track'.")] = None,
    slip: Annotated[Optional[list[str]], typer.Option(parser=slip_spec, metavar="WHEEL:START:END:SPEED",
        help="Slip event 'wheel:start:end:speed' (s, s, m/s); repeat for more. Replaces the scenario's.")] = None,
    no_slip: Annotated[bool, typer.Option("--no-slip", help="No slip events at all.")] = False,
    initial: Annotated[bool, typer.Option(help="Write the true start pose as robot.toml [initial].")] = False,
    outliers: Annotated[Optional[str], typer.Option(
        help="Fault: GPS and range outliers 'rate:size[:from]' (fraction, m, s), e.g. 0.05:5.", rich_help_panel="Faults")]
    = None,
    outage: Annotated[Optional[list[str]], typer.Option(
        help="Fault: 'sensor:start:end' [s] with no data from gps, gyro, ranges or velocity; repeatable.",
        rich_help_panel="Faults")] = None,
    stop: Annotated[Optional[list[str]], typer.Option(
        help="Fault: 'sensor:time' [s] from which the sensor is silent for good; repeatable.",
        rich_help_panel="Faults")] = None,
    stall: Annotated[Optional[list[str]], typer.Option(
        help="Fault: 'start:end[:left:right]' [s, m/s]: the robot stands still while both wheels spin "
             "(default 0.5 m/s each); repeatable.", rich_help_panel="Faults")] = None,
    motion: Annotated[Optional[str], typer.Option(
        help="Fault: replace the motion with 'still', 'rotate' (in place) or 'slow' (3 % speed).",
        rich_help_panel="Faults")] = None,
    encoder_dropout: Annotated[Optional[list[str]], typer.Option(
        help="Fault: 'start:end' [s]: encoder rows lost, their ticks arrive summed in the next row; repeatable.",
        rich_help_panel="Faults")] = None,
    drop_rate: Annotated[float, typer.Option(help="Fault: fraction of single encoder rows lost (ticks summed "
                                                  "into the next).", rich_help_panel="Faults")] = 0.0,
    dup_rate: Annotated[float, typer.Option(help="Fault: fraction of encoder rows written twice.",
                                            rich_help_panel="Faults")] = 0.0,
    clock_jump: Annotated[Optional[list[str]], typer.Option(
        help="Fault: 'sensor:time:jump' [s]: that file's stamps from time on are off by jump; repeatable.",
        rich_help_panel="Faults")] = None,
    spike: Annotated[Optional[list[str]], typer.Option(
        help="Fault: 'sensor:time:size': one encoders (left wheel, m/s) or gyro (rad/s) sample off by size; "
             "repeatable.", rich_help_panel="Faults")] = None,
):
    """Simulate a scenario and write a log directory with truth.csv and truth.toml.

    The fault options inject what real logs contain (odomgraph.sim.faults);
    truth stays what really happened."""
    from odomgraph.errors import OdomgraphError
    from odomgraph.io.log import write_log
    from odomgraph.sim.scenarios import SCENARIOS
    from odomgraph.sim.simulate import beacons_around_path

    from odomgraph.io.outdir import check_output
    check_output(output)
    if duration is not None and not (0 < duration <= 1e6):
        raise OdomgraphError(f"--duration must be positive (and at most 1e6 s), got {duration:g}")
    sc = SCENARIOS[scenario.value]() if duration is None else SCENARIOS[scenario.value](duration)

    rates = {k: v for k, v in dict(encoders=encoder_hz, gyro=gyro_hz, gps=gps_hz, ranges=range_hz,
                                     velocity=velocity_hz).items() if v is not None}
    if any(not 0 <= v <= 1e4 for v in rates.values()) or rates.get("encoders", 1) == 0:
        raise OdomgraphError("sensor rates must be between 0 and 1e4 Hz, and the encoder rate > 0")
    sc = sc.with_(rates=sc.rates.__class__(**{**sc.rates.__dict__, **rates}))
    robot = sc.robot
    for name, val in (("gps_sigma", gps_sigma), ("gyro_sigma", gyro_sigma), ("range_sigma", range_sigma)):
        if val is not None:
            if not val > 0:
                raise OdomgraphError(f"--{name.replace('_', '-')} must be positive, got {val:g}")
            robot = robot.with_(**{name: val})
    if encoder_sigma is not None:
        robot = robot.with_(encoder_sigma=encoder_sigma)
    if sc.rates.ranges > 0 and not robot.beacons:
        robot = robot.with_(beacons=beacons_around_path(sc))
    sc = sc.with_(robot=robot, write_initial=initial)
    if scales is not None:
        sc = sc.with_(scales=scales)
        if not all(0.2 < v < 5 for v in sc.scales):
            raise OdomgraphError(f"--scales: each scale factor must be between 0.2 and 5, got {list(scales)}")
    if no_slip:
        sc = sc.with_(slips=())
    elif slip:
        sc = sc.with_(slips=tuple(slip))
    from odomgraph.sim.faults import Faults, inject, parse
    kw = parse("outliers", outliers) if outliers else {}
    faults = Faults(**kw, outages=tuple(parse("outage", v) for v in outage or ()),
                    stops=tuple(parse("stop", v) for v in stop or ()),
                    stalls=tuple(parse("stall", v) for v in stall or ()), motion=motion,
                    encoder_dropouts=tuple(parse("encoder-dropout", v) for v in encoder_dropout or ()),
                    encoder_drop_rate=drop_rate, encoder_dup_rate=dup_rate,
                    clock_jumps=tuple(parse("clock-jump", v) for v in clock_jump or ()),
                    spikes=tuple(parse("spike", v) for v in spike or ()))
    log = inject(sc, faults, seed)
    write_log(log, output)
    _out(f"wrote {output} ({sc.name}, {sc.duration:g} s, seed {seed})")


@app.command()
@_user_errors
def estimate(
    log_dir: Annotated[list[Path], typer.Argument(
        metavar="LOG...", help="Log directory (LOG_FORMAT.md); several, or a directory of logs, run as a fleet.")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Estimate directory to write (a fleet: one "
                                                                 "per log inside it, and fleet.csv).")],
    method: Annotated[MethodName, typer.Option("--method", "-m", help="Estimator.")] = MethodName.ekf,
    calibrate_until: Annotated[str, typer.Option(
        help="Seconds from the log start (the wheels' first row when the other sensors ran before them) to "
             "estimate scale factors with slip forced to 0; "
             "after it the scale factors are held and slip is estimated. 0 = slip only.")] = "20",
    hold: Annotated[HoldName, typer.Option(
        help="consider: hold scale factors with zero gain, keep honest sigma (default); "
             "pseudo: the paper's literal pseudo-update (eq. 37-38).")] = HoldName.consider,
    gate: Annotated[Optional[float], typer.Option(
        help="EKF: NIS above which GPS, range and velocity updates are rejected (when they also differ from "
             "the sensor's recent ones). Default: the chi-square quantile at 1 - 1e-6 (27.6 for GPS).")] = None,
    keyframe_hz: Annotated[Optional[float], typer.Option(
        help="Smoothers: keyframe rate [Hz] (default 5; at most the encoder rate).")] = None,
    lag: Annotated[Optional[float], typer.Option(help="fixed-lag: window length [s] (default 5).")] = None,
    slip_cauchy: Annotated[Optional[float], typer.Option(
        help="Smoothers: Cauchy scale [m/s] of the sparse zero-slip prior outside the calibration window "
             "(default 0.005).")] = None,
    slip_check: Annotated[Optional[bool], typer.Option(
        "--slip-check/--no-slip-check",
        help="Smoothers: check the sparse slip prior against the prior-free solution where slip is seen after "
             "the window (default on; batch then gives the prior-free rows or widens its sigma, isam2 and "
             "fixed-lag are flagged).")] = None,
    robust: Annotated[Optional[RobustName], typer.Option(
        help="Smoothers: robust loss for GPS fixes and ranges (real data has outliers); default cauchy, "
             "with graduated non-convexity in batch; none: Gaussian.")]
    = None,
    robust_k: Annotated[Optional[float], typer.Option(
        help="Threshold of the robust loss in sigmas (default: 5 Cauchy, 1.345 Huber).")] = None,
    range_bias: Annotated[Optional[bool], typer.Option(
        "--range-bias/--no-range-bias", help="batch: estimate a constant range bias per beacon (UWB antenna "
        "delay), or not (default: when the first fit's residuals show one).")]
    = None,
    time_offset: Annotated[bool, typer.Option(
        "--time-offset", help="Estimate how late the GPS stamps are against the wheels, and apply it "
                              "(without it, a clear offset is only warned about).")] = False,
    rate: Annotated[Optional[float], typer.Option(
        min=1e-6, max=1000.0, help="Write the states at this regular rate [Hz] (smoother rows are interpolated along "
                       "the arc between keyframes, with their sigma), for tools such as evo.")] = None,
    at: Annotated[Optional[AtName], typer.Option(
        help="Write the states at the truth's or the GPS fixes' times (interpolated as with --rate).")] = None,
    workers: Annotated[Optional[int], typer.Option(
        min=1, help="A fleet: local worker processes (default: all cores).")] = None,
    scheduler: Annotated[Optional[str], typer.Option(
        help="A fleet: Dask scheduler address tcp://HOST:PORT to run the logs on.")] = None,
):
    """Estimate states and odometry errors of a log; writes states.csv, trajectory.tum, summary.json
    (and online.csv, the causal estimate, for isam2; truth.tum when the log has truth).

    Methods: ekf (the paper's filter), batch (whole-log smoother), isam2 (incremental smoother),
    fixed-lag (incremental smoother over a window). --calibrate-until none estimates slip and
    scale factors together with a sparse slip prior (smoothers only).
    """
    from odomgraph.io.log import read_log
    from odomgraph.pipeline import Method, estimate_to_dir
    schedule = _parse_schedule(calibrate_until, hold)
    options = dict(gate=gate, keyframe_hz=keyframe_hz, lag=lag, slip_cauchy=slip_cauchy, slip_check=slip_check,
                   robust=robust.value if robust else None, robust_k=robust_k, range_bias=range_bias,
                   time_offset=time_offset, rate=rate, at=at.value if at else None)
    if _is_fleet(log_dir, workers, scheduler):
        _fleet("estimate", log_dir, output, Method(method.value), schedule, workers, scheduler, options)
        return
    log = read_log(log_dir[0])
    with _Progress(f"{method.value}") as bar:
        s = estimate_to_dir(log, output, Method(method.value), schedule, progress=bar, **options)
    _print_summary(s)
    _out(f"wrote {output}")


def _is_fleet(paths: list[Path], workers, scheduler) -> bool:
    """Several logs, or one directory of logs: a fleet (odomgraph.fleet)."""
    from odomgraph.errors import OdomgraphError
    from odomgraph.fleet import is_log_dir
    fleet = len(paths) > 1 or (paths[0].is_dir() and not is_log_dir(paths[0]))
    if not fleet and (workers is not None or scheduler is not None):
        raise OdomgraphError("--workers and --scheduler are for a fleet: several logs, or a directory of logs")
    return fleet


def _fleet(kind: str, paths, output: Path, method, schedule, workers, scheduler, options: dict) -> None:
    """Run a fleet, print one line per log and where it went; exit 1 if any log failed."""
    from odomgraph.errors import OdomgraphError
    from odomgraph.fleet import run_fleet
    if output.suffix == ".toml":
        raise OdomgraphError(f"-o {output}: a fleet writes a directory (NAME.toml per log and fleet.csv); "
                             "give -o DIR")
    with _Progress(f"fleet {kind} ({method.value})") as bar:
        rows = run_fleet(paths, output, kind, method, schedule, workers, scheduler, progress=bar, **options)
    failed = [r for r in rows if r["result"] == "failed"]
    for r in rows:
        if r["result"] == "failed":
            typer.echo(f"odomgraph: error: {r['name']}: {r['error']}", err=True)
            continue
        k = " ".join(f"{n.removeprefix('scale_')} {r[n]:.4f}" for n in ("scale_left", "scale_right", "scale_track")
                     if r.get(n) is not None)
        _out(f"{r['name']:<24} {r['status']:<9} {k}" + (f"  ({r['warnings']} warning(s))" if r["warnings"] else ""))
    _out(f"wrote {output}/fleet.csv: {len(rows) - len(failed)} of {len(rows)} logs done"
         + (f", {len(failed)} failed" if failed else ""))
    if failed:
        raise typer.Exit(code=1)


@app.command()
@_user_errors
def demo(
    output: Annotated[Path, typer.Option("--output", "-o", help="Directory for the log, estimates and report.")]
    = Path("demo-out"),
    seed: Annotated[int, typer.Option(help="Random seed of the simulation.")] = 0,
):
    """Simulate the paper's scenario (sec. IV), run the EKF, iSAM2 and the batch smoother, and write
    the comparison report (report.html, the paper's figures, metrics.json) with the log and estimates."""
    from odomgraph.estimators.schedule import Schedule
    from odomgraph.runs import compare_to_dir
    from odomgraph.sim.scenarios import paper
    from odomgraph.sim.simulate import simulate as run_sim

    sc = paper()
    log = run_sim(sc, seed).with_(path=output / "log")
    with _MultiProgress() as bars:
        cmp = compare_to_dir(log, output, Schedule(calibrate_until=sc.calibrate_until), bars,
                             title=f"odomgraph demo: paper scenario (sec. IV), seed {seed}", include_log=True)
    _print_comparison(cmp.metrics, {k: {n: c["observable"] for n, c in e.calibration.items()}
                                    for k, e in cmp.estimates.items()})
    _out(f"wrote {output}/report.html (open it in a browser), the figures, metrics.json, "
               f"{output}/log and one estimate directory per estimator")


@app.command()
@_user_errors
def compare(
    log_dir: Annotated[Path, typer.Argument(metavar="LOG", help="Log directory (LOG_FORMAT.md).")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Report directory to write.")],
    calibrate_until: Annotated[str, typer.Option(
        help="Seconds from the log start (the wheels' first row when the other sensors ran before them) to "
             "estimate scale factors with slip forced to 0; "
             "after it the scale factors are held and slip is estimated. 0 = slip only.")] = "20",
    hold: Annotated[HoldName, typer.Option(help="How the EKF holds the scale factors (see estimate).")]
    = HoldName.consider,
    gate: Annotated[Optional[float], typer.Option(help="EKF: NIS gate for GPS/range/velocity (default off).")]
    = None,
    keyframe_hz: Annotated[Optional[float], typer.Option(help="Smoothers: keyframe rate [Hz] (default 5).")]
    = None,
    robust: Annotated[Optional[RobustName], typer.Option(help="Smoothers: robust loss for GPS and ranges.")]
    = None,
    range_bias: Annotated[Optional[bool], typer.Option(
        "--range-bias/--no-range-bias", help="batch: estimate a constant range bias per beacon, or not "
        "(default: when the first fit's residuals show one; the others cannot).")]
    = None,
):
    """Run the EKF, iSAM2 (online and smoothed) and the batch smoother on one log and write a
    self-contained report.html, the paper's figures (1-3, 7, NEES/NIS), metrics.json and the estimates.
    Without truth in the log, positions are compared with GPS."""
    from odomgraph.io.log import read_log
    from odomgraph.runs import compare_to_dir
    schedule = _parse_schedule(calibrate_until, hold)
    log = read_log(log_dir)
    with _MultiProgress() as bars:
        cmp = compare_to_dir(log, output, schedule, bars, gate=gate, keyframe_hz=keyframe_hz,
                             robust=robust.value if robust else None, range_bias=range_bias)
    _print_comparison(cmp.metrics, {k: {n: c["observable"] for n, c in e.calibration.items()}
                                    for k, e in cmp.estimates.items()})
    _out(f"wrote {output}/report.html")


@app.command()
@_user_errors
def montecarlo(
    config: Annotated[int, typer.Option(help="1: GPS + gyro; 2: GPS + velocity sensor at 5 Hz; "
                                             "3: three range beacons + gyro (paper sec. VI).")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Study directory (resumable).")],
    runs: Annotated[int, typer.Option(help="Seeded runs per grid point (the paper: 50).")] = 50,
    grid: Annotated[int, typer.Option(help="Grid size per noise axis (values spread uniformly).")] = 6,
    duration: Annotated[float, typer.Option(help="Length of each run [s].")] = 60.0,
    seed: Annotated[int, typer.Option(help="Study seed (every run's seed derives from it).")] = 0,
    smoother: Annotated[bool, typer.Option("--smoother/--no-smoother",
                                           help="Also run the batch smoother on every run.")] = True,
    paper_ekf: Annotated[bool, typer.Option(
        "--paper-ekf/--default-ekf",
        help="The EKF as the paper ran it, its encoder update moving the scale factors in every "
             "direction (as in the paper's figures); --default-ekf: odomgraph's EKF, whose encoder "
             "gain leaves the common scale to the absolute sensors (EKFOptions.encoder_scale_gain).")] = True,
    workers: Annotated[Optional[int], typer.Option(help="Local worker processes (default: all cores).")] = None,
    scheduler: Annotated[Optional[str], typer.Option(
        help="Dask scheduler address tcp://HOST:PORT: run the points on that cluster instead "
             "(pip install 'odomgraph[dask]').")] = None,
):
    """The paper's Monte-Carlo study (sec. VI): sweep two sensor noise levels, run N seeded
    simulations per grid point with the EKF and the batch smoother, and write results.csv,
    results.json, heatmaps (paper figs. 8-10) and summary.html. An interrupted run resumes
    where it stopped when started again with the same options."""
    from odomgraph.analysis.montecarlo import StudySpec, run_study
    from odomgraph.analysis.montecarlo_report import write_outputs
    from odomgraph.analysis.montecarlo_report import findings
    from odomgraph.errors import OdomgraphError
    if config not in (1, 2, 3):
        raise OdomgraphError(f"--config must be 1, 2 or 3, got {config}")
    if runs < 1 or grid < 2 or not 30 <= duration <= 1e5:
        raise OdomgraphError("need --runs >= 1, --grid >= 2 and --duration between 30 s (20 s of calibration, "
                             "then slip) and 1e5 s")
    if workers is not None and workers < 1:
        raise OdomgraphError(f"--workers must be at least 1, got {workers}")
    spec = StudySpec.grid(config, grid, runs=runs, duration=duration, seed=seed, smoother=smoother,
                          paper_ekf=paper_ekf)
    try:
        with _Progress(f"config {config}: {grid}x{grid} points x {runs} runs") as bar:
            results = run_study(spec, output, workers=workers, scheduler=scheduler, progress=bar)
    except KeyboardInterrupt:
        done = len(list((output / "points").glob("*.json"))) if (output / "points").is_dir() else 0
        typer.echo(f"odomgraph: interrupted; {done} finished grid point(s) are kept in {output}/points; "
                   "run the same command again to resume", err=True)
        raise typer.Exit(code=130)
    files = write_outputs(spec, results, output)
    for f in findings(spec, results):
        verdict = {True: "reproduces", False: "does NOT reproduce", None: "grid cannot tell"}[f["holds"]]
        _out(f"paper: {f['claim']}\n  ours: {f['measured']} -> {verdict}")
    _out("wrote " + ", ".join(str(f) for f in files))


@app.command()
@_user_errors
def calibrate(
    log_dir: Annotated[list[Path], typer.Argument(
        metavar="LOG...", help="A calibration log (LOG_FORMAT.md); several, or a directory of logs, run as a "
                               "fleet.")],
    output: Annotated[Path, typer.Option("--output", "-o", help="robot.toml to write (a fleet: a directory, "
                                                                 "with NAME.toml per log and fleet.csv).")]
    = Path("robot-calibrated.toml"),
    method: Annotated[MethodName, typer.Option(
        "--method", "-m", help="Estimator (a smoother; ekf works too, with --calibrate-until SECONDS: it needs a "
                               "slip-free window).")] = MethodName.batch,
    calibrate_until: Annotated[str, typer.Option(
        help="'none' (default): slip and scale together with a sparse slip prior; or seconds of "
             "slip-free driving at the start.")] = "none",
    tune: Annotated[bool, typer.Option(
        "--tune/--no-tune", help="Choose the velocity process noise by predicting held-out fixes "
                                 "(default on; it is written to the [process] table).")] = True,
    force: Annotated[bool, typer.Option(
        "--force", help="Write even when the checks fail (a mounting mistake, a GPS clock off against the "
                        "wheels, or parameters that predict held-out data worse than nominal).")] = False,
    time_offset: Annotated[bool, typer.Option(
        "--time-offset", help="Estimate the GPS time offset against the wheels, apply it, and write it as "
                              "[gps] time_offset.")] = False,
    workers: Annotated[Optional[int], typer.Option(
        min=1, help="A fleet: local worker processes (default: all cores).")] = None,
    scheduler: Annotated[Optional[str], typer.Option(
        help="A fleet: Dask scheduler address tcp://HOST:PORT to run the logs on.")] = None,
):
    """Estimate corrected ticks per metre and track width from a calibration log and write them
    (with their 1-sigma) as a robot.toml. Run it once after changing tyres."""
    from odomgraph.io.log import read_log
    from odomgraph.pipeline import Method, calibrate_to_file
    schedule = _parse_schedule(calibrate_until, HoldName.consider)
    if _is_fleet(log_dir, workers, scheduler):
        _fleet("calibrate", log_dir, output, Method(method.value), schedule, workers, scheduler,
               dict(tune=tune, force=force, **({"time_offset": True} if time_offset else {})))
        return
    log = read_log(log_dir[0])
    with _Progress(f"calibrate ({method.value})") as bar:
        new, rep = calibrate_to_file(log, output, schedule, Method(method.value), progress=bar, tune=tune,
                                     force=force, **({"time_offset": True} if time_offset else {}))
    r = log.robot
    unobs = rep["unobservable"]
    for key, old, names in (("ticks_per_meter_left", r.ticks_per_meter_left, ("scale_left", "scale_common")),
                            ("ticks_per_meter_right", r.ticks_per_meter_right, ("scale_right", "scale_common")),
                            ("track_width", r.track_width, ("scale_track",))):
        v = rep[key]
        held = [n for n in names if n in unobs]
        tail = f"  ({held[0]} not determined: kept at nominal)" if held else ""
        _out(f"{key:<22} {old:.6g} -> {v['value']:.6g} ± {v['sigma']:.2g}{tail}")
    if rep["held_out"]:
        _out(rep["held_out"]["text"])
    if rep.get("time_offsets"):
        o = rep["time_offsets"]["gps"]
        _out(f"GPS time offset {o['value']:+.3f} ± {o['sigma']:.3f} s (written as [gps] time_offset)")
    pn = rep["process_noise"]
    if pn["held_out_rms_m"]:
        from odomgraph.io.robot import ProcessNoise
        d = ProcessNoise()
        # a candidate below the wheels' own motion ran at it (pipeline.tune_process_noise)
        floored = lambda r: (r["accel"] > d.accel * r["factor"] * (1 + 1e-9)
                             or r["yaw_accel"] > d.yaw_accel * r["factor"] * (1 + 1e-9))
        cv = ", ".join(f"x{r['factor']:g}"
                       + (f" (ran at accel {r['accel']:.3g}, yaw {r['yaw_accel']:.3g}: the wheels' floor)"
                          if floored(r) else "") + f": {100 * r['rms_m']:.2f} cm" for r in pn["held_out_rms_m"])
        rms = {r["factor"]: r["rms_m"] for r in pn["held_out_rms_m"]}
        pick, best = pn.get("chosen_factor"), min(rms, key=rms.get)
        why = (f"; x{pick:g} kept: x{best:g} is not better beyond the held-out errors' scatter"
               if pick is not None and pick != best and pn.get("lost_m") is None else "")
        _out(f"process noise: accel {pn['accel']:.3g} m/s^2/sqrt(Hz), yaw {pn['yaw_accel']:.3g} rad/s^2/sqrt(Hz) "
                   f"(held-out fix error by multiple of the default: {cv}{why})")
    a, b = rep["dead_reckoning_nominal"], rep["dead_reckoning_calibrated"]
    _out(f"dead reckoning on this log (vs {rep['reference']}): RMS {a['rms_m']:.3f} -> {b['rms_m']:.3f} m, "
               f"final {a['final_m']:.3f} -> {b['final_m']:.3f} m")
    _warn(rep["warnings"])
    for w in rep["problems"]:
        typer.echo(f"odomgraph: warning: written with --force despite: {' '.join(str(w).split())}", err=True)
    _out(f"wrote {output}")


@app.command()
@_user_errors
def stream(
    robot: Annotated[Optional[Path], typer.Option(
        help="robot.toml of the robot (default: the replayed log's).")] = None,
    method: Annotated[MethodName, typer.Option(
        "--method", "-m",
        help="Estimator: ekf (a row per encoder row), isam2 (its causal row per keyframe, as online.csv), "
             "fixed-lag (a row per keyframe as it leaves the lag window).")] = MethodName.ekf,
    calibrate_until: Annotated[str, typer.Option(
        help="Seconds from the first measurement (the wheels' first when the others ran before them) to "
             "estimate scale factors with slip forced to 0 (as estimate).")]
    = "20",
    hold: Annotated[HoldName, typer.Option(help="How the scale factors are held after calibration (as estimate).")]
    = HoldName.consider,
    gate: Annotated[Optional[float], typer.Option(help="EKF: NIS gate on GPS, range and velocity (as estimate).")]
    = None,
    keyframe_hz: Annotated[Optional[float], typer.Option(help="Smoothers: keyframe rate [Hz] (default 5).")] = None,
    lag: Annotated[Optional[float], typer.Option(help="fixed-lag: window length [s] (default 5).")] = None,
    slip_cauchy: Annotated[Optional[float], typer.Option(
        help="Smoothers: Cauchy scale [m/s] of the sparse zero-slip prior (as estimate).")] = None,
    robust: Annotated[Optional[RobustName], typer.Option(
        help="Smoothers: robust loss for GPS fixes and ranges (as estimate).")] = None,
    robust_k: Annotated[Optional[float], typer.Option(help="Threshold of the robust loss in sigmas.")] = None,
    history: Annotated[Optional[Path], typer.Option(
        help="Smoothers: at the end, write the fully smoothed states of the whole stream to this states.csv.")]
    = None,
    rate: Annotated[Optional[float], typer.Option(
        min=1e-6, max=1000.0, help="Write one row per 1/rate seconds of log time [Hz]: the first at or after "
                                   "each multiple of 1/rate (default: every row).")]
    = None,
    latency: Annotated[float, typer.Option(
        min=0.0, help="How far out of order [s] measurements may arrive; older ones are rejected and counted.")]
    = 0.25,
    warmup: Annotated[Optional[float], typer.Option(
        min=0.0, help="Seconds of data held before the filter starts (default: the calibration window, or the "
                      "start-pose fit without [initial], plus 5 s).")] = None,
    replay: Annotated[Optional[Path], typer.Option(
        help="Stream a log directory's files, merged in time order, instead of stdin.")] = None,
    speed: Annotated[float, typer.Option(
        min=0.0, help="--replay: pace the lines at this multiple of real time (0: as fast as possible).")] = 0.0,
    checkpoint: Annotated[Optional[Path], typer.Option(
        help="Write the estimator's state to this file every --checkpoint-every seconds and at the end.")]
    = None,
    checkpoint_every: Annotated[float, typer.Option(
        min=0.0, help="Seconds of log time between checkpoints.")] = 60.0,
    resume: Annotated[Optional[Path], typer.Option(
        help="Go on from a checkpoint (with --replay: after the lines it had read).")] = None,
):
    """Estimate live: measurement lines on stdin (<sensor>,<t>,<values...>, LOG_FORMAT.md's columns), one
    states.csv row per estimate on stdout, flushed as soon as it is known.

    Example lines: encoders,0.023,-6,6  gps,0.152,-0.278,0.0525  gyro,0.011,0.82  ranges,1.2,A,25.3
    velocity,3.1,0.5,0.1. Bad lines, recoveries and the final counts go to stderr.
    """
    from odomgraph.livestream import check_resume, run_stream, summary_lines
    from odomgraph.online import Online
    if history is not None and method is MethodName.ekf:
        raise _click_exc.UsageError("--history: only isam2 and fixed-lag smooth the whole stream")
    for p in (checkpoint, history):
        if p is not None and not p.parent.is_dir():
            raise _click_exc.UsageError(f"{p}: its directory does not exist")
    _check_stream_outputs(checkpoint, history, (replay, robot, resume))
    if resume is not None:
        live = Online.load(resume)
        check_resume(live, method.value)
        if robot is not None or warmup is not None or gate is not None or keyframe_hz is not None or lag is not None:
            typer.echo("odomgraph: warning: --resume goes on with the checkpoint's robot and options; --robot, "
                       "--warmup, --gate, --keyframe-hz and --lag are ignored", err=True)
    else:
        from odomgraph.io.robot import load_robot
        if robot is None and replay is None:
            raise _click_exc.UsageError("give --robot robot.toml (or --replay LOG, whose robot.toml is used)")
        live = Online(load_robot(robot if robot is not None else replay / "robot.toml"), method.value,
                      _parse_schedule(calibrate_until, hold), latency=latency, warmup=warmup,
                      journal=checkpoint is not None and method is not MethodName.ekf,  # (an EKF pickles)
                      gate=gate, keyframe_hz=keyframe_hz, lag=lag,
                      slip_cauchy=slip_cauchy, robust=robust.value if robust else None, robust_k=robust_k)
    if replay is not None:
        from odomgraph.io.log import read_log
        from odomgraph.io.stream import log_lines
        replayed = read_log(replay)
        lines, source = log_lines(replayed), str(replay)
    else:
        import io
        # universal newlines (a bare CR ends a line too); bytes that are no UTF-8 become a bad line
        lines = io.TextIOWrapper(sys.stdin.buffer, encoding="utf-8", errors="replace", newline=None)
        source = "stdin"
    st = run_stream(live, lines, sys.stdout, sys.stderr, source=source, rate=rate, speed=speed,
                    checkpoint=checkpoint, checkpoint_every=checkpoint_every,
                    skip_lines=live.lines_read if (resume is not None and replay is not None) else 0)
    for line in summary_lines(live, st):
        typer.echo(f"odomgraph: {line}", err=True)
    if replay is not None:
        _warn(replayed.warnings)    # the log's own (a read fix, an import's assumption), as estimate says them
    if history is not None:
        if live.final is None:
            raise _click_exc.UsageError("--history: only isam2 and fixed-lag smooth the whole stream")
        from odomgraph.io.estimate import is_states_file, write_states
        from odomgraph.io.outdir import atomic_output_file
        live.final.t_origin = live.t_origin or 0
        with atomic_output_file(history, (replay, robot, resume, checkpoint), is_ours=is_states_file) as tmp:
            write_states(tmp, live.final)
        typer.echo(f"odomgraph: wrote the smoothed history to {history}", err=True)


def _check_stream_outputs(checkpoint: Path | None, history: Path | None, inputs: tuple) -> None:
    """The files ``stream`` writes, held to the rules of ``-o``: never an
    input (the replayed log, robot.toml), never a file odomgraph did not
    write. A checkpoint may replace the one it resumes from (``inputs``:
    the replayed log, robot.toml, the checkpoint resumed from)."""
    from odomgraph.errors import OutputDirError
    from odomgraph.io.estimate import is_states_file
    from odomgraph.io.outdir import check_output, check_output_file
    from odomgraph.online import Online
    if checkpoint is not None:
        check_output(checkpoint, inputs[:2], directory=False)
        if checkpoint.exists() and not Online.is_checkpoint(checkpoint):
            raise OutputDirError(f"{checkpoint}: exists and is not an odomgraph checkpoint; choose another file")
    if history is not None:
        check_output_file(history, (*inputs, checkpoint), is_ours=is_states_file)


@app.command("import")
@_user_errors
def import_(
    kind: Annotated[ImportKind, typer.Argument(help="optiodom: an OptiOdom run CSV; librsf: a libRSF *_Input.txt.")],
    source: Annotated[Path, typer.Argument(help="The file to import (rosbag: a .bag, or a ROS 2 bag directory).")],
    output: Annotated[Optional[Path], typer.Option("--output", "-o", help="Log directory to write.")] = None,
    metadata: Annotated[Optional[Path], typer.Option(
        help="optiodom: the session's *_metadata.csv (default: the one beside SOURCE).")] = None,
    fixes_hz: Annotated[float, typer.Option(
        help="optiodom: also write motion capture as gps.csv at this rate [Hz] (0: no).")] = 0.0,
    fix_sigma: Annotated[float, typer.Option(help="optiodom: 1-sigma of those fixes [m].")] = 0.01,
    ground_truth: Annotated[Optional[Path], typer.Option(
        help="librsf: the ground-truth file (default: *_GT.txt beside SOURCE).")] = None,
    list_topics: Annotated[bool, typer.Option(
        "--list", help="rosbag: list every topic (type, count, rate), the ones the import would pick, and the "
                       "/tf_static frames; write nothing.")] = False,
    wheel_topic: Annotated[Optional[str], typer.Option(
        help="rosbag: the wheels: sensor_msgs/JointState, or nav_msgs/Odometry or geometry_msgs/TwistStamped "
             "(their twist is split into wheel speeds through --track-width, which assumes the odometry came "
             "from the wheels alone). Default: the one such topic.")] = None,
    left_joint: Annotated[Optional[str], typer.Option(
        help="rosbag: left wheel joint name (default: the joints named left ... wheel; a skid-steer's front "
             "and rear ones averaged). Given, that one joint alone.")] = None,
    right_joint: Annotated[Optional[str], typer.Option(
        help="rosbag: right wheel joint name (default: the joints named right ... wheel, averaged). Given, that "
             "one joint alone.")] = None,
    wheel_radius: Annotated[Optional[float], typer.Option(
        help="rosbag: nominal wheel radius [m] (JointState wheels only).")] = None,
    track_width: Annotated[Optional[float], typer.Option(help="rosbag: nominal track width [m].")] = None,
    gps_topic: Annotated[Optional[str], typer.Option(
        help="rosbag: sensor_msgs/NavSatFix topic (default: the one there is; '' for none).")] = None,
    imu_topic: Annotated[Optional[str], typer.Option(
        help="rosbag: sensor_msgs/Imu topic (default: the one there is; '' for none).")] = None,
    imu_axis: Annotated[str, typer.Option(
        help="rosbag: the IMU axis that measures yaw: auto (the mounting in /tf_static, else the signed axis "
             "that follows the wheels' turn rate), x, y, z, -x, -y or -z.")] = "auto",
    tick_topics: Annotated[Optional[tuple], typer.Option(
        parser=lambda v: _names(v, 2, "LEFT,RIGHT"), metavar="LEFT,RIGHT",
        help="rosbag: the wheels as two std_msgs integer tick counters (default: the pair named left/right "
             "when the bag has no other wheel topic); stamped with the receive times.")] = None,
    ticks_per_meter: Annotated[Optional[tuple], typer.Option(
        parser=lambda v: _one_or_two(v), metavar="TPM[,TPM]",
        help="rosbag: nominal ticks per metre of the tick counters, one value or left,right.")] = None,
    gps_lever_arm: Annotated[Optional[tuple], typer.Option(
        parser=Numbers(2, "x,y"), metavar="X,Y",
        help="rosbag: GPS antenna 'x,y' in the robot frame [m] (default: from /tf_static, else 0,0).")] = None,
    stamps: Annotated[str, typer.Option(
        help="rosbag: time stamps from the message headers (the sensors' clock) or the bag's receive time: "
             "header or receive.")] = "header",
):
    """Convert another dataset's files into a log directory (LOG_FORMAT.md)."""
    from odomgraph.errors import OdomgraphError
    from odomgraph.io.log import write_log
    from odomgraph.io.outdir import check_output
    if list_topics:
        if kind is not ImportKind.rosbag:
            raise OdomgraphError("--list is for import rosbag")
        from odomgraph.io.importers.rosbag import list_topics as topics_of
        topics, frames = topics_of(source)
        w = max([len(t.topic) for t in topics] + [5])
        _out(f"{'topic':<{w}}  {'type':<34} {'count':>7} {'rate':>9}  picked as")
        for t in topics:
            _out(f"{t.topic:<{w}}  {t.msgtype:<34} {t.count:>7} {t.rate_hz:>6.1f} Hz  {t.role or ''}")
        for f in frames:
            _out(f"tf_static: {f}")
        if not frames:
            _out("tf_static: none")
        return
    if output is None:
        raise OdomgraphError("import needs --output/-o, the log directory to write")
    inputs = (source, metadata, ground_truth)
    check_output(output, inputs)
    if kind is ImportKind.optiodom:
        from odomgraph.io.importers.optiodom import import_optiodom
        log = import_optiodom(source, metadata, fixes_hz, fix_sigma)
    elif kind is ImportKind.rosbag:
        from odomgraph.io.importers.rosbag import import_rosbag
        if track_width is None:
            raise OdomgraphError("import rosbag needs --track-width (the nominal robot) [m]")
        log = import_rosbag(source, wheel_topic, left_joint, right_joint, wheel_radius, track_width,
                            gps_topic, imu_topic, gps_lever_arm=gps_lever_arm, imu_axis=imu_axis, stamps=stamps,
                            tick_topics=tick_topics, ticks_per_meter=ticks_per_meter)
    else:
        from odomgraph.io.importers.librsf import import_librsf
        log = import_librsf(source, ground_truth)
    from odomgraph.errors import LogFormatError
    from odomgraph.io.log import check_log
    try:
        check_log(log)
    except LogFormatError as exc:
        raise LogFormatError(source, f"the import would give a log that cannot be used: {exc.path.name}: "
                                     f"{exc.problem}") from None
    from odomgraph import __version__
    # the importer's own options (given or default), as it ran
    own = (dict(metadata=metadata, fixes_hz=fixes_hz, fix_sigma=fix_sigma) if kind is ImportKind.optiodom
           else dict(ground_truth=ground_truth) if kind is ImportKind.librsf
           else dict(wheel_topic=wheel_topic, left_joint=left_joint, right_joint=right_joint,
                     wheel_radius=wheel_radius, track_width=track_width, gps_topic=gps_topic, imu_topic=imu_topic,
                     imu_axis=imu_axis, tick_topics=tick_topics, ticks_per_meter=ticks_per_meter,
                     gps_lever_arm=gps_lever_arm, stamps=stamps))
    log = log.with_(provenance={
        "importer": kind.value, "source": str(source.resolve()), "odomgraph": __version__,
        "options": {k: (str(v.resolve()) if isinstance(v, Path) else list(v) if isinstance(v, tuple) else v)
                    for k, v in own.items() if v is not None},
        "notes": list(log.notes), "warnings": [" ".join(str(w).split()) for w in log.warnings]})
    write_log(log, output, inputs)
    _out(f"wrote {output} ({'; '.join(log.notes)})")
    _warn(log.warnings)


def main() -> None:
    signal.signal(signal.SIGTERM, _on_sigterm)
    app()


if __name__ == "__main__":
    sys.exit(main())
