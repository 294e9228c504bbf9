"""The results card at the top of the report: the corrected wheel parameters
in physical units with sigma, whether the log determines each, the robot.toml
snippet, what was rejected or recovered, and a one-line verdict.

Physical parameters follow LOG_FORMAT.md's error model: the true ticks per
metre are ``scale_left * ticks_per_meter_left`` (likewise right) and the
true track ``scale_track * track_width``; sigma scales the same way.
"""
from __future__ import annotations

import hashlib
import html
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

#: Which estimate the card reports, best first: the smoothed ones use all the data.
PREFERRED = ("batch", "isam2", "fixed-lag", "ekf", "isam2-online")
#: A parameter further than this many sigma from the truth is called inconsistent.
Z_LIMIT = 3.0


@dataclass(frozen=True)
class Parameter:
    key: str
    """robot.toml key: ticks_per_meter_left, ticks_per_meter_right or track_width."""
    label: str
    unit: str
    nominal: float
    value: float
    sigma: float
    observable: bool
    truth: float | None

    @property
    def z(self) -> float | None:
        """(value - truth) / sigma, or None without truth."""
        if self.truth is None:
            return None
        return (self.value - self.truth) / self.sigma if self.sigma > 0 else float("inf")


def parameters(summary: dict, robot, truth_scales) -> list[Parameter]:
    """The three wheel parameters of one estimator's summary.json."""
    cal = summary["calibration"]
    rows = (("ticks_per_meter_left", "left ticks per metre", "ticks/m", robot.ticks_per_meter_left, "scale_left", 0),
            ("ticks_per_meter_right", "right ticks per metre", "ticks/m", robot.ticks_per_meter_right, "scale_right",
             1),
            ("track_width", "track width", "m", robot.track_width, "scale_track", 2))
    out = []
    for key, label, unit, nominal, name, k in rows:
        c = cal[name]
        out.append(Parameter(key, label, unit, float(nominal), c["value"] * nominal, c["sigma"] * nominal,
                             bool(c.get("observable", True)),
                             None if truth_scales is None else truth_scales[k] * nominal))
    return out


def _digits(sigma: float, nominal: float) -> int:
    """Decimals that show sigma to two significant digits."""
    ref = sigma if sigma > 0 else abs(nominal) * 1e-4
    import math
    return max(0, min(8, 1 - int(math.floor(math.log10(ref))))) if ref > 0 else 4


def snippet(params: list[Parameter]) -> str:
    """robot.toml's [wheels] table with the corrected values; a parameter the
    log does not determine keeps its nominal value, and says so."""
    lines = ["[wheels]"]
    for p in params:
        d = _digits(p.sigma, p.nominal)
        if p.observable:
            lines.append(f"{p.key} = {p.value:.{d}f}    # ± {p.sigma:.{d}f} {p.unit}")
        else:
            lines.append(f"{p.key} = {p.nominal!r}    # not determined by this log: nominal kept")
    return "\n".join(lines)


#: Share of the states inside +-3 sigma of the truth below which the card calls the estimate inconsistent.
COVERAGE_MIN = 0.8


def verdict(params: list[Parameter], summary: dict, failed: list[str]) -> tuple[str, str]:
    """(level "good" | "partial" | "bad", one line) for the card's estimate."""
    if summary.get("status") == "degraded":
        return "bad", "Not trustworthy: " + "; ".join(summary.get("status_reasons", [])) + "."
    off = [p for p in params if p.observable and p.z is not None and abs(p.z) > Z_LIMIT]
    if off:
        return "bad", "Inconsistent: " + ", ".join(f"{p.label} is {p.z:+.1f}σ from the truth" for p in off) + "."
    # Against truth, the path must hold its sigma too: right scale factors on
    # a path 1 m off at a 3 cm sigma are no result to trust (a probe's card).
    cov = (summary.get("errors") or {}).get("coverage_3sigma") or {}
    low = {k: v for k, v in cov.items() if k in ("x", "y", "theta") and v is not None and v < COVERAGE_MIN}
    if low:
        return "bad", ("Inconsistent: only " + ", ".join(f"{v:.0%} of {k}" for k, v in low.items())
                       + f" inside ±3σ of the truth (expected about 99 %){_counts(summary)}.")
    unknown = [p.label for p in params if not p.observable]
    counts = _counts(summary)
    if unknown:
        known = [p.label for p in params if p.observable]
        return "partial", (f"Partly determined: {', '.join(known) or 'nothing'} "
                           f"{'is' if len(known) == 1 else 'are'} estimated; {', '.join(unknown)} "
                           f"{'is' if len(unknown) == 1 else 'are'} not determined by this log (nominal kept)"
                           f"{counts}.")
    truth = " and within 3σ of the truth" if all(p.truth is not None for p in params) else ""
    extra = f" ({', '.join(failed)} diverged)" if failed else ""
    return "good", f"Trustworthy: every parameter is determined by the log{truth}{counts}{extra}."


