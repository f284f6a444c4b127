"""End to end through the CLI functions: synth -> segment -> track -> frames.h5 (source ct)."""
import numpy as np
import pytest
import pandas as pd
from scipy.spatial import cKDTree

from orchestrator.ct.cli import main
from orchestrator.ct.export import assign_ids
from orchestrator.ct.track import Links
from orchestrator.frames import Frames


def test_assign_ids_lost_and_new():
    L = Links(np.array([1, -1, 0]), np.array([2, 0, -1]), np.array([0.1, np.nan, 0.2]))
    rows = assign_ids([3, 3], [L])
    # ids 0,1,2 in scan 0; id 0 -> row 1, id 1 lost, id 2 -> row 0, new grain row 2 -> id 3
    assert rows.tolist() == [[0, 1, 2, -1], [1, -1, 0, 2]]


def test_cli_pipeline(tmp_path):
    assert main(["ct", "synth", "--demo", "shear", "--voxel-size", "10 um", "--out", str(tmp_path / "s"),
                 "--hollow", "0.1"]) == 0
    scans = sorted((tmp_path / "s").glob("scan_*.tif"))
    assert len(scans) == 2
    assert main(["ct", "segment", *map(str, scans), "--out", str(tmp_path / "seg")]) == 0
    g = pd.read_csv(tmp_path / "seg" / "scan_000_grains.csv")
    assert {"label", "x", "y", "z", "volume", "radius", "flag", "R0", "R15"} <= set(g.columns)
    assert main(["ct", "track", str(tmp_path / "seg"), "--out", str(tmp_path / "frames.h5"),
                 "--method", "rotation"]) == 0
    fr = Frames(tmp_path / "frames.h5")
    truth = Frames(tmp_path / "s" / "truth.h5")
    assert fr.meta["source"] == "ct" and abs(fr.meta["voxel_size"] - 1e-5) < 1e-12
    assert fr.shape.shape == (fr.n_particles, 16)
    pos = fr.position
    # the same id is the same true grain in both scans
    both = np.all(np.isfinite(pos).reshape(2, fr.n_particles, -1), axis=(0, 2))
    ka = cKDTree(truth.position[0]).query(pos[0, both])[1]
    kb = cKDTree(truth.position[1]).query(pos[1, both])[1]
    assert both.mean() > 0.98 and (ka == kb).mean() > 0.99
    assert fr.contact_frames == [0, 1]
    c = fr.contact_arrays(0)
    assert set(np.unique(np.concatenate([c["i"], c["j"]]))) <= set(fr.ids.tolist())


def test_cli_clear_error_on_inconsistent_series(tmp_path, capsys):
    from orchestrator.ct.io import Scan, write_scan
    write_scan(Scan(np.zeros((5, 5, 5), np.uint16), 1e-5), tmp_path / "a.tif")
    write_scan(Scan(np.zeros((5, 5, 6), np.uint16), 1e-5), tmp_path / "b.tif")
    assert main(["ct", "segment", str(tmp_path / "a.tif"), str(tmp_path / "b.tif"), "--out", str(tmp_path / "o")]) == 2
    assert "b.tif: shape (5, 5, 6) differs" in capsys.readouterr().err
