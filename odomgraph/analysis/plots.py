"""Figures in the style of the paper's figs. 1-3 (matplotlib, Agg backend)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from odomgraph import state as S
from odomgraph.estimators.result import Estimate
from odomgraph.io.log import Log

_COLORS = ("tab:blue", "tab:red", "tab:green", "tab:purple")


def overview_figure(estimates: list[Estimate], log: Log, path: Path | str, title: str = "") -> Path:
    """One PNG: trajectory (fig. 1), slip per wheel (fig. 2) and scale factors (fig. 3),
    each estimate with +-3 sigma bands, truth where known."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(13, 9), constrained_layout=True)
    gs = fig.add_gridspec(3, 2)
    ax_traj = fig.add_subplot(gs[:, 0])
    ax_slip = [fig.add_subplot(gs[0, 1]), fig.add_subplot(gs[1, 1])]
    ax_scale = fig.add_subplot(gs[2, 1])
    tr = log.truth
    t0 = log.t_start
    if tr is not None:
        ax_traj.plot(tr.values["x"], tr.values["y"], "k-", lw=1, label="truth")
    if log.gps is not None:
        ax_traj.plot(log.gps.x, log.gps.y, ".", color="0.6", ms=2, label="GPS (antenna)")
    if log.robot.beacons:
        b = np.array([[bc.x, bc.y] for bc in log.robot.beacons])
        ax_traj.plot(b[:, 0], b[:, 1], "k^", ms=8, label="beacons")
    for est, c in zip(estimates, _COLORS):
        ax_traj.plot(est.mean[:, S.X], est.mean[:, S.Y], color=c, lw=1.2, label=est.method)
        for ax, name, w in zip(ax_slip, ("slip_left", "slip_right"), ("left", "right")):
            i = S.IDX[name]
            m, s = est.mean[:, i], est.sigma[:, i]
            ax.plot(est.t - t0, m, color=c, lw=1, label=est.method)
            ax.fill_between(est.t - t0, m - 3 * s, m + 3 * s, color=c, alpha=0.2, lw=0)
        for k, (i, ls) in enumerate(zip(S.SCALE, ("-", "--", ":"))):
            m, s = est.mean[:, i], est.sigma[:, i]
            ax_scale.plot(est.t - t0, m, color=c, ls=ls, lw=1,
                          label=f"{est.method} {('left', 'right', 'track')[k]}")
            ax_scale.fill_between(est.t - t0, m - 3 * s, m + 3 * s, color=c, alpha=0.12, lw=0)
        if est.t_switch is not None:
            for ax in (*ax_slip, ax_scale):
                ax.axvline(est.t_switch - t0, color="0.5", lw=0.8, ls="--")
    if tr is not None:
        for ax, name in zip(ax_slip, ("slip_left", "slip_right")):
            if name in tr.values:
                ax.plot(tr.t - t0, tr.values[name], "k-", lw=0.8, label="truth")
    if log.truth_scales is not None:
        for val, ls in zip(log.truth_scales, ("-", "--", ":")):
            ax_scale.axhline(val, color="k", ls=ls, lw=0.8)
    ax_traj.set_aspect("equal", adjustable="datalim")
    ax_traj.set_xlabel("x east [m]"); ax_traj.set_ylabel("y north [m]")
    ax_traj.set_title("Trajectory (paper fig. 1)"); ax_traj.legend(loc="best", fontsize=8)
    for ax, w in zip(ax_slip, ("Left", "Right")):
        ax.set_ylabel(f"{w} slip [m/s]"); ax.legend(loc="upper right", fontsize=8)
    ax_slip[0].set_title("Wheel slip with ±3σ (paper fig. 2); dashed: end of calibration")
    ax_scale.set_title("Scale factors with ±3σ (paper fig. 3); black: truth")
    ax_scale.set_ylabel("scale [-]"); ax_scale.set_xlabel("time since log start [s]")
    ax_scale.legend(loc="upper right", fontsize=7, ncol=2)
    lo = min(np.min(e.mean[:, S.SCALE]) for e in estimates)
    hi = max(np.max(e.mean[:, S.SCALE]) for e in estimates)
    ax_scale.set_ylim(lo - 0.03, hi + 0.03)
    if title:
        fig.suptitle(title)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)
