"""The HTML reports open in a real headless Chromium: screenshot, no console errors, no network."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from orchestrator.compare.browser import check_page, find_chromium

pytestmark = pytest.mark.engine
SCHEDULE_MINUTES = 4


@pytest.fixture(scope="module")
def chromium():
    exe = find_chromium()
    if exe is None:
        pytest.fail("chromium is not installed; run `bash .ci/setup` (Debian packages chromium, chromium-driver)")
    return exe


def _png_ok(path: Path):
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000


def test_checker_catches_a_broken_page(chromium, tmp_path):
    bad = tmp_path / "bad.html"
    bad.write_text("<!DOCTYPE html><html><head><title>t</title></head><body><img src='missing.png'>"
                   "<script>console.error('boom'); nope();</script></body></html>")
    r = check_page(bad, tmp_path / "bad.png")
    assert not r.ok
    assert any("boom" in m for m in r.console_errors) and r.exceptions and r.broken_images == 1


def test_run_report_opens_offline(chromium, liggghts_run, tmp_path):
    out = tmp_path / "run.html"
    cp = subprocess.run([sys.executable, "-m", "orchestrator", "report", str(liggghts_run), "--out", str(out)],
                        capture_output=True, text=True, timeout=300)
    assert cp.returncode == 0, cp.stderr
    html = out.read_text()
    order = ["<h2>Results</h2>", "<h2>Stability and protocol checks</h2>", "<h2>Substitutions</h2>", "<h2>Run</h2>",
             "<h2>Run time</h2>", "<h2>Resolved case</h2>"]
    at = [html.find(sec) for sec in order]
    assert all(a >= 0 for a in at) and at == sorted(at), dict(zip(order, at))   # results lead, bookkeeping last
    import re
    cells = re.findall(r"<td[^>]*>(.*?)</td>", html)
    assert not [c for c in cells if c.lstrip().startswith("{")], "a table cell prints a raw mapping"
    # the shear cell's key figures: mu_macro, and the band's width or the statement that none was
    # fitted (the smoke case is too small for a band every time)
    assert "μ_macro" in html and ("band width" in html or "no steady band fitted" in html)
    assert "seed000_damping" in html
    r = check_page(out, tmp_path / "run.png")
    assert r.ok, r.problems()
    assert r.requests == []                          # nothing fetched: no CDN, no network
    import json
    asum = json.loads((liggghts_run / "analysis" / "analysis_summary.json").read_text())   # the case's analyses
    n_png = sum(1 for e in asum.values() if e["status"] == "ok" for f in e["files"] if f.endswith(".png"))
    assert n_png >= 3
    assert r.images == 1 + n_png and r.broken_images == 0 and r.title.startswith("Run report")   # + run-time plot
    _png_ok(tmp_path / "run.png")


def test_compare_report_opens_offline(chromium, crossval_smoke, tmp_path):
    page = crossval_smoke.comparison.files["html"]
    r = check_page(page, tmp_path / "cmp.png")
    assert r.ok, r.problems()
    # 9 measures x (overlay + A + B), 'macro' overlay only, the grain plot
    assert r.requests == [] and r.images == 9 * 3 + 1 + 1 and r.broken_images == 0
    _png_ok(tmp_path / "cmp.png")


def test_compare_cli(liggghts_run, tmp_path):
    out = tmp_path / "cli"
    cp = subprocess.run([sys.executable, "-m", "orchestrator", "compare", str(liggghts_run), str(liggghts_run),
                         "--out", str(out), "--measure", "profiles", "--measure", "rdf", "--states", "all"],
                        capture_output=True, text=True, timeout=300)
    assert cp.returncode == 0, cp.stderr
    import pandas as pd
    t = pd.read_csv(out / "comparison.csv")
    assert set(t.measure) == {"profiles", "rdf"} and (t.distance.dropna() == 0).all()
    assert len(t[t.measure == "rdf"]) == 5          # all five matched states
