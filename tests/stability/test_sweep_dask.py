"""A sweep on a real dask.distributed.LocalCluster: hashed run ids, one failing run does not lose
the others, a re-run reuses the finished runs and retries only what is missing."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from orchestrator.stability.sweep import sweep

CASE = Path(__file__).resolve().parents[2] / "cases" / "stability" / "mu1.yaml"


@pytest.mark.engine
def test_sweep_on_local_cluster(tmp_path, engines_installed):
    from distributed import Client, LocalCluster
    sets = {"contact.friction": [0.3, 0.6, 0.9],
            # the third run cannot finish in 0.01 s: the engine is killed, the run fails (the timeout is
            # not part of the run hash, so it gets its own friction to have its own run directory)
            "engine_options.timeout": ["300 s", "300 s", "0.01 s"]}
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        df = sweep(CASE, sets, engines=["liggghts"], runs_root=tmp_path, scheduler=client)
        assert list(df["status"]) == ["complete", "complete", "failed"], df[["status", "error"]].to_string()
        assert df["run_id"].nunique() == 3 and all(r.startswith("liggghts-") for r in df["run_id"])
        assert df.loc[:1, "mu_macro"].notna().all()
        assert not df["reused"].any()
        files = list((tmp_path / "stability_mu1").glob("sweep-*.json"))
        assert len(files) == 1
        data = json.loads(files[0].read_text())
        assert [r["result"]["status"] for r in data["runs"]] == ["complete", "complete", "failed"]
        assert "wall-clock limit" in data["runs"][2]["result"]["error"]
        again = sweep(CASE, sets, engines=["liggghts"], runs_root=tmp_path, scheduler=client)
    assert list(again["reused"]) == [True, True, False]
    assert list(again["status"]) == ["complete", "complete", "failed"]
    assert again.loc[0, "mu_macro"] == pytest.approx(df.loc[0, "mu_macro"])
