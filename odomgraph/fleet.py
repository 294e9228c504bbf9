"""Fleets of logs: ``estimate`` and ``calibrate`` over many logs in one command.

A fleet operator calibrating a hundred robots overnight gives the log
directories, or a directory that holds them, and one output directory:

    odomgraph calibrate /data/robots -o calibrations/ --workers 8
    odomgraph estimate run1 run2 run3 -o estimates/ --scheduler tcp://HOST:8786

Each log is one job (``odomgraph.jobs``: a local process pool, or a Dask
cluster) and runs exactly as it would alone, so each log's output equals the
one-at-a-time command's. A job writes its output in a temporary directory of
its own machine and returns the files' bytes, so a cluster's workers need
to read the logs (shared storage) but never write where the client does. A
log that fails (bad input, a refused calibration, an estimator that stops)
does not stop the others: its row in ``fleet.csv`` says why, and the command
exits 1 after writing everything else; when every log fails nothing is
written. The output directory is written all at once (io.outdir): OUT/NAME/
(an estimate directory) or OUT/NAME.toml (a calibrated robot.toml) per log,
and fleet.csv / fleet.json with one row per log.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

from odomgraph.errors import LogFormatError, OdomgraphError

#: A directory is a log when it holds one of these (LOG_FORMAT.md: the wheel odometry).
LOG_MARKERS = ("encoders.csv", "wheel_speeds.csv")
#: fleet.csv's columns, in order.
COLUMNS = ("name", "log", "result", "status", "scale_left", "sigma_scale_left", "scale_right", "sigma_scale_right",
           "scale_track", "sigma_scale_track", "ticks_per_meter_left", "ticks_per_meter_right", "track_width",
           "unobservable", "warnings", "error")


#: Output names a log may not take (the fleet's own files).
RESERVED = ("fleet", ".odomgraph")


def is_log_dir(p: Path) -> bool:
    return p.is_dir() and any((p / m).is_file() for m in LOG_MARKERS)


def log_dirs(paths) -> list[Path]:
    """The log directories ``paths`` name: each path that is a log, and every
    log directly inside a path that is not one (a directory of logs), sorted
    by name. LogFormatError for a path that is neither."""
    out: list[Path] = []
    for p in map(Path, paths):
        if is_log_dir(p):
            out.append(p)
        elif p.is_dir():
            # hidden entries are temporaries (io.outdir's .NAME.tmp-PID-...), not robots
            inside = sorted(q for q in p.iterdir() if not q.name.startswith(".") and is_log_dir(q))
            if not inside:
                raise LogFormatError(p, f"is not a log directory (no {' or '.join(LOG_MARKERS)}) and holds none")
            out += inside
        else:
            raise LogFormatError(p, "no such log directory")
    if not out:
        raise OdomgraphError("no log given")
    seen = set()
    for p in out:
        r = p.resolve()
        if r in seen:
            raise OdomgraphError(f"{p}: given twice")
        seen.add(r)
    return out


def output_names(logs: list[Path]) -> list[str]:
    """One output name per log: its directory's name ("." resolved), or
    parent_name where two logs share a name (a/run1 and b/run1), unique
    also on a file system that ignores case, and never a RESERVED one."""
    names = [p.resolve().name for p in logs]
    out: list[str] = []
    for p, n in zip(logs, names):
        if sum(m.casefold() == n.casefold() for m in names) > 1:
            n = f"{p.resolve().parent.name}_{n}"
        if n.casefold() in RESERVED or n.startswith("."):
            n = f"log_{n.lstrip('.')}"
        while n.casefold() in {m.casefold() for m in out}:
            n += "_"
        out.append(n)
    return out


@dataclass(frozen=True)
class Job:
    """One log of a fleet: what ``run_job`` needs, all picklable (Dask, fork)."""
    log: str
    name: str
    kind: str
    """"estimate" or "calibrate"."""
    method: str
    schedule: object
    options: dict = field(default_factory=dict)


def run_job(job: Job) -> tuple[dict, dict[str, bytes]]:
    """Run one log and return (its fleet row, its output files: path relative
    to the fleet directory -> bytes). The output is written in a temporary
    directory of the machine the job runs on, read back and removed. Never
    raises for a problem of the log: the row's ``error`` says it, in one line."""
    import shutil
    import tempfile
    from odomgraph.io.log import read_log
    from odomgraph.pipeline import calibrate_to_file, estimate_to_dir
    row = {"name": job.name, "log": job.log}
    tmp = Path(tempfile.mkdtemp(prefix="odomgraph-fleet-"))
    try:
        log = read_log(job.log)
        if job.kind == "estimate":
            s = estimate_to_dir(log, tmp / job.name, job.method, job.schedule, **job.options)
            row.update(result="written", status=s["status"], unobservable=" ".join(s["unobservable"]),
                       warnings=len(s["warnings"]))
            for n, c in s["calibration"].items():
                row[n], row[f"sigma_{n}"] = c["value"], c["sigma"]
        else:
            options = dict(job.options)
            new, rep = calibrate_to_file(log, tmp / f"{job.name}.toml", job.schedule, job.method,
                                         tune=options.pop("tune", True), force=options.pop("force", False),
                                         **options)
            row.update(result="written" if not rep["problems"] else "written despite problems (--force)",
                       status="degraded" if rep["problems"] else "ok",
                       unobservable=" ".join(rep["unobservable"]), warnings=len(rep["warnings"]),
                       ticks_per_meter_left=rep["ticks_per_meter_left"]["value"],
                       ticks_per_meter_right=rep["ticks_per_meter_right"]["value"],
                       track_width=rep["track_width"]["value"])
            for w, n in (("left", "scale_left"), ("right", "scale_right"), ("track", "scale_track")):
                row[n] = rep["scale"][w]
        files = {p.relative_to(tmp).as_posix(): p.read_bytes() for p in sorted(tmp.rglob("*")) if p.is_file()}
    except OdomgraphError as exc:
        # named as in the fleet's output, not in the temporary directory it is written in first
        row.update(result="failed", error=" ".join(str(exc).replace(f"{tmp}{os.sep}", "").split()))
        files = {}
    except OSError as exc:           # as the CLI's one-line errors: the file and what the system said
        where = f"{str(exc.filename).replace(f'{tmp}{os.sep}', '')}: " if exc.filename else ""
        row.update(result="failed", error=f"{where}{exc.strerror or type(exc).__name__}")
        files = {}
    except Exception as exc:         # a solver's failure: this log's, not the fleet's
        first = next((ln.strip() for ln in str(exc).splitlines() if ln.strip()), "")
        row.update(result="failed", error=f"{type(exc).__name__}: {first}".rstrip(": "))
        files = {}
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return row, files


