"""The comparison report: PNG figures, metrics.json and one self-contained report.html.

The HTML inlines its scripts (plotly.js for the interactive figures, a few
lines for sortable tables) and styles and fetches nothing, so it opens from
disk in any browser, offline, and can be mailed. The PNGs stay beside it,
for papers.
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
    """The report's metrics table as text cells (header row first); the scale
    factors have their own table (scale_table_rows)."""
    ref = metrics["reference"]
    pos_head = {"truth": "RMS position error [m]", "gps": "RMS deviation from GPS [m]",
                "ranges": "RMS range residual [m]", "none": "position"}[ref]
    head = ["estimator", pos_head, "slip RMS left [m/s]", "slip RMS right [m/s]", "3σ coverage (worst state)",
            "mean pose NEES", "wall time [s]", "updates/s"]
    rows = [head]
    for label, m in metrics["estimators"].items():
        if "failed" in m:
            rows.append([label, "diverged"] + [""] * (len(head) - 2))
            continue
        pos = {"truth": m["rms_position_m"], "gps": m["rms_gps_deviation_m"],
               "ranges": m["rms_range_residual_m"], "none": None}[ref]
        cov = m["coverage_3sigma_min"]
        rows.append([label, _fmt(pos), _fmt(m["rms_slip_mps"]["left"]), _fmt(m["rms_slip_mps"]["right"]),
                     _fmt(None if cov is None else 100 * cov, ".1f") + ("%" if cov is not None else ""),
                     _fmt(m["mean_nees_pose"], ".2f"), _fmt(m["wall_time_s"], ".2f"),
                     _fmt(m["updates_per_second"], ".0f")])
    return rows


def scale_table_rows(metrics: dict, determined: dict[str, dict[str, bool]]) -> list[list[str]]:
    """One row per estimator and scale factor: value, 1σ, error against the
    truth (and in σ) where known, and whether the log determines it
    (``determined[label][name]``; a parameter it does not is its prior)."""
    rows = [["estimator", "scale factor", "value", "1σ", "error", "error / σ", "determined"]]
    for label, m in metrics["estimators"].items():
        if "failed" in m:
            continue
        for name, s in m["scale"].items():
            err, sig = s["error"], s["sigma"]
            det = determined.get(label, {}).get(name, True)
            rows.append([label, name.removeprefix("scale_"), f"{s['value']:.4f}", f"{sig:.4f}",
                         _fmt(err, "+.4f"), "–" if err is None or not sig else f"{err / sig:+.1f}",
                         "yes" if det else "no (prior)"])
    return rows


_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:2em auto;max-width:1150px;
color:#222;line-height:1.45;padding:0 1em}
table{border-collapse:collapse;font-size:0.88em;margin:1em 0}
th,td{border:1px solid #ccc;padding:0.3em 0.55em;text-align:right}
th{background:#f2f2f2;cursor:pointer}td:first-child,th:first-child{text-align:left}
figure{margin:1.5em 0}.plot{width:100%;min-height:300px;border:1px solid #eee}
figcaption{color:#555;font-size:0.9em}.note{background:#fff8e0;padding:0.6em 1em;border-left:4px solid #e0b000}
code,pre{background:#f4f4f4;padding:0 0.2em}pre{padding:0.6em}
.card{border:1px solid #bbb;border-left:8px solid #888;padding:0.2em 1.2em;margin:1em 0}
.card.good{border-left-color:#2ca02c}.card.partial{border-left-color:#e0b000}.card.bad{border-left-color:#d62728}
.verdict{font-size:1.15em;font-weight:600}.prov{color:#666;font-size:0.85em}
"""

#: Click a header to sort its table (numbers numerically); no library needed.
_SORT_JS = """
document.querySelectorAll('table.sortable th').forEach(function(th,i){th.addEventListener('click',function(){
var t=th.closest('table'),rows=Array.from(t.querySelectorAll('tr')).slice(1),asc=th.dataset.asc!=='1';
th.dataset.asc=asc?'1':'0';rows.sort(function(a,b){var x=a.cells[i].textContent,y=b.cells[i].textContent,
p=parseFloat(x),q=parseFloat(y);var c=(isNaN(p)||isNaN(q))?x.localeCompare(y):p-q;return asc?c:-c;});
rows.forEach(function(r){t.appendChild(r);});});});
"""


def _table(rows: list[list[str]], table_id: str, sortable: bool = True) -> str:
    esc = html.escape
    cls = " class='sortable'" if sortable else ""
    out = [f"<table id='{table_id}'{cls}><tr>" + "".join(f"<th>{esc(c)}</th>" for c in rows[0]) + "</tr>"]
    out += ["<tr>" + "".join(f"<td>{esc(c)}</td>" for c in r) + "</tr>" for r in rows[1:]]
    return "".join(out) + "</table>"


def summaries_of(cmp: Comparison, directory: Path) -> dict[str, dict]:
    """Each estimator's summary.json as written beside the report (its
    warnings, rejections and recoveries), or the same fields from the
    estimate where no file was written (isam2-online)."""
    from odomgraph.result import status_of
    out = {}
    for label, est in cmp.estimates.items():
        f = Path(directory) / label / "summary.json"
        if f.is_file():
            out[label] = json.loads(f.read_text(encoding="utf-8"))
            continue
        status, why = status_of(est)
        out[label] = {"calibration": est.calibration, "status": status, "status_reasons": why,
                      "rejected": est.rejected, "used": est.used, "recoveries": est.recoveries,
                      "departures": est.departures, "warnings": list(est.warnings)}
    return out


