"""One run sent whole to a Dask cluster (engine_options.scheduler), on a real LocalCluster."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

from orchestrator.case import load_case
from orchestrator.frames import Frames
from orchestrator.runner import run_case

CASE = Path(__file__).resolve().parents[1] / "cases" / "verification" / "chung_ooi_1_sphere_sphere_glass.yaml"


def test_scheduler_field_is_validated():
    case = load_case(CASE, overrides={"engine_options": {"scheduler": "tcp://127.0.0.1:8786"}})
    assert case.engine_options.scheduler == "tcp://127.0.0.1:8786"


@pytest.mark.engine
def test_a_run_goes_to_a_dask_worker_and_lands_in_the_shared_runs_dir(tmp_path):
    from distributed import LocalCluster
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        case = load_case(CASE, overrides={"engine_options": {"scheduler": cluster.scheduler_address}})
        out = run_case(case, "liggghts", runs_root=tmp_path, analyze=False)
    assert out.status == "complete"
    assert out.summary["ran_on"]["worker_pid"] != os.getpid()          # ran in the worker process
    assert out.run_dir.parent.parent == tmp_path.resolve()
    fr = Frames(out.run_dir / "frames.h5")
    assert fr.n_frames > 2 and fr.n_particles == 2
    # the same case run here, without the scheduler, is the same run (same hash: the scheduler is
    # how a run is launched, not what it simulates) and is reused
    local = run_case(load_case(CASE), "liggghts", runs_root=tmp_path, analyze=False)
    assert local.reused and local.run_dir.resolve() == out.run_dir
