"""Shared runs for the compare tests: the smoke shear cell on both engines (one crossval, reused by
every test) and a synthetic CT series rendered from the LIGGGHTS run (synth -> segment -> track)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
SMOKE = REPO / "cases" / "shear_cell_smoke.yaml"
VOXEL = 3e-6          # 3 um voxels: the smoke case's 25-50 um grains are 8-17 voxels across


@pytest.fixture(scope="session")
def crossval_smoke(runs_root, engines_installed, tmp_path_factory):
    from orchestrator.case import load_case
    from orchestrator.compare import crossval
    out = tmp_path_factory.mktemp("crossval")
    # the smoke case as tests/test_shear_cell.py runs it (monitors on: both engines complete), in the
    # same session runs directory, so on one xdist worker each engine's run is made once for both
    case = load_case(SMOKE)
    # the two Debian engines (the smoke case names none, so it would run LAMMPS too: its shear cell
    # is tested in tests/test_lammps_shear_cell.py, and a third run would add minutes to CI)
    return crossval(case, runs_root=runs_root, out_dir=out, engines=["liggghts", "yade"])


@pytest.fixture(scope="session")
def liggghts_run(crossval_smoke):
    return crossval_smoke.runs["liggghts"].run_dir


@pytest.fixture(scope="session")
def ct_frames(liggghts_run, tmp_path_factory):
    """Scans of the compressed state and the four shear angles, segmented and tracked."""
    from orchestrator.ct import segment, synth, track
    from orchestrator.ct.export import write_ct_frames
    from orchestrator.frames import Frames
    fr = Frames(liggghts_run)
    idx = [k for k in range(fr.n_frames) if fr.stage[k] >= 2]           # compressed + shear frames
    scans, _ = synth.scans_from_frames(fr, VOXEL, frame_indices=idx, progress=False, noise=0.03, psf_sigma=0.7,
                                       seed=5)
    tables = [segment.segment(s).grains for s in scans]
    links = track.track_sequence(tables, "displacement")
    controls = {k: [s.controls[k] for s in scans] for k in scans[0].controls}
    out = tmp_path_factory.mktemp("ct") / "ct_frames.h5"
    write_ct_frames(out, tables, links, times=[s.time for s in scans], controls=controls, voxel_size=VOXEL)
    return out
