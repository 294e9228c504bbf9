"""Figures in the style of the paper's (matplotlib, Agg backend).

Every figure draws all estimates on the same axes with +-3 sigma bands and
the truth where the log has it. Each function writes one PNG and returns its
path; nothing here computes an estimate.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from odomgraph import state as S
from odomgraph.analysis.metrics import gps_deviation, nees_series
from odomgraph.result import Estimate
from odomgraph.io.log import Log

#: One colour per estimator label, the same in every figure.
COLORS = {"ekf": "tab:blue", "isam2-online": "tab:orange", "isam2": "tab:green", "batch": "tab:red",
          "fixed-lag": "tab:purple", "ekf-no-slip": "0.45"}
_SPARE = ("tab:brown", "tab:pink", "tab:olive", "tab:cyan")
_SCALE_NAMES = ("left ticks/m", "right ticks/m", "track width")


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _color(est: Estimate, k: int) -> str:
    return COLORS.get(est.method, _SPARE[k % len(_SPARE)])


def _save(fig, path, title: str):
    if title:
        fig.suptitle(title)
    fig.savefig(path, dpi=110)
    _plt().close(fig)
    return Path(path)


def _switch_lines(ax, estimates, t0):
    ts = {e.t_switch for e in estimates if e.t_switch is not None}
    for t in ts:
        ax.axvline(t - t0, color="0.5", lw=0.8, ls="--")


def draw_trajectory(ax, estimates: list[Estimate], log: Log) -> None:
    """Paper fig. 1: the path of each estimate, truth, GPS fixes and beacons."""
    tr = log.truth
    if tr is not None:
        ax.plot(tr.values["x"], tr.values["y"], "k-", lw=1, label="truth")
    if log.gps is not None:
        ax.plot(log.gps.x, log.gps.y, ".", color="0.6", ms=2, label="GPS (antenna)")
    if log.robot.beacons:
        b = np.array([[bc.x, bc.y] for bc in log.robot.beacons])
        ax.plot(b[:, 0], b[:, 1], "k^", ms=8, label="beacons")
    for k, est in enumerate(estimates):
        ax.plot(est.mean[:, S.X], est.mean[:, S.Y], color=_color(est, k), lw=1.2, label=est.method)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x east [m]"); ax.set_ylabel("y north [m]")
    ax.legend(loc="best", fontsize=8)


def draw_state(ax, estimates: list[Estimate], log: Log, name: str, ls: str = "-", label_suffix: str = "",
               band_alpha: float = 0.2) -> None:
    """One state of each estimate against time since the log start, with +-3 sigma."""
    t0, i = log.t_start, S.IDX[name]
    for k, est in enumerate(estimates):
        c = _color(est, k)
        m, s = est.mean[:, i], est.sigma[:, i]
        ax.plot(est.t - t0, m, color=c, ls=ls, lw=1, label=est.method + label_suffix)
        if np.any(s > 0):
            ax.fill_between(est.t - t0, m - 3 * s, m + 3 * s, color=c, alpha=band_alpha, lw=0)
    _switch_lines(ax, estimates, t0)


def _truth_slip(ax, log: Log, name: str) -> None:
    tr = log.truth
    if tr is not None and name in tr.values:
        ax.plot(tr.t - log.t_start, tr.values[name], "k-", lw=0.8, label="truth")


def trajectory_figure(estimates, log, path, title: str = "") -> Path:
    """fig1_trajectory.png (paper fig. 1)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 7), constrained_layout=True)
    draw_trajectory(ax, estimates, log)
    ax.set_title("Estimated path (paper fig. 1)")
    return _save(fig, path, title)


def slip_figure(estimates, log, path, title: str = "") -> Path:
    """fig2_slip.png: slip per wheel with +-3 sigma and truth (paper figs. 2, 5, 6)."""
    plt = _plt()
    fig, axes = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True, constrained_layout=True)
    for ax, w in zip(axes, ("left", "right")):
        draw_state(ax, estimates, log, f"slip_{w}")
        _truth_slip(ax, log, f"slip_{w}")
        ax.set_ylabel(f"{w} wheel slip [m/s]")
        ax.legend(loc="upper right", fontsize=8)
    axes[0].set_title("Wheel slip with ±3σ (paper figs. 2, 5, 6); dashed: end of calibration")
    axes[1].set_xlabel("time since log start [s]")
    return _save(fig, path, title)


