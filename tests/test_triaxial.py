"""The membrane triaxial test (seed 001, issue 4) on both real engines, smoke case.

One run per engine (about 1.2 min LIGGGHTS, 5.5 min YADE on one free core of session 22's machine), plus two short unstable
runs for the monitors, and the triaxial notebook on the LIGGGHTS run; a YADE run on a second
packing (seed 2) is in the slow tier (``-m slow``). Checks the floors of
issue 4: confining pressure within 3 % of the target before axial loading, σ1/σ3 = 1 ± 0.05 after
isotropic compression, the final axial strain as asked, no grain escaping the lateral boundary,
volumetric strain measured two independent ways (boundary volume, convex hull of the grains)
within 0.02 of each other during shear, and a reported lateral-stress stray during shear. Also
checks the per-frame outputs (rotations, particle stress, contacts) and their sign conventions.
"""
from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from scipy.stats import poisson

from engines import get_engine
from notebook_util import execute_notebook, notebook_images, notebook_text
from orchestrator.case import load_case

REPO = Path(__file__).resolve().parents[1]
SMOKE = REPO / "cases" / "triaxial_smoke.yaml"
ENGINES = ["liggghts", "yade"]
#: expected minutes (tests/conftest.py schedule_groups: this file starts first)
SCHEDULE_MINUTES = {"yade": 9, "liggghts": 3}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    from orchestrator.runner import run_case
    root = tmp_path_factory.mktemp("triaxial_runs")
    return {"root": root, "run": lambda eng: run_case(load_case(SMOKE), eng, runs_root=root, progress=False)}


_CACHE: dict = {}


def outcome(runs, eng):
    if eng not in _CACHE:
        if shutil.which(eng) is None:
            pytest.fail(f"{eng} is not installed; run `bash .ci/setup`")
        _CACHE[eng] = runs["run"](eng)
    return _CACHE[eng]


def test_cases_validate_and_render(tmp_path):
    """All three cases validate; the seed case renders for both engines with a run-time estimate."""
    from orchestrator.runner import run_case
    for name in ("triaxial_smoke", "triaxial_small", "triaxial_seed"):
        case = load_case(REPO / "cases" / f"{name}.yaml")
        assert case.scene.kind == "triaxial"
    seed = load_case(REPO / "cases" / "triaxial_seed.yaml")
    for eng in ENGINES:
        if shutil.which(eng) is None:
            continue
        out = run_case(seed, eng, runs_root=tmp_path, dry_run=True, progress=False)
        assert out.status == "rendered"
        assert out.summary["estimated_engine_time_s"] > 0
        p = json.loads((out.run_dir / "params.json").read_text())["scene"]
        assert 14000 <= p["n"] <= 18000                      # ~16 000 grains (seed §2.1)
        assert abs(p["pressure"] - 300e3) < 1e-6 and abs(p["axial_strain"] - 0.2) < 1e-12


@pytest.mark.engine
@pytest.mark.parametrize("eng", ENGINES)
def test_isotropic_stage(runs, eng):
    out = outcome(runs, eng)
    iso = out.summary["scene"]["isotropic_end"]
    # measured lateral stress (boundary force on the grains / boundary area), chunk-averaged
    assert abs(iso["sigma3_error"]) <= 0.03, iso
    assert abs(iso["stress_ratio"] - 1) <= 0.05, iso


@pytest.mark.engine
@pytest.mark.parametrize("eng", ENGINES)
def test_axial_loading(runs, eng):
    out = outcome(runs, eng)
    case = load_case(SMOKE)
    sh = out.summary["scene"]["shear"]
    assert abs(sh["final_axial_strain"] - case.scene.axial_strain) <= 0.002 * case.scene.axial_strain, sh
    # the lateral stress stray during shear is reported (and stays within 10 % of the target)
    for key in ("sigma3_error_mean", "sigma3_error_rms", "sigma3_error_max_abs", "sigma3_hull_error_max_abs"):
        assert np.isfinite(sh[key])
    assert sh["sigma3_error_max_abs_smoothed"] <= 0.10, sh
    # the sample must be loaded: the peak stress ratio exceeds 1.3 at 5 % axial strain
    assert sh["peak_stress_ratio"] > 1.3, sh
    if eng == "liggghts":
        subs = {s["feature"]: s["mechanism"] for s in out.summary["substitutions"]}
        assert subs.get("membrane") == "shell_pressure"


