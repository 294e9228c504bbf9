"""Issue 3 and 17 scale: wall time, per-update time and peak memory against log
length (5, 10, 30, 60, 180 minutes; encoders 20 Hz, gyro 20 Hz, GPS 10 Hz), and
the straightforward GTSAM design (plain CustomFactors in LevenbergMarquardtOptimizer
and in ISAM2) on the 5-minute log as the peer. Each log is simulated and written
once; each run is a separate process that reads it from disk as
``odomgraph estimate`` does, so its peak memory (VmHWM) is that of a user's run:
imports, the sensor files and the estimator, not the simulation. A cProfile of
batch on the one-hour log (top functions by cumulative time) goes into the
same results. Writes results/smoother_scaling.{json,md,png}.

    python -m benchmarks.smoother_scaling [--minutes 5 10 30 60 180] [--peer-limit 900]
"""
from __future__ import annotations

import argparse
import multiprocessing as mp
import re
import resource
import shutil
import tempfile
from pathlib import Path

from benchmarks._common import RESULTS, save


def _scenario(minutes: float):
    from odomgraph.sim.scenarios import Rates, paper
    return paper(60.0 * minutes).with_(rates=Rates(encoders=20.0, gyro=20.0, gps=10.0))


def _write(args):
    minutes, path = args
    from odomgraph.io.log import write_log
    from odomgraph.sim.simulate import simulate
    write_log(simulate(_scenario(minutes), 0), path)


def _iterations(est) -> int | None:
    """Batch's Gauss-Newton iterations, from its note."""
    for n in est.notes:
        m = re.search(r"(\d+) Gauss-Newton iterations", n)
        if m:
            return int(m.group(1))
    return None


