"""The report's interactive figures: plotly.js figure specifications (plain
dicts of data and layout), drawn by the plotly.js bundle embedded in the page,
so it opens offline and fetches nothing.

The same five figures as the PNGs (analysis.plots): trajectory, slip per
wheel with +-3 sigma, scale factors with +-3 sigma, deviation from GPS, and
NEES/NIS. A one-hour log has ~18 000 keyframes per estimator; each trace is
cut to at most ``MAX_POINTS`` points by keeping every bucket's minimum and
maximum (a 1 s slip spike survives, where plain striding would skip it), so
a one-hour report stays a few MB.
"""
from __future__ import annotations

import json

import numpy as np

from odomgraph import state as S
from odomgraph.analysis.metrics import gps_deviation, nees_series
from odomgraph.analysis.plots import running_mean
from odomgraph.io.log import Log
from odomgraph.result import Estimate

#: Points per trace at most (each bucket of the series keeps its min and max).
MAX_POINTS = 2000
#: One colour per estimator label, as analysis.plots.COLORS (matplotlib's tab10).
COLORS = {"ekf": "#1f77b4", "isam2-online": "#ff7f0e", "isam2": "#2ca02c", "batch": "#d62728",
          "fixed-lag": "#9467bd", "ekf-no-slip": "#737373"}
_SPARE = ("#8c564b", "#e377c2", "#bcbd22", "#17becf")
TIME_AXIS = "time since log start [s]"