def scale_figure(estimates, log, path, title: str = "") -> Path:
    """fig3_scale_factors.png: the three scale factors with +-3 sigma (paper figs. 3, 4)."""
    plt = _plt()
    fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True, constrained_layout=True)
    for k, (ax, name) in enumerate(zip(axes, ("scale_left", "scale_right", "scale_track"))):
        draw_state(ax, estimates, log, name)
        vals = np.concatenate([e.mean[:, S.IDX[name]] for e in estimates])
        lo, hi = np.percentile(vals, [1, 99])
        if log.truth_scales is not None:
            ax.axhline(log.truth_scales[k], color="k", lw=0.9, label="truth")
            lo, hi = min(lo, log.truth_scales[k]), max(hi, log.truth_scales[k])
        pad = max(0.01, 0.3 * (hi - lo))
        ax.set_ylim(lo - pad, hi + pad)
        ax.set_ylabel(f"{_SCALE_NAMES[k]} scale [-]")
        # outside the axes: inside, the legend covers the bands it explains
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0)
    axes[0].set_title("Scale factors with ±3σ (paper figs. 3, 4)")
    axes[-1].set_xlabel("time since log start [s]")
    return _save(fig, path, title)


def gps_deviation_figure(estimates, log, path, title: str = "") -> Path | None:
    """fig7_gps_deviation.png: distance from each estimate's predicted antenna
    position to the GPS fix, with and without slip states (paper fig. 7).
    None when the log has no GPS."""
    series = [(e, gps_deviation(e, log)) for e in estimates]
    if all(s is None for _, s in series):
        return None
    plt = _plt()
    fig, ax = plt.subplots(figsize=(10, 4.5), constrained_layout=True)
    for k, (est, s) in enumerate(series):
        if s is not None and s[1].size:
            # RMS over about one second: single fixes scatter by the GPS noise
            # and would hide the slow drift that fig. 7 is about.
            n = max(1, int(round(s[1].size / max(s[0][-1] - s[0][0], 1e-9))))
            ax.plot(s[0] - log.t_start, np.sqrt(running_mean(s[1] ** 2, n)), color=_color(est, k), lw=1.1,
                    ls="--" if est.method == "ekf-no-slip" else "-", label=est.method)
    _switch_lines(ax, estimates, log.t_start)
    sig = log.gps.sigma if log.gps.sigma is not None else np.full(1, log.robot.gps_sigma)
    ax.axhline(float(np.median(sig)) * np.sqrt(2), color="k", lw=0.7, ls=":", label="GPS 1σ (2-D RMS)")
    _plain_log_axis(ax)
    ax.set_xlabel("time since log start [s]"); ax.set_ylabel("|predicted antenna − GPS|, 1 s RMS [m]")
    ax.set_title("Position deviation from GPS, with and without slip states (paper fig. 7)")
    ax.legend(loc="upper right", fontsize=8)
    return _save(fig, path, title)


