"""EKF throughput against the peer: the same filter on FilterPy's
ExtendedKalmanFilter (benchmarks/peers.py), in the same run, interleaved.

Both use the paper's literal pseudo-update hold (FilterPy has no consider
update), so their outputs are identical (checked here). The machine is shared
and noisy, so each side is run R times alternately and the best times are
compared. Writes results/ekf_throughput.{json,md,png}.

    python -m benchmarks.ekf_throughput [--repeats 7]
"""
from __future__ import annotations

import argparse

import numpy as np

from benchmarks._common import RESULTS, save
from benchmarks.peers import FilterPyEKF
from odomgraph.estimators.ekf import EKF, EKFOptions
from odomgraph.estimators.schedule import Hold, Schedule
from odomgraph.sim.scenarios import paper, yard
from odomgraph.sim.simulate import simulate


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args(argv)
    out, rows = {}, []
    for sc in (paper(), yard()):
        log = simulate(sc, 0)
        sch = Schedule(sc.calibrate_until, Hold.pseudo)
        ours, peer = [], []
        for _ in range(args.repeats):
            a = EKF(log, sch, EKFOptions(encoder_scale_gain=True)).run()   # the paper's update, as the peer's
            b = FilterPyEKF(log, sch).run()
            ours.append(a.wall_time_s)
            peer.append(b.wall_time_s)
        diff = float(np.abs(a.mean - b.mean).max())
        n = a.n_updates
        r = {"updates": n, "ours_best_s": min(ours), "filterpy_best_s": min(peer),
             "ours_updates_per_s": n / min(ours), "filterpy_updates_per_s": n / min(peer),
             "speedup_best": min(peer) / min(ours),
             "speedup_median_pairwise": float(np.median(np.array(peer) / np.array(ours))),
             "max_abs_state_difference": diff}
        out[sc.name] = r
        rows.append(f"| {sc.name} | {n} | {r['ours_updates_per_s']:.0f} | {r['filterpy_updates_per_s']:.0f} | "
                    f"{r['speedup_best']:.2f}× (median pair {r['speedup_median_pairwise']:.2f}×) | {diff:.1e} |")
    _plot(out)
    md = "\n".join([
        "| log | updates | odomgraph EKF updates/s | FilterPy EKF updates/s | speed-up | max state difference |",
        "|---|---|---|---|---|---|", *rows, "",
        f"Best of {args.repeats} interleaved runs each; 'updates' counts measurement updates (pseudo-updates "
        "excluded).",
    ])
    save("ekf_throughput", out, md)


def _plot(out):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 3.2), constrained_layout=True)
    names = list(out)
    x = np.arange(len(names))
    ax.bar(x - 0.2, [out[n]["ours_updates_per_s"] for n in names], 0.4, label="odomgraph EKF")
    ax.bar(x + 0.2, [out[n]["filterpy_updates_per_s"] for n in names], 0.4, label="FilterPy EKF (peer)")
    ax.set_xticks(x, names)
    ax.set_ylabel("measurement updates / s")
    ax.set_title("EKF throughput, same model, same run")
    ax.legend()
    fig.savefig(RESULTS / "ekf_throughput.png", dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    main()
