"""A sweep on the default local executor with 2 worker processes: the workers start and warm up
while the sweep plans, runs are handed over as they are planned, and the results are the same
runs (same hashed directories, same observables) a serial sweep gets."""
from __future__ import annotations

from pathlib import Path

import pytest

from orchestrator.stability.executor import LocalExecutor, warm_worker
from orchestrator.stability.sweep import sweep

CASE = Path(__file__).resolve().parents[2] / "cases" / "stability" / "mu1.yaml"


@pytest.mark.engine
def test_sweep_two_local_workers(tmp_path, engines_installed):
    sets = {"contact.friction": [0.3, 0.6]}
    with LocalExecutor(2) as ex:
        df = sweep(CASE, sets, engines=["liggghts"], runs_root=tmp_path, executor=ex)
    assert list(df["status"]) == ["complete", "complete"]
    assert not df["reused"].any() and df["run_id"].nunique() == 2
    assert df["mu_macro"].notna().all()
    # a serial re-run finds the same run directories finished and reuses them
    again = sweep(CASE, sets, engines=["liggghts"], runs_root=tmp_path, workers=1)
    assert list(again["reused"]) == [True, True]
    assert list(again["run_id"]) == list(df["run_id"])
    assert list(again["mu_macro"]) == pytest.approx(list(df["mu_macro"]))


def test_warm_worker_never_raises():
    warm_worker("/nonexistent/case.yaml", ("no_such_engine",))      # a bad warm-up is left to the runs