@pytest.mark.engine
@pytest.mark.parametrize("eng", ENGINES)
def test_the_deck_says_where_the_run_ends(runs, eng):
    """Stage 1 goes on until it converges, so the run's length is known once the loading starts: the
    deck then prints the step it ends at (``RUN ENDS at step N``, engines.base.RUN_ENDS, the progress
    lines' goal from there on), which is the loading's first step plus ``shear_steps`` and the step
    the run ended at."""
    out = outcome(runs, eng)
    log = (out.run_dir / "engine.log").read_text(errors="replace")
    ends = {get_engine(eng).progress_end(line) for line in log.splitlines()} - {None}
    start = int(re.search(r"^SHEAR (?:start at iter|from step) (\d+)", log, flags=re.M).group(1))
    shear_steps = json.loads((out.run_dir / "params.json").read_text())["scene"]["shear_steps"]
    assert ends == {start + shear_steps}, (ends, start, shear_steps)
    assert out.summary["steps_run"] == start + shear_steps


@pytest.mark.engine
@pytest.mark.parametrize("eng", ENGINES)
def test_preparation_friction_then_contact_friction(runs, eng):
    """Stage 1 prepares the sample with ``isotropic.friction`` (0.1 in the smoke case, a denser
    sample); ``contact.friction`` (0.5) is restored for loading. Measured on the grain-grain
    contacts carrying more than the median normal force, by the sliding ones: a sliding contact
    sits exactly at the Coulomb limit |F_t| = μ|F_n| of the friction in force, on both engines
    (LIGGGHTS: tangential_model_history.h caps the spring force at μ|F_n|; YADE: Mindlin's Coulomb
    cap). Measured on the smoke case: at the end of stage 1, 4.1 % (LIGGGHTS, 15-21 % before the
    drag's ramp; 1.0 % on session 15's packing, 27 Nov 2026: 4 contacts) and 26 % (YADE) of them sit
    within 0.2 % of 0.1 and none at 0.5. The check pools every stage-1 frame (the preparation) and
    asks for many more contacts within 0.2 % of 0.1 than of 0.09 or 0.11, where a smooth distribution
    puts about as many (five times); at the end of
    loading 5.7 % and 6.3 % sit at 0.5. A quantile of |F_t|/|F_n| is no such test on LIGGGHTS: its sticking
    contacts add the tangential dashpot to the capped spring (q90 0.100-0.111 at the end of stage
    1, with the realisation), so only the loading quantile is checked, against the contact value."""
    case = load_case(SMOKE)
    mu_prep, mu = case.scene.isotropic.friction, case.contact.friction
    assert mu_prep is not None and mu_prep < mu
    out = outcome(runs, eng)
    at, q90 = {}, {}
    with h5py.File(out.run_dir / "frames.h5") as f:
        stage = f["frames/stage"][:]
        ids = f["particles/id"][:]
        for name, frames in (("prep", np.flatnonzero(stage == 1)), ("load", [len(stage) - 1])):
            ratio = []
            for k in frames:        # every stage-1 frame: the preparation; the last frame: the loading
                g = f["contacts"][str(int(k))]
                gg = np.isin(g["i"][:], ids) & np.isin(g["j"][:], ids)
                fn = np.linalg.norm(g["fn"][:][gg], axis=1)
                ft = np.linalg.norm(g["ft"][:][gg], axis=1)
                if not len(fn):         # the loose packing's first frame: no contact yet
                    continue
                strong = fn > np.median(fn)
                ratio.append(ft[strong] / fn[strong])
            ratio = np.concatenate(ratio)
            at[name] = {m: float(np.mean(np.abs(ratio / m - 1) < 2e-3))
                        for m in (mu_prep, mu, 0.9 * mu_prep, 1.1 * mu_prep)}
            q90[name] = float(np.quantile(ratio, 0.9))
    print(f"{eng}: fraction of strong contacts at the Coulomb limit {at}; q90 {q90}")
    # during stage 1 the sliding contacts pile up at μ_prep: many more sit within 0.2 % of it than
    # within 0.2 % of 0.9 or 1.1 μ_prep (a smooth distribution puts about as many at each)
    controls = max(at["prep"][0.9 * mu_prep], at["prep"][1.1 * mu_prep])
    assert at["prep"][mu_prep] >= 0.005 and at["prep"][mu_prep] >= 5 * controls and at["prep"][mu] == 0.0, at
    assert at["load"][mu] >= 0.02, at
    assert 0.6 * mu <= q90["load"] <= 1.1 * mu, q90


