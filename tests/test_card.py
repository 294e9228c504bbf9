"""The report's results card: parameters in physical units, the snippet, the verdict."""
import tomllib

import pytest

from odomgraph.analysis.card import card_html, fingerprint, parameters, snippet, verdict
from odomgraph.io.robot import RobotConfig

ROBOT = RobotConfig(ticks_per_meter_left=2000.0, ticks_per_meter_right=1990.0, track_width=0.5)


def _summary(sl=1.03, sr=0.98, sb=1.04, sig=(0.001, 0.001, 0.002), observable=(True, True, True), **kw):
    cal = {n: {"value": v, "sigma": s, "observable": o}
           for n, v, s, o in zip(("scale_left", "scale_right", "scale_track"), (sl, sr, sb), sig, observable)}
    return {"calibration": cal, "status": "ok", "status_reasons": [], "rejected": {}, "recoveries": [],
            "used": {"gps": 100}, "warnings": [], **kw}


def test_parameters_are_the_scale_factors_times_the_nominal_robot():
    p = parameters(_summary(), ROBOT, (1.03, 0.98, 1.04))
    assert [x.key for x in p] == ["ticks_per_meter_left", "ticks_per_meter_right", "track_width"]
    assert p[0].value == pytest.approx(2060.0) and p[0].sigma == pytest.approx(2.0)
    assert p[1].value == pytest.approx(1950.2) and p[2].value == pytest.approx(0.52)
    assert p[2].sigma == pytest.approx(0.001) and p[2].z == pytest.approx(0.0)


def test_the_snippet_is_valid_toml_and_keeps_nominal_what_is_not_determined():
    p = parameters(_summary(observable=(False, False, True)), ROBOT, None)
    text = snippet(p)
    w = tomllib.loads(text)["wheels"]
    assert w == {"ticks_per_meter_left": 2000.0, "ticks_per_meter_right": 1990.0, "track_width": 0.52}
    assert "not determined by this log: nominal kept" in text


@pytest.mark.parametrize("summary,truth,level,words", [
    (_summary(), (1.03, 0.98, 1.04), "good", "Trustworthy: every parameter is determined by the log and within 3σ"),
    (_summary(rejected={"gps": 3}), None, "good", "3 measurements rejected"),
    (_summary(observable=(False, False, True)), None, "partial",
     "track width is estimated; left ticks per metre, right ticks per metre are not determined"),
    (_summary(sl=1.05), (1.03, 0.98, 1.04), "bad", "left ticks per metre is +20.0σ from the truth"),
    (_summary(status="degraded", status_reasons=["gps: 40 of 100 measurements rejected"]), None, "bad",
     "Not trustworthy: gps: 40 of 100 measurements rejected."),
    # a probe's card: scale factors right, the path 1.3 m off at a few cm sigma
    (_summary(errors={"coverage_3sigma": {"x": 0.6, "y": 0.59, "theta": 0.38}}), (1.03, 0.98, 1.04), "bad",
     "Inconsistent: only 60% of x, 59% of y, 38% of theta inside ±3σ of the truth"),
    (_summary(errors={"coverage_3sigma": {"x": 0.97, "y": 0.99, "theta": 1.0}}), (1.03, 0.98, 1.04), "good",
     "Trustworthy"),
])
def test_the_verdict(summary, truth, level, words):
    got_level, line = verdict(parameters(summary, ROBOT, truth), summary, [])
    assert got_level == level and words in line, line


def test_a_result_that_is_not_trustworthy_gets_no_snippet():
    s = _summary(status="degraded", status_reasons=["scale factors far outside their prior"])
    page = card_html("batch", parameters(s, ROBOT, None), s, "GPS", [])
    assert "<pre id='snippet'>" not in page and "not one to drive on" in page
    good = card_html("batch", parameters(_summary(), ROBOT, None), _summary(), "GPS", [])
    assert "<pre id='snippet'>[wheels]\nticks_per_meter_left = 2060.0" in good


def test_fingerprint_changes_with_any_byte(tmp_path):
    (tmp_path / "a.csv").write_text("t\n1\n")
    f1 = fingerprint(tmp_path)
    (tmp_path / "a.csv").write_text("t\n2\n")
    assert fingerprint(tmp_path) != f1 and len(f1) == 16 and fingerprint(None) is None
