"""The run-time model (orchestrator.clock): the fit recovers known costs, and refresh reads real
summary.json/params.json files of complete runs."""
from __future__ import annotations

import json
import os
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import pytest

from orchestrator.clock import (RunSample, Throughput, estimate_engine_time, expected_steps, fit, load_table, planned_steps,
                                refresh, step_plan)
from orchestrator.case import load_case
from orchestrator.derive import derive
from orchestrator.humanize import fmt_s
from orchestrator.sizing import (SizeError, _basis_note, busy_cores, busy_note, check_fits, describe, estimate,
                                 problems)

CASES = Path(__file__).resolve().parents[1] / "cases"


def _runs(a, b, startup, sizes, ranks=1, eff=1.0):
    out = []
    for n in sizes:
        steps = 10_000
        loop = steps * (a + b * n) / (1 + eff * (ranks - 1))
        out.append(RunSample("liggghts", "shear_cell", n, steps, ranks, loop + startup, loop))
    return out


def test_fit_separates_per_step_and_per_particle_costs():
    tp = fit(_runs(2e-4, 1e-6, 0.5, [300, 1000, 4000]))
    assert tp.per_step_s == pytest.approx(2e-4, rel=1e-6)
    assert tp.per_particle_step_s == pytest.approx(1e-6, rel=1e-6)
    assert tp.startup_s == pytest.approx(0.5)
    assert tp.engine_time(2000, 1000) == pytest.approx(0.5 + 1000 * (2e-4 + 2e-3))


def test_a_start_up_that_grows_with_the_grains_is_fitted_and_a_constant_one_stays_constant():
    """YADE's triaxial set-up took 8, 35 and 54 s with 300, 2 000 and 4 000 grains: a constant
    start-up (their median) put the 300-grain run's estimate 36 % long."""
    runs = [replace(r, engine_s=r.loop_s + 4.0 + 0.0125 * r.n_particles) for r in _runs(2e-4, 1e-6, 0.0, [300, 2000, 4000])]
    tp = fit(runs)
    assert tp.startup_s == pytest.approx(4.0, rel=1e-6)
    assert tp.startup_per_particle_s == pytest.approx(0.0125, rel=1e-6)
    assert tp.engine_time(300, 0) == pytest.approx(4.0 + 0.0125 * 300)
    assert "per particle" in tp.note
    flat = fit(_runs(2e-4, 1e-6, 0.5, [300, 2000, 4000]))
    assert flat.startup_per_particle_s == 0 and flat.startup_s == pytest.approx(0.5)
    assert Throughput(1.0, 0.0, 1e-6).startup_time(10_000) == 1.0      # entries without it: unchanged


def test_a_table_entry_with_a_term_this_version_does_not_know_is_read():
    entry = asdict(Throughput(1.0, 2e-4, 1e-6)) | {"a_later_term_s": 3.0}
    assert Throughput.from_dict(entry) == Throughput(1.0, 2e-4, 1e-6)


def test_parallel_efficiency_is_fitted_from_multi_rank_runs():
    tp = fit(_runs(0.0, 1e-6, 0.5, [300, 1000]) + _runs(0.0, 1e-6, 0.5, [1000], ranks=2, eff=0.8))
    assert tp.parallel_efficiency == pytest.approx(0.8, rel=1e-6)
    assert "parallel efficiency from 1 run" in tp.note


def test_one_size_says_so():
    tp = fit(_runs(0.0, 1e-6, 0.2, [500]))
    assert tp.per_step_s == 0 and "one size" in tp.note


def test_unknown_scene_falls_back_to_the_slowest_known_one():
    table = {"yade": {"impact": Throughput(1.0, 0.0, 1e-7), "triaxial": Throughput(2.0, 1e-3, 5e-6)}}
    t, basis = estimate_engine_time("yade", "shear_cell", 1000, 100, table=table)
    assert t == pytest.approx(2.0 + 100 * (1e-3 + 5e-3)) and "slowest" in basis
    t, basis = estimate_engine_time("lammps", "impact", 10, 10, table=table)
    assert np.isnan(t) and "no throughput" in basis


def _plane_shear_run(root, name, n, steps, eng_s, loop_s):
    d = root / name
    d.mkdir(parents=True)
    (d / "summary.json").write_text(json.dumps({
        "engine": "liggghts", "status": "complete", "steps": steps, "steps_run": steps,
        "wall_time": {"engine": eng_s, "engine_loop": loop_s}}))
    (d / "params.json").write_text(json.dumps({"scene": {"n": n}}))
    (d / "case.yaml").write_text("scene: {kind: plane_shear}\n")
    return d


def test_refresh_from_run_directories(tmp_path, monkeypatch):
    runs = tmp_path / "runs"
    for k, (n, steps, eng_s, loop_s) in enumerate([(300, 20000, 7.0, 6.0), (1000, 20000, 21.0, 20.0)]):
        _plane_shear_run(runs / "c", f"liggghts-{k}", n, steps, eng_s, loop_s)
    out = tmp_path / "tp.json"
    monkeypatch.setenv("ORCHESTRATOR_THROUGHPUT", str(out))
    fitted = refresh([runs])
    tp = fitted["liggghts"]["plane_shear"]
    # loop/step = 3e-4 and 1e-3 s at n = 300 and 1000: a = 0, b = 1e-6
    assert tp.per_particle_step_s == pytest.approx(1e-6, rel=1e-6) and tp.per_step_s == pytest.approx(0, abs=1e-12)
    assert tp.startup_s == pytest.approx(1.0)
    assert load_table()["liggghts"]["plane_shear"] == tp


def test_refresh_add_fits_new_runs_with_those_the_entry_kept(tmp_path, monkeypatch):
    """Run directories do not outlive their machine: an entry keeps the runs it was fitted on, and
    ``refresh --add`` fits new runs together with them (a run met again counts once); without
    ``--add`` the runs given replace them; an entry fitted on another machine is not mixed in."""
    import shutil
    out = tmp_path / "tp.json"
    monkeypatch.setenv("ORCHESTRATOR_THROUGHPUT", str(out))
    first = [_plane_shear_run(tmp_path / "a", "liggghts-0", 300, 20000, 7.0, 6.0),
             _plane_shear_run(tmp_path / "a", "liggghts-1", 1000, 20000, 21.0, 20.0)]
    refresh([tmp_path / "a"])
    rows = json.loads(out.read_text())["liggghts"]["plane_shear"]["samples"]
    assert [r["n"] for r in rows] == [300, 1000] and rows[0]["run"] == "liggghts-0"
    for d in first:
        shutil.rmtree(d)                                   # the machine is gone, its runs with it
    # a 3 000-grain run of the same model (a = 0, b = 1e-6): with the kept runs, one line through three sizes
    _plane_shear_run(tmp_path / "b", "liggghts-2", 3000, 20000, 61.0, 60.0)
    tp = refresh([tmp_path / "b"], add=True)["liggghts"]["plane_shear"]
    assert tp.runs == 3 and tp.per_particle_step_s == pytest.approx(1e-6, rel=1e-6)
    again = refresh([tmp_path / "b"], add=True)["liggghts"]["plane_shear"]
    assert again.runs == 3                                 # the 3 000-grain run is not counted twice
    alone = refresh([tmp_path / "b"])["liggghts"]["plane_shear"]
    assert alone.runs == 1 and "one size" in alone.note
    table = json.loads(out.read_text())
    table["liggghts"]["plane_shear"]["machine"] = "another machine x64"
    out.write_text(json.dumps(table))
    with pytest.raises(ValueError, match="fitted on another machine x64"):
        refresh([tmp_path / "b"], add=True)