@pytest.mark.engine
@pytest.mark.slow
@pytest.mark.parametrize("eng", ENGINES)
def test_friction_restored_before_the_drag_ramp(tmp_path, eng):
    """``isotropic.restore_friction: before_drag_ramp``: contact.friction (0.5) replaces the
    preparation friction (0.1) once stage 1 has converged with the drag, so in the stage-1 frames
    of the ramp some strong grain-grain contact carries |F_t|/|F_n| above 0.2 (impossible at the
    preparation friction, whose sliding contacts sit at 0.1: test above), and at the end of stage 1
    none of them sits at 0.1 (the default leaves >= 2 % there). The smoke case loaded to 1 % with its
    frame interval (frames 2 for 1 % instead of 10 for 5 %: the same stage-1 chunks)."""
    from orchestrator.runner import run_case
    case = load_case(SMOKE, overrides={"scene": {"axial_strain": 0.01, "frames": 2,
                                                 "isotropic": {"restore_friction": "before_drag_ramp"}}})
    mu_prep, mu = case.scene.isotropic.friction, case.contact.friction
    out = run_case(case, eng, runs_root=tmp_path, progress=False)
    assert out.summary["status"] == "complete", out.summary.get("error")
    log = (out.run_dir / "engine.log").read_text()
    ramp = [int(m) for m in re.findall(r"drag ramped to zero over \d+ steps from step (\d+)", log)]
    assert ramp, "stage 1 never converged with the drag: no ramp to test"
    assert re.search(r"^FRICTION restored", log, re.M), "no friction switch in the engine log"
    ratios = {}
    with h5py.File(out.run_dir / "frames.h5") as f:
        stage, steps, ids = f["frames/stage"][:], f["frames/step"][:], f["particles/id"][:]
        for k in np.flatnonzero((stage == 1) & (steps > ramp[0])):
            g = f["contacts"][str(k)]
            gg = np.isin(g["i"][:], ids) & np.isin(g["j"][:], ids)
            fn = np.linalg.norm(g["fn"][:][gg], axis=1)
            ft = np.linalg.norm(g["ft"][:][gg], axis=1)
            strong = fn > np.median(fn)
            ratios[int(steps[k])] = ft[strong] / fn[strong]
    assert ratios, "no stage-1 frame after the ramp began"
    last = ratios[max(ratios)]
    above = max(float(np.max(r)) for r in ratios.values())
    # contacts sliding at the preparation friction pile up at |Ft|/|Fn| = mu_prep (>= 2 % of the
    # strong ones within 0.2 % of it when friction is not restored); once restored, a contact sits
    # there only by chance, at the rate of its neighbourhood (1-2 of ~300 on session 37's packings,
    # where the old test's "none" failed): at most the Poisson 99.9 % bound of that rate
    dev = np.abs(last / mu_prep - 1)
    n_at = int(np.sum(dev < 2e-3))
    chance = np.sum((dev >= 2e-3) & (dev < 0.1)) * 2e-3 / (0.1 - 2e-3)
    bound = int(poisson.ppf(0.999, max(chance, 0.1)))
    print(f"{eng}: largest |Ft|/|Fn| in the ramp's frames {above:.3f}; at {mu_prep} at the end of stage 1: "
          f"{n_at} of {last.size} strong contacts (by chance {chance:.2f}, bound {bound})")
    assert 2 * mu_prep < above <= 1.1 * mu      # LIGGGHTS: sticking contacts exceed μ by their dashpot (≤ 11 %)
    assert n_at <= bound


