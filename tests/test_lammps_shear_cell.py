"""The vaned shear cell (seed 000 §3.3) on LAMMPS from the same case file as LIGGGHTS and YADE:
walls as fix wall/gran/region regions (vanes the STL's boxes, circles for the STL's polygons),
the lower piston under the force servo (its z a marker atom moved by fix move), the upper piston
and sidewall turned by ``region … rotate``; stages, frames and wall series as on the other engines.
Engine test on cases/shear_cell_smoke.yaml (228 grains, 57 631 steps), plus engine-free checks of
the deck and of the geometry difference against the STL."""
from __future__ import annotations

import json
import math
from pathlib import Path

import h5py
import numpy as np
import pytest

from orchestrator.case import load_case
from orchestrator.derive import derive
from shear_cell_protocol import check_smoke_protocol

CASES = Path(__file__).resolve().parents[1] / "cases"
SMOKE = CASES / "shear_cell_smoke.yaml"


# ------------------------------------------------------------------------------------------------
# engine-free: the deck and the geometry
# ------------------------------------------------------------------------------------------------
def _render(tmp_path, case_file):
    from engines import get_engine
    from orchestrator.runner import prepare
    case = load_case(case_file)
    params, subs = prepare(case, "lammps", tmp_path)
    deck = get_engine("lammps").render(case, params, tmp_path)
    return case, params, deck.read_text(), {s.feature: s.mechanism for s in subs}


def test_seed_law_deck_terms(tmp_path):
    """The small case asks for the seed's full law: dmt adhesion, viscoelastic damping, the seed's
    linear tangential spring, rolling and twisting sds between grains; walls Hertz + damping only."""
    from engines.lammps.numbers import seed_gamma_n
    case, params, deck, subs = _render(tmp_path, CASES / "shear_cell_small.yaml")
    assert subs == {"seed000_damping": "viscoelastic_median_pair", "mesh_walls": "region_walls",
                    "rolling_friction_load": "sds_constant", "torsion_friction": "sds_median_pair"}
    pair = next(line for line in deck.splitlines() if line.startswith("pair_coeff"))
    for term in ("dmt", "damping viscoelastic", "tangential linear_history", "rolling sds", "twisting sds"):
        assert term in pair, term
    walls = [line for line in deck.splitlines() if "wall/gran/region" in line and line.startswith("fix")]
    # 2 x (face, plate, 6 vanes) + sidewall, defined again in every segment of the deck
    segments = sum(line.startswith(("read_data", "read_restart")) for line in deck.splitlines())
    assert len({w.split()[1] for w in walls}) == 17 and len(walls) == 17 * segments
    for w in walls:
        assert "hertz/material" in w and "tangential linear_nohistory 0.0 0.0" in w
        assert "dmt" not in w and "rolling" not in w and "twisting" not in w
    # DMT pull-off of the median pair = the case's F_adh; the median pair's damping = the seed's gamma_n
    f = pair.split()
    E, eta, nu, gamma = (float(x) for x in f[4:8])
    c = params["scene"]["contact"]
    assert 4 * math.pi * gamma * c["r_eff_mean"] == pytest.approx(c["adhesion_force"], rel=1e-12)
    x50 = case.scene.psd.median
    m50 = params["material"]["rho"] * math.pi / 6 * x50 ** 3
    E_eff = E / (2 * (1 - nu ** 2))
    assert eta * (m50 / 2) * math.sqrt(x50 / 4) == pytest.approx(seed_gamma_n(E_eff, m50 / 2), rel=1e-12)


def test_geometry_difference_from_the_stl():
    """The vanes are the STL's boxes (same volume and swept annulus); plates, flanges and sidewall are
    circles where the STL has n-gons: the STL encloses 1 - n/(2 pi) sin(2 pi/n) less (0.13 % at n = 72)."""
    from engines.lammps.numbers import polygon_area_deficit, shear_cell_geometry_difference
    from orchestrator.scenes.shear_cell import build_meshes
    case = load_case(CASES / "shear_cell_small.yaml")
    params = derive(case)
    d = shear_cell_geometry_difference(case, params, build_meshes(case, params))
    assert d["vane_volume"] == pytest.approx(1.0, abs=1e-9)
    assert d["vane_swept_volume"] == pytest.approx(1.0, abs=1e-9)
    for k in ("sidewall_volume", "plate_volume", "pocket_area"):
        assert d[k] == pytest.approx(1 - polygon_area_deficit(d["segments"]), rel=1e-9), k
    assert 1 - d["pocket_area"] < 2e-3