def test_a_clump_run_is_counted_by_its_member_spheres(tmp_path):
    """The estimate sizes a clump sample by the spheres the engine integrates (the members,
    ``n_spheres``; sizing.integrated_particles); a run's sample must count the same, not the grains
    its summary.json names (a 300-clump probe recorded as 300 particles read 1.50 of the table, as
    its 2 400 members 0.38, and the next dry run was 4x too long)."""
    from orchestrator.clock import _sample
    d = tmp_path / "liggghts-0"
    d.mkdir()
    (d / "summary.json").write_text(json.dumps({
        "engine": "liggghts", "status": "complete", "steps": 1000, "steps_run": 1000, "n_particles": 300,
        "wall_time": {"engine": 10.0, "engine_loop": 9.0}}))
    (d / "params.json").write_text(json.dumps({"scene": {"n": 300, "n_spheres": 2400}}))
    (d / "case.yaml").write_text("scene: {kind: triaxial, particles: {shape: clumps}}\n"
                                 "contact: {substitutes: {liggghts.membrane: shell_pressure}}\n")
    smp = _sample(d)
    assert smp.n_particles == 2400 and smp.scene == "triaxial:shell_pressure+clumps"


def test_a_resumed_runs_engine_time_sums_its_attempts(tmp_path):
    """A ladder or sweep puts each run's engine time beside its observables: for a run killed and
    resumed, whose summary.json times its last attempt only, the cost of the whole run from its
    attempts' record (YADE's 2x rung of the small shear cell's stiffness ladder, session 20: its
    summary said 115 s of CPU, its two attempts 974 s and 115 s, of which 7 000 steps ran twice)."""
    from orchestrator.clock import run_engine_seconds
    d = tmp_path / "yade-0"
    d.mkdir()
    attempts = [{"first_step": 0, "last_step": 427064, "cpu_s": 974.154931, "wall_s": 2116.1, "done": False},
                {"first_step": 420101, "last_step": 464293, "cpu_s": 114.79449, "wall_s": 200.2, "done": True}]
    summary = {"status": "complete", "steps_run": 464293, "resumed_from": 420101, "attempts": attempts,
               "wall_time": {"engine": 200.2, "engine_cpu": 114.79449}}
    (d / "summary.json").write_text(json.dumps(summary))
    whole = 974.154931 + 114.79449 * (464293 - 427064) / (464293 - 420101)
    assert run_engine_seconds(d) == pytest.approx(whole)
    assert run_engine_seconds(d, {k: v for k, v in summary.items() if k != "resumed_from"}) == pytest.approx(114.79449)


def test_multi_rank_runs_alone_keep_the_assumed_efficiency():
    from orchestrator.clock import ASSUMED_PARALLEL_EFFICIENCY
    tp = fit(_runs(0.0, 1e-6, 0.5, [1000], ranks=2, eff=ASSUMED_PARALLEL_EFFICIENCY))
    assert tp.parallel_efficiency == ASSUMED_PARALLEL_EFFICIENCY and "no one-rank run" in tp.note
    assert tp.per_particle_step_s == pytest.approx(1e-6, rel=1e-9)       # scaled back to one rank


def test_a_triaxial_run_whose_summary_holds_its_scene_results_is_read(tmp_path):
    """summary.json's "scene" holds the triaxial's stage figures (a dict), not its kind: the kind
    comes from the run's case (bench_estimate.py failed on the CI runs: unhashable dict)."""
    from orchestrator.clock import samples_from_runs
    d = tmp_path / "triaxial_smoke" / "yade-0"
    d.mkdir(parents=True)
    (d / "summary.json").write_text(json.dumps({
        "engine": "yade", "status": "complete", "steps": 1000, "steps_run": 1000, "n_particles": 300,
        "scene": {"isotropic_end": {"converged": True}}, "wall_time": {"engine": 5.0, "engine_loop": 0}}))
    (d / "params.json").write_text(json.dumps({"scene": {"n": 300}}))
    (d / "case.yaml").write_text("scene: {kind: triaxial}\n")
    (s,) = samples_from_runs([tmp_path])
    assert (s.engine, s.scene, s.n_particles, s.steps) == ("yade", "triaxial", 300, 1000)
    assert s.loop_s == 5.0          # engine_loop 0: not measured (YADE), the engine time stands in


def _cpu_run(tmp_path, ranks: int):
    from orchestrator.clock import samples_from_runs
    d = tmp_path / f"r{ranks}" / "c" / "liggghts-0"
    d.mkdir(parents=True)
    (d / "summary.json").write_text(json.dumps({
        "engine": "liggghts", "status": "complete", "steps": 1000, "steps_run": 1000, "n_particles": 500,
        "workers": ranks, "wall_time": {"engine": 300.0, "engine_loop": 290.0, "engine_cpu": 200.0}}))
    (d / "params.json").write_text(json.dumps({"scene": {"n": 500}}))
    (d / "case.yaml").write_text("scene: {kind: shear_cell}\n")
    (s,) = samples_from_runs([d])
    return s


def test_cpu_time_stands_for_the_wall_time_of_a_loaded_one_rank_run(tmp_path):
    """One rank that shared its cores: wall 300 s, CPU 200 s -> 200 s of quiet engine time."""
    s = _cpu_run(tmp_path, 1)
    assert s.engine_s == pytest.approx(200.0) and s.loop_s == pytest.approx(190.0)


def test_several_ranks_keep_their_wall_time(tmp_path):
    """MPI ranks poll while they wait, so their CPU time grows with the load too (the default case on
    2 ranks: 201 s quiet, 806 s CPU beside a YADE run): the wall time is kept."""
    s = _cpu_run(tmp_path, 2)
    assert s.engine_s == pytest.approx(300.0) and s.loop_s == pytest.approx(290.0)


def test_packings_of_nearly_one_size_count_as_one_size():
    """226 and 228 grains (two seeds of one case) cannot separate the per-step from the
    per-particle cost: the fit is one-size, not an extrapolation from a 1 % lever arm (it predicted
    the 1025-grain default case at 0.15 of its engine time)."""
    tp = fit(_runs(2e-4, 1e-6, 0.5, [226, 228]))
    assert tp.per_step_s == 0 and "one size" in tp.note
    assert tp.engine_time(227, 10_000) == pytest.approx(0.5 + 10_000 * (2e-4 + 227e-6), rel=0.01)


def _triaxial_run(root, name: str, chunks: int | None, steps_run: int | None = None):
    """A complete triaxial_smoke run directory with the case's real derived numbers whose stage 1
    took ``chunks`` chunks (engine time 1 ms per step)."""
    from orchestrator.registry import get_scene
    params = derive(load_case("cases/triaxial_smoke.yaml")).to_dict()
    plan = get_scene("triaxial").step_plan(params["scene"])
    steps = steps_run if steps_run is not None else plan.fixed + chunks * plan.unit
    d = root / "triaxial_smoke" / f"yade-{name}"
    d.mkdir(parents=True)
    (d / "summary.json").write_text(json.dumps({
        "engine": "yade", "status": "complete", "steps": params["scene"]["total_steps"], "steps_run": steps,
        "n_particles": 300, "wall_time": {"engine": 1e-3 * steps, "engine_loop": 0}}))
    (d / "params.json").write_text(json.dumps(params, default=str))
    (d / "case.yaml").write_text("scene: {kind: triaxial}\n")
    return plan, params


