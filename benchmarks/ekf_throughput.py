"""EKF throughput against the peer: the same filter on FilterPy's
ExtendedKalmanFilter (benchmarks/peers.py), in the same run, interleaved,
and issue 17's second design beside them: the predict and update arithmetic
compiled with numba (benchmarks/ekf_compiled.py, a prototype; measured when
numba is installed, ``pip install -e ".[bench]"``). A profile of the shipped
filter's run says where the rest of its time goes.

Both use the paper's literal pseudo-update hold (FilterPy has no consider
update), so their outputs are identical (checked here). The machine is shared
and noisy, so each side is run R times alternately and the best times are
compared. Writes results/ekf_throughput.{json,md,png}.

    python -m benchmarks.ekf_throughput [--repeats 7]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from benchmarks._common import RESULTS, save
from benchmarks.ekf_compiled import CompiledEKF, njit
from benchmarks.peers import FilterPyEKF
from benchmarks.readme_blocks import compiled_md, profile_md
from odomgraph.estimators.ekf import EKF, EKFOptions
from odomgraph.estimators.schedule import Hold, Schedule
from odomgraph.sim.scenarios import paper, yard
from odomgraph.sim.simulate import simulate


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--top", type=int, default=12, help="profile rows to keep")
    args = ap.parse_args(argv)
    out, rows = {}, []
    compiled = njit is not None
    for sc in (paper(), yard()):
        log = simulate(sc, 0)
        sch = Schedule(sc.calibrate_until, Hold.pseudo)
        opt = EKFOptions(encoder_scale_gain=True)     # the paper's update, as the peer's
        if compiled:
            CompiledEKF(log, sch, opt).run()          # compiles (or loads numba's cache) outside the timing
        ours, peer, comp = [], [], []
        for _ in range(args.repeats):
            a = EKF(log, sch, opt).run()
            b = FilterPyEKF(log, sch).run()
            ours.append(a.wall_time_s)
            peer.append(b.wall_time_s)
            if compiled:
                c = CompiledEKF(log, sch, opt).run()
                comp.append(c.wall_time_s)
        diff = float(np.abs(a.mean - b.mean).max())
        n = a.n_updates
        r = {"updates": n, "ours_best_s": min(ours), "filterpy_best_s": min(peer),
             "ours_updates_per_s": n / min(ours), "filterpy_updates_per_s": n / min(peer),
             "speedup_best": min(peer) / min(ours),
             "speedup_median_pairwise": float(np.median(np.array(peer) / np.array(ours))),
             "max_abs_state_difference": diff}
        if compiled:
            r.update(compiled_best_s=min(comp), compiled_updates_per_s=n / min(comp),
                     compiled_speedup_vs_filterpy=min(peer) / min(comp), compiled_speedup_vs_ours=min(ours) / min(comp),
                     compiled_max_abs_state_difference=float(np.abs(a.mean - c.mean).max()))
        out[sc.name] = r
        rows.append(f"| {sc.name} | {n} | {r['ours_updates_per_s']:.0f} | {r['filterpy_updates_per_s']:.0f} | "
                    f"{r['speedup_best']:.2f}× (median pair {r['speedup_median_pairwise']:.2f}×) | {diff:.1e} |")
    out["profile"] = _profile(paper(), args.top)
    _plot(out)
    md = "\n".join([
        "| log | updates | odomgraph EKF updates/s | FilterPy EKF updates/s | speed-up | max state difference |",
        "|---|---|---|---|---|---|", *rows, "",
        f"Best of {args.repeats} interleaved runs each; 'updates' counts measurement updates (pseudo-updates "
        "excluded).", "",
        *compiled_md(out), "",
        *profile_md(out["profile"]),
    ])
    save("ekf_throughput", out, md)


def _profile(sc, top: int) -> dict:
    """cProfile of one run of the shipped filter on ``sc``'s log: the share
    of the run in each of its ``top`` functions by own time."""
    import cProfile
    import pstats
    log = simulate(sc, 0)
    sch = Schedule(sc.calibrate_until, Hold.pseudo)
    pr = cProfile.Profile()
    pr.enable()
    est = EKF(log, sch, EKFOptions(encoder_scale_gain=True)).run()
    pr.disable()
    st = pstats.Stats(pr).stats
    total = sum(v[2] for v in st.values())
    rows = sorted(((v[2], v[0], f"{Path(k[0]).name}:{k[1]}({k[2]})") for k, v in st.items()), reverse=True)[:top]
    return {"log": sc.name, "updates": est.n_updates, "total_s": total,
            "top": [{"function": f, "calls": int(c), "own_s": t, "share": t / total} for t, c, f in rows]}


def _plot(out):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 3.2), constrained_layout=True)
    names = [n for n in out if "updates" in out[n] and "ours_updates_per_s" in out[n]]
    x = np.arange(len(names))
    comp = all("compiled_updates_per_s" in out[n] for n in names)
    w = 0.27 if comp else 0.4
    ax.bar(x - w, [out[n]["filterpy_updates_per_s"] for n in names], w, label="FilterPy EKF (peer)")
    ax.bar(x, [out[n]["ours_updates_per_s"] for n in names], w, label="odomgraph EKF (numpy)")
    if comp:
        ax.bar(x + w, [out[n]["compiled_updates_per_s"] for n in names], w, label="kernels compiled (prototype)")
    ax.set_xticks(x, names)
    ax.set_ylabel("measurement updates / s")
    ax.set_title("EKF throughput, same model, same run")
    ax.legend()
    fig.savefig(RESULTS / "ekf_throughput.png", dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    main()
