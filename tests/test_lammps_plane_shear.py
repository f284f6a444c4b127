"""Plane shear (seed 000 §3.2 calibration set-up) on LAMMPS from the same case file as the other
engines: rough walls of frozen grains, the top wall under the force servo (fix move variable with
an equal-style velocity), the stages, frames and wall series as on LIGGGHTS, and μ_macro within
the statistical error of LIGGGHTS' on the 100-grain smoke case; a killed run resumes exactly."""
from __future__ import annotations

import json
import math
import random
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from orchestrator.case import load_case
from orchestrator.frames import Frames
from orchestrator.runner import run_case
from orchestrator.scenes.plane_shear import steady_mu
from resume_util import engine_step, kill_run, rerun_resumes, wait_until

CASES = Path(__file__).resolve().parents[1] / "cases"

pytestmark = pytest.mark.engine


@pytest.fixture(scope="module")
def runs(tmp_path_factory, engines_installed):
    case = load_case(CASES / "plane_shear_smoke.yaml")
    root = tmp_path_factory.mktemp("ps")
    return case, {e: run_case(case, e, runs_root=root, progress=False) for e in ("lammps", "liggghts")}


def test_stages_frames_and_walls_as_on_liggghts(runs):
    case, out = runs
    lmp, lig = (Frames(out[e].run_dir / "frames.h5") for e in ("lammps", "liggghts"))
    params = json.loads((out["lammps"].run_dir / "params.json").read_text())
    sc = params["scene"]
    np.testing.assert_array_equal(lmp.step, sc["frame_steps"])
    np.testing.assert_array_equal(lmp.step, lig.step)
    np.testing.assert_array_equal(lmp.shear_strain, lig.shear_strain)
    assert not np.isnan(lmp.position).any()
    top = lmp.wall("top")
    assert len(top) == len(lig.wall("top")) > 50
    # the bottom wall grains never move; the top wall moves in x by v_shear x shear time
    bottom = slice(sc["ids_bottom"][0] - 1, sc["ids_bottom"][1])
    np.testing.assert_array_equal(lmp.position[-1, bottom], lmp.position[0, bottom])
    shear_time = (sc["stages"]["shear"][1] - sc["stages"]["shear"][0]) * params["dt"]
    topg = slice(sc["ids_top"][0] - 1, sc["ids_top"][1])
    # per grain, modulo the periodic width (the dump holds wrapped positions)
    frac = ((lmp.position[-1, topg, 0] - lmp.position[1, topg, 0] - sc["v_shear"] * shear_time) / sc["geometry"]["L"]) % 1
    assert np.minimum(frac, 1 - frac).max() < 1e-6


def test_servo_holds_the_normal_stress_and_mu_agrees_with_liggghts(runs, tmp_path):
    """The servo holds the normal stress, and the two engines, one law, give the same μ_macro within
    the packings' scatter. On 100 grains μ_macro scatters by ±0.06 from packing to packing, several
    times a run's own standard error (0.01-0.05), so one packing cannot test the engines' agreement:
    the seed-12345 packing gave 0.387 ± 0.015 against 0.291 ± 0.017 in the suite (27 Nov 2026), i.e.
    5.7 of its own standard errors apart, where four packings give differences of -0.04 to +0.18
    around a mean of +0.03. So μ_macro is compared over four packings, seed by seed: the mean
    difference within twice its standard error (the small shear cell's ladder does the same on five
    packings of 1 025 grains, docs/crossval.md)."""
    case, out = runs
    res = {}
    for e in ("lammps", "liggghts"):
        params = json.loads((out[e].run_dir / "params.json").read_text())
        res[e] = steady_mu(Frames(out[e].run_dir / "frames.h5"), params)
    # measured: LAMMPS -0.3 %, LIGGGHTS -5.8 % (the smoke case's servo floor is 10 %); the segmented
    # deck +1.5 %, LIGGGHTS -6.5 % (realizations of the old deck perturbed by a resume: -3.6 % to +1.6 %,
    # docs/lammps.md, Plane shear)
    assert abs(res["lammps"]["normal_stress_rel_error"]) < 0.02
    d = [res["lammps"]["mu"] - res["liggghts"]["mu"]]
    for seed in (1, 2, 3):
        mu = {}
        for e in ("lammps", "liggghts"):
            o = run_case(load_case(CASES / "plane_shear_smoke.yaml", overrides={"seed": seed}), e, runs_root=tmp_path,
                         progress=False, analyze=False)
            assert o.status == "complete", (e, seed)
            mu[e] = steady_mu(Frames(o.run_dir / "frames.h5"), json.loads((o.run_dir / "params.json").read_text()))["mu"]
        d.append(mu["lammps"] - mu["liggghts"])
    d = np.array(d)
    print(f"LAMMPS - LIGGGHTS mu_macro per packing: {np.round(d, 3)}")
    assert abs(d.mean()) < 2 * d.std(ddof=1) / math.sqrt(len(d)), d


def test_killed_run_resumes_exactly(runs, tmp_path):
    """A run killed (SIGKILL of the orchestrator and LAMMPS) at a random step between its first
    restart file and 90 % of the run, then run again, resumes from its last restart file and ends
    equal to the uninterrupted run: every frame once at the same steps, every frame's positions
    bit-identical, the wall series sampled at the same steps with equal rows. The deck runs in
    segments (each restart step ends one, the next starts with ``clear`` and ``read_restart``, in an
    uninterrupted run too; docs/engines.md, Resume). Before the segments: 11.7 r_min (periodic
    images included; 4.6 r_min by the minimum image) at the end and 129 of 217 wall rows different,
    killed at step 9116 and resumed from 7040. Measured 7 s (the killed and the resumed run; the
    module's fixture, 8 s, runs the reference and LIGGGHTS')."""
    case, out = runs
    ref_dir = out["lammps"].run_dir
    sc = json.loads((ref_dir / "params.json").read_text())["scene"]
    first = max(1, sc.get("restart_every", sc["steps"] // 10))
    kill_at = random.randint(first + 1, int(0.9 * sc["steps"]))
    print(f"killing at step {kill_at} or just after")
    root = tmp_path / "runs"
    cmd = [sys.executable, "-m", "orchestrator", "run", str(CASES / "plane_shear_smoke.yaml"), "--engine", "lammps",
           "--runs", str(root), "--quiet", "--no-report"]
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    run_dir = lambda: next(iter(root.glob("plane_shear_smoke/lammps-*")), None)     # noqa: E731
    wait_until(proc, lambda: run_dir() and list((run_dir() / "restart").glob("state.*.restart"))
               and (engine_step(run_dir(), "lammps") or 0) >= kill_at, 300, f"step {kill_at}")
    kill_run(proc, run_dir())
    summary = rerun_resumes(cmd, run_dir(), timeout=600)
    s_resume = int(summary["resumed_from"]["step"])
    assert first <= s_resume < sc["steps"]

    ref, got = Frames(ref_dir), Frames(run_dir())
    assert list(got.step) == list(ref.step) == list(sc["frame_steps"])
    r_min = float(ref.radius.min())
    dev = float(np.abs(got.position - ref.position).max()) / r_min
    print(f"resumed from step {s_resume}: {len(got.step)} frames, max |dx| = {dev:.3g} r_min")
    np.testing.assert_array_equal(got.position, ref.position)
    for name in ref.wall_names:
        a, b = ref.wall(name), got.wall(name)
        assert np.array_equal(b["time"], a["time"]), name            # continuous, nothing twice
        np.testing.assert_array_equal(np.asarray(b.to_numpy()), np.asarray(a.to_numpy()), err_msg=name)
