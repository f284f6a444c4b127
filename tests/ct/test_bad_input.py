"""Bad input to ``orchestrator ct ...``: one message naming the option or file and the fix, exit 2, no
traceback, and for what can be checked up front nothing written (engine-free, tiny inputs)."""
import json
from pathlib import Path

import numpy as np
import pytest
from cli_util import main_here

from orchestrator.ct.io import Scan, ScanError, read_scan, write_scan
from orchestrator.frames import write_frames

CASES = Path(__file__).resolve().parents[2] / "cases"


def _refused(r, *words):
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr and "internal error" not in r.stderr, r.stderr
    for w in words:
        assert w in r.stderr, (w, r.stderr)


@pytest.fixture
def frames(tmp_path):
    """3 frames of 2 particles, 10 um apart."""
    pos = np.array([[[0, 0, 0], [1e-5, 0, 0]]] * 3, float)
    return write_frames(tmp_path / "frames.h5", [0, 1], [4e-6, 4e-6], [0.0, 1.0, 2.0], pos)


@pytest.fixture
def scan(tmp_path):
    p = tmp_path / "a.tif"
    write_scan(Scan(np.zeros((5, 5, 5), np.uint16), 1e-5), p)
    return p


def test_synth_frame_out_of_range(tmp_path, frames):
    out = tmp_path / "s"
    r = main_here("ct", "synth", "--frames", frames, "--frame", "99", "--voxel-size", "2 um", "--out", out)
    _refused(r, "--frame 99", "3 frames", "0..2", "-3..-1")
    assert not out.exists()


def test_synth_too_fine_voxel_prints_plain_shape(tmp_path, frames):
    r = main_here("ct", "synth", "--frames", frames, "--voxel-size", "1 nm", "--out", tmp_path / "s")
    _refused(r, "--voxel-size", "shape (")
    assert "np.int64" not in r.stderr
    assert not (tmp_path / "s").exists()


def test_raw_dtype_unknown(tmp_path):
    raw = tmp_path / "g.raw"
    raw.write_bytes(bytes(1000))
    r = main_here("ct", "segment", raw, "--out", tmp_path / "s", "--voxel-size", "2 um", "--shape", "10", "10", "10",
                  "--dtype", "notatype")
    _refused(r, "--dtype", "'notatype'", "uint16")
    assert not (tmp_path / "s").exists()
    with pytest.raises(ScanError, match="g.raw: dtype 'notatype'.*uint16"):
        read_scan(raw, voxel_size=2e-6, shape=(10, 10, 10), dtype="notatype")


@pytest.mark.parametrize("text, what", [("[]", "empty"), ("xx", "not JSON"), ('{"a": 1}', "not a list of scans")])
def test_track_bad_segment_json(tmp_path, text, what):
    (tmp_path / "seg").mkdir()
    (tmp_path / "seg" / "segment.json").write_text(text)
    r = main_here("ct", "track", tmp_path / "seg", "--out", tmp_path / "t.h5")
    _refused(r, str(tmp_path / "seg" / "segment.json"), what, "orchestrator ct segment")
    assert not (tmp_path / "t.h5").exists()


@pytest.mark.parametrize("cmd, option, value, what", [
    ("synth", "--voxel-size", "2 kg", "[mass], not a length"),
    ("synth", "--voxel-size", "abc", "cannot read 'abc'"),
    ("synth", "--voxel-size", "-2 um", "not a positive length"),
    ("segment", "--voxel-size", "2 kg", "[mass], not a length"),
    ("segment", "--h", "2 kg", "[mass], not a length"),
    ("shapes", "--h", "0 um", "not a positive length"),
    ("track", "--max-disp", "5 kg", "[mass], not a length"),
])
def test_length_option_named(tmp_path, scan, cmd, option, value, what):
    out = tmp_path / "out"
    if cmd == "synth":
        args = ["--demo", "shear", "--voxel-size", "2 um", "--out", out]
    elif cmd == "segment":
        args = [scan, "--out", out]
    elif cmd == "shapes":
        args = [scan, "--out", out.with_suffix(".yaml")]
    else:
        (tmp_path / "seg").mkdir()
        (tmp_path / "seg" / "segment.json").write_text(json.dumps([{"scan": str(scan), "voxel_size": 1e-5}]))
        args = [tmp_path / "seg", "--out", out]
    r = main_here("ct", cmd, *args, option, value)
    _refused(r, f"{option}: ", f"'{value}'", what, "'30 um'")
    assert not out.exists() and not out.with_suffix(".yaml").exists()


@pytest.mark.parametrize("cmd, option, value, rule", [
    ("synth", "--psf", "-1", ">= 0"),
    ("synth", "--noise", "-3", ">= 0"),
    ("synth", "--hollow", "5", "[0, 1]"),
    ("segment", "--sigma", "-1", ">= 0"),
    ("segment", "--degree", "-3", "0..30"),
    ("segment", "--shape", "0", ">= 1"),
    ("track", "--rings", "0", ">= 1"),
])
def test_range_option_named(tmp_path, scan, cmd, option, value, rule):
    out = tmp_path / "out"
    args = {"synth": ["--demo", "shear", "--voxel-size", "2 um"], "segment": [scan, "--no-shape"],
            "track": [tmp_path]}[cmd]
    extra = [value, "10", "10"] if option == "--shape" else [value]
    r = main_here("ct", cmd, *args, "--out", out, option, *extra)
    _refused(r, f"argument {option}: '{value}' is out of range", rule)
    assert not out.exists()


def test_run_case_without_ct_section(tmp_path):
    case = CASES / "plane_shear_smoke.yaml"
    r = main_here("ct", "run", case, "--runs", tmp_path / "runs")
    _refused(r, str(case), "no ct: section", "docs/ct.md")
    assert not (tmp_path / "runs").exists()