def slip_events_rows(cmp: Comparison, label: str) -> list[list[str]]:
    """Slip events of the ``label`` estimate and, where the log has it, the truth."""
    from odomgraph.analysis.slip_events import estimated_events, true_events
    rows = [["source", "wheel", "start [s]", "end [s]", "peak slip [m/s]", "peak 1σ [m/s]"]]
    est = cmp.estimates.get(label)
    for src, evs in ((label, estimated_events(est, cmp.log) if est is not None else []),
                     ("truth", true_events(cmp.log) or [])):
        for e in evs:
            rows.append([src, e.wheel, f"{e.start:.1f}", f"{e.end:.1f}", f"{e.peak:+.3f}",
                         "–" if e.peak_sigma is None else f"{e.peak_sigma:.3f}"])
    return rows


def report_html(cmp: Comparison, directory: Path, figures: list[Path], title: str,
                provenance: dict | None = None) -> str:
    """The page: the results card, the tables, the interactive figures (the
    plotly.js bundle inlined, so it opens offline and fetches nothing), links
    to the PNGs in ``directory``, and where it came from."""
    from odomgraph.analysis import card, interactive
    m = cmp.metrics
    esc = html.escape
    prov = provenance or card.provenance(cmp.log.path)
    summ = summaries_of(cmp, directory)
    failed = [k for k, e in m["estimators"].items() if "failed" in e]
    parts = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{esc(title)}</title>"
             f"<style>{_CSS}</style><script>{interactive.plotly_js()}</script></head><body>",
             f"<h1>{esc(title)}</h1>",
             f"<p class='prov' id='provenance'>odomgraph {esc(prov['odomgraph'])} · {esc(prov['date'])} · "
             f"<code>{esc(prov['command'])}</code> · log <code>{esc(str(prov['log']))}</code>"
             + (f" (sha256 {esc(prov['log_sha256'])})" if prov.get("log_sha256") else " (not read from files)")
             + "</p>"]
    label = card.choose(summ)
    if label is not None:
        params = card.parameters(summ[label], cmp.log.robot, cmp.log.truth_scales)
        parts.append(card.card_html(label, params, summ[label], m["reference_note"], failed))
    cls = "" if m["reference"] == "truth" else " class='note'"
    parts.append(f"<p{cls}>Reference: {esc(m['reference_note'])}.</p>")
    sch = m["schedule"]
    parts.append(f"<p>Schedule: scale factors estimated with slip forced to 0 for the first "
                 f"{sch['calibrate_until']:g} s, then held (<code>{esc(sch['hold'])}</code>) while slip is "
                 "estimated. Click a column header to sort.</p>")
    parts.append("<h2>Metrics</h2>" + _table(metrics_table_rows(m), "metrics"))
    determined = {k: {n: c.get("observable", True) for n, c in s["calibration"].items()} for k, s in summ.items()}
    parts.append("<h2>Scale factors</h2>" + _table(scale_table_rows(m, determined), "scales"))
    for lbl, e in m["estimators"].items():
        if "failed" in e:
            parts.append(f"<p class='note'><b>{esc(lbl)} diverged</b>: {esc(e['failed'])}</p>")
    if label is not None:
        ev = slip_events_rows(cmp, label)
        parts.append("<h2>Slip events</h2><p>Stretches where a wheel's slip estimate exceeds both 0.05 m/s and "
                     "3σ for at least 0.5 s" + (", and the true events" if cmp.log.truth is not None else "")
                     + ".</p>" + (_table(ev, "slip-events") if len(ev) > 1 else "<p>None found.</p>"))
    parts.append("<p>isam2-online is the causal estimate (each row as it stood at its time, "
                 "comparable with the EKF); isam2 and batch are smoothed. ekf-no-slip is the same EKF without "
                 "slip states. Slip is scored after the calibration window.</p>")
    ests = list(cmp.estimates.values())
    gps_ests = ([e for e in (cmp.estimates.get("ekf"), cmp.no_slip) if e is not None]
                + [e for k, e in cmp.estimates.items() if k != "ekf"])
    parts.append("<h2>Figures</h2><p>Drag to zoom, double-click to reset, hover for values; click a legend "
                 "entry to hide it.</p>")
    for fid, caption, fig in interactive.figure_specs(ests, gps_ests, cmp.log):
        parts.append(f"<figure>{interactive.figure_script(fid, fig)}<figcaption>{esc(caption)}</figcaption>"
                     "</figure>")
    if figures:
        parts.append("<p>The same figures as PNG, for papers: " + ", ".join(
            f"<a href='{esc(p.name)}'>{esc(p.name)}</a>" for p in figures) + ".</p>")
    notes = sorted({n for e in cmp.estimates.values() for n in e.notes})
    if notes:
        parts.append("<h2>Estimator notes</h2><ul>" + "".join(f"<li>{esc(n)}</li>" for n in notes) + "</ul>")
    parts.append(f"<script>{_SORT_JS}</script></body></html>\n")
    return "".join(parts)


def write_report(cmp: Comparison, directory: Path | str, title: str = "odomgraph: EKF vs smoother",
                 provenance: dict | None = None) -> Path:
    """Figures, metrics.json and report.html into an existing directory
    (after the estimate directories, whose summary.json the card reads)."""
    from odomgraph.analysis.card import provenance as prov_of
    d = Path(directory)
    figures = write_figures(cmp, d)
    prov = provenance or prov_of(cmp.log.path)
    (d / "metrics.json").write_text(json.dumps({**cmp.metrics, "provenance": prov}, indent=2) + "\n",
                                    encoding="utf-8")
    (d / "report.html").write_text(report_html(cmp, d, figures, title, prov), encoding="utf-8")
    return d / "report.html"