@pytest.mark.engine
@pytest.mark.parametrize("eng", ENGINES)
def test_volumetric_strain_two_ways(runs, eng):
    out = outcome(runs, eng)
    with h5py.File(out.run_dir / "frames.h5") as f:
        fr = f["frames"]
        shear = fr["stage"][:] >= 2
        ev_b = fr["volumetric_strain"][:][shear]
        ev_h = fr["volumetric_strain_hull"][:][shear]
        ev_s = fr["volumetric_strain_slab_hull"][:][shear]
    assert shear.sum() >= 5
    diff = np.max(np.abs(ev_b - ev_h))
    assert diff <= 0.02, f"{eng}: volumetric strain boundary vs hull differ by up to {diff:.4f}"
    # the slab hull (2 d50 slabs) follows a neck; a 300-grain sample has ~50 grains per slab
    diff = np.max(np.abs(ev_b - ev_s))
    assert diff <= 0.02, f"{eng}: volumetric strain boundary vs slab hull differ by up to {diff:.4f}"


@pytest.mark.engine
@pytest.mark.parametrize("eng", ENGINES)
def test_no_grain_escapes(runs, eng):
    out = outcome(runs, eng)
    with h5py.File(out.run_dir / "frames.h5") as f:
        pos = f["frames/position"][:]
        r = f["particles/radius"][:]
        steps = f["frames/step"][:]
        w = f["walls"]
        zb = np.interp(steps, w["triaxial/step"][:], w["platen_bottom/position"][:, 2])
        zt = np.interp(steps, w["triaxial/step"][:], w["platen_top/position"][:, 2])
        vol = f["frames/volume_boundary"][:]
        mem = w["membrane/node_position"][:] if "membrane" in w else None
    assert not np.isnan(pos).any(), "a grain went missing from a frame"
    tol = 0.5 * r.min()
    for k in range(len(steps)):
        z = pos[k, :, 2]
        assert np.all(z - r >= zb[k] - tol) and np.all(z + r <= zt[k] + tol), f"frame {k}: a grain left the platens"
        R_eq = np.sqrt(vol[k] / (np.pi * (zt[k] - zb[k])))
        rho = np.hypot(pos[k, :, 0], pos[k, :, 1])
        assert np.all(rho <= 1.5 * R_eq), f"frame {k}: a grain is far outside the sample"
    if mem is not None:                          # YADE: every grain centre inside the membrane
        from scipy.spatial import Delaunay
        assert len(mem) == len(steps)
        for k in range(len(steps)):
            hull = Delaunay(mem[k])
            inside = hull.find_simplex(pos[k]) >= 0
            assert inside.all(), f"frame {k}: {np.sum(~inside)} grain(s) outside the membrane"


@pytest.mark.engine
@pytest.mark.parametrize("eng", ENGINES)
def test_frame_outputs(runs, eng):
    """Rotations (YADE), particle stress and contact lists in every frame, signs as documented."""
    out = outcome(runs, eng)
    with h5py.File(out.run_dir / "frames.h5") as f:
        fr = f["frames"]
        T = len(fr["time"])
        st = fr["stress"][-1]
        assert np.isfinite(st).all()
        # compressed sample, tension-positive convention: mean particle stress is negative
        assert np.mean(np.trace(st, axis1=1, axis2=2)) < 0
        if eng == "yade":
            q = fr["orientation"][-1]
            assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-9)
        c = f["contacts"]
        assert len(c) == T
        last = c[str(T - 1)]
        n, fn, ft = last["normal"][:], last["fn"][:], last["ft"][:]
        assert len(n) > len(f["particles/id"])      # a jammed sample: more contacts than grains
        assert np.allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-9)
        # fn is the force on i, repulsive: opposite to the normal from i to j
        assert np.mean(np.sum(n * fn, axis=1) < 0) > 0.99
        # tangential forces lie in the contact plane (LIGGGHTS rotates its history lazily: 1e-3)
        assert np.allclose(np.sum(n * ft, axis=1), 0.0, atol=1e-3 * np.abs(fn).max())


