"""A convergence ladder of three runs on a tiny case: table, plot, Pareto front, recommendation."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from orchestrator.stability.convergence import extrapolations, ladder, pareto, relative_error, rung_means
from orchestrator.stability.extrapolation import extrapolate, fidelity_distance, knob_value

CASE = Path(__file__).resolve().parents[2] / "cases" / "stability" / "mu1.yaml"


def test_pareto_and_errors():
    assert pareto(np.array([1.0, 2.0, 3.0, 4.0]), np.array([0.5, 0.6, 0.1, 0.2])) == [0, 2]
    assert relative_error(1.1, 1.0) == pytest.approx(0.1)
    assert relative_error([1, 1], [1, 2]) == pytest.approx(1 / np.sqrt(5))


def test_extrapolation_recovers_a_law_exactly_and_bounds_the_cheapest_setting():
    # stiffness: y = 0.5 + 0.3 h with h = s^(-2/3); the seed is 100x stiffer than the case (full = 100)
    s = np.array([1.0, 2.0, 4.0])
    y = 0.5 + 0.3 * s ** (-2 / 3)
    r = extrapolate("stiffness_scale", s, y, full=100, tolerance=0.05, times=[50.0, 70.0, 100.0])
    y_full = 0.5 + 0.3 * 100 ** (-2 / 3)
    assert r["value_full"] == pytest.approx(y_full, rel=1e-12)
    assert r["sem_full"] < 1e-12 and r["slope"] == pytest.approx(0.3)
    # the cheapest stiffness is exactly 5 % away from full fidelity, and it lies above the ladder
    y_cheap = 0.5 + 0.3 * r["cheapest"] ** (-2 / 3)
    assert abs(y_cheap - y_full) == pytest.approx(0.05 * y_full, rel=1e-9)
    assert r["cheapest"] > 4 and r["where"].startswith("finer than every rung")
    # engine time from the power law through the rungs: t = 50 s^q
    q = np.polyfit(np.log(s), np.log([50.0, 70.0, 100.0]), 1)[0]
    assert r["cheapest_time_s"] == pytest.approx(np.exp(np.polyfit(np.log(s), np.log([50.0, 70.0, 100.0]), 1)[1])
                                                 * r["cheapest"] ** q, rel=1e-9)
    # the ideal limits and the inverse map
    assert fidelity_distance("count", [None])[0] == 0 and fidelity_distance("dt_fraction", [0.4])[0] == 0.4
    assert knob_value("count", fidelity_distance("count", [8000])[0]) == pytest.approx(8000)
    # two rungs without standard errors: an exact line, its uncertainty unknown and said so
    r2 = extrapolate("dt_fraction", [0.4, 0.2], [1.2, 1.1])
    assert r2["value_full"] == pytest.approx(1.0) and np.isnan(r2["sem_full"]) and "unknown" in r2["note"]


def test_extrapolation_uncertainty_covers_the_truth_at_its_stated_rate():
    # noisy rungs of a known law (rate ladder, quasi-static limit): the 1-sigma interval of the
    # extrapolated value holds the truth in ~68 % of 400 ladders, with the rungs' sems and without
    rng = np.random.default_rng(7)
    v = np.array([0.5, 1.0, 2.0, 4.0])
    for sems in (True, False):
        hits = 0
        for _ in range(400):
            y = 0.55 + 0.02 * v + rng.normal(0.0, 0.004, v.size)
            r = extrapolate("rate_scale", v, y, y_sem=[0.004] * v.size if sems else None)
            hits += abs(r["value_full"] - 0.55) <= r["sem_full"]
        assert 0.60 <= hits / 400 <= 0.90, (sems, hits)


def test_seeds_give_each_rung_its_mean_and_run_to_run_error():
    import pandas as pd
    # two seeds per rung: y = 0.5 + 0.1 h +- 0.01 (seed 1 high, seed 2 low)
    rows = [{"engine": "liggghts", "rate_scale": v, "seed": sd, "status": "complete", "engine_time_s": 100 / v,
             "mu_macro": 0.5 + 0.1 * v + (0.01 if sd == 1 else -0.01), "mu_macro_sem": None}
            for v in (2.0, 1.0, 0.5) for sd in (1, 2)]
    df = pd.DataFrame(rows)
    vals, y, sem, t = rung_means(df, "rate_scale", "mu_macro")
    assert vals.tolist() == [2.0, 1.0, 0.5]
    # std of (+0.01, -0.01) is 0.02/sqrt(2), its standard error over two seeds 0.01
    assert np.allclose(y, [0.7, 0.6, 0.55]) and np.allclose(sem, 0.01) and np.allclose(t, [50, 100, 200])
    ext = extrapolations(df, "rate_scale")
    row = ext[ext["observable"] == "mu_macro"].iloc[0]
    # the means lie on the line: the interval is the seeds' standard error propagated to h = 0
    assert row["rungs"] == 3 and row["value_full"] == pytest.approx(0.5)
    h = np.array([2.0, 1.0, 0.5])
    A = np.column_stack([np.ones(3), h])
    cov = np.linalg.inv(A.T @ A) * 0.01 ** 2
    assert row["sem_full"] == pytest.approx(np.sqrt(cov[0, 0]))


def test_a_run_whose_sample_is_not_the_cases_is_marked_and_left_out_of_the_fit():
    import pandas as pd
    # the rows of test_seeds_...: the law y = 0.5 + 0.1 h, plus a run at rate 2 whose sample failed
    # its scene's check (a triaxial's stage 1 unconverged) and whose value is far off the law
    rows = [{"engine": "liggghts", "rate_scale": v, "seed": sd, "status": "complete", "sample": "ok",
             "engine_time_s": 100 / v, "mu_macro": 0.5 + 0.1 * v} for v in (2.0, 1.0, 0.5) for sd in (1, 2)]
    rows[1].update(sample="stage 1 ended unconverged", mu_macro=0.2)
    ext = extrapolations(pd.DataFrame(rows), "rate_scale")
    row = ext[ext["observable"] == "mu_macro"].iloc[0]
    assert row["value_full"] == pytest.approx(0.5) and row["slope"] == pytest.approx(0.1)


def test_the_triaxial_and_shear_cell_read_their_own_sample_checks(tmp_path):
    import json
    from orchestrator.registry import get_scene
    tri, cell = tmp_path / "tri", tmp_path / "cell"
    tri.mkdir(), cell.mkdir()
    (tri / "params.json").write_text(json.dumps({"scene": {"iso": {"tolerance": 0.01}}}))
    iso = {"converged": False, "sigma1_error": -0.015, "sigma3_error": 0.0}
    (tri / "summary.json").write_text(json.dumps({"scene": {"isotropic_end": iso}, "case_source": "/c/t.yaml"}))
    (tri / "case.yaml").write_text("scene: {kind: triaxial, isotropic: {max_chunks: 20}}\n")
    (msg,) = get_scene("triaxial").sample_problems(tri)
    assert "unconverged" in msg and "0.985" in msg
    # the case field that fixes it, with the file and its value (the default where the case is silent)
    assert "scene.isotropic.max_chunks in /c/t.yaml (now 20)" in msg
    assert "scene.isotropic.inertial_number in /c/t.yaml (now 0.001)" in msg
    iso["converged"] = True
    (tri / "summary.json").write_text(json.dumps({"scene": {"isotropic_end": iso}}))
    assert get_scene("triaxial").sample_problems(tri) == []
    for err, n in ((-0.025, 1), (0.019, 0)):
        (cell / "shear_cell_checks.json").write_text(json.dumps({"compression": {"relative_error": err}}))
        assert len(get_scene("shear_cell").sample_problems(cell)) == n
    assert get_scene("impact").sample_problems(tmp_path) == []          # nothing to say


@pytest.mark.engine
def test_dt_ladder(runs_root, tmp_path, engines_installed):
    # rungs below the pre-run check's safe limit for this case (0.48 of the critical step, coordination)
    said = []          # one line a run as it ends (or is found complete): a ladder of hours says how far it is
    out = ladder(CASE, "dt_fraction", [0.4, 0.2, 0.1], engines=["liggghts"], runs_root=runs_root,
                 target_error=0.2, plot=tmp_path / "ladder.png", on_result=lambda t, r: said.append(t["point"]))
    df = out["table"]
    assert len(df) == 3 and (df["status"] == "complete").all()
    assert sorted(p["dt_fraction"] for p in said) == [0.1, 0.2, 0.4]
    assert df["reference"].tolist() == [False, False, True]
    assert df.loc[2, "error"] == 0.0
    assert np.isfinite(df.loc[:1, "error"]).all()
    # more steps cost more engine time
    t = df["engine_time_s"].to_numpy()
    assert t[0] < t[2]
    assert "err_mu_macro" in df.columns
    assert (tmp_path / "ladder.png").stat().st_size > 5000
    ext = out["extrapolation"]
    mu = ext[(ext["engine"] == "liggghts") & (ext["observable"] == "mu_macro")]
    assert len(mu) == 1 and mu["rungs"].iloc[0] == 3 and np.isfinite(mu["value_full"].iloc[0])
    rec = out["recommendation"]["liggghts"]
    assert rec["dt_fraction"] in (0.4, 0.2, 0.1)
    if "note" not in rec:
        assert rec["error"] <= 0.2
    # every rung on each seed: seed 7 is the case's own, so two of these four runs are the ones above
    out = ladder(CASE, "dt_fraction", [0.4, 0.2], engines=["liggghts"], runs_root=runs_root, seeds=[7, 8],
                 target_error=0.2, plot=tmp_path / "ladder_seeds.png")
    df = out["table"]
    assert len(df) == 4 and (df["status"] == "complete").all()
    assert sorted(zip(df["dt_fraction"], df["seed"])) == [(0.2, 7), (0.2, 8), (0.4, 7), (0.4, 8)]
    # each seed is compared with the reference rung's run of the same seed
    assert df.loc[df["reference"], "seed"].tolist() == [7, 8] and (df.loc[df["reference"], "error"] == 0).all()
    assert len(set(df["run_id"])) == 4          # four packings and time steps, four runs
    mu = out["extrapolation"].query("observable == 'mu_macro'").iloc[0]
    assert mu["rungs"] == 2 and np.isfinite(mu["sem_full"])     # two rungs, but their seeds' errors


def test_refused_rung_is_a_row_that_says_why(runs_root):
    # dt_fraction 1.0 is above the coordination limit's safe fraction for this case: refused, not run;
    # the row's sample column and the line said as the rung ends carry the reason (a refused rung
    # was a row of nan without one: `--values 0 1` for size_scale)
    said = []
    out = ladder(CASE, "dt_fraction", [1.0], engines=["liggghts"], runs_root=runs_root, reference=1.0,
                 on_result=lambda task, res: said.append((task["point"], res)))
    row = out["table"].loc[0]
    assert row["status"] == "refused" and "is unsafe" in row["sample"]
    assert said == [({"dt_fraction": 1.0}, {"status": "refused", "error": row["sample"]})]


def test_a_misspelt_knob_or_field_is_one_message_before_any_run(tmp_path):
    """A knob or --set field the case has no place for is bad input, refused before any rung is
    planned (it made every rung a 'refused' row and the command end with status 0), with the
    nearest name; a value the pre-run check refuses stays a row (above)."""
    from orchestrator.case import CaseError
    from orchestrator.stability.sweep import sweep
    with pytest.raises(CaseError, match=r"--knob stifness_scale: unknown field; did you mean 'stiffness_scale'"):
        ladder(CASE, "stifness_scale", [1, 2], engines=["liggghts"], runs_root=tmp_path)
    with pytest.raises(CaseError, match=r"--knob scene.normal_stres: unknown field; did you mean 'normal_stress'.*"
                                        r"\(under scene\)"):
        ladder(CASE, "scene.normal_stres", [1, 2], engines=["liggghts"], runs_root=tmp_path)
    with pytest.raises(CaseError, match=r"--set contact.fricton: unknown field; did you mean 'friction'"):
        sweep(CASE, ["contact.fricton=0.1,0.2"], engines=["liggghts"], runs_root=tmp_path)
    assert not any(tmp_path.iterdir())                 # nothing planned, nothing written


def test_size_and_count_knobs_scale_each_scene_as_it_defines_its_size():
    # issue #15 item 4: the system-size ladders; no engine, only the derived scene
    from orchestrator.case import load_case
    from orchestrator.derive import derive
    from orchestrator.stability.convergence import knob_overrides

    cases = Path(__file__).resolve().parents[2] / "cases"

    def derived(name, knob, value):
        c = load_case(cases / name, overrides=knob_overrides(cases / name, knob, value))
        return c, derive(c)["scene"]

    # shear cell: the diameter doubles at the same fill height, so the grain count grows ~4x
    c1, s1 = derived("shear_cell_small.yaml", "size_scale", 1)
    c2, s2 = derived("shear_cell_small.yaml", "size_scale", 2)
    assert c2.scene.cell_diameter == pytest.approx(2 * c1.scene.cell_diameter)
    assert c2.scene.fill_height == c1.scene.fill_height and c2.scene.gap == c1.scene.gap
    assert 3.5 < s2["n"] / s1["n"] < 4.5
    # triaxial: grains x scale^3; count sets the same field
    t, _ = derived("triaxial_small.yaml", "size_scale", 0.5)
    assert t.scene.grains == 250
    t, _ = derived("triaxial_small.yaml", "count", 1000)
    assert t.scene.grains == 1000
    # a scene without the knob, or a value that is not one, is one message naming the case and knob
    from orchestrator.case import CaseError
    impact = cases / "verification" / "chung_ooi_1_sphere_sphere_glass.yaml"
    for knob, value, says in (("size_scale", 2, "no size_scale knob"), ("count", 10, "no grain count"),
                              ("count", "abc", "'abc' is not a whole number")):
        with pytest.raises(CaseError, match=says):
            knob_overrides(impact if value != "abc" else cases / "triaxial_small.yaml", knob, value)
    # h = 1/size: the ideal limit is the infinite system
    assert fidelity_distance("size_scale", [2.0])[0] == pytest.approx(0.5)
    assert knob_value("size_scale", 0.25) == pytest.approx(4.0)


@pytest.mark.engine                  # the run directories' names probe the engine's version
def test_a_dry_run_lists_the_runs_their_estimates_and_what_is_reused(tmp_path):
    """``convergence --dry-run`` and ``sweep --dry-run``: every run the command would make, before
    any (nothing packed, nothing written under the runs root), each with its size and estimated
    engine time (as ``run --dry-run`` gives it), a complete run reused, a rung the loader refuses
    with its reason, and the CLI's total of the runs to do."""
    from orchestrator.case import load_case
    from orchestrator.cli import main
    from orchestrator.derive import derive
    from orchestrator.sizing import estimate
    from orchestrator.stability.convergence import knob_overrides, ladder_plan
    from orchestrator.stability.sweep import sweep_plan
    plan = ladder_plan(CASE, "dt_fraction", [0.2, 0.3, 1.0], engines=["liggghts"], runs_root=tmp_path, seeds=[7])
    assert list(plan["dt_fraction"]) == [0.2, 0.3, 1.0] and list(plan["seed"]) == [7, 7, 7]
    assert list(plan["status"]) == ["to run", "to run", "refused"] and "is unsafe" in plan["note"].iloc[2]
    case = load_case(CASE, overrides=dict(knob_overrides(CASE, "dt_fraction", 0.2), seed=7))
    size = estimate(case, derive(case), "liggghts")
    assert plan["engine_time_s"].iloc[0] == pytest.approx(size["engine_time_s"])
    assert plan["particles"].iloc[0] == size["particles"] and plan["steps"].iloc[0] == size["steps_expected"]
    assert not any(tmp_path.iterdir())                         # nothing planned is written
    # a complete run under the runs root is reused; one started before resumes, and says so
    done, started = (Path(p) for p in plan["run_dir"].iloc[:2])
    for d, status in ((done, "complete"), (started, "interrupted")):
        d.mkdir(parents=True)
        (d / "summary.json").write_text(f'{{"status": "{status}", "steps_run": 100}}')
    (done / "frames.h5").write_bytes(b"")
    again = ladder_plan(CASE, "dt_fraction", [0.2, 0.3, 1.0], engines=["liggghts"], runs_root=tmp_path, seeds=[7])
    assert list(again["status"]) == ["reused", "to run", "refused"] and "resumes" in again["note"].iloc[1]
    (started / "summary.json").write_text('{"status": "unstable"}')     # reused as the ladder reuses it
    assert ladder_plan(CASE, "dt_fraction", [0.3], engines=["liggghts"], runs_root=tmp_path,
                       seeds=[7])["status"].tolist() == ["reused"]
    sw = sweep_plan(CASE, ["timestep.fraction=0.2,1.0"], engines=["liggghts"], runs_root=tmp_path)
    assert list(sw["timestep.fraction"]) == [0.2, 1.0] and list(sw["status"]) == ["reused", "refused"]
    # the CLI: the table and the total of the runs to do; 2 when every run is refused
    assert main(["convergence", str(CASE), "--knob", "dt_fraction", "--values", "0.3", "--engine", "liggghts",
                 "--runs", str(tmp_path), "--seeds", "7", "--dry-run"]) == 0
    assert main(["sweep", str(CASE), "--set", "timestep.fraction=1.0", "--engine", "liggghts", "--runs",
                 str(tmp_path), "--dry-run"]) == 2


@pytest.mark.engine                  # the run directories' names probe the engine's version
def test_a_ladder_run_rung_by_rung_shows_each_rungs_progress_under_its_name(monkeypatch):
    """A ladder of hour-long rungs printed nothing between two rungs' ends: run one rung at a time
    on this machine, each rung's progress lines now show, named by engine, case, knob value and
    seed (``run_task``'s ``progress`` label); several workers or a cluster keep them off."""
    from orchestrator.stability import convergence
    seen = []

    class Recorder:
        def __init__(self, workers):
            self.workers = workers

        def run(self, fn, tasks):
            seen.append([t.get("progress") for t in tasks])
            return iter([(j, {"status": "failed", "error": "not run"}) for j in range(len(tasks))])

        def close(self):
            pass
    for workers in (1, 2):
        monkeypatch.setattr(convergence, "get_executor", lambda scheduler, w, n=workers: Recorder(n))
        convergence.ladder(CASE, "dt_fraction", [0.2, 0.3], engines=["liggghts"], runs_root="/nonexistent/runs",
                           seeds=[7], reference=0.3)
    assert seen == [["liggghts mu1 dt_fraction=0.2 seed 7", "liggghts mu1 dt_fraction=0.3 seed 7"], [None, None]]
