"""Runs of the estimators over whole workloads, above ``pipeline``: the
comparison of every estimator on one log (``odomgraph compare`` and the
demo), the seeded accuracy studies, and the fault cases.

They call ``pipeline.estimate``, with its checks, so that a study scores what
a user gets; their scoring is ``analysis``'s (compare, study, faults).
"""
from __future__ import annotations

import os
import tempfile
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

from odomgraph.analysis.compare import ESTIMATORS, Comparison, comparison_metrics
from odomgraph.analysis.faults import CASES, Case, scenario, score, written
from odomgraph.analysis.study import SeedResult, score_seed
from odomgraph.errors import EstimatorDivergedError, OdomgraphError
from odomgraph.estimators.schedule import Schedule
from odomgraph.io.log import Log
from odomgraph.pipeline import Method, estimate, summary
from odomgraph.result import Estimate
from odomgraph.sim.faults import Faults


# ------------------------------------------------------------- comparison
def compare(log: Log, schedule: Schedule = Schedule(), progress_for=None, **options) -> Comparison:
    """Every estimator on ``log``, scored side by side (``odomgraph.compare``;
    see run_comparison). ``Comparison.metrics`` is metrics.json's content."""
    return run_comparison(log, schedule, progress_for, **options)


def run_comparison(log: Log, schedule: Schedule, progress_for=None, **options) -> Comparison:
    """Run every estimator of ESTIMATORS (and the no-slip EKF) on ``log``.

    ``progress_for(label)`` may return a progress(done, total) callback for
    each run. Each estimator takes those of ``options`` its options type has
    (registry.foreign; see pipeline.estimate): range biases, say, only batch.
    """
    from odomgraph.io.log import rebased
    log = rebased(log)  # Log.t_origin
    from odomgraph.estimators.ekf import EKFOptions, run_ekf
    from odomgraph.estimators.registry import foreign
    if schedule.calibrate_until is None:
        raise OdomgraphError("compare runs the EKF, which needs a schedule: use --calibrate-until SECONDS "
                             "(0 = slip only), not 'none'")
    prog = progress_for or (lambda label: None)
    ests: dict[str, Estimate] = {}
    failed: dict[str, str] = {}

    def attempt(label, run):
        # A diverged estimator is a result of the comparison, not the end of it.
        try:
            return run()
        except EstimatorDivergedError as exc:
            failed[label] = str(exc)
            return None

    for label, method in (("ekf", Method.ekf), ("isam2", Method.isam2), ("batch", Method.batch)):
        # each its own (an EKF gate for the EKF, batch's Huber slip steps for batch)
        opts = {k: v for k, v in options.items() if k not in foreign(method)}
        est = attempt(label, lambda: estimate(log, method, schedule, prog(label), **opts))
        if est is None:
            if label == "isam2":
                failed["isam2-online"] = failed["isam2"]
            continue
        if label == "isam2":
            ests["isam2-online"] = replace(est.online, method="isam2-online", t_switch=est.t_switch,
                                           wall_time_s=est.wall_time_s, n_updates=est.n_updates)
        ests[label] = est
    if not ests:
        raise EstimatorDivergedError("every estimator diverged on this log: " + "; ".join(failed.values()))
    gate = options.get("gate")
    # Without slip states the filter is expected to disagree with its encoders
    # during slip (that is what fig. 7 shows), so its NIS watch is off.
    no_slip = attempt("ekf-no-slip", lambda: run_ekf(
        log, schedule, EKFOptions(gate=gate, slip_states=False, max_mean_nis=np.inf), prog("ekf without slip")))
    metrics = comparison_metrics(ests, log, schedule, no_slip)
    for label, msg in failed.items():
        metrics["estimators"][label] = {"failed": msg}
    order = [*ESTIMATORS, "ekf-no-slip"]
    metrics["estimators"] = {k: metrics["estimators"][k] for k in order if k in metrics["estimators"]}
    return Comparison(log, schedule, ests, no_slip, metrics)


