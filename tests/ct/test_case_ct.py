"""A case's ct: section: `orchestrator ct run CASE` segments and tracks its scan series into
runs/<case>/ct-<hash>/frames.h5, and a second call reuses it.

The commands run through the `orchestrator` console entry point (:func:`orchestrator.cli.main`, what
`python -m orchestrator` calls) in this process: a subprocess per command would re-import numpy,
scipy, pandas and the analysis (~3 s CPU each); `python -m orchestrator` itself is tests/test_cli.py's."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from orchestrator.case import CaseError, load_case
from orchestrator.cli import main as orchestrator_main
from orchestrator.frames import Frames

REPO = Path(__file__).resolve().parents[2]


def _orchestrator(argv, capsys):
    """Run ``orchestrator ARGV`` (the console entry point, in this process); returns (exit status,
    stdout, stderr) of the command."""
    capsys.readouterr()
    status = orchestrator_main([str(a) for a in argv])
    out = capsys.readouterr()
    return status, out.out, out.err


def test_ct_section_runs_and_matches_truth(tmp_path, capsys):
    scans = tmp_path / "scans"
    status, _, log = _orchestrator(["ct", "synth", "--demo", "shear", "--voxel-size", "2 um", "--out", scans], capsys)
    assert status == 0, log
    case = tmp_path / "with_ct.yaml"
    case.write_text(f"extends: {REPO / 'cases' / 'verification' / 'chung_ooi_2_sphere_plane_alumina.yaml'}\n"
                    "name: with_ct\n"
                    "ct:\n  scans: ['scans/scan_*.tif']\n  voxel_size: 2 um\n"
                    "  segment: {shape: false}\n  track: {method: displacement, max_disp: 10 um}\n")
    runs = tmp_path / "runs"
    cmd = ["ct", "run", case, "--runs", runs]
    status, stdout, log = _orchestrator(cmd, capsys)
    assert status == 0, log[-2000:]
    path = Path(stdout.strip().split("ct frames: ")[-1])
    fr = Frames(path)
    truth = Frames(scans / "truth.h5")
    assert fr.n_frames == 2 and fr.meta["source"] == "ct"
    # every true grain is found in the first scan, within a tenth of a voxel
    d, _ = cKDTree(fr.position[0][~np.isnan(fr.position[0]).any(1)]).query(truth.position[0])
    assert np.median(d) < 0.1 * 2e-6 and (d < 2e-6).mean() > 0.99
    # tracked grains moved as the truth did
    ok = ~np.isnan(fr.position).any(axis=(0, 2))
    assert ok.mean() > 0.98
    _, j = cKDTree(truth.position[0]).query(fr.position[0][ok])
    err = np.linalg.norm((fr.position[1][ok] - fr.position[0][ok]) - (truth.position[1][j] - truth.position[0][j]), axis=1)
    assert np.median(err) < 0.2 * 2e-6
    status, stdout, _ = _orchestrator(cmd, capsys)
    assert status == 0 and str(path) in stdout                             # reused


def test_ct_section_errors_name_the_field(tmp_path):
    case = tmp_path / "bad.yaml"
    case.write_text(f"extends: {REPO / 'cases' / 'verification' / 'chung_ooi_2_sphere_plane_alumina.yaml'}\n"
                    "ct: {scans: [], voxel_size: 2}\n")
    try:
        load_case(case)
    except CaseError as exc:
        msg = str(exc)
        assert "ct.scans" in msg and "at least one scan" in msg
        assert "ct.voxel_size" in msg and "has no unit" in msg
    else:
        raise AssertionError("bad ct: section accepted")
