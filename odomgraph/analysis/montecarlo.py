"""The paper's Monte-Carlo study (sec. VI): a noise grid per sensor configuration,
N seeded runs per grid point, for the EKF and the batch smoother.

One grid point is one job (``run_point``): it simulates its N runs with shared
timestamps and independent noise, filters all N at once with the vectorised
EKF (``ekf_many``), smooths each run starting from its EKF estimate, and
scores every run. Jobs go to a local process pool or to a Dask cluster; each
finished point is written to ``DIR/points/`` atomically, so an interrupted
sweep resumes where it stopped.

Scores, per run and estimator (after the 20 s calibration window, where the
schedule holds the scale factors and estimates slip):
  * the RMS error of each scale-factor state [-] (x100 = %),
  * the RMS error of each wheel's slip [m/s];
per grid point: their medians over the runs that did not fail, and the
failure rate (runs that diverged, or whose estimator raised).
"""
from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field

import numpy as np

from odomgraph.errors import EstimatorDivergedError, OdomgraphError

#: Scores of a run, in this order.
QUANTITIES = ("scale_left", "scale_right", "scale_track", "slip_left", "slip_right")
ESTIMATORS = ("ekf", "batch")


@dataclass(frozen=True)
class StudySpec:
    config: int
    x_values: tuple[float, ...]
    """Noise values of the configuration's first axis (see sensor_configs)."""
    y_values: tuple[float, ...]
    runs: int = 50
    duration: float = 60.0
    seed: int = 0
    smoother: bool = True
    """Also run the batch smoother (else the EKF only)."""
    calibrate_until: float = 20.0
    paper_ekf: bool = True
    """Run the EKF as the paper did, its encoder update moving the scale
    factors in every direction (EKFOptions.encoder_scale_gain); False: the
    default EKF, whose encoder gain has no component along the common scale."""

    @classmethod
    def grid(cls, config: int, size: int = 6, **kw) -> "StudySpec":
        from odomgraph.sim.sensor_configs import CONFIGS
        c = CONFIGS[config]
        return cls(config, tuple(float(v) for v in c.x.values(size)), tuple(float(v) for v in c.y.values(size)),
                   **kw)

    def points(self) -> list["PointSpec"]:
        return [PointSpec(self, i, j) for i in range(len(self.x_values)) for j in range(len(self.y_values))]


@dataclass(frozen=True)
class PointSpec:
    study: StudySpec
    i: int
    j: int

    @property
    def key(self) -> str:
        return f"c{self.study.config}_x{self.i}_y{self.j}"

    def seeds(self) -> tuple[int, list[int]]:
        """(timing seed, run seeds): a pure function of the study seed and the point,
        so every executor gives the same runs."""
        s = np.random.SeedSequence([self.study.seed, self.study.config, self.i, self.j]).generate_state(
            self.study.runs + 1)
        return int(s[0]), [int(v) for v in s[1:]]


@dataclass
class PointResult:
    config: int
    i: int
    j: int
    x: float
    y: float
    runs: int
    scores: dict[str, list[list[float] | None]]
    """Estimator -> per run, QUANTITIES (None for a failed run)."""
    failures: dict[str, list[str]]
    """Estimator -> messages of the runs that failed."""
    wall_s: dict[str, float] = field(default_factory=dict)
    """Wall time spent per stage: simulate, ekf, batch [s]."""

    def medians(self, estimator: str) -> dict[str, float | None]:
        ok = [s for s in self.scores[estimator] if s is not None]
        if not ok:
            return {q: None for q in QUANTITIES}
        med = np.median(np.asarray(ok), axis=0)
        return {q: float(v) for q, v in zip(QUANTITIES, med)}

    def failure_rate(self, estimator: str) -> float:
        s = self.scores[estimator]
        return sum(v is None for v in s) / len(s)


def _score(est, log) -> list[float]:
    """QUANTITIES of one run: RMS over the rows after the schedule's switch (metrics.truth_errors)."""
    from odomgraph.analysis.metrics import truth_errors
    err = truth_errors(est, log)
    post = err.slip_mask
    out = [float(np.sqrt(np.mean(err.error_series[q][post] ** 2))) for q in QUANTITIES]
    if not np.all(np.isfinite(out)):
        raise EstimatorDivergedError("non-finite score")
    return out


