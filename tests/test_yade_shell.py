"""YADE's shell-pressure lateral boundary (``yade.membrane: shell_pressure``,
engines/yade_runtime/shell.py) is the LIGGGHTS deck's: on the smoke case (same packing, same
stage-1 drag and servo) the two engines' stage 1 agrees frame by frame until the drag goes off,
both converge, and σ3 equals p by construction. Real runs of both engines (~6 min on one core)."""
from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from orchestrator.case import load_case
from orchestrator.runner import run_case

pytestmark = [pytest.mark.engine, pytest.mark.slow]

CASE = Path(__file__).resolve().parents[1] / "cases" / "triaxial_smoke_shell.yaml"


def _max_speed(run_dir: Path):
    with h5py.File(run_dir / "frames.h5", "r") as h:
        return h["frames/step"][:], np.linalg.norm(h["frames/velocity"][:], axis=2).max(axis=1)


@pytest.mark.usefixtures("engines_installed")
def test_yade_shell_pressure_is_the_liggghts_boundary(tmp_path):
    case = load_case(CASE)
    out = {eng: run_case(case, eng, runs_root=tmp_path, progress=False) for eng in ("yade", "liggghts")}
    for eng, o in out.items():
        assert o.status == "complete", (eng, o.status)
        iso = o.summary["scene"]["isotropic_end"]
        assert iso["converged"] and abs(iso["sigma3_error"]) < 1e-6, (eng, iso)
    assert any(s["feature"] == "membrane" and s["mechanism"] == "shell_pressure"
               for s in out["yade"].summary["substitutions"])
    (sy, vy), (sl, vl) = _max_speed(out["yade"].run_dir), _max_speed(out["liggghts"].run_dir)
    # frames 1..8 (the first 15 000 steps of stage 1, with the drag; YADE stamps a frame one step
    # after LIGGGHTS): the fastest grain moves at the same speed on both engines (measured: within
    # 1 %; later frames part chaotically, 0.42 vs 0.53 m/s at frame 11)
    n = 9
    assert np.all(np.abs(sy[1:n] - sl[1:n]) <= 1)
    np.testing.assert_allclose(vy[1:n], vl[1:n], rtol=0.02)