def _counts(summary: dict) -> str:
    rej = sum(summary.get("rejected", {}).values())
    rec = len(summary.get("recoveries", []))
    dep = len(summary.get("departures", []))
    parts = ([f"{rej} measurement{'s' if rej != 1 else ''} rejected"] if rej else []) + \
            ([f"{rec} recover{'ies' if rec != 1 else 'y'}"] if rec else []) + \
            ([f"{dep} departure{'s' if dep != 1 else ''} followed"] if dep else [])
    return f"; {', '.join(parts)}" if parts else ""


def fingerprint(path: Path | None) -> str | None:
    """sha256[:16] over a log directory's file names and bytes (None without a directory)."""
    if path is None or not Path(path).is_dir():
        return None
    h = hashlib.sha256()
    for f in sorted(p for p in Path(path).iterdir() if p.is_file()):
        h.update(f.name.encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()[:16]


def provenance(log_path: Path | None, argv: list[str] | None = None) -> dict:
    """odomgraph version, command line, date (UTC) and the input log's fingerprint."""
    import shlex
    import sys

    from odomgraph import __version__
    argv = sys.argv if argv is None else argv
    cmd = "odomgraph " + shlex.join(argv[1:]) if argv and Path(argv[0]).name == "odomgraph" else shlex.join(argv)
    return {"odomgraph": __version__, "command": cmd,
            "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "log": None if log_path is None else str(log_path), "log_sha256": fingerprint(log_path)}


def choose(summaries: dict[str, dict]) -> str | None:
    return next((k for k in PREFERRED if k in summaries), next(iter(summaries), None))


def card_html(label: str, params: list[Parameter], summary: dict, reference_note: str, failed: list[str]) -> str:
    """The card as an HTML <section>."""
    esc = html.escape
    level, line = verdict(params, summary, failed)
    rows = []
    for p in params:
        d = _digits(p.sigma, p.nominal)
        truth = "–" if p.truth is None else f"{p.truth:.{d}f}"
        z = "–" if p.z is None else f"{p.z:+.1f}"
        det = "yes" if p.observable else "<b>no</b> (prior)"
        rows.append(f"<tr><td>{esc(p.label)}</td><td>{p.nominal:g}</td><td>{p.value:.{d}f}</td>"
                    f"<td>{p.sigma:.{d}f}</td><td>{esc(p.unit)}</td><td>{det}</td><td>{truth}</td><td>{z}</td></tr>")
    warn = summary.get("warnings", [])
    rej = summary.get("rejected", {})
    used = summary.get("used", {})
    rec = summary.get("recoveries", [])
    parts = [f"<section class='card {level}' id='card'><h2>Result</h2>",
             f"<p class='verdict'>{esc(line)}</p>",
             f"<p>Parameters from <b>{esc(label)}</b> (status {esc(summary.get('status', '?'))}). "
             f"Compared against: {esc(reference_note)}.</p>",
             "<table id='parameters'><tr><th>parameter</th><th>nominal</th><th>estimate</th><th>1σ</th>"
             "<th>unit</th><th>determined</th><th>truth</th><th>error / σ</th></tr>", *rows, "</table>",
             *(["<p>robot.toml (<code>odomgraph calibrate</code> checks these against held-out data before "
                "it writes them):</p>", f"<pre id='snippet'>{esc(snippet(params))}</pre>"] if level != "bad" else
               ["<p>No robot.toml snippet: a result that is not trustworthy is not one to drive on.</p>"])]
    if used:
        cells = "".join(f"<tr><td>{esc(s)}</td><td>{n}</td><td>{rej.get(s, 0)}</td></tr>" for s, n in used.items())
        parts.append("<table><tr><th>sensor</th><th>measurements</th><th>rejected</th></tr>" + cells + "</table>")
    for lines, what in ((rec, ("recovery", "recoveries")),
                        (summary.get("departures", []), ("departure followed", "departures followed"))):
        if lines:
            parts.append(f"<p>{len(lines)} {what[len(lines) != 1]}: " + esc("; ".join(lines[:5]))
                         + (" …" if len(lines) > 5 else "") + "</p>")
    if warn:
        parts.append("<p>Warnings:</p><ul class='warnings'>" + "".join(f"<li>{esc(w)}</li>" for w in warn) + "</ul>")
    parts.append("</section>")
    return "".join(parts)