def _check_options(kind: str, method, options: dict) -> None:
    """The options every log shares, checked once before any log is read
    (a bad one would otherwise fail every log the same way)."""
    from odomgraph.estimators.registry import check_option_names, options_for, parse_method
    parse_method(method)
    own = {"rate", "at", "time_offset", "fit_noise"} | ({"tune", "force"} if kind == "calibrate" else set())
    check_option_names({k: v for k, v in options.items() if k not in own})
    # another estimator's option set here would fail every log alike
    options_for(method, {k: v for k, v in options.items() if k not in own})
    rate = options.get("rate")
    if rate is not None and not rate > 0:
        raise OdomgraphError(f"--rate must be a positive number of Hz, got {rate!r}")
    if options.get("rate") is not None and options.get("at") is not None:
        raise OdomgraphError("give --rate or --at, not both")


def run_fleet(paths, out: Path, kind: str, method, schedule, workers: int | None = None,
              scheduler: str | None = None, progress=None, client=None, **options) -> list[dict]:
    """Run ``kind`` ("estimate" or "calibrate") over every log ``paths`` name
    (``log_dirs``) and write OUT (see the module doc). Returns the rows in
    the order of the logs. ``progress(done, total)`` as logs finish. When
    every log fails, nothing is written and OdomgraphError says the first
    failure."""
    from odomgraph.io.outdir import atomic_output_dir, check_output
    from odomgraph.jobs import run_jobs
    if kind not in ("estimate", "calibrate"):
        raise OdomgraphError(f"a fleet runs estimate or calibrate, not {kind!r}")
    method = getattr(method, "value", method)
    _check_options(kind, method, options)
    logs = log_dirs(paths)
    # the directories named too: an output inside a directory of logs would
    # mix its files with the logs (a single log's inside refused alike)
    check_output(out, [*logs, *paths])
    names = output_names(logs)
    rows: dict[str, dict] = {}
    with atomic_output_dir(out, logs, kind=f"fleet {kind}") as d:
        jobs = [Job(str(p), n, kind, method, schedule, options) for p, n in zip(logs, names)]

        def finished(job: Job, result) -> None:
            row, files = result
            for rel, data in files.items():
                f = d / rel
                f.parent.mkdir(parents=True, exist_ok=True)
                f.write_bytes(data)
            rows[job.name] = row
            if progress is not None:
                progress(len(rows), len(jobs))

        if progress is not None:
            progress(0, len(jobs))
        run_jobs(run_job, jobs, finished, workers, scheduler, client)
        ordered = [rows[n] for n in names]
        failed = [r for r in ordered if r["result"] == "failed"]
        if len(failed) == len(ordered):
            raise OdomgraphError(f"every one of the {len(ordered)} logs failed, so {out} was not written; the "
                                 f"first, {failed[0]['name']}: {failed[0]['error']}")
        (d / "fleet.csv").write_text(fleet_csv(ordered), encoding="utf-8")
        (d / "fleet.json").write_text(json.dumps({"kind": kind, "method": method, "logs": ordered}, indent=1)
                                      + "\n", encoding="utf-8")
    return ordered


def fleet_csv(rows: list[dict]) -> str:
    """fleet.csv: COLUMNS, one row per log; numbers at full precision, text quoted as CSV needs."""
    import csv
    import io
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(COLUMNS)
    for r in rows:
        w.writerow(["" if r.get(c) is None else (repr(r[c]) if isinstance(r[c], float) else r[c]) for c in COLUMNS])
    return buf.getvalue()
