"""The comparison report: PNG figures, metrics.json and one self-contained report.html.

The HTML embeds every figure as a base64 data URI and has no external
scripts or styles, so it opens from disk in any browser and can be mailed.
"""
from __future__ import annotations

import base64
import html
import json
from pathlib import Path

from odomgraph.analysis import plots
from odomgraph.analysis.compare import Comparison

#: Figure files of a report, in page order, with their captions.
FIGURES = (
    ("fig1_trajectory.png", "Estimated path of each estimator with truth and GPS (paper fig. 1)."),
    ("fig2_slip.png", "Slip per wheel with ±3σ bands and truth where known (paper figs. 2, 5, 6)."),
    ("fig3_scale_factors.png", "Scale factors with ±3σ bands (paper figs. 3, 4)."),
    ("fig7_gps_deviation.png", "Position deviation from GPS with and without slip states (paper fig. 7)."),
    ("consistency.png", "NEES against truth and the EKF's NIS per sensor over time."),
)


def write_figures(cmp: Comparison, directory: Path, title: str = "") -> list[Path]:
    """Every figure of FIGURES that the log supports; returns the files written."""
    ests = list(cmp.estimates.values())
    d = Path(directory)
    out = [
        plots.trajectory_figure(ests, cmp.log, d / FIGURES[0][0], title),
        plots.slip_figure(ests, cmp.log, d / FIGURES[1][0], title),
        plots.scale_figure(ests, cmp.log, d / FIGURES[2][0], title),
        plots.gps_deviation_figure([e for e in (cmp.estimates.get("ekf"), cmp.no_slip) if e is not None]
                                   + [e for k, e in cmp.estimates.items() if k != "ekf"], cmp.log,
                                   d / FIGURES[3][0], title),
        plots.consistency_figure(ests, cmp.log, d / FIGURES[4][0], title),
    ]
    return [p for p in out if p is not None]


def embed_png(path: Path | str, alt: str) -> str:
    """An <img> with the PNG inlined as a data URI, so the page needs no other file."""
    data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
    return f"<img alt='{html.escape(alt)}' src='data:image/png;base64,{data}'>"


def _fmt(v, spec: str = ".3f", empty: str = "–") -> str:
    return empty if v is None else format(v, spec)


def metrics_table_rows(metrics: dict) -> list[list[str]]:
    """The report's metrics table as text cells (header row first)."""
    ref = metrics["reference"]
    pos_head = {"truth": "RMS position error [m]", "gps": "RMS deviation from GPS [m]",
                "ranges": "RMS range residual [m]", "none": "position"}[ref]
    head = ["estimator", pos_head, "slip RMS left [m/s]", "slip RMS right [m/s]",
            "scale left", "scale right", "scale track", "3σ coverage (worst state)", "mean pose NEES",
            "wall time [s]", "updates/s"]
    rows = [head]
    for label, m in metrics["estimators"].items():
        if "failed" in m:
            rows.append([label, "diverged"] + [""] * (len(head) - 2))
            continue
        pos = {"truth": m["rms_position_m"], "gps": m["rms_gps_deviation_m"],
               "ranges": m["rms_range_residual_m"], "none": None}[ref]
        scales = []
        for name in ("scale_left", "scale_right", "scale_track"):
            s = m["scale"][name]
            cell = f"{s['value']:.4f} ± {s['sigma']:.4f}"
            if s["error"] is not None:
                cell += f" (err {s['error']:+.4f})"
            scales.append(cell)
        cov = m["coverage_3sigma_min"]
        rows.append([label, _fmt(pos), _fmt(m["rms_slip_mps"]["left"]), _fmt(m["rms_slip_mps"]["right"]),
                     *scales, _fmt(None if cov is None else 100 * cov, ".1f") + ("%" if cov is not None else ""),
                     _fmt(m["mean_nees_pose"], ".2f"), _fmt(m["wall_time_s"], ".2f"),
                     _fmt(m["updates_per_second"], ".0f")])
    return rows


_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:2em auto;max-width:1150px;
color:#222;line-height:1.45}
table{border-collapse:collapse;font-size:0.88em;margin:1em 0}
th,td{border:1px solid #ccc;padding:0.3em 0.55em;text-align:right}
th{background:#f2f2f2}td:first-child,th:first-child{text-align:left}
figure{margin:1.5em 0}img{max-width:100%;border:1px solid #ddd}
figcaption{color:#555;font-size:0.9em}.note{background:#fff8e0;padding:0.6em 1em;border-left:4px solid #e0b000}
code{background:#f4f4f4;padding:0 0.2em}
"""


def report_html(cmp: Comparison, directory: Path, figures: list[Path], title: str) -> str:
    """The page, with the figures read from ``directory`` and embedded."""
    m = cmp.metrics
    esc = html.escape
    parts = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{esc(title)}</title>"
             f"<style>{_CSS}</style></head><body>", f"<h1>{esc(title)}</h1>"]
    sch = m["schedule"]
    parts.append(f"<p>Log: <code>{esc(str(m['log']))}</code>. Schedule: scale factors estimated with slip "
                 f"forced to 0 for the first {sch['calibrate_until']:g} s, then held "
                 f"(<code>{esc(sch['hold'])}</code>) while slip is estimated.</p>")
    cls = "" if m["reference"] == "truth" else " class='note'"
    parts.append(f"<p{cls}>Reference: {esc(m['reference_note'])}.</p>")
    if m["truth_scales"]:
        ts = ", ".join(f"{k} {v:.4f}" for k, v in m["truth_scales"].items())
        parts.append(f"<p>True scale factors: {esc(ts)}.</p>")
    rows = metrics_table_rows(m)
    parts.append("<h2>Metrics</h2><table><tr>" + "".join(f"<th>{esc(c)}</th>" for c in rows[0]) + "</tr>")
    for r in rows[1:]:
        parts.append("<tr>" + "".join(f"<td>{esc(c)}</td>" for c in r) + "</tr>")
    parts.append("</table>")
    for label, e in m["estimators"].items():
        if "failed" in e:
            parts.append(f"<p class='note'><b>{esc(label)} diverged</b>: {esc(e['failed'])}</p>")
    parts.append("<p>isam2-online is the causal estimate (each row as it stood at its time, "
                 "comparable with the EKF); isam2 and batch are smoothed. ekf-no-slip is the same EKF without "
                 "slip states. Slip is scored after the calibration window.</p>")
    captions = dict(FIGURES)
    parts.append("<h2>Figures</h2>")
    for p in figures:
        parts.append(f"<figure>{embed_png(Path(directory) / p.name, p.name)}"
                     f"<figcaption>{esc(p.name)}: {esc(captions.get(p.name, ''))}</figcaption></figure>")
    notes = sorted({n for e in cmp.estimates.values() for n in e.notes})
    if notes:
        parts.append("<h2>Estimator notes</h2><ul>" + "".join(f"<li>{esc(n)}</li>" for n in notes) + "</ul>")
    parts.append("<p><small>Written by odomgraph.</small></p></body></html>\n")
    return "".join(parts)


def write_report(cmp: Comparison, directory: Path | str, title: str = "odomgraph: EKF vs smoother") -> Path:
    """Figures, metrics.json and report.html into an existing directory."""
    d = Path(directory)
    figures = write_figures(cmp, d)
    (d / "metrics.json").write_text(json.dumps(cmp.metrics, indent=2) + "\n", encoding="utf-8")
    (d / "report.html").write_text(report_html(cmp, d, figures, title), encoding="utf-8")
    return d / "report.html"
