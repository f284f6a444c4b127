"""``benchmarks/triaxial_report.py``'s pace of a run still going (``pace_against_estimate``): an
attempt stopped before its first checkpoint made no steps; its CPU time counts, its zero pace
does not (it divided by zero on the YADE clump run of sessions 37-40)."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from bench_util import load_benchmark

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def report():
    return load_benchmark("triaxial_report")


def _run(tmp_path: Path, attempts: list[dict]) -> Path:
    run = tmp_path / "triaxial_smoke" / "yade-000000000000"
    run.mkdir(parents=True)
    shutil.copy(REPO / "cases" / "triaxial_smoke.yaml", run / "case.yaml")
    (run / "attempts.json").write_text(json.dumps(attempts))
    return run


def test_an_attempt_that_made_no_steps_counts_in_cpu_time_not_in_pace(report, tmp_path):
    run = _run(tmp_path, [{"first_step": 0, "last_step": 10_000, "cpu_s": 100.0},
                          {"first_step": 10_000, "last_step": 10_000, "cpu_s": 50.0},
                          {"first_step": 10_000, "last_step": 16_000, "cpu_s": 200.0}])
    out = report.pace_against_estimate(run, "yade")
    assert out["last_step"] == 16_000 and out["cpu_h_so_far"] == round(350 / 3600, 2)
    assert out["pace_steps_per_cpu_s"] == [30.0, 30.0]      # the third attempt's: 6 000 steps in 200 s
    left = max(out["steps_expected"] - 16_000, 0)
    assert out["projected_h"][0] == round((350 + left / 30.0) / 3600, 1)


def test_a_run_whose_resumes_made_no_steps_keeps_the_first_attempts_pace(report, tmp_path):
    run = _run(tmp_path, [{"first_step": 0, "last_step": 191_520, "cpu_s": 5918.68},
                          {"first_step": 192_000, "last_step": 192_000, "cpu_s": 170.37}])
    out = report.pace_against_estimate(run, "yade")
    assert out["pace_steps_per_cpu_s"][1] == round(191_520 / 5918.68, 1)
    assert report.pace_against_estimate(_run(tmp_path / "b", [{"first_step": 5, "last_step": 5, "cpu_s": 9.0}]),
                                        "yade") is None


def test_a_resumed_runs_repeated_chunk_counts_once(report):
    log = "\n".join(["ISO chunk 1: sigma1/p = 1.2 sigma3/p = 1.0", "ISO creep: chunk-mean volume change n/a",
                     "ISO chunk 2: sigma1/p = 1.01 sigma3/p = 1.0", "ISO creep: chunk-mean volume change -0.02",
                     "RESUMED at iter 32000, stage 1",
                     "ISO chunk 2: sigma1/p = 1.01 sigma3/p = 1.0", "ISO creep: chunk-mean volume change -0.02",
                     "ISO chunk 3: sigma1/p = 1.0 sigma3/p = 1.0", "ISO creep: chunk-mean volume change -0.011"])
    chunks, creep = report._iso_chunks(log)
    assert [c[0] for c in chunks] == [1, 2, 3] and creep == [None, -0.02, -0.011]