# ------------------------------------------------------------------------------------------------
# the smoke case on LAMMPS
# ------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def smoke(runs_root, engines_installed):
    """The smoke case on LAMMPS in the session's runs directory: the three-engine crossval of
    tests/compare reuses it."""
    from orchestrator.runner import run_case
    case = load_case(SMOKE)
    out = run_case(case, "lammps", runs_root=runs_root, progress=False)
    return case, out


@pytest.mark.engine
def test_smoke_protocol_on_lammps(smoke):
    case, out = smoke
    r = check_smoke_protocol(case, out)
    sc, lp, shear = r["params"]["scene"], r["lp"], r["shear"]
    # servo: measured -0.6 % at the end of compression (checked above within 2 %), and held during
    # the rotation (mean within 5 %)
    target = sc["servo"]["target_force"]
    assert abs(np.mean(-lp["force"][shear, 2]) / target - 1) < 0.05


@pytest.mark.engine
def test_smoke_upper_piston_turned_by_the_commanded_angle(smoke):
    case, out = smoke
    params = json.loads((out.run_dir / "params.json").read_text())
    end = json.loads((out.run_dir / "rotation_final.json").read_text())
    assert end["step"] == params["scene"]["steps"]
    assert end["angle"] == pytest.approx(case.scene.final_angle, abs=params["scene"]["omega"] * params["dt"])
    # the wall series' last angle is the same and the lower piston's final height the marker's
    with h5py.File(out.run_dir / "frames.h5") as h:
        assert h["walls/rotating/angle"][-1] <= end["angle"] + 1e-12
        assert h["walls/lower_piston/position"][-1, 2] == pytest.approx(end["z_lower"], rel=0.01)


@pytest.mark.engine
@pytest.mark.slow   # a second LAMMPS smoke run, killed and resumed (~2 min): out of the 15-minute default suite
def test_smoke_killed_run_resumes_from_its_restart_file(smoke, tmp_path):
    """A run killed (SIGKILL of the orchestrator and LAMMPS) after its second restart file resumes
    from it: the servo's state is the marker atom's z in the restart file. Every frame once at
    the same steps, the wall series at the same steps, every frame's positions equal to the uninterrupted
    run's (1e-9 r_min: the deck runs in segments, docs/engines.md, Resume)."""
    import os
    import signal
    import subprocess
    import sys
    import time
    from orchestrator.frames import Frames
    case, ref_out = smoke
    runs = tmp_path / "runs"
    cmd = [sys.executable, "-m", "orchestrator", "run", str(SMOKE), "--engine", "lammps", "--runs", str(runs),
           "--quiet", "--no-report"]
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t0 = time.time()
    while time.time() - t0 < 600:
        found = list(runs.glob("shear_cell_smoke/lammps-*/restart/state.*.restart"))
        if len(found) >= 2:
            break
        assert proc.poll() is None, "the run ended before it could be killed"
        time.sleep(0.2)
    else:
        raise AssertionError("no second restart file")
    time.sleep(1.0)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=60)
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=3600)
    assert out.returncode == 0, out.stderr[-3000:]
    run_dir = found[0].parents[1]
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == "complete" and summary["resumed_from"], summary.get("resumed_from")
    s_resume = int(summary["resumed_from"]["step"])
    ref, got = Frames(ref_out.run_dir), Frames(run_dir)
    assert list(got.step) == list(ref.step)
    for name in ref.wall_names:
        assert np.array_equal(got.wall(name)["time"], ref.wall(name)["time"]), name
    before = np.asarray(got.step) <= s_resume
    assert before.any()
    np.testing.assert_array_equal(got.position[before], ref.position[before])
    after = ~before
    r_min = float(ref.radius.min())
    dev = float(np.abs(got.position[after] - ref.position[after]).max()) / r_min if after.any() else 0.0
    print(f"resumed from step {s_resume}: largest position difference after it {dev:.3g} r_min")
    # the floor (issue #16): equal to the uninterrupted run to 1e-9 r_min. Before the deck ran in
    # segments: 5.21 r_min by the end from step 11 560 (a resumed LAMMPS run sorts its atoms and
    # rebuilds its neighbour lists at set-up, which an uninterrupted one did not do at that step)
    assert dev <= 1e-9, f"LAMMPS shear-cell resume not exact: {dev:.3g} r_min after step {s_resume}"