def keep(n: int, primary: np.ndarray | None = None, max_points: int = MAX_POINTS) -> np.ndarray:
    """Sorted row indices (at most ~max_points) of an (n,) series: all rows
    when few, else each bucket's first row and the rows of its minimum and
    maximum of ``primary``."""
    if n <= max_points:
        return np.arange(n)
    buckets = max(1, max_points // 3)
    edges = np.linspace(0, n, buckets + 1).astype(int)
    idx = [edges[:-1]]
    if primary is not None:
        p = np.where(np.isfinite(primary), primary, 0.0)
        for fn in (np.argmin, np.argmax):
            idx.append(np.array([a + fn(p[a:b]) for a, b in zip(edges[:-1], edges[1:]) if b > a]))
    idx.append(np.array([n - 1]))
    return np.unique(np.concatenate(idx))


def _nums(a) -> list:
    """JSON-ready floats at 6 significant digits (None for non-finite)."""
    a = np.asarray(a, dtype=float)
    return [float(s) if s not in ("nan", "inf", "-inf") else None for s in np.char.mod("%.6g", a)]


def _color(est: Estimate, k: int) -> str:
    return COLORS.get(est.method, _SPARE[k % len(_SPARE)])


def _rgba(hex_color: str, alpha: float) -> str:
    r, g, b = (int(hex_color[i:i + 2], 16) for i in (1, 3, 5))
    return f"rgba({r},{g},{b},{alpha})"


def _axes(n: int) -> list[tuple[str, str]]:
    return [("x", "y" if i == 0 else f"y{i + 1}") for i in range(n)]


def _state_traces(estimates, log: Log, name: str, axes: tuple[str, str], show_legend: bool) -> list[dict]:
    """Each estimate's state ``name`` against time with its +-3 sigma band."""
    out = []
    t0, i = log.t_start, S.IDX[name]
    for k, est in enumerate(estimates):
        c = _color(est, k)
        m, s = est.mean[:, i], est.sigma[:, i]
        j = keep(len(est.t), m if not np.any(s > 0) else m + 3 * s * np.sign(m))
        x = _nums(est.t[j] - t0)
        if np.any(s > 0):
            out.append({"type": "scatter", "x": x, "y": _nums(m[j] - 3 * s[j]), "mode": "lines",
                        "line": {"width": 0}, "hoverinfo": "skip", "showlegend": False,
                        "legendgroup": est.method, "xaxis": axes[0], "yaxis": axes[1]})
            out.append({"type": "scatter", "x": x, "y": _nums(m[j] + 3 * s[j]), "mode": "lines",
                        "line": {"width": 0}, "fill": "tonexty", "fillcolor": _rgba(c, 0.18),
                        "hoverinfo": "skip", "showlegend": False, "legendgroup": est.method,
                        "xaxis": axes[0], "yaxis": axes[1]})
        out.append({"type": "scatter", "x": x, "y": _nums(m[j]), "mode": "lines", "name": est.method,
                    "line": {"color": c, "width": 1.3}, "legendgroup": est.method, "showlegend": show_legend,
                    "hovertemplate": f"{est.method}<br>t %{{x:.2f}} s<br>{name} %{{y:.4g}}<extra></extra>",
                    "xaxis": axes[0], "yaxis": axes[1]})
    return out


def _switch_shapes(estimates, log: Log, n_rows: int) -> list[dict]:
    ts = sorted({e.t_switch for e in estimates if e.t_switch is not None})
    return [{"type": "line", "xref": "x", "yref": "paper", "x0": t - log.t_start, "x1": t - log.t_start,
             "y0": 0, "y1": 1, "line": {"color": "#888", "width": 1, "dash": "dash"}} for t in ts]


def _layout(title: str, height: int, **kw) -> dict:
    base = {"title": {"text": title, "font": {"size": 15}}, "height": height, "margin": {"l": 70, "r": 20,
                                                                                        "t": 50, "b": 50},
            "legend": {"orientation": "h", "y": -0.12}, "hovermode": "closest", "template": None}
    base.update(kw)
    return base


def trajectory(estimates: list[Estimate], log: Log) -> dict:
    data = []
    tr = log.truth
    if tr is not None:
        j = keep(len(tr.t))
        data.append({"type": "scatter", "x": _nums(tr.values["x"][j]), "y": _nums(tr.values["y"][j]),
                     "mode": "lines", "name": "truth", "line": {"color": "black", "width": 1}})
    if log.gps is not None and len(log.gps.t):
        j = keep(len(log.gps.t))
        data.append({"type": "scatter", "x": _nums(log.gps.x[j]), "y": _nums(log.gps.y[j]), "mode": "markers",
                     "name": "GPS (antenna)", "marker": {"color": "#999", "size": 3}})
    if log.robot.beacons:
        data.append({"type": "scatter", "x": [b.x for b in log.robot.beacons], "y": [b.y for b in log.robot.beacons],
                     "mode": "markers+text", "text": [b.id for b in log.robot.beacons], "textposition": "top center",
                     "name": "beacons", "marker": {"symbol": "triangle-up", "size": 11, "color": "black"}})
    for k, est in enumerate(estimates):
        j = keep(len(est.t))
        data.append({"type": "scatter", "x": _nums(est.mean[j, S.X]), "y": _nums(est.mean[j, S.Y]),
                     "mode": "lines", "name": est.method, "line": {"color": _color(est, k), "width": 1.4},
                     "text": [f"t {v:.2f} s" for v in est.t[j] - log.t_start],
                     "hovertemplate": f"{est.method}<br>%{{text}}<br>x %{{x:.3f}} m, y %{{y:.3f}} m<extra></extra>"})
    return {"data": data, "layout": _layout("Estimated path (paper fig. 1)", 620,
                                            xaxis={"title": {"text": "x east [m]"}},
                                            yaxis={"title": {"text": "y north [m]"}, "scaleanchor": "x"})}


def _rows_figure(estimates, log, names, labels, title, height, truth_lines=None, truth_series=None) -> dict:
    data, layout = [], _layout(title, height, grid={"rows": len(names), "columns": 1, "pattern": "coupled"},
                               hovermode="x unified")
    for r, (name, label, ax) in enumerate(zip(names, labels, _axes(len(names)))):
        data += _state_traces(estimates, log, name, ax, show_legend=(r == 0))
        key = "yaxis" if r == 0 else f"yaxis{r + 1}"
        layout[key] = {"title": {"text": label}}
        if truth_lines is not None:
            data.append({"type": "scatter", "x": [0, log.t_end - log.t_start], "y": [truth_lines[r]] * 2,
                         "mode": "lines", "name": "truth", "showlegend": r == 0, "legendgroup": "truth",
                         "line": {"color": "black", "width": 1}, "xaxis": ax[0], "yaxis": ax[1]})
        if truth_series is not None and name in truth_series.values:
            j = keep(len(truth_series.t), truth_series.values[name])
            data.append({"type": "scatter", "x": _nums(truth_series.t[j] - log.t_start),
                         "y": _nums(truth_series.values[name][j]), "mode": "lines", "name": "truth",
                         "showlegend": r == 0, "legendgroup": "truth", "line": {"color": "black", "width": 1},
                         "xaxis": ax[0], "yaxis": ax[1]})
    layout["xaxis"] = {"title": {"text": TIME_AXIS}}
    layout["shapes"] = _switch_shapes(estimates, log, len(names))
    return {"data": data, "layout": layout}


def slip(estimates: list[Estimate], log: Log) -> dict:
    return _rows_figure(estimates, log, ("slip_left", "slip_right"), ("left slip [m/s]", "right slip [m/s]"),
                        "Wheel slip with ±3σ (paper figs. 2, 5, 6); dashed: end of calibration", 560,
                        truth_series=log.truth)


def scales(estimates: list[Estimate], log: Log) -> dict:
    return _rows_figure(estimates, log, ("scale_left", "scale_right", "scale_track"),
                        ("left ticks/m scale [-]", "right ticks/m scale [-]", "track width scale [-]"),
                        "Scale factors with ±3σ (paper figs. 3, 4)", 700, truth_lines=log.truth_scales)


def gps_deviation_fig(estimates: list[Estimate], log: Log) -> dict | None:
    series = [(e, gps_deviation(e, log)) for e in estimates]
    if all(s is None for _, s in series):
        return None
    data = []
    for k, (est, s) in enumerate(series):
        if s is None or not s[1].size:
            continue
        # RMS over about one second, as the PNG (single fixes scatter by the GPS noise).
        n = max(1, int(round(s[1].size / max(s[0][-1] - s[0][0], 1e-9))))
        y = np.sqrt(running_mean(s[1] ** 2, n))
        j = keep(len(y), y)
        data.append({"type": "scatter", "x": _nums(s[0][j] - log.t_start), "y": _nums(y[j]), "mode": "lines",
                     "name": est.method, "line": {"color": _color(est, k), "width": 1.2,
                                                  "dash": "dash" if est.method == "ekf-no-slip" else "solid"}})
    sig = log.gps.sigma if log.gps.sigma is not None else np.full(1, log.robot.gps_sigma)
    level = float(np.median(sig)) * np.sqrt(2)
    data.append({"type": "scatter", "x": [0, log.t_end - log.t_start], "y": [level, level], "mode": "lines",
                 "name": "GPS 1σ (2-D RMS)", "line": {"color": "black", "width": 1, "dash": "dot"}})
    return {"data": data, "layout": _layout("Deviation from GPS, with and without slip states (paper fig. 7)", 460,
                                            xaxis={"title": {"text": TIME_AXIS}},
                                            yaxis={"title": {"text": "|predicted antenna − GPS|, 1 s RMS [m]"},
                                                   "type": "log", "exponentformat": "power"},
                                            shapes=_switch_shapes(estimates, log, 1), hovermode="x unified")}


def consistency(estimates: list[Estimate], log: Log, window: int = 50) -> dict:
    data = []
    for k, est in enumerate(estimates):
        s = nees_series(est, log)
        if s is not None and s[1].size:
            y = running_mean(s[1], window)
            j = keep(len(y), y)
            data.append({"type": "scatter", "x": _nums(s[0][j] - log.t_start), "y": _nums(y[j]), "mode": "lines",
                         "name": f"{est.method} NEES", "line": {"color": _color(est, k), "width": 1.1},
                         "xaxis": "x", "yaxis": "y"})
    ekf = next((e for e in estimates if e.innovations), None)
    if ekf is not None:
        for k, (name, inn) in enumerate(ekf.innovations.items()):
            if inn.nis.size:
                y = running_mean(inn.nis, window) / inn.dof
                j = keep(len(y), y)
                data.append({"type": "scatter", "x": _nums(inn.t[j] - log.t_start), "y": _nums(y[j]),
                             "mode": "lines", "name": f"{ekf.method} NIS/dof {name}",
                             "line": {"color": _SPARE[k % len(_SPARE)], "width": 1.1}, "xaxis": "x", "yaxis": "y2"})
    span = [0, log.t_end - log.t_start]
    data.append({"type": "scatter", "x": span, "y": [3, 3], "mode": "lines", "name": "expected NEES (3)",
                 "line": {"color": "black", "width": 1, "dash": "dash"}, "xaxis": "x", "yaxis": "y"})
    data.append({"type": "scatter", "x": span, "y": [1, 1], "mode": "lines", "name": "expected NIS/dof (1)",
                 "line": {"color": "black", "width": 1, "dash": "dot"}, "xaxis": "x", "yaxis": "y2"})
    return {"data": data, "layout": _layout(f"Consistency: pose NEES against truth, running mean of {window}; "
                                            "the EKF's NIS per sensor", 600,
                                            grid={"rows": 2, "columns": 1, "pattern": "coupled"},
                                            xaxis={"title": {"text": TIME_AXIS}},
                                            yaxis={"title": {"text": "pose NEES"}, "type": "log",
                                                   "exponentformat": "power"},
                                            yaxis2={"title": {"text": "NIS / dof"}, "type": "log",
                                                    "exponentformat": "power"})}


#: (element id, builder, caption), in page order.
FIGURES = (
    ("fig-trajectory", trajectory, "Estimated path of each estimator with truth and GPS (paper fig. 1)."),
    ("fig-slip", slip, "Slip per wheel with ±3σ bands and truth where known (paper figs. 2, 5, 6)."),
    ("fig-scales", scales, "Scale factors with ±3σ bands (paper figs. 3, 4)."),
    ("fig-gps", gps_deviation_fig, "Position deviation from GPS with and without slip states (paper fig. 7)."),
    ("fig-consistency", consistency, "NEES against truth and the EKF's NIS per sensor over time."),
)


def figure_specs(estimates: list[Estimate], gps_estimates: list[Estimate], log: Log) -> list[tuple[str, str, dict]]:
    """(id, caption, figure) of every figure the log supports; the GPS
    figure draws ``gps_estimates`` (with the no-slip EKF)."""
    out = []
    for fid, build, caption in FIGURES:
        fig = build(gps_estimates if fid == "fig-gps" else estimates, log)
        if fig is not None:
            out.append((fid, caption, fig))
    return out


#: The plotly.js bundle the pages inline: the "cartesian" partial bundle
#: (scatter and heatmap are all the figures use), vendored in assets/ with
#: its MIT licence. It is 1.4 MB where the full bundle is 4.8 MB, and the
#: browser's parsing of the bundle is most of a report's load time
#: (benchmarks/report_size.py times the one-hour report with each).
PLOTLY_BUNDLE = "plotly-cartesian.min.js"


def plotly_js() -> str:
    """The vendored plotly.js bundle's source, inlined into the page."""
    from importlib.resources import files
    return files("odomgraph.analysis").joinpath("assets", PLOTLY_BUNDLE).read_text(encoding="utf-8")


def figure_script(fid: str, fig: dict) -> str:
    """A <div> and the script that draws ``fig`` into it."""
    spec = json.dumps(fig, separators=(",", ":"), allow_nan=False)
    return (f"<div id='{fid}' class='plot'></div><script>(function(){{var f={spec};"
            f"Plotly.newPlot('{fid}',f.data,f.layout,{{responsive:true,displaylogo:false}});}})();</script>")