def test_monitor_deck_has_one_pair_local_compute(tmp_path):
    """LIGGGHTS allows one compute pair/gran/local (checked: 'Pair gran allows only one compute of
    type pair/local'): with contact output and monitors on, the monitors read the overlap column
    of the contact compute, and the contact dump keeps its 18 columns."""
    from orchestrator.runner import run_case
    case = load_case(SMOKE)
    assert case.output.contacts and case.stability.monitors
    out = run_case(case, "liggghts", runs_root=tmp_path, dry_run=True, progress=False)
    deck = (out.run_dir / "deck.in").read_text().splitlines()
    computes = [ln for ln in deck if ln.startswith("compute") and "pair/gran/local" in ln]
    assert len(computes) == 1 and " delta contactPoint" in computes[0], computes
    dump = next(ln for ln in deck if ln.startswith("dump") and "contacts" in ln)
    assert dump.count("c_pgl[") == 18 and "c_pgl[16]" not in dump
    assert any(ln.startswith("compute") and "ORCH_dmax" in ln and "c_pgl[16]" in ln for ln in deck)
    runs = [ln for ln in deck if ln.startswith("run") and ln.split()[1] != "0"]
    assert runs and all(" every " in ln and "ORCH_UNSTABLE" in ln for ln in runs), runs
    yade = run_case(case, "yade", runs_root=tmp_path, dry_run=True, progress=False)
    assert "orch_monitor_engine()," in (yade.run_dir / "script.py").read_text()


@pytest.mark.engine
@pytest.mark.parametrize("eng", ENGINES)
def test_monitors_stop_an_unstable_triaxial_run(eng, tmp_path):
    """The stability monitors are wired into both triaxial decks: the smoke case at 5x the
    critical time step is stopped early and marked unstable (docs/stability.md §2)."""
    from orchestrator.derive import derive
    from orchestrator.runner import run_case
    if shutil.which(eng) is None:
        pytest.fail(f"{eng} is not installed; run `bash .ci/setup`")
    dt = 5 * derive(load_case(SMOKE))["dt_critical"]     # (6x: the stage-1 drag itself is refused)
    case = load_case(SMOKE, overrides={"timestep": {"dt": f"{dt!r} s", "allow_unsafe": True}})
    out = run_case(case, eng, runs_root=tmp_path, progress=False)
    s = json.loads((out.run_dir / "summary.json").read_text())
    assert out.status == "unstable" and s["status"] == "unstable", s.get("status")
    u = s["unstable"]
    assert u["figure"] in ("kinetic_energy", "overlap", "grains_outside", "nan", "wall_force", "wall_force_swing")
    assert u["step"] < s["steps"] / 2
    assert not (out.run_dir / "frames.h5").exists()


@pytest.mark.engine
@pytest.mark.parametrize("eng", ENGINES)
def test_monitors_watch_the_smoke_runs(runs, eng):
    """The monitors ran during the smoke runs (LIGGGHTS echoes each check) and nothing tripped."""
    out = outcome(runs, eng)
    assert out.status == "complete"
    log = (out.run_dir / "engine.log").read_text()
    assert "\nORCH_UNSTABLE:" not in log
    if eng == "liggghts":
        assert log.count("if '${ORCH_ke} >") >= 10
    else:
        assert "orch_monitor_engine()," in (out.run_dir / "script.py").read_text()


@pytest.mark.engine
@pytest.mark.parametrize("eng", ["liggghts"])
def test_triaxial_notebook_runs(runs, eng, tmp_path):
    """notebooks/triaxial_postprocessing.ipynb runs top to bottom on this file's LIGGGHTS smoke run
    (the notebook's run_case finds it complete in the same runs directory and reuses it)."""
    run = outcome(runs, eng)
    assert run.status == "complete"
    nb = execute_notebook("triaxial_postprocessing.ipynb", runs["root"], tmp_path, timeout=1800)
    assert f"complete {run.run_dir}" in notebook_text(nb)         # the notebook's run is this one
    assert notebook_images(nb) >= 2