def compare_to_dir(log: Log, out: Path, schedule: Schedule, progress_for=None, title: str | None = None,
                   include_log: bool = False, **options):
    """Run the EKF, iSAM2 and batch on ``log`` and write the comparison directory
    atomically: report.html, metrics.json, the figures, figure.png (overview)
    and one estimate directory per estimator (isam2/ holds online.csv).
    ``include_log`` also writes the log itself to out/log (the demo does).
    Returns the Comparison."""
    from odomgraph.io.log import rebased
    if log.truth is not None:
        log.truth.values    # scored at the end: a bad truth.csv is said now, not after three runs
    log = rebased(log)  # Log.t_origin
    from odomgraph.analysis.plots import overview_figure
    from odomgraph.analysis.report import write_report
    from odomgraph.io.estimate import write_estimate
    from odomgraph.io.log import write_log
    from odomgraph.io.outdir import atomic_output_dir, check_output
    inputs = (log.path,) if log.path and not include_log else ()
    check_output(out, inputs)
    cmp = run_comparison(log, schedule, progress_for, **options)
    title = title or f"odomgraph: EKF vs smoother on {log.path.name if log.path else 'a log'}"
    with atomic_output_dir(out, inputs, kind="report") as d:
        if include_log:
            write_log(log, d / "log")
        for label, est in cmp.estimates.items():
            if label != "isam2-online":  # it is isam2/online.csv
                write_estimate(est, d / label, summary(est, log, schedule))
        write_report(cmp, d, title)
        shown = [e for k, e in cmp.estimates.items() if k in ("ekf", "batch")] or list(cmp.estimates.values())
        overview_figure(shown, log, d / "figure.png", title=title)
    return cmp


# ------------------------------------------------------- seeded studies
def _one(args) -> SeedResult:
    scenario, seed, schedule, method = args
    from dataclasses import replace
    from odomgraph.sim.simulate import simulate
    log = simulate(scenario, seed)
    est = estimate(log, Method(method), schedule)
    res = score_seed(est, log, seed)
    if est.online is not None:
        res = replace(res, online=score_seed(replace(est.online, t_switch=est.t_switch), log, seed))
    return res


def run_study(scenario, seeds, schedule: Schedule | None = None, method: str = "ekf",
              workers: int | None = None) -> list[SeedResult]:
    """Simulate and estimate each seed (in a process pool); results in seed order."""
    schedule = schedule or Schedule(calibrate_until=scenario.calibrate_until)
    jobs = [(scenario, s, schedule, method) for s in seeds]
    workers = workers or min(len(jobs), os.cpu_count() or 1)
    if workers <= 1:
        return [_one(j) for j in jobs]
    with ProcessPoolExecutor(workers) as pool:
        return list(pool.map(_one, jobs))


# ----------------------------------------------------------- fault cases
def run_case(case: Case | str, method: str, seed: int = 0, duration: float = 90.0) -> dict:
    """Simulate ``case`` and its clean twin with ``seed``, run ``method`` on
    both (through written files), and score the faulty run. A run that stops
    is reported with ``finished: False`` and its one-line reason."""
    from odomgraph.analysis.metrics import truth_errors
    from odomgraph.errors import OdomgraphError
    from odomgraph.estimators.schedule import Schedule
    from odomgraph.sim.faults import inject
    case = CASES[case] if isinstance(case, str) else case
    sc = scenario(case, duration)
    with tempfile.TemporaryDirectory() as tmp:
        bad = written(inject(sc, case.faults, seed), Path(tmp) / "faulty")
        clean = written(inject(sc, Faults(), seed), Path(tmp) / "clean")
    sch = Schedule(20.0)
    try:
        clean_rms = truth_errors(estimate(clean, method, sch), clean).rms_position_m
    except OdomgraphError:
        clean_rms = None
    try:
        est = estimate(bad, method, sch)
    except OdomgraphError as exc:
        return {"case": case.name, "method": method, "seed": seed, "finished": False, "reason": str(exc)}
    return {"case": case.name, "method": method, "seed": seed, **score(est, bad, clean_rms, case)}