def _plain_log_axis(ax) -> None:
    """A log y axis labelled 0.05, 0.1, 0.5, 1 rather than 6×10⁻¹ (matplotlib
    labels minor ticks in powers of ten when a decade is short)."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter
    ax.set_yscale("log")
    ax.yaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.yaxis.set_minor_formatter(NullFormatter())


def running_mean(x: np.ndarray, n: int) -> np.ndarray:
    n = max(1, min(n, x.size))
    c = np.cumsum(np.concatenate([[0.0], x]))
    out = np.empty_like(x, dtype=float)
    out[n - 1:] = (c[n:] - c[:-n]) / n
    out[:n - 1] = c[1:n] / np.arange(1, n)
    return out


def consistency_figure(estimates, log, path, title: str = "", window: int = 50) -> Path:
    """consistency.png: pose NEES of each estimate (truth needed) and the EKF's NIS
    per sensor, as running means over ``window`` samples, against their expected
    values (the dimension)."""
    plt = _plt()
    fig, axes = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True, constrained_layout=True)
    t0 = log.t_start
    ax = axes[0]
    drawn = False
    for k, est in enumerate(estimates):
        s = nees_series(est, log)
        if s is not None and s[1].size:
            ax.plot(s[0] - t0, running_mean(s[1], window), color=_color(est, k), lw=1, label=est.method)
            drawn = True
    if drawn:
        ax.axhline(3.0, color="k", lw=0.8, ls="--", label="expected (3)")
        _plain_log_axis(ax)
        ax.legend(loc="upper right", fontsize=8)
    else:
        ax.text(0.5, 0.5, "no truth pose in this log: NEES cannot be computed", ha="center", va="center",
                transform=ax.transAxes)
    ax.set_ylabel(f"pose NEES (running mean of {window})")
    ax.set_title("Consistency: NEES against truth; NIS of the EKF's innovations")
    ax = axes[1]
    ekf = next((e for e in estimates if e.innovations), None)
    if ekf is not None:
        for k, (name, inn) in enumerate(ekf.innovations.items()):
            if inn.nis.size:
                c = _SPARE[k % len(_SPARE)]
                ax.plot(inn.t - t0, running_mean(inn.nis, window) / inn.dof, color=c, lw=1,
                        label=f"{name} (dof {inn.dof})")
        ax.axhline(1.0, color="k", lw=0.8, ls="--", label="expected")
        _plain_log_axis(ax)
        ax.set_ylim(bottom=1e-2)  # the first few running means can be ~0
        ax.legend(loc="upper right", fontsize=8)
    ax.set_ylabel(f"{ekf.method if ekf else 'EKF'} NIS / dof")
    ax.set_xlabel("time since log start [s]")
    return _save(fig, path, title)


def overview_figure(estimates: list[Estimate], log: Log, path: Path | str, title: str = "") -> Path:
    """figure.png: trajectory (fig. 1), slip per wheel (fig. 2) and scale factors
    (fig. 3) on one page."""
    plt = _plt()
    fig = plt.figure(figsize=(13, 9), constrained_layout=True)
    gs = fig.add_gridspec(3, 2)
    ax_traj = fig.add_subplot(gs[:, 0])
    ax_slip = [fig.add_subplot(gs[0, 1]), fig.add_subplot(gs[1, 1])]
    ax_scale = fig.add_subplot(gs[2, 1])
    draw_trajectory(ax_traj, estimates, log)
    ax_traj.set_title("Trajectory (paper fig. 1)")
    for ax, w in zip(ax_slip, ("left", "right")):
        draw_state(ax, estimates, log, f"slip_{w}")
        _truth_slip(ax, log, f"slip_{w}")
        ax.set_ylabel(f"{w.capitalize()} slip [m/s]"); ax.legend(loc="upper right", fontsize=8)
    for name, ls, short in zip(("scale_left", "scale_right", "scale_track"), ("-", "--", ":"),
                               ("left", "right", "track")):
        draw_state(ax_scale, estimates, log, name, ls=ls, label_suffix=f" {short}", band_alpha=0.12)
    if log.truth_scales is not None:
        for val, ls in zip(log.truth_scales, ("-", "--", ":")):
            ax_scale.axhline(val, color="k", ls=ls, lw=0.8)
    ax_slip[0].set_title("Wheel slip with ±3σ (paper fig. 2); dashed: end of calibration")
    ax_scale.set_title("Scale factors with ±3σ (paper fig. 3); black: truth")
    ax_scale.set_ylabel("scale [-]"); ax_scale.set_xlabel("time since log start [s]")
    ax_scale.legend(loc="upper right", fontsize=7, ncol=2)
    lo = min(np.min(e.mean[:, S.SCALE]) for e in estimates)
    hi = max(np.max(e.mean[:, S.SCALE]) for e in estimates)
    ax_scale.set_ylim(lo - 0.03, hi + 0.03)
    return _save(fig, path, title)