#: the smoke floors on a second packing (seed 2), YADE: before stage 1 ended without the drag
#: (isotropic.drag_free_end) its lateral stress strayed 0.128; then 0.035 (Δε_v 0.010); with the
#: preparation friction 0.1 (a dense sample) 0.017 (Δε_v 0.002); with the derived servo gain 0.015 (0.001)
@pytest.fixture(scope="module")
def yade_seed2(tmp_path_factory):
    from orchestrator.runner import run_case
    if shutil.which("yade") is None:
        pytest.fail("yade is not installed; run `bash .ci/setup`")
    return run_case(load_case(SMOKE, overrides={"seed": 2}), "yade",
                    runs_root=tmp_path_factory.mktemp("triaxial_seed2"), progress=False)


@pytest.mark.engine
@pytest.mark.slow   # a second YADE smoke packing: 583 s in CI with the drag ramp (23 Nov 2026), out of the 15-minute suite
def test_yade_lateral_stray_second_packing(yade_seed2):
    sh = yade_seed2.summary["scene"]["shear"]
    assert sh["sigma3_error_max_abs_smoothed"] <= 0.10, sh


@pytest.mark.engine
@pytest.mark.slow   # the same second packing (its run is the fixture's), out of the 15-minute suite
def test_yade_volume_two_ways_second_packing(yade_seed2):
    with h5py.File(yade_seed2.run_dir / "frames.h5") as f:
        fr = f["frames"]
        shear = fr["stage"][:] >= 2
        diff = np.max(np.abs(fr["volumetric_strain"][:][shear] - fr["volumetric_strain_hull"][:][shear]))
    assert shear.sum() >= 5
    assert diff <= 0.02, f"seed 2: volumetric strain boundary vs hull differ by up to {diff:.4f}"


def test_servo_gain_below_its_stability_limit():
    """The stage-1 servo's gain defaults to half the largest gain stable over the platen's stiffness and
    damping range (servo_loop.stability_limit); a gain at or above it is refused, naming the field. The
    integral's time constant is a tenth of a chunk."""
    from orchestrator.case import CaseError
    from orchestrator.derive import derive
    iso = derive(load_case(SMOKE))["scene"]["iso"]
    assert iso["gain"] == pytest.approx(0.5 * iso["gain_limit"])
    assert 0.1 < iso["gain_limit"] < 50.0
    assert iso["gain_integral"] == pytest.approx(iso["gain"] / iso["integral_steps"])
    assert iso["integral_steps"] == pytest.approx(0.1 * iso["chunk"], abs=1)
    with pytest.raises(CaseError, match="scene.isotropic.gain .* stability limit"):
        load_case(SMOKE, overrides={"scene": {"isotropic": {"gain": 1.01 * iso["gain_limit"]}}})


def test_servo_loop_chatters_where_the_4000_clump_sample_did():
    """The loop model against the YADE 4 000-clump sample of session 18 (docs/triaxial.md, Servo): its
    platen had K = 1.33x and C = 0.58x the estimates (benchmarks/servo_probe.py on its checkpoint); at the old default g = 0.8 pA/(v_max dt K) the
    loop is unstable by the dashpot's same-step feedback (even/odd chatter, as measured), at the new
    default it is stable with margin, and so is the integral at a tenth of a 49 200-step chunk."""
    from orchestrator.scenes import servo_loop as sl
    p, d50, E, rho, zeta, dt, v = 3e5, 5.51e-4, 9.3306e10, 2650.0, 0.0300065, 6.99776e-9, 1.0687
    k, c = sl.platen_stiffness(p, d50, E), sl.platen_damping(p, d50, E, rho, zeta)
    alpha, beta = v * dt * k / (p * d50 ** 2), v * c / (p * d50 ** 2)
    old = 0.8 / alpha
    assert sl.spectral_radius(old * alpha * 1.33, old * beta * 0.58) > 1.0
    g = sl.GAIN_MARGIN * sl.stability_limit(alpha, beta)
    assert sl.spectral_radius(g * alpha * 1.33, g * beta * 0.58) < 0.9
    assert sl.stable_everywhere(g, alpha, beta, integral_ratio=1 / 4920)
    # with no dashpot the limit is the delayed spring's own: lambda^2 - lambda + a = 0 is stable for
    # a < 1, at every corner (K up to 2x): g < 1/(2 alpha)
    assert sl.stability_limit(alpha, 0.0) == pytest.approx(0.5 / alpha, rel=1e-6)


