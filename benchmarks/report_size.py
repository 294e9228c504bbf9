"""The comparison report of a one-hour log: its size and how fast it opens.

The log is smoother_scaling's hour (paper scenario, encoders and gyro at
20 Hz, GPS at 10 Hz). ``odomgraph compare``'s directory is written, then
report.html is opened in headless Chromium (Playwright) five times; the load
time is the navigation's loadEventEnd, which includes drawing every
interactive figure (plotly draws synchronously in the page's scripts). The
same page with plotly's full bundle in place of the vendored cartesian one
is timed in the same run, as the other design. The
targets (issue 16): below about 10 MB, open in under 3 s. A screenshot of a
60 s report's top goes to docs/report.png for the README.

python -m benchmarks.report_size [--minutes 60]
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from benchmarks._common import RESULTS, save

DOCS = RESULTS.parent.parent / "docs"


def _open(path: Path, screenshot: Path | None = None, repeats: int = 5) -> list[float]:
    import shutil

    from playwright.sync_api import sync_playwright
    exe = shutil.which("chromium")
    flags = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
             "--disable-background-networking", "--disable-component-update", "--disable-sync"]
    out = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=exe, args=flags)
        for k in range(repeats):
            page = browser.new_page(viewport={"width": 1250, "height": 1400})
            page.goto(path.resolve().as_uri(), wait_until="load")
            out.append(float(page.evaluate("performance.getEntriesByType('navigation')[0].loadEventEnd")))
            if screenshot is not None and k == 0:
                page.screenshot(path=str(screenshot), full_page=False)
            page.close()
        browser.close()
    return out


def _full_bundle(page: Path) -> tuple[list[float] | None, int | None]:
    """Load times (sorted, ms) and size of ``page`` with plotly's full
    plotly.js bundle in place of the vendored one; (None, None) without the
    plotly package."""
    try:
        from plotly.offline import get_plotlyjs
    except ImportError:
        return None, None
    from odomgraph.analysis.interactive import plotly_js
    html = page.read_text(encoding="utf-8")
    assert plotly_js() in html
    other = page.with_name("report-full-bundle.html")
    other.write_text(html.replace(plotly_js(), get_plotlyjs(), 1), encoding="utf-8")
    return sorted(_open(other)), other.stat().st_size


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=60.0)
    args = ap.parse_args(argv)
    from odomgraph.estimators.schedule import Schedule
    from odomgraph.runs import compare_to_dir
    from odomgraph.sim.scenarios import Rates, paper
    from odomgraph.sim.simulate import simulate
    with tempfile.TemporaryDirectory() as tmp:
        log = simulate(paper(60.0 * args.minutes).with_(rates=Rates(encoders=20.0, gyro=20.0, gps=10.0)), 0)
        t0 = time.perf_counter()
        compare_to_dir(log, Path(tmp) / "hour", Schedule(20.0))
        wall = time.perf_counter() - t0
        page = Path(tmp) / "hour" / "report.html"
        size = page.stat().st_size
        loads = _open(page)
        # The other design: the same page with plotly's full bundle (what the
        # report inlined before the cartesian bundle was vendored).
        full_loads, full_size = _full_bundle(page)
        small = simulate(paper(60.0), 0)
        compare_to_dir(small, Path(tmp) / "minute", Schedule(20.0), title="odomgraph: EKF vs smoother, paper scenario")
        DOCS.mkdir(exist_ok=True)
        _open(Path(tmp) / "minute" / "report.html", DOCS / "report.png", repeats=1)
    loads.sort()
    from odomgraph.analysis.interactive import MAX_POINTS, PLOTLY_BUNDLE, plotly_js
    data = {"minutes": args.minutes, "report_bytes": size, "load_ms": loads, "median_load_ms": loads[len(loads) // 2],
            "compare_wall_s": wall, "targets": {"report_bytes": 10e6, "load_ms": 3000.0},
            "bundle": PLOTLY_BUNDLE, "bundle_bytes": len(plotly_js().encode()), "max_points": MAX_POINTS,
            "full_bundle": None if full_loads is None else
            {"report_bytes": full_size, "load_ms": full_loads, "median_load_ms": full_loads[len(full_loads) // 2]}}
    ok = size < 10e6 and data["median_load_ms"] < 3000
    md = (f"# The report of a {args.minutes:g}-minute log\n\n"
          f"| | value | target |\n|---|---|---|\n"
          f"| report.html | {size / 1e6:.1f} MB | < 10 MB |\n"
          f"| load in headless Chromium (median of {len(loads)}) | {data['median_load_ms'] / 1e3:.2f} s "
          f"(range {loads[0] / 1e3:.2f}–{loads[-1] / 1e3:.2f} s) | < 3 s |\n"
          f"| `compare` (EKF, iSAM2, batch, no-slip EKF, figures) | {wall:.0f} s | |\n\n"
          f"{'Both targets met.' if ok else 'A target is missed.'} The page inlines plotly.js's cartesian "
          f"bundle ({data['bundle_bytes'] / 1e6:.1f} MB, vendored); each trace keeps at most {MAX_POINTS} points "
          "(every bucket's minimum and maximum).\n")
    fb = data["full_bundle"]
    if fb is None:
        md += "\nThe full-bundle design was not measured: the plotly package is not installed (the test extra).\n"
    else:
        md += (f"\nThe other design, measured in the same run: the same page with plotly's full bundle is "
               f"{fb['report_bytes'] / 1e6:.1f} MB and loads in {fb['median_load_ms'] / 1e3:.2f} s (median of "
               f"{len(fb['load_ms'])}), {fb['median_load_ms'] / data['median_load_ms']:.2f}x the shipped page.\n")
    save("report_size", data, md)


if __name__ == "__main__":
    main()