def test_triaxial_estimate_takes_the_chunks_measured_runs_took(tmp_path, monkeypatch):
    """The triaxial's stage 1 goes on chunk by chunk until it converges (at most max_chunks): the
    clock learns how many chunks the engine's runs took (median) and the dry run estimates with
    those, not with the budget of every chunk (YADE smoke: 12 of 40 chunks; the budget made the
    estimate 1.9x the engine time, docs/validation.md). A run that skipped the plan (stage 1 out of
    chunks, no drag ramp) does not count."""
    runs = tmp_path / "runs"
    for name, k in (("a", 11), ("b", 12), ("c", 14)):
        plan, params = _triaxial_run(runs, name, k)
    _triaxial_run(runs, "short", None, steps_run=5000)          # fewer steps than the fixed part
    table = tmp_path / "throughput.json"
    monkeypatch.setenv("ORCHESTRATOR_THROUGHPUT", str(table))
    fitted = refresh([runs], table)["yade"]["triaxial"]
    # stage 1 counted in pressure-ramp lengths, not chunks (a chunk is two loading frame intervals)
    assert plan.scale == params["scene"]["iso"]["ramp_steps"] > 0
    assert fitted.units == pytest.approx(12.0 * plan.unit / plan.scale) and fitted.runs == 4
    case = load_case("cases/triaxial_smoke.yaml")
    size = estimate(case, derive(case), "yade")
    # the budget: every tested chunk and the pressure ramp's chunks before them, as the derived total_steps
    iso = params["scene"]["iso"]
    assert plan.max_units == iso["max_chunks"] + -(-iso["ramp_steps"] // iso["chunk"])
    assert size["steps"] == plan.fixed + plan.max_units * plan.unit == params["scene"]["total_steps"]
    assert size["steps_expected"] == plan.fixed + 12 * plan.unit
    assert size["engine_time_s"] == pytest.approx(fitted.engine_time(300, size["steps_expected"]))
    assert size["engine_time_s"] < 0.7 * fitted.engine_time(300, size["steps"])


def test_an_estimate_says_the_spread_of_the_steps_its_runs_took(tmp_path, monkeypatch):
    """Where the packing decides how long stage 1 takes (YADE's triaxial smoke on seeds 1 and 2 of
    one case: 2.5 and 8.0 pressure-ramp lengths, 194.6 and 357.8 s, docs/validation.md), one figure
    cannot hold both: the dry run prints the time at the fewest and at the most units the entry's
    runs took beside the median's; with one run, or runs that agree, it prints none. The same
    range for a steps-only refresh, and a table written before the range existed still reads."""
    runs = tmp_path / "runs"
    for name, k in (("a", 3), ("b", 5), ("c", 12)):
        plan, _ = _triaxial_run(runs, name, k)
    table = tmp_path / "throughput.json"
    monkeypatch.setenv("ORCHESTRATOR_THROUGHPUT", str(table))
    fitted = refresh([runs], table)["yade"]["triaxial"]
    lo, hi = (plan.units_of(plan.fixed + k * plan.unit) for k in (3, 12))
    assert fitted.units_range == pytest.approx((lo, hi))
    assert load_table()["yade"]["triaxial"].units_range == pytest.approx((lo, hi))   # JSON list read back
    case = load_case("cases/triaxial_smoke.yaml")
    size = estimate(case, derive(case), "yade")
    t_lo, t_hi = (fitted.engine_time(300, plan.fixed + k * plan.unit) for k in (3, 12))
    assert t_lo < size["engine_time_s"] < t_hi
    line = describe(size)
    assert (f"{fmt_s(t_lo)} to {fmt_s(t_hi)} as the runs measured took {lo:.1f} to {hi:.1f} "
            "pressure-ramp lengths in stage 1") in line, line
    # runs that agree within SPREAD_NOTE, or one run: no spread printed
    for keep in (("a",), ("a", "b", "c")):
        entry = asdict(fitted) | {"units_range": [lo, lo * 1.1] if len(keep) == 3 else None}
        table.write_text(json.dumps({"yade": {"triaxial": entry}}))
        assert "as the runs measured took" not in describe(estimate(case, derive(case), "yade"))
    # a steps-only refresh records the range too; an entry without the field (older tables) reads
    old = Throughput(2.0, 1e-3, 5e-6, 0.7, 9, "3 sizes; 12 units (median of 9, steps refreshed alone)", 12.0)
    row = {k: v for k, v in asdict(old).items() if k != "units_range"}
    table.write_text(json.dumps({"yade": {"triaxial": row}}))
    assert load_table()["yade"]["triaxial"].units_range is None
    new = refresh([runs], table, steps_only=True)["yade"]["triaxial"]
    assert new.units_range == pytest.approx((lo, hi)) and new.note.count("units") == 1


def test_steps_only_refresh_keeps_the_costs_per_step(tmp_path, monkeypatch):
    """``clock refresh --steps-only``: a new stage-1 law changes how many steps a run takes, the same
    on every machine, not what a step costs on the machine the table was fitted on (the other
    machines' speed records are ratios to those costs): the units become the new runs' median, the
    costs stay; an entry the table lacks is not created."""
    runs = tmp_path / "runs"
    for name, k in (("a", 3), ("b", 4), ("c", 6)):
        plan, _ = _triaxial_run(runs, name, k)
    table = tmp_path / "throughput.json"
    old = Throughput(2.0, 1e-3, 5e-6, 0.7, 9, "3 sizes; 12 units (median of 9)", 12.0)
    table.write_text(json.dumps({"yade": {"triaxial": asdict(old)}}))
    monkeypatch.setenv("ORCHESTRATOR_THROUGHPUT", str(table))
    new = refresh([runs], table, steps_only=True)["yade"]["triaxial"]
    assert new.units == pytest.approx(4.0 * plan.unit / plan.scale)
    assert (new.startup_s, new.per_step_s, new.per_particle_step_s, new.runs) == (2.0, 1e-3, 5e-6, 9)
    assert new.note.count("units") == 1 and "steps refreshed alone" in new.note
    assert load_table()["yade"]["triaxial"] == new
    table.write_text("{}")
    assert refresh([runs], table, steps_only=True) == {} and json.loads(table.read_text()) == {}


def test_stage_one_is_learned_in_its_own_time_scale_not_in_chunks():
    """The triaxial's chunk is two frame intervals of the loading: halving the loading rate doubles
    it, while stage 1 (compression at the stage's own inertial number) takes as long as before. The
    clock counts stage 1 in pressure-ramp lengths, so a case loading at half the rate is estimated
    with the same stage-1 steps (LIGGGHTS, 2 000 grains: 114 000 steps in 15 chunks of 7 600 at
    I = 2.5e-3, 106 400 in 7 of 15 200 at 1.25e-3; counted in chunks the clock put the second at
    1.36x its engine time, docs/validation.md)."""
    from orchestrator.clock import Throughput
    from orchestrator.registry import get_scene
    scene = get_scene("triaxial")
    fast = derive(load_case("cases/triaxial_smoke.yaml")).to_dict()["scene"]
    case = load_case("cases/triaxial_smoke.yaml")
    slow_case = case.model_copy(update={"scene": case.scene.model_copy(
        update={"inertial_number": case.scene.inertial_number / 2})})
    slow = derive(slow_case).to_dict()["scene"]
    p_fast, p_slow = scene.step_plan(fast), scene.step_plan(slow)
    assert p_slow.unit > 1.9 * p_fast.unit and p_slow.scale == p_fast.scale     # chunk doubles, ramp does not
    stage1 = 12 * p_fast.unit                               # the measured run: 12 chunks at the fast rate
    tp = Throughput(0.0, 0.0, 1e-6, units=p_fast.units_of(p_fast.fixed + stage1))
    est_slow = expected_steps(10**9, p_slow, tp) - p_slow.fixed
    assert est_slow % p_slow.unit == 0 and stage1 <= est_slow < stage1 + p_slow.unit   # same length, whole chunks
    # counted in chunks (scale 0) the slow case would be given 12 of its chunks: about twice the stage
    in_chunks = type(p_slow)(p_slow.fixed, p_slow.unit, p_slow.max_units)
    assert expected_steps(10**9, in_chunks, Throughput(0.0, 0.0, 1e-6, units=12.0)) - p_slow.fixed > 1.9 * stage1


def test_three_sizes_on_a_curve_fit_a_power_law_and_each_size_counts_once():
    """The LIGGGHTS shear cell's cost per step grows as n^0.8 from 228 to 14 107 grains: a + b n
    cannot follow it (eleven small runs and one medium run put the medium one at 1.76x before the
    medium runs were in the table, and at 1.26x after). With three sizes the fit takes c n^alpha
    where it is closer, each size weighted once, however many runs it has."""
    def run(n, k):
        t_step = 3e-6 * n ** 0.8
        return RunSample("liggghts", "shear_cell", n, 100_000, 1, 100_000 * t_step, 100_000 * t_step, f"r{n}-{k}")
    runs = [run(228, 0)] + [run(1025, k) for k in range(11)] + [run(14107, 0)]
    tp = fit(runs)
    assert tp.exponent == pytest.approx(0.8, rel=1e-6) and tp.per_step_s == 0 and "power law" in tp.note
    for n in (228, 1025, 14107):
        assert tp.engine_time(n, 100_000) == pytest.approx(100_000 * 3e-6 * n ** 0.8, rel=1e-6)
    # a straight line over three sizes stays a straight line
    lin = [RunSample("yade", "impact", n, 1000, 1, 1000 * (2e-4 + 1e-6 * n), 1000 * (2e-4 + 1e-6 * n), f"y{n}")
           for n in (100, 1000, 10000)]
    tl = fit(lin)
    assert tl.exponent == 1.0 and tl.per_step_s == pytest.approx(2e-4, rel=1e-6)


def test_a_power_law_steeper_than_linear_goes_on_linearly_beyond_the_largest_run():
    """YADE's shell triaxial costs 0.57, 5.7 and 16.5 ms a step with 300, 2 000 and 4 000 grains
    (n^1.32, session 26). Carried to the 32 000 member spheres of the clump sample the power law said
    ~260 ms a step, where that run keeps ~100-115 ms (8.7-10.2 steps per CPU second, attempts.json):
    beyond the largest run the clock continues at that run's cost per particle (O(n) work per step),
    and inside the runs' range the power law is untouched."""
    def run(n):
        t_step = 2e-8 * n ** 1.32
        return RunSample("yade", "triaxial:shell_pressure", n, 10_000, 1, 10_000 * t_step, 10_000 * t_step, f"s{n}")
    tp = fit([run(n) for n in (300, 2000, 4000)])
    assert tp.exponent == pytest.approx(1.32, rel=1e-6) and tp.max_particles == 4000
    assert "linear beyond 4000 particles" in tp.note
    for n in (300, 2000, 4000):
        assert tp.step_time(n) == pytest.approx(2e-8 * n ** 1.32, rel=1e-6)
    assert tp.step_time(32_000) == pytest.approx(8 * tp.step_time(4000), rel=1e-9)
    assert tp.step_time(32_000) < 0.55 * 2e-8 * 32_000 ** 1.32
    # an entry from before the field (max_particles 0) and a sublinear law are not capped
    old = Throughput.from_dict({k: v for k, v in asdict(tp).items() if k != "max_particles"})
    assert old.step_time(32_000) == pytest.approx(2e-8 * 32_000 ** 1.32, rel=1e-6)
    sub = fit([RunSample("liggghts", "shear_cell", n, 1000, 1, 1000 * 3e-6 * n ** 0.8, 1000 * 3e-6 * n ** 0.8, f"l{n}")
               for n in (228, 1025, 14107)])
    assert sub.step_time(10 * 14107) == pytest.approx(3e-6 * (10 * 14107) ** 0.8, rel=1e-6)
    # an estimate far beyond the runs says so (the fitted curve's form decides it there)
    table = {"yade": {"triaxial:shell_pressure": tp}}
    _, near = estimate_engine_time("yade", "triaxial:shell_pressure", 4000, 1000, table=table)
    _, far = estimate_engine_time("yade", "triaxial:shell_pressure", 32_000, 1000, table=table)
    assert "extrapolation" not in near and "8.0x the largest run fitted (4,000 particles): an extrapolation" in far


def test_a_complete_run_teaches_the_clock_this_machines_speed(tmp_path, monkeypatch):
    """A quiet run that took 0.44 of the package table's prediction (LIGGGHTS' small shear cell on
    a newer 2-core machine, 27 Nov 2026) scales the next estimates from the package table by its
    median, and says so; a run that shared its cores, or an entry of a user table, is left alone."""
    from orchestrator.clock import UNMEASURED_WORDS, _package_table, machine_factor, machine_id, record_speed
    monkeypatch.setenv("ORCHESTRATOR_MACHINE_SPEED", str(tmp_path / "speed.json"))
    monkeypatch.setenv("ORCHESTRATOR_THROUGHPUT", str(tmp_path / "user.json"))
    tp = Throughput(**_package_table()["liggghts"]["shear_cell"])
    n, steps = 1025, 383_546
    before, basis = estimate_engine_time("liggghts", "shear_cell", n, steps, 2)
    assert before == pytest.approx(tp.engine_time(n, steps, 2))
    # before any run here the estimate says whose speed it is (session 37's machine ran the default
    # case in 0.43 of the table's time, unwarned)
    assert tp.machine != machine_id()
    assert f"{UNMEASURED_WORDS} (the table's is an earlier machine's" in basis and "liggghts run here measures it" in basis
    _, basis = estimate_engine_time("liggghts", "shear_cell:smooth_sidewall", n, steps, 2)
    smooth = Throughput(**_package_table()["liggghts"]["shear_cell:smooth_sidewall"])
    assert smooth.machine and f"{UNMEASURED_WORDS} (the table's is {smooth.machine}'s" in basis

    def run(name, ratio, load):
        d = tmp_path / "runs" / name
        d.mkdir(parents=True)
        t = ratio * tp.engine_time(n, steps, 2)
        (d / "summary.json").write_text(json.dumps({
            "engine": "liggghts", "status": "complete", "steps": steps, "steps_run": steps, "n_particles": n,
            "workers": 2, "wall_time": {"engine": t, "engine_loop": t - tp.startup_s}}))
        (d / "params.json").write_text(json.dumps({"scene": {"n": n}}))
        (d / "case.yaml").write_text("scene: {kind: shear_cell, wall_friction: shear}\n")   # the mesh sidewall's key
        (d / "attempts.json").write_text(json.dumps([{"cores": 2, "load": load, "wall_s": t, "done": True}]))
        return record_speed(d)

    assert run("quiet-1", 0.44, 2.0) == pytest.approx(0.44, rel=1e-3)
    assert run("quiet-2", 0.50, 2.1) == pytest.approx(0.50, rel=1e-3)
    assert run("shared", 1.50, 4.0) is None                  # two ranks beside other runs: wall time too long
    assert machine_factor("liggghts") == (pytest.approx(0.47, rel=1e-3), 2)
    after, basis = estimate_engine_time("liggghts", "shear_cell", n, steps, 2)
    assert after == pytest.approx(0.47 * before, rel=1e-3)
    assert "× 0.47 for this machine's speed on 2 ranks or threads (2 run(s))" in basis     # the runs had 2 ranks
    assert UNMEASURED_WORDS not in basis
    # a record names its run by its absolute path (a relative one names other runs from elsewhere)
    monkeypatch.chdir(tmp_path)
    assert record_speed(Path("runs") / "quiet-1") == pytest.approx(0.44, rel=1e-3)
    rows = json.loads((tmp_path / "speed.json").read_text())[machine_id()]["liggghts"]
    assert sorted(r["run"] for r in rows) == sorted(str(tmp_path / "runs" / k) for k in ("quiet-1", "quiet-2"))
    (tmp_path / "user.json").write_text(json.dumps({"liggghts": {"shear_cell": {
        "startup_s": 1.0, "per_step_s": 0.0, "per_particle_step_s": 1e-7}}}))
    t_user, basis = estimate_engine_time("liggghts", "shear_cell", n, steps)
    assert t_user == pytest.approx(1.0 + steps * 1e-7 * n) and "machine" not in basis


def test_this_machines_speed_is_interpolated_in_size_not_carried_across_sizes(tmp_path, monkeypatch):
    """The newer machine of 27 Nov 2026 ran LIGGGHTS' smoke shear cell (228 grains) at ~0.3 of the
    table's time and the small one (1 025) at 0.44: one median carried across sizes missed the smoke
    case by up to 2.2x. The factor is each size's median, interpolated in log n, held beyond the ends."""
    from orchestrator.clock import machine_factor, machine_id, speed_at_size
    ns, ratios = [228, 230, 1025, 1025, 1025], [0.29, 0.31, 0.44, 0.45, 0.43]
    assert speed_at_size(ns, ratios, 229) == pytest.approx(0.30, rel=1e-4)
    assert speed_at_size(ns, ratios, 1025) == pytest.approx(0.44)
    mid = float(np.sqrt(228.99 * 1025))
    assert speed_at_size(ns, ratios, mid) == pytest.approx(np.sqrt(0.30 * 0.44), rel=2e-3)
    assert speed_at_size(ns, ratios, 14_107) == pytest.approx(0.44)      # never extrapolated
    assert speed_at_size(ns, ratios, 50) == pytest.approx(0.30)
    assert speed_at_size([None, None], [0.3, 0.5], 1000) == pytest.approx(0.4)   # rows without counts: median
    monkeypatch.setenv("ORCHESTRATOR_MACHINE_SPEED", str(tmp_path / "speed.json"))
    (tmp_path / "speed.json").write_text(json.dumps({machine_id(): {"liggghts": [
        {"run": f"r{k}", "scene": "shear_cell", "n": n, "ratio": r} for k, (n, r) in enumerate(zip(ns, ratios))]}}))
    assert machine_factor("liggghts", "shear_cell", 228) == (pytest.approx(0.30), 5)
    assert machine_factor("liggghts", "shear_cell") == (pytest.approx(0.43), 5)
    assert machine_factor("liggghts", "triaxial", 228) == (pytest.approx(0.43), 5)   # another scene: the median


def test_this_machines_speed_on_several_threads_is_kept_apart_from_its_speed_on_one(tmp_path, monkeypatch):
    """YADE's small shear cell (1 025 grains) took 315 s on one thread and 366 s on two (session 38,
    quiet): 0.30 and 0.59 of the package table, whose two-thread figure divides by an assumed
    speed-up of 1.7. One median of both (0.45) said neither. A run on two threads takes the records of
    two-thread runs of its scene, and then says it; on one thread, or on more threads than any record
    ran, the one-rank records (the machine's speed; the table's speed-up)."""
    from orchestrator.clock import ASSUMED_WORDS, _package_table, machine_factor, machine_id, speed_factor
    recs = [("shear_cell", 1025, 0.30, True, 1), ("shear_cell", 1025, 0.59, True, 2), ("shear_cell", 228, 0.41, True, None)]
    assert speed_factor(recs, "shear_cell", 1025)[0] == pytest.approx(0.30)
    assert speed_factor(recs, "shear_cell", 1025, ranks=2) == (pytest.approx(0.59), 1)
    assert speed_factor(recs, "shear_cell", 1025, ranks=4) == (pytest.approx(0.30), 2)   # none ran on 4: one rank's
    assert speed_factor(recs, "plane_shear", 150, ranks=2)[0] == pytest.approx(np.median([0.30, 0.41]))  # another scene
    assert speed_factor([r[:4] for r in recs], "shear_cell", 1025)[0] == pytest.approx(0.445)  # rows without ranks: one group
    monkeypatch.setenv("ORCHESTRATOR_MACHINE_SPEED", str(tmp_path / "speed.json"))
    monkeypatch.setenv("ORCHESTRATOR_THROUGHPUT", str(tmp_path / "user.json"))
    key = "shear_cell:smooth_sidewall"
    (tmp_path / "speed.json").write_text(json.dumps({machine_id(): {"yade": [
        {"run": f"r{k}", "scene": key, "n": n, "ratio": r, "quiet": True, "ranks": w}
        for k, (_, n, r, _, w) in enumerate(recs)]}}))
    tp = Throughput.from_dict(_package_table()["yade"][key])
    assert not tp.efficiency_measured
    n, steps = 1025, 355_237
    one, basis1 = estimate_engine_time("yade", key, n, steps, 1)
    two, basis2 = estimate_engine_time("yade", key, n, steps, 2)
    assert one == pytest.approx(0.30 * tp.engine_time(n, steps, 1), rel=1e-3)
    assert two == pytest.approx(0.59 * tp.engine_time(n, steps, 2), rel=1e-3)
    assert "on 2 ranks or threads (1 run(s))" in basis2 and ASSUMED_WORDS not in basis2
    assert "ranks or threads" not in basis1
    assert machine_factor("yade", key, n, 2) == (pytest.approx(0.59), 1)
    three, basis3 = estimate_engine_time("yade", key, n, steps, 3)       # no run on 3: assumed, and said
    assert three == pytest.approx(0.30 * tp.engine_time(n, steps, 3), rel=1e-3) and ASSUMED_WORDS in basis3


def test_a_run_on_threads_this_machine_ran_slower_on_is_warned_about(tmp_path, monkeypatch):
    """YADE's small shear cell ran 366 s on two threads and 315 s on one here (session 38): a case
    asking for two threads is told one is estimated faster; where two threads measured a speed-up,
    or no run on two was recorded (the table's assumed speed-up), nothing is said."""
    from orchestrator.clock import machine_id
    monkeypatch.setenv("ORCHESTRATOR_MACHINE_SPEED", str(tmp_path / "speed.json"))
    monkeypatch.setenv("ORCHESTRATOR_THROUGHPUT", str(tmp_path / "user.json"))
    case = load_case(CASES / "shear_cell_small.yaml", overrides={"engine_options": {"threads": 2}})
    params = derive(case)

    def warnings(records):
        (tmp_path / "speed.json").write_text(json.dumps({machine_id(): {"yade": [
            {"run": f"r{k}", "scene": "shear_cell:smooth_sidewall", "n": 1025, "ratio": r, "quiet": True, "ranks": w}
            for k, (r, w) in enumerate(records)]}}))
        size = estimate(case, params, "yade")
        return size, [p for p in problems(case, size) if "on one thread" in p]

    size, said = warnings([(0.30, 1), (0.59, 2)])
    assert size["engine_time_one_worker_s"] < size["engine_time_s"]
    assert len(said) == 1 and "set engine_options.threads to 1" in said[0], said
    assert warnings([(0.30, 1), (0.35, 2)])[1] == []        # two threads measured faster than one
    assert warnings([(0.30, 1)])[1] == []                   # none measured on two: the table's speed-up
    one_thread = load_case(CASES / "shear_cell_small.yaml", overrides={"engine_options": {"threads": 1}})
    assert estimate(one_thread, derive(one_thread), "yade")["engine_time_one_worker_s"] is None


def test_a_busy_machine_is_said_and_a_quiet_one_is_not():
    # 2 cores: a one-rank run leaves one core free, so more than 1.5 cores in use shares it
    assert busy_note(1, busy=1.4, cores=2) is None
    note = busy_note(1, busy=1.7, cores=2)
    assert note and "1.7 of its 2 cores in use" in note and "quiet machine" in note
    # a two-rank run needs both cores: more than half a core in use shares them
    assert busy_note(2, busy=0.4, cores=2) is None and busy_note(2, busy=0.9, cores=2)
    # the machine's own figure: between none and every core
    b = busy_cores(0.05)
    assert b is None or -0.01 <= b <= os.cpu_count() + 0.01


def test_more_ranks_than_cores_are_warned_about_and_every_rank_counts_its_memory(monkeypatch):
    """``mpi_ranks: 3000`` on a 2-core machine validated without a word, with 3000 ranks' speed-up
    in its estimate and one process's memory: the ranks now count in the memory (each an engine
    process), the speed-up counts at most the cores, and a warning names the field and the fix;
    YADE's threads share one process; a run sent to a cluster counts every rank."""
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    base = load_case("cases/shear_cell_smoke.yaml")
    params = derive(base)

    def sized(engine, **opts):
        case = base.model_copy(update={"engine_options": base.engine_options.model_copy(update=opts)})
        return case, estimate(case, params, engine)
    _, one = sized("liggghts")
    case, many = sized("liggghts", mpi_ranks=3000)
    _, two = sized("liggghts", mpi_ranks=2)
    assert many["memory_bytes"] - one["memory_bytes"] == pytest.approx(2999 * 50e6)
    assert many["engine_time_s"] == pytest.approx(two["engine_time_s"])          # no faster than 2 ranks
    warn = [p for p in problems(case, many) if "more than this machine's 2 cores" in p]
    assert len(warn) == 1 and "engine_options.mpi_ranks = 3000" in warn[0] and "at most 2" in warn[0]
    assert any("on 3,000 MPI ranks" in p for p in problems(case, many) if not p.startswith("warning"))
    with pytest.raises(SizeError, match="fewer engine_options.mpi_ranks than 3,000"):
        check_fits(case, many)
    assert not [p for p in problems(*sized("liggghts", mpi_ranks=2)) if "cores" in p]
    case_y, threads = sized("yade", threads=8)
    assert threads["memory_bytes"] == sized("yade")[1]["memory_bytes"]            # threads share a process
    assert any("engine_options.threads = 8" in p for p in problems(case_y, threads))
    case_c, cluster = sized("liggghts", mpi_ranks=8, scheduler="tcp://head:8786")
    assert not [p for p in problems(case_c, cluster) if "cores" in p]
    assert cluster["engine_time_s"] < two["engine_time_s"]                        # the cluster's 8 ranks count


def test_a_one_rank_run_counts_its_cpu_time_and_a_multi_rank_run_its_wall_time():
    from orchestrator.clock import engine_seconds
    # a one-rank rung paused for 7 min beside the ladder: 510 s of wall time, 70 s of CPU
    assert engine_seconds({"workers": 1, "wall_time": {"engine": 510.3, "engine_cpu": 70.1}}) == 70.1
    # two ranks poll while they wait: the wall time is the time
    assert engine_seconds({"workers": 2, "wall_time": {"engine": 636.0, "engine_cpu": 806.0}}) == 636.0
    assert engine_seconds({"wall_time": {"engine": 12.0}}) == 12.0 and engine_seconds({}) is None


def test_a_copied_run_counts_once_and_a_rerun_twice(tmp_path):
    import shutil
    from orchestrator.clock import samples_from_runs
    src = tmp_path / "runs" / "triaxial_smoke" / "yade-0a1b2c3d4e5f"
    src.mkdir(parents=True)
    (src / "summary.json").write_text(json.dumps({
        "engine": "yade", "status": "complete", "steps": 1000, "steps_run": 1000, "n_particles": 300,
        "wall_time": {"engine": 5.0, "engine_loop": 0}}))
    (src / "params.json").write_text(json.dumps({"scene": {"n": 300}}))
    (src / "case.yaml").write_text("scene: {kind: triaxial}\n")
    shutil.copytree(src, tmp_path / "other" / src.name)               # a rung copied to be reused
    assert len(samples_from_runs([tmp_path / "runs", tmp_path / "other"])) == 1
    rerun = tmp_path / "again" / src.name                               # the same case run again
    shutil.copytree(src, rerun)
    s = json.loads((rerun / "summary.json").read_text())
    s["wall_time"]["engine"] *= 1.3
    (rerun / "summary.json").write_text(json.dumps(s))
    assert len(samples_from_runs([tmp_path / "runs", tmp_path / "other", tmp_path / "again"])) == 2


def test_a_scene_measured_at_one_size_borrows_the_engines_size_trend_within_what_was_measured():
    from orchestrator.clock import size_trend, speed_factor
    # scene A measured at two sizes: ratio 0.25 at 200 particles, 0.5 at 1 000 (beta = ln 2 / ln 5);
    # scene B only at 300 particles (YADE on 28 Nov 2026: shear cell 228 and 1 025, triaxial 300)
    recs = [("A", 200, 0.25), ("A", 210, 0.25), ("A", 1000, 0.5), ("B", 300, 0.3)]
    beta, lo, hi = size_trend([r for r in recs if r[0] == "A"])
    assert beta == pytest.approx(np.log(2) / np.log(1000 / 205), rel=0.02) and (lo, hi) == pytest.approx((205, 1000), rel=0.02)
    assert speed_factor(recs, "B", 300)[0] == pytest.approx(0.3)
    assert speed_factor(recs, "B", 600)[0] == pytest.approx(0.3 * 2 ** beta)
    # beyond the largest size any scene measured the ratio is held, not extrapolated
    assert speed_factor(recs, "B", 5000)[0] == pytest.approx(speed_factor(recs, "B", 1000)[0])
    # below scene B's size the trend carries it down as far as A measured
    assert speed_factor(recs, "B", 100)[0] == pytest.approx(0.3 * (205 / 300) ** beta, rel=0.02)
    # an engine without a scene of two sizes: held, as before
    assert speed_factor([("B", 300, 0.3)], "B", 2000)[0] == pytest.approx(0.3)


def test_a_quiet_run_stands_in_for_those_that_shared_the_machine():
    from orchestrator.clock import speed_factor
    # YADE, 2 000 grains: one run beside another YADE run (1.22 of the table), one quiet (0.6)
    recs = [("triaxial", 2000, 1.22, False), ("triaxial", 2010, 0.6, True), ("triaxial", 300, 0.3, None)]
    assert speed_factor(recs, "triaxial", 2000)[0] == pytest.approx(0.6, rel=0.01)
    # without a quiet run of that size the shared one is all there is
    assert speed_factor(recs[:1], "triaxial", 2000)[0] == pytest.approx(1.22)


def test_yades_triaxial_on_the_shell_is_its_own_clock_entry():
    from orchestrator.clock import base_kind, clock_key, key_fallbacks, speed_factor
    shell = {"yade.membrane": "shell_pressure", "liggghts.membrane": "shell_pressure"}
    assert clock_key("triaxial", "yade", shell) == "triaxial:shell_pressure"
    assert clock_key("triaxial", "yade", {"liggghts.membrane": "shell_pressure"}) == "triaxial"   # PFacet
    assert clock_key("triaxial", "liggghts", shell) == "triaxial:shell_pressure"
    # a shear cell's frictionless sidewall is LIGGGHTS' analytic cylinder: a key of its own, which the
    # other engines' unchanged decks share until they have runs of it (then "shear_cell")
    assert clock_key("shear_cell", "yade", shell) == "shear_cell:smooth_sidewall"
    assert clock_key("shear_cell", "liggghts", {}, {"wall_friction": "shear"}) == "shear_cell"
    assert key_fallbacks("shear_cell:smooth_sidewall") == ["shear_cell:smooth_sidewall", "shear_cell"]
    assert base_kind("triaxial:shell_pressure") == "triaxial"
    # the membrane costs 3x the shell a step (28 Nov 2026): each boundary's runs set its own factor,
    # and a variant not yet measured falls back to its scene's runs
    recs = [("triaxial", 2000, 1.1, True), ("triaxial:shell_pressure", 2000, 0.35, True)]
    assert speed_factor(recs, "triaxial:shell_pressure", 2000)[0] == pytest.approx(0.35)
    assert speed_factor(recs, "triaxial", 2000)[0] == pytest.approx(1.1)
    assert speed_factor(recs[:1], "triaxial:shell_pressure", 2000)[0] == pytest.approx(1.1)


def test_clump_samples_are_their_own_clock_entry_and_fall_back_to_their_boundarys_spheres():
    from orchestrator.clock import Throughput, clock_key, estimate_engine_time, key_fallbacks, speed_factor
    shell = {"yade.membrane": "shell_pressure", "liggghts.membrane": "shell_pressure",
             "liggghts.placed_clumps": "inserted_clumps"}
    clumps = {"particles": {"shape": "clumps", "library": "shapes/ct_synthetic.yaml"}}
    assert clock_key("triaxial", "yade", shell, clumps) == "triaxial:shell_pressure+clumps"
    assert clock_key("triaxial", "liggghts", shell, clumps) == "triaxial:shell_pressure+clumps"
    assert clock_key("triaxial", "yade", {}, clumps) == "triaxial:clumps"          # PFacet membrane
    assert clock_key("triaxial", "yade", shell, {"particles": {"shape": "spheres"}}) == "triaxial:shell_pressure"
    assert key_fallbacks("triaxial:shell_pressure+clumps") == ["triaxial:shell_pressure+clumps",
                                                               "triaxial:shell_pressure", "triaxial"]
    # not measured yet: the same boundary's sphere entry stands in (not the PFacet one), and the
    # basis names it; once measured, its own entry
    sphere = Throughput(0.0, 0.0, 1e-6, 0.7, 2, "")
    pfacet = Throughput(0.0, 3e-3, 1e-6, 0.7, 3, "")
    table = {"yade": {"triaxial": pfacet, "triaxial:shell_pressure": sphere}}
    t, basis = estimate_engine_time("yade", "triaxial:shell_pressure+clumps", 32000, 1000, table=table)
    assert t == pytest.approx(1000 * 32000 * 1e-6) and "the triaxial:shell_pressure entry" in basis
    table["yade"]["triaxial:shell_pressure+clumps"] = Throughput(0.0, 0.0, 2.2e-6, 0.7, 1, "")
    t, basis = estimate_engine_time("yade", "triaxial:shell_pressure+clumps", 32000, 1000, table=table)
    assert t == pytest.approx(1000 * 32000 * 2.2e-6) and basis.startswith("measured on 1 yade")
    recs = [("triaxial", 2000, 1.1, True), ("triaxial:shell_pressure", 2000, 0.35, True)]
    assert speed_factor(recs, "triaxial:shell_pressure+clumps", 32000)[0] == pytest.approx(0.35, rel=0.2)


def test_an_unmeasured_variant_counts_its_steps_from_the_engine_that_ran_it():
    """How many steps a triaxial's stage 1 takes is the sample's physics: a clump sample took 9.7
    pressure-ramp lengths on LIGGGHTS where spheres take 2.5-4.2 on either engine. YADE without a
    clump run of its own keeps its sphere entry's cost per step but counts the steps LIGGGHTS' clump
    runs took, and says so; once it has its own entry, its own units count."""
    case = load_case("cases/triaxial_smoke.yaml")
    plan = step_plan("triaxial", derive(case)["scene"])
    key = "triaxial:shell_pressure+clumps"
    sphere = Throughput(1.0, 1e-4, 1e-6, runs=3, units=2.5)
    clumps_elsewhere = Throughput(1.0, 1e-4, 1e-6, runs=2, units=9.7)
    table = {"yade": {"triaxial": sphere}, "liggghts": {key: clumps_elsewhere}}
    budget = plan.steps(plan.max_units)
    steps, lead = planned_steps(table, "yade", key, budget, plan)
    assert lead == ("liggghts", 9.7) and steps == plan.steps(9.7) > plan.steps(2.5)
    t, basis = estimate_engine_time("yade", key, 300, budget, table=table, plan=plan, machine_speed=False)
    assert t == pytest.approx(sphere.engine_time(300, plan.steps(9.7)))
    assert "its steps as liggghts took them (9.7 plan units)" in basis
    table["yade"][key] = Throughput(1.0, 1e-4, 1e-6, runs=1, units=6.0)          # YADE's own clump run
    assert planned_steps(table, "yade", key, budget, plan) == (plan.steps(6.0), None)
    assert planned_steps(table, "yade", "triaxial", budget, plan) == (plan.steps(2.5), None)


def test_ratios_recorded_against_a_since_refitted_entry_are_left_out(tmp_path, monkeypatch):
    """This machine's speed is a ratio to a package entry: once the entry is refitted (here a new
    variant gets its own entry where its fallback stood in), the ratios recorded against the old one
    say nothing and are left out; rows of before the record kept its entry still count."""
    import orchestrator.clock as clock
    pkg = tmp_path / "package.json"
    base = asdict(Throughput(1.0, 1e-4, 1e-6, runs=3))
    pkg.write_text(json.dumps({"liggghts": {"shear_cell": base}}))
    monkeypatch.setattr(clock, "package_table_path", lambda: pkg)
    monkeypatch.setenv("ORCHESTRATOR_MACHINE_SPEED", str(tmp_path / "speed.json"))
    n, steps, key = 1025, 100_000, "shear_cell:smooth_sidewall"
    d = tmp_path / "runs" / "a"
    d.mkdir(parents=True)
    t = 0.6 * Throughput(**base).engine_time(n, steps)
    (d / "summary.json").write_text(json.dumps({
        "engine": "liggghts", "status": "complete", "steps": steps, "steps_run": steps, "n_particles": n,
        "workers": 1, "clock_key": key, "wall_time": {"engine": t, "engine_loop": t - 1.0}}))
    (d / "params.json").write_text(json.dumps({"scene": {"n": n}}))
    (d / "case.yaml").write_text("scene: {kind: shear_cell}\n")
    (d / "attempts.json").write_text(json.dumps([{"cores": 2, "load": 1.0, "wall_s": t, "cpu_s": t, "done": True}]))
    assert clock.record_speed(d) == pytest.approx(0.6, rel=1e-3)
    assert clock.machine_factor("liggghts", key, n)[0] == pytest.approx(0.6, rel=1e-3)
    # the variant's own entry, fitted on this machine's runs: the old ratio no longer applies
    pkg.write_text(json.dumps({"liggghts": {"shear_cell": base, key: asdict(Throughput(1.0, 6e-5, 6e-7, runs=4))}}))
    assert clock.machine_factor("liggghts", key, n) is None
    # a row recorded before rows named their entry still counts
    table = json.loads((tmp_path / "speed.json").read_text())
    for rows in table.values():
        for r in rows["liggghts"]:
            r.pop("against")
    (tmp_path / "speed.json").write_text(json.dumps(table))
    assert clock.machine_factor("liggghts", key, n)[0] == pytest.approx(0.6, rel=1e-3)
    # an entry fitted on this machine's own runs (clock refresh): no ratio is recorded against it,
    # and its estimates take no machine factor
    here = asdict(replace(Throughput(1.0, 6e-5, 6e-7, runs=4), machine=clock.machine_id()))
    pkg.write_text(json.dumps({"liggghts": {"shear_cell": base, key: here}}))
    assert clock.record_speed(d) is None
    t_here, basis = clock.estimate_engine_time("liggghts", key, n, steps)
    assert t_here == pytest.approx(Throughput(**here).engine_time(n, steps)) and "machine" not in basis


def test_an_estimate_on_several_ranks_says_when_their_efficiency_is_assumed():
    """YADE's two OpenMP threads ran the 4 108-grain shear cell 1.33-1.52x faster than one
    (docs/engines.md), where the assumed efficiency 0.7 says 1.7x: an estimate on several ranks or
    threads from an entry no such run was fitted on says so beside the figure (the dry run's line),
    and one whose efficiency runs measured does not."""
    def run(n, ranks, loop):
        return RunSample("yade", "shear_cell", n, 10_000, ranks, loop + 5.0, loop, f"r{n}-{ranks}")
    single = fit([run(1000, 1, 30.0), run(4000, 1, 120.0)])
    both = fit([run(1000, 1, 30.0), run(4000, 1, 120.0), run(4000, 2, 80.0)])
    assert not single.efficiency_measured and both.efficiency_measured
    assert Throughput(1.0, 0.0, 1e-7, parallel_efficiency=0.45).efficiency_measured     # a user's own figure
    assert both.parallel_efficiency == pytest.approx(0.5, rel=1e-6)        # 120 s on one, 80 s on two
    for tp, ranks, said in ((single, 2, True), (single, 1, False), (both, 2, False)):
        t, basis = estimate_engine_time("yade", "shear_cell", 4000, 10_000, ranks, table={"yade": {"shear_cell": tp}})
        note = _basis_note(basis)
        assert ("2 ranks or threads at an assumed parallel efficiency of 0.7" in note) is said, (ranks, note)
        assert t == pytest.approx(tp.engine_time(4000, 10_000, ranks))


def test_a_runs_recorded_estimate_is_the_dry_runs_figure(tmp_path, monkeypatch):
    """The estimate a run records at its start (summary.json: `orchestrator status`' "left: clock",
    the report) is the figure its dry run printed, this machine's speed factor included: from
    session 30 to 33 it was taken without the factor (YADE's clump triaxial recorded 10.7 h where
    its dry run said 7.5 h, × 0.70 for this machine's speed)."""
    import orchestrator.clock as clock
    from orchestrator.sizing import clock_inputs, run_estimate
    monkeypatch.setattr(clock, "machine_id", lambda: "a test machine x2")     # no entry was fitted on it
    monkeypatch.setenv("ORCHESTRATOR_MACHINE_SPEED", str(tmp_path / "speed.json"))
    monkeypatch.setenv("ORCHESTRATOR_THROUGHPUT", str(tmp_path / "user.json"))      # no user table
    case = load_case("cases/triaxial_smoke.yaml")
    params = derive(case)
    key = clock_inputs(case, params["scene"], "yade")[0]
    (tmp_path / "speed.json").write_text(json.dumps({"a test machine x2": {"yade": [
        {"run": "r", "scene": key, "n": 300, "ratio": 0.5, "quiet": True}]}}))
    dry = estimate(case, params, "yade")
    assert "× 0.50 for this machine's speed" in dry["engine_time_basis"]
    seconds, steps = run_estimate(case, params, "yade")
    assert seconds == pytest.approx(dry["engine_time_s"]) and steps == dry["steps_expected"]


def test_clock_refresh_takes_its_options_before_or_after_the_runs():
    """``orchestrator clock refresh --add RUNS`` (the form docs/validation.md gives) once stopped at
    "unrecognized arguments: RUNS": the runs list after a choice took nothing once an option stood
    between them. show and refresh are sub-commands now; both orders parse alike."""
    from orchestrator.cli import build_parser
    for argv in (["clock", "refresh", "--add", "r1", "r2"], ["clock", "refresh", "r1", "r2", "--add"],
                 ["clock", "refresh", "--package", "--steps-only", "r1", "r2"]):
        args = build_parser(argv).parse_args(argv)
        assert args.action == "refresh" and args.runs == ["r1", "r2"], argv
    args = build_parser(["clock", "refresh"]).parse_args(["clock", "refresh"])
    assert args.runs == ["runs"] and not args.add
    args = build_parser(["clock", "show"]).parse_args(["clock", "show"])
    assert args.action == "show" and args.func.__name__ == "cmd_clock"


def test_clock_show_lists_this_machines_runs(tmp_path, monkeypatch, capsys):
    """`orchestrator clock show` lists the runs behind this machine's factors, each with its ranks or
    threads and its ratio to the package table (the figures docs/validation.md quotes: YADE's small
    shear cell 0.301 on one thread, 0.593 on two, session 38)."""
    from orchestrator.cli import main
    from orchestrator.clock import machine_id
    monkeypatch.setenv("ORCHESTRATOR_MACHINE_SPEED", str(tmp_path / "speed.json"))
    monkeypatch.setenv("ORCHESTRATOR_THROUGHPUT", str(tmp_path / "user.json"))
    monkeypatch.setenv("COLUMNS", "250")
    (tmp_path / "speed.json").write_text(json.dumps({machine_id(): {"yade": [
        {"run": "/r/one", "scene": "shear_cell:smooth_sidewall", "n": 1025, "ratio": 0.3006, "quiet": True, "ranks": 1},
        {"run": "/r/two", "scene": "shear_cell:smooth_sidewall", "n": 1025, "ratio": 0.5932, "quiet": True, "ranks": 2}]}}))
    assert main(["clock", "show"]) == 0
    rows = [l for l in capsys.readouterr().out.splitlines() if "/r/" in l]
    cells = [[c.strip() for c in l.split("│")[1:-1]] for l in rows]
    assert [c[3:6] + [c[6]] for c in cells] == [["1", "0.301", "yes", "/r/one"], ["2", "0.593", "yes", "/r/two"]]