def _job(args):
    kind, minutes, q, peer_limit, path = args
    import time
    from odomgraph.estimators.schedule import Schedule
    sch = Schedule(20.0)
    out = {"kind": kind, "minutes": minutes}
    if kind.startswith("peer"):
        from odomgraph.sim.simulate import simulate
        log = simulate(_scenario(minutes), 0)
        t0 = time.perf_counter()
        from odomgraph.estimators.batch import SmootherOptions
        from benchmarks.peers import straightforward_isam2, straightforward_lm
        if kind == "peer-lm":
            secs, iters = straightforward_lm(log, sch, SmootherOptions())
            out.update(wall_s=secs, iterations=iters)
        else:
            secs, times, done = straightforward_isam2(log, sch, SmootherOptions(), time_limit=peer_limit)
            n = len(times)
            k = max(1, n // 10)
            out.update(wall_s=secs, completed=done, updates=n, first_ms=1e3 * times[:k].mean(),
                       last_ms=1e3 * times[-k:].mean())
    else:
        from odomgraph.io.log import read_log
        from odomgraph.pipeline import Method, estimate
        t0 = time.perf_counter()
        log = read_log(path)
        t_read = time.perf_counter() - t0
        if kind == "profile-batch":
            import cProfile
            import pstats
            pr = cProfile.Profile()
            pr.enable()
            estimate(log, Method.batch, sch)
            pr.disable()
            st = pstats.Stats(pr).stats
            total = max(v[3] for v in st.values())
            # Our own functions only (the builtins' cumulative times are their own), the wrappers that only
            # pass the call on left out by keeping one row per distinct cumulative time.
            rows, seen = [], set()
            for k, v in sorted(st.items(), key=lambda kv: -kv[1][3]):
                name = f"{Path(k[0]).parent.name}/{Path(k[0]).name}:{k[1]}({k[2]})"
                if "odomgraph" not in k[0] or round(v[3], 2) in seen:
                    continue
                seen.add(round(v[3], 2))
                rows.append({"function": name, "calls": int(v[0]), "cum_s": v[3], "share": v[3] / total})
                if len(rows) == 16:
                    break
            gt = [(v[2], v[0]) for k, v in st.items() if k[2] == "<built-in method gtsam.gtsam.optimize>"]
            out.update(total_s=total, top=rows, gtsam_optimize_s=gt[0][0] if gt else 0.0)
            q.put(out)
            return
        est = estimate(log, Method(kind), sch)
        out["wall_s"] = time.perf_counter() - t0
        out["read_s"] = t_read
        out["rows"] = len(est.t)
        if kind == "batch":
            out["iterations"] = _iterations(est)
        if est.update_times is not None:
            ut = est.update_times
            k = max(1, len(ut) // 10)
            out.update(updates=len(ut), first_ms=1e3 * ut[:k].mean(), last_ms=1e3 * ut[-k:].mean(),
                       mean_ms=1e3 * ut.mean())
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    q.put(out)


def run(kind, minutes, peer_limit=900.0, path=None):
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    p = ctx.Process(target=_job, args=((kind, minutes, q, peer_limit, path),))
    p.start()
    res = q.get()
    p.join()
    print(res, flush=True)
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--minutes", type=float, nargs="+", default=[5, 10, 30, 60, 180])
    ap.add_argument("--peer-limit", type=float, default=900.0, help="stop the peer ISAM2 after this many s")
    ap.add_argument("--profile-minutes", type=float, default=60.0, help="log length of the batch profile")
    args = ap.parse_args(argv)
    results = []
    tmp = Path(tempfile.mkdtemp(prefix="odomgraph-scaling-"))
    profile = None
    try:
        ctx = mp.get_context("spawn")
        for m in sorted(set(args.minutes) | {args.profile_minutes}):
            path = tmp / f"log{m:g}"
            with ctx.Pool(1) as pool:           # the simulation's memory stays out of this process
                pool.map(_write, [(m, str(path))])
            if m in args.minutes:
                for kind in ("ekf", "batch", "isam2", "fixed-lag"):
                    results.append(run(kind, m, path=str(path)))
            if m == args.profile_minutes:
                profile = run("profile-batch", m, path=str(path))
            shutil.rmtree(path)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    peer_min = min(args.minutes)
    results.append(run("peer-lm", peer_min))
    results.append(run("peer-isam2", peer_min, args.peer_limit))
    _plot(results)
    by = {(r["kind"], r["minutes"]): r for r in results}
    lines = ["| minutes | method | wall s | × real time | per-update ms first 10 % → last 10 % | peak MB |",
             "|---|---|---|---|---|---|"]
    for r in results:
        per = f"{r['first_ms']:.2f} → {r['last_ms']:.2f} ({r['last_ms'] / r['first_ms']:.2f}×)" if "first_ms" in r else ""
        lines.append(f"| {r['minutes']:g} | {r['kind']} | {r['wall_s']:.1f} | {60 * r['minutes'] / r['wall_s']:.0f} | "
                     f"{per} | {r['peak_rss_mb']:.0f} |")
    ours_b, ours_i = by[("batch", peer_min)], by[("isam2", peer_min)]
    pl, pi = by[("peer-lm", peer_min)], by[("peer-isam2", peer_min)]
    lines += ["", f"Peer on the {peer_min:g}-minute log: straightforward LM {pl['wall_s']:.1f} s vs batch "
              f"{ours_b['wall_s']:.1f} s (**{pl['wall_s'] / ours_b['wall_s']:.1f}×** faster); straightforward ISAM2 "
              f"{pi['wall_s']:.1f} s{'' if pi['completed'] else ' (stopped at the limit, unfinished)'} vs isam2 "
              f"{ours_i['wall_s']:.1f} s (**{pi['wall_s'] / ours_i['wall_s']:.1f}×**)."]
    save("smoother_scaling", {"runs": results, "profile": profile}, "\n".join(lines))


def _plot(results):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 2, figsize=(11, 4), constrained_layout=True)
    for kind, mk in (("ekf", "o-"), ("batch", "s-"), ("isam2", "^-"), ("fixed-lag", "v-")):
        rs = sorted((r for r in results if r["kind"] == kind), key=lambda r: r["minutes"])
        m = [r["minutes"] for r in rs]
        ax[0].plot(m, [r["wall_s"] for r in rs], mk, label=kind)
        if rs and "first_ms" in rs[0]:
            ax[1].plot(m, [r["last_ms"] for r in rs], mk, label=f"{kind}: last 10 %")
            ax[1].plot(m, [r["first_ms"] for r in rs], mk, alpha=0.4, label=f"{kind}: first 10 %")
    mx = max(r["minutes"] for r in results)
    ax[0].plot([0, mx], [0, 60 * mx / 30], "k:", lw=1, label="30× real time")
    ax[0].set_xlabel("log length [min]"); ax[0].set_ylabel("wall time [s]"); ax[0].legend(); ax[0].grid(alpha=.3)
    ax[0].set_title("Total time (linear = cost per minute constant)")
    ax[1].set_xlabel("log length [min]"); ax[1].set_ylabel("mean update time [ms]"); ax[1].legend(fontsize=8)
    ax[1].grid(alpha=.3); ax[1].set_title("Incremental update time, start vs end of the log")
    fig.savefig(RESULTS / "smoother_scaling.png", dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    main()