def run_point(p: PointSpec) -> PointResult:
    """Simulate, estimate and score the runs of one grid point."""
    import time
    from odomgraph.estimators.batch import SmootherOptions, run_batch
    from odomgraph.estimators.priorcheck import applied
    from odomgraph.estimators.ekf_many import run_ekf_many
    from odomgraph.estimators.schedule import Schedule
    from odomgraph.sim.sensor_configs import study_scenario
    from odomgraph.sim.simulate import simulate
    st = p.study
    x, y = st.x_values[p.i], st.y_values[p.j]
    sc = study_scenario(st.config, x, y, st.duration)
    timing, seeds = p.seeds()
    w0 = time.perf_counter()
    logs = [simulate(sc, s, timing_seed=timing) for s in seeds]
    w1 = time.perf_counter()
    schedule = Schedule(calibrate_until=st.calibrate_until)
    from odomgraph.estimators.ekf import EKFOptions
    ekf = run_ekf_many(logs, schedule, EKFOptions(encoder_scale_gain=st.paper_ekf))
    w2 = time.perf_counter()
    scores = {"ekf": [], "batch": []}
    failures = {"ekf": [], "batch": []}
    for log, est in zip(logs, ekf):
        try:
            if isinstance(est, Exception):
                raise est
            scores["ekf"].append(_score(est, log))
        except (EstimatorDivergedError, FloatingPointError, np.linalg.LinAlgError) as exc:
            scores["ekf"].append(None)
            failures["ekf"].append(str(exc))
        if not st.smoother:
            continue
        try:
            if isinstance(est, Exception):
                raise EstimatorDivergedError(f"no EKF estimate to start from ({est})")
            smoothed = applied(run_batch(log, schedule, SmootherOptions(), initial=est))   # (its slip-prior check)
            scores["batch"].append(_score(smoothed, log))
        except (EstimatorDivergedError, FloatingPointError, np.linalg.LinAlgError, RuntimeError) as exc:
            scores["batch"].append(None)
            failures["batch"].append(str(exc))
    w3 = time.perf_counter()
    if not st.smoother:
        del scores["batch"], failures["batch"]
    return PointResult(st.config, p.i, p.j, x, y, st.runs, scores, failures,
                       {"simulate": w1 - w0, "ekf": w2 - w1, "batch": w3 - w2})


# ---------------------------------------------------------------- the sweep
def write_atomic(path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def spec_json(spec: StudySpec) -> dict:
    return asdict(spec) | {"x_values": list(spec.x_values), "y_values": list(spec.y_values)}


def open_study_dir(directory, spec: StudySpec):
    """Create DIR (or reopen it to resume); returns the points directory.

    A DIR that holds another study, or files odomgraph did not write, is refused.
    """
    from pathlib import Path
    d = Path(directory)
    spec_file = d / "study.json"
    if d.exists():
        if not d.is_dir():
            raise OdomgraphError(f"{d}: exists and is not a directory")
        if spec_file.exists():
            try:
                old = json.loads(spec_file.read_text())
            except (OSError, json.JSONDecodeError) as exc:
                raise OdomgraphError(f"{spec_file}: unreadable ({exc}); remove it or choose another -o") from None
            if old != spec_json(spec):
                diff = sorted(k for k in old if old.get(k) != spec_json(spec).get(k))
                raise OdomgraphError(f"{d}: holds a different study (differs in {', '.join(diff)}); "
                                     "choose another -o or repeat the original options to resume")
        elif any(d.iterdir()):
            raise OdomgraphError(f"{d}: exists, is not empty and was not written by odomgraph montecarlo")
    (d / "points").mkdir(parents=True, exist_ok=True)
    if not spec_file.exists():
        write_atomic(spec_file, json.dumps(spec_json(spec), indent=2) + "\n")
    return d / "points"


def load_point(path) -> PointResult | None:
    try:
        return PointResult(**json.loads(path.read_text()))
    except (OSError, json.JSONDecodeError, TypeError):
        return None  # unreadable: computed again


def run_study(spec: StudySpec, directory, workers: int | None = None, scheduler: str | None = None,
              progress=None, client=None) -> list[PointResult]:
    """Run (or resume) a sweep; returns every point's result in grid order.

    Points already in DIR/points are not run again. ``scheduler`` is a Dask
    scheduler address (tcp://HOST:PORT); ``client`` an existing
    dask.distributed.Client (tests pass a LocalCluster's). Otherwise a local
    process pool of ``workers`` processes (default: all cores).
    ``progress(done, total)`` is called as points finish.
    """
    points_dir = open_study_dir(directory, spec)
    todo, done = [], {}
    for p in spec.points():
        r = load_point(points_dir / f"{p.key}.json")
        if r is not None:
            done[p.key] = r
        else:
            todo.append(p)
    total = len(spec.points())

    def finished(p: PointSpec, r: PointResult):
        write_atomic(points_dir / f"{p.key}.json", json.dumps(asdict(r)) + "\n")
        done[p.key] = r
        if progress is not None:
            progress(len(done), total)

    if progress is not None:
        progress(len(done), total)
    from odomgraph.jobs import run_jobs
    run_jobs(run_point, todo, finished, workers, scheduler, client)
    return [done[p.key] for p in spec.points()]


# ---------------------------------------------------------------- outputs
def results_table(spec: StudySpec, results: list[PointResult]) -> list[dict]:
    """One row per grid point and estimator: the noise values, runs, failures and medians."""
    from odomgraph.sim.sensor_configs import CONFIGS
    cfg = CONFIGS[spec.config]
    rows = []
    for r in results:
        for est in r.scores:
            med = r.medians(est)
            rows.append({"config": r.config, "estimator": est, cfg.x.name: r.x, cfg.y.name: r.y, "runs": r.runs,
                         "failures": sum(v is None for v in r.scores[est]), "failure_rate": r.failure_rate(est),
                         **{f"median_rms_{q}": med[q] for q in QUANTITIES}})
    return rows


def grid_of(spec: StudySpec, results: list[PointResult], estimator: str, quantity: str) -> np.ndarray:
    """(len(x_values), len(y_values)) medians of one quantity (NaN where all runs failed)."""
    g = np.full((len(spec.x_values), len(spec.y_values)), np.nan)
    for r in results:
        if estimator in r.scores:
            v = r.medians(estimator)[quantity]
            g[r.i, r.j] = np.nan if v is None else v
    return g
