"""Figures, findings and the HTML summary of a Monte-Carlo study (paper figs. 8-10)."""
from __future__ import annotations

import html
import json
from dataclasses import asdict
from pathlib import Path

import numpy as np

from odomgraph.analysis.montecarlo import PointResult, StudySpec, grid_of, results_table, spec_json, write_atomic

#: Heatmap rows: (label, quantities averaged, factor to display units, unit).
_ROWS = (("left ticks/m scale", ("scale_left",), 100.0, "%"),
         ("right ticks/m scale", ("scale_right",), 100.0, "%"),
         ("track width scale", ("scale_track",), 100.0, "%"),
         ("wheel slip (mean of wheels)", ("slip_left", "slip_right"), 100.0, "cm/s"))


def quantity_grid(spec, results, estimator, quantities) -> np.ndarray:
    return np.mean([grid_of(spec, results, estimator, q) for q in quantities], axis=0)


def failure_grid(spec: StudySpec, results: list[PointResult], estimator: str) -> np.ndarray:
    g = np.zeros((len(spec.x_values), len(spec.y_values)))
    for r in results:
        if estimator in r.scores:
            g[r.i, r.j] = r.failure_rate(estimator)
    return g


def heatmap_figure(spec: StudySpec, results: list[PointResult], directory) -> Path:
    """heatmap_config{N}.png: median RMS error over the noise grid, EKF and smoother
    side by side, and their ratio (paper figs. 8-10). Cells show the value;
    'f 12%' marks the share of runs that failed."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm, TwoSlopeNorm
    from odomgraph.sim.sensor_configs import CONFIGS
    cfg = CONFIGS[spec.config]
    ests = [e for e in ("ekf", "batch") if any(e in r.scores for r in results)]
    ncol = len(ests) + (1 if len(ests) == 2 else 0)
    fig, axes = plt.subplots(len(_ROWS), ncol, figsize=(4.6 * ncol, 3.4 * len(_ROWS)), constrained_layout=True,
                             squeeze=False)
    xv, yv = np.asarray(spec.x_values), np.asarray(spec.y_values)

    def cells(ax, g, fmt, fail=None):
        for i in range(len(xv)):
            for j in range(len(yv)):
                txt = "–" if not np.isfinite(g[i, j]) else format(g[i, j], fmt)
                if fail is not None and fail[i, j] > 0:
                    txt += f"\nf {fail[i, j]:.0%}"
                ax.text(j, i, txt, ha="center", va="center", fontsize=7)
        ax.set_xticks(range(len(yv)), [f"{v:.3g}" for v in yv], fontsize=7)
        ax.set_yticks(range(len(xv)), [f"{v:.3g}" for v in xv], fontsize=7)
        ax.set_xlabel(cfg.y.label); ax.set_ylabel(cfg.x.label)

    for row, (label, qs, k, unit) in enumerate(_ROWS):
        grids = {e: k * quantity_grid(spec, results, e, qs) for e in ests}
        finite = np.concatenate([g[np.isfinite(g)] for g in grids.values()])
        lo, hi = (max(finite.min(), 1e-6), max(finite.max(), 2e-6)) if finite.size else (1e-3, 1.0)
        for col, e in enumerate(ests):
            ax = axes[row, col]
            im = ax.imshow(grids[e], origin="lower", cmap="viridis", norm=LogNorm(lo, hi), aspect="auto")
            cells(ax, grids[e], ".2g", failure_grid(spec, results, e))
            ax.set_title(f"{'EKF' if e == 'ekf' else 'batch smoother'}: {label} [{unit}]", fontsize=9)
            fig.colorbar(im, ax=ax, shrink=0.8)
        if len(ests) == 2:
            ax = axes[row, 2]
            ratio = grids["batch"] / grids["ekf"]
            fin = ratio[np.isfinite(ratio)]
            span = max(2.0, float(np.max(np.abs(np.log2(fin))))) if fin.size else 2.0
            im = ax.imshow(np.log2(ratio), origin="lower", cmap="RdBu_r", aspect="auto",
                           norm=TwoSlopeNorm(0.0, -span, span))
            cells(ax, ratio, ".2f")
            ax.set_title(f"smoother / EKF: {label} (blue: smoother better)", fontsize=9)
            fig.colorbar(im, ax=ax, shrink=0.8, label="log2 ratio")
    fig.suptitle(f"Configuration {cfg.number}: {cfg.title}; median RMS error over {spec.runs} runs "
                 f"of {spec.duration:g} s (paper fig. {7 + cfg.number})")
    path = Path(directory) / f"heatmap_config{spec.config}.png"
    tmp = path.with_name(f".{path.name}.tmp.png")
    fig.savefig(tmp, dpi=100)
    plt.close(fig)
    tmp.replace(path)
    return path


# ---------------------------------------------------------------- findings
def _near(values, v) -> int:
    return int(np.argmin(np.abs(np.asarray(values) - v)))


def track_vs_rate_sensor(spec, results, estimator="ekf") -> tuple[np.ndarray, np.ndarray]:
    """(rate-sensor sigmas, median over the position axis of the track-width error)."""
    g = grid_of(spec, results, estimator, "scale_track")
    return np.asarray(spec.y_values), np.nanmedian(g, axis=0)


def ticks_vs_position_sensor(spec, results, estimator="ekf") -> tuple[np.ndarray, np.ndarray]:
    """(position-sensor sigmas, median over the rate axis of the mean ticks/m error)."""
    g = quantity_grid(spec, results, estimator, ("scale_left", "scale_right"))
    return np.asarray(spec.x_values), np.nanmedian(g, axis=1)


def findings(spec: StudySpec, results: list[PointResult], estimator: str = "ekf") -> list[dict]:
    """The paper's qualitative findings for this configuration, on our numbers.

    Each: {"claim", "measured", "holds"} (holds None when the grid cannot tell).
    """
    out = []
    if spec.config in (1, 3):
        gy, track = track_vs_rate_sensor(spec, results, estimator)
        k = _near(gy, 0.05)
        if 0 < k < len(gy) - 1:
            below = (track[k] - track[0]) / (gy[k] - gy[0])
            above = (track[-1] - track[k]) / (gy[-1] - gy[k])
            out.append({"claim": "track-width error rises steeply once gyro σ passes about 0.05 rad/s",
                        "measured": f"track error {100 * track[0]:.3g}% at {gy[0]:.3g}, {100 * track[k]:.3g}% at "
                                    f"{gy[k]:.3g}, {100 * track[-1]:.3g}% at {gy[-1]:.3g} rad/s; slope above "
                                    f"{gy[k]:.3g} is {above / below if below > 0 else np.inf:.1f}x the slope below",
                        "holds": bool(track[-1] > 2 * track[k] and above > 2 * below)})
    if spec.config == 1:
        gx, ticks = ticks_vs_position_sensor(spec, results, estimator)
        r = ticks[-1] / ticks[0]
        out.append({"claim": "from 1.5 m to 0.05 m GPS the ticks-per-metre error improves by about 2x",
                    "measured": f"ticks/m error {100 * ticks[-1]:.3g}% at {gx[-1]:.3g} m, {100 * ticks[0]:.3g}% at "
                                f"{gx[0]:.3g} m: {r:.2f}x",
                    "holds": bool(1.4 <= r <= 3.0) if gx[-1] >= 1.0 and gx[0] <= 0.1 else None})
    return out


def heatmap_specs(spec: StudySpec, results: list[PointResult]) -> list[tuple[str, str, dict]]:
    """(id, caption, plotly figure) per heatmap row of _ROWS: the EKF's and
    the smoother's medians side by side over the noise grid; hovering a cell
    shows both noise values, the median, the share of failed runs and the
    runs it rests on."""
    from odomgraph.sim.sensor_configs import CONFIGS
    cfg = CONFIGS[spec.config]
    ests = [e for e in ("ekf", "batch") if any(e in r.scores for r in results)]
    xs = [f"{v:.3g}" for v in spec.y_values]
    ys = [f"{v:.3g}" for v in spec.x_values]
    out = []
    for row, (label, qs, k, unit) in enumerate(_ROWS):
        data, layout = [], {"title": {"text": f"{label}: median RMS error [{unit}]", "font": {"size": 15}},
                            "height": 420, "grid": {"rows": 1, "columns": len(ests), "pattern": "independent"},
                            "margin": {"l": 70, "r": 20, "t": 60, "b": 60}, "template": None}
        for c, e in enumerate(ests):
            g = k * quantity_grid(spec, results, e, qs)
            fail = failure_grid(spec, results, e)
            text = [[f"{e}<br>{cfg.x.label} {ys[i]}, {cfg.y.label} {xs[j]}<br>median "
                     f"{'–' if not np.isfinite(g[i, j]) else format(g[i, j], '.3g')} {unit}<br>failed "
                     f"{fail[i, j]:.0%} of {spec.runs} runs" for j in range(len(xs))] for i in range(len(ys))]
            ax = "" if c == 0 else str(c + 1)
            data.append({"type": "heatmap", "z": [[None if not np.isfinite(v) else float(f"{v:.4g}") for v in r]
                                                  for r in g], "x": xs, "y": ys, "text": text,
                         "hovertemplate": "%{text}<extra></extra>", "colorscale": "Viridis",
                         "zmin": 0, "showscale": c == len(ests) - 1, "xaxis": f"x{ax}", "yaxis": f"y{ax}",
                         "texttemplate": "%{z:.3g}", "name": e})
            layout[f"xaxis{ax}"] = {"title": {"text": f"{e}: {cfg.y.label}"}, "type": "category"}
            layout[f"yaxis{ax}"] = {"title": {"text": cfg.x.label}, "type": "category"}
        out.append((f"heat-{row}", f"{label}, EKF and smoother side by side (paper figs. 8-10).",
                    {"data": data, "layout": layout}))
    return out


def summary_html(spec: StudySpec, results: list[PointResult], directory, figures: list[Path]) -> str:
    from odomgraph.analysis.interactive import figure_script, plotly_js
    from odomgraph.sim.sensor_configs import CONFIGS
    cfg = CONFIGS[spec.config]
    esc = html.escape
    rows = results_table(spec, results)
    parts = ["<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
             f"<title>Monte-Carlo configuration {cfg.number}</title><style>"
             "body{font-family:system-ui,sans-serif;max-width:1300px;margin:2em auto;color:#222}"
             "table{border-collapse:collapse;font-size:.82em}td,th{border:1px solid #ccc;padding:.2em .5em;"
             "text-align:right}th{background:#f2f2f2}img{max-width:100%}</style>"
             f"<script>{plotly_js()}</script></head><body>",
             f"<h1>Monte-Carlo study, configuration {cfg.number}: {esc(cfg.title)}</h1>",
             f"<p>{len(spec.x_values)}×{len(spec.y_values)} grid, {spec.runs} runs of {spec.duration:g} s per point "
             f"(seed {spec.seed}), schedule: scale factors for the first {spec.calibrate_until:g} s, then slip. "
             "Values are medians over the runs that did not fail of each run's RMS error after the switch.</p>"]
    fnd = findings(spec, results)
    if fnd:
        parts.append("<h2>The paper's findings on these numbers (EKF)</h2><ul>")
        for f in fnd:
            verdict = {True: "reproduces", False: "does not reproduce", None: "grid cannot tell"}[f["holds"]]
            parts.append(f"<li><b>{esc(f['claim'])}</b>: {esc(f['measured'])}. <i>{verdict}</i></li>")
        parts.append("</ul>")
    parts.append("<h2>Heatmaps</h2><p>Hover a cell for its grid point's numbers; drag to zoom.</p>")
    for fid, caption, fig in heatmap_specs(spec, results):
        parts.append(f"<figure>{figure_script(fid, fig)}<figcaption>{esc(caption)}</figcaption></figure>")
    if figures:
        parts.append("<p>As PNG, for papers: " + ", ".join(f"<a href='{esc(Path(p).name)}'>{esc(Path(p).name)}</a>"
                                                           for p in figures) + ".</p>")
    cols = list(rows[0])
    parts.append("<h2>Results</h2><table><tr>" + "".join(f"<th>{esc(c)}</th>" for c in cols) + "</tr>")
    for r in rows:
        parts.append("<tr>" + "".join(
            f"<td>{'' if r[c] is None else (format(r[c], '.4g') if isinstance(r[c], float) else esc(str(r[c])))}"
            "</td>" for c in cols) + "</tr>")
    wall = {k: sum(r.wall_s.get(k, 0.0) for r in results) for k in ("simulate", "ekf", "batch")}
    parts.append("</table><p>CPU time in the workers: " + ", ".join(f"{k} {v:.0f} s" for k, v in wall.items())
                 + ".</p></body></html>\n")
    return "".join(parts)


def write_outputs(spec: StudySpec, results: list[PointResult], directory) -> list:
    """results.csv, results.json, heatmaps and summary.html into DIR (each file atomically)."""
    d = Path(directory)
    rows = results_table(spec, results)
    cols = list(rows[0])
    lines = [",".join(cols)] + [",".join("" if row[c] is None else (f"{row[c]:.6g}" if isinstance(row[c], float)
                                                                   else str(row[c])) for c in cols) for row in rows]
    write_atomic(d / "results.csv", "\n".join(lines) + "\n")
    write_atomic(d / "results.json", json.dumps({"study": spec_json(spec), "rows": rows,
                                                  "points": [asdict(r) for r in results]}, indent=1) + "\n")
    figs = [heatmap_figure(spec, results, d)]
    write_atomic(d / "summary.html", summary_html(spec, results, d, figs))
    return [d / "results.csv", d / "results.json", *figs, d / "summary.html"]
