"""Issue 16: report.html in a real headless browser (Debian's Chromium,
driven by Playwright): it loads with no console error and no network
request, every interactive figure is drawn, and the results card shows the
parameters. Skips, saying why, where the browser or Playwright is missing
(.ci/run installs Chromium)."""
import shutil
from pathlib import Path

import pytest

from odomgraph.estimators.schedule import Schedule
from odomgraph.runs import compare_to_dir
from odomgraph.sim.scenarios import paper
from odomgraph.sim.simulate import simulate

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
#: As the machine's notes say: without the background-networking flags Chromium dials out at start.
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def open_page(path: Path, screenshot: Path | None = None) -> dict:
    """Load ``path`` in Chromium; return console errors, requests, the figures
    drawn, the card's text and the load time [ms]."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="Playwright is in the test extra")
    if CHROMIUM is None:
        pytest.skip("no Chromium on this machine (.ci/run installs Debian's chromium package)")
    url = path.resolve().as_uri()
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=FLAGS)
        page = browser.new_page(viewport={"width": 1250, "height": 900})
        errors, requests = [], []
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.on("request", lambda r: requests.append(r.url))
        page.goto(url, wait_until="load")
        load_ms = page.evaluate("performance.getEntriesByType('navigation')[0].loadEventEnd")
        drawn = page.evaluate("Array.from(document.querySelectorAll('.plot')).map(d => "
                              "[d.id, d.querySelectorAll('.main-svg').length, "
                              "(d.data || []).length])")
        card = page.inner_text("#card") if page.query_selector("#card") else ""
        params = page.evaluate("Array.from(document.querySelectorAll('#parameters tr')).slice(1).map("
                               "r => Array.from(r.cells).map(c => c.textContent))")
        if screenshot is not None:
            page.screenshot(path=str(screenshot), full_page=False)
        browser.close()
    return {"errors": errors, "requests": requests, "drawn": drawn, "card": card, "params": params,
            "load_ms": load_ms, "url": url}


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    d = tmp_path_factory.mktemp("rep") / "compare"
    log = simulate(paper(40), 3)
    cmp = compare_to_dir(log, d, Schedule(20.0))
    return d, cmp, log


def test_the_report_renders_offline_with_every_figure_and_the_card(report):
    d, cmp, log = report
    res = open_page(d / "report.html")
    assert res["errors"] == []
    assert res["requests"] == [res["url"]]           # the page itself, nothing fetched
    ids = [i for i, _, _ in res["drawn"]]
    assert ids == ["fig-trajectory", "fig-slip", "fig-scales", "fig-gps", "fig-consistency"]
    assert all(svg >= 1 and traces >= 2 for _, svg, traces in res["drawn"]), res["drawn"]
    # the card: each parameter in physical units, from the batch estimate, with the truth
    labels = [r[0] for r in res["params"]]
    assert labels == ["left ticks per metre", "right ticks per metre", "track width"]
    b = cmp.estimates["batch"].calibration
    r = log.robot
    assert float(res["params"][0][2]) == pytest.approx(b["scale_left"]["value"] * r.ticks_per_meter_left, abs=0.05)
    assert float(res["params"][2][2]) == pytest.approx(b["scale_track"]["value"] * r.track_width, abs=5e-5)
    assert "Trustworthy" in res["card"] and "ticks_per_meter_left = " in res["card"]
    # measured 3.4 s with both cores busy (the target, 3 s for a one-hour log on a quiet machine, is
    # benchmarks/report_size.py's): this bound only catches a page that has become far slower
    assert res["load_ms"] < 10000


def test_a_log_without_truth_says_what_it_is_compared_against(tmp_path):
    log = simulate(paper(40), 4)
    log = log.with_(truth=None, truth_scales=None)
    compare_to_dir(log, tmp_path / "c", Schedule(20.0))
    res = open_page(tmp_path / "c" / "report.html")
    assert res["errors"] == []
    assert "Compared against: the log has no truth: positions are compared with the GPS fixes" in res["card"]
    assert [r[6] for r in res["params"]] == ["–", "–", "–"]   # no truth column values
    assert [i for i, _, _ in res["drawn"]] == ["fig-trajectory", "fig-slip", "fig-scales", "fig-gps",
                                               "fig-consistency"]