def test_drag_ramp_is_the_rearrangement_time_under_the_drag():
    """The stage-1 drag falls linearly to zero over T = 18 nu/p (t_i^2/tau_d of a d50 grain: the
    sample's overdamped rearrangement time under the initial drag) times ``isotropic.drag_ramp``
    (1 by default, as the smoke case since session 35; 0.5 halves it), rounded up to whole chunks;
    drag_ramp: 0 switches it off at once."""
    import math
    from orchestrator.derive import derive
    assert load_case(SMOKE).scene.isotropic.drag_ramp == 1.0
    whole = derive(load_case(SMOKE))
    iso, dt = whole["scene"]["iso"], whole["dt"]
    T = 18 * iso["drag_viscosity"] / 3e5                      # the smoke case's p = 300 kPa
    assert iso["drag_ramp_time"] == pytest.approx(T)
    # the same time from its definition t_i^2 / tau_d with d50's mass and drag coefficient
    d50, rho, p = 0.551e-3, 2650.0, 3e5
    t_i = d50 * math.sqrt(rho / p)
    tau_d = (rho * math.pi * d50 ** 3 / 6) / (6 * math.pi * iso["drag_viscosity"] * d50 / 2)
    assert iso["drag_ramp_time"] == pytest.approx(t_i ** 2 / tau_d)
    half = derive(load_case(SMOKE, overrides={"scene": {"isotropic": {"drag_ramp": 0.5}}}))["scene"]["iso"]
    assert half["drag_ramp_time"] == pytest.approx(0.5 * T)
    assert half["drag_ramp_steps"] % iso["chunk"] == 0 and 0 <= half["drag_ramp_steps"] * dt - 0.5 * T < iso["chunk"] * dt
    n = iso["drag_ramp_steps"]
    assert n % iso["chunk"] == 0 and 0 <= n * dt - T < iso["chunk"] * dt
    off = derive(load_case(SMOKE, overrides={"scene": {"isotropic": {"drag_ramp": 0}}}))["scene"]["iso"]
    assert off["drag_ramp_steps"] == 0


@pytest.mark.engine
@pytest.mark.parametrize("eng", ENGINES)
def test_servo_reaches_p_while_the_sample_creeps(runs, eng):
    """Stage 1 with the drag: the sample creeps (compacts at the drag's pace) and the top platen must
    follow it. A proportional servo at the derived gain would read sigma1 below p by v_creep/(v_max g)
    for as long as the sample creeps; the integral removes that error, so a chunk mean within the
    tolerance comes by the second tested chunk and stage 1 converges with the drag there
    (docs/triaxial.md, Servo; under the old proportional law the smoke case's first chunk within the
    tolerance was the 4th to the 9th: session 16-17 runs on both engines)."""
    out = outcome(runs, eng)
    log = (out.run_dir / "engine.log").read_text(errors="replace")
    iso = json.loads((out.run_dir / "params.json").read_text())["scene"]["iso"]
    means = [float(m) for m in re.findall(r"ISO chunk \d+: sigma1/p = ([0-9.eE+-]+)", log)]
    assert means, "no stage-1 chunk test in the engine log"
    first_ok = next((k for k, m in enumerate(means, 1) if abs(m - 1) < iso["tolerance"]), None)
    assert first_ok is not None and first_ok <= 2, f"{eng}: chunk means sigma1/p {means[:4]}"
    head = log.split("ISO converged with drag")[0]
    assert len(re.findall(r"ISO chunk \d+: sigma1/p", head)) <= 2, f"{eng}: converged with the drag only after {means}"
