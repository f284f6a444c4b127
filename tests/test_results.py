"""Key results of a run (orchestrator.results): precision rules and the figures read from a run
directory's own files."""
from __future__ import annotations

import json

import numpy as np
import pytest
import pandas as pd
import yaml

from orchestrator.registry import get_scene
from orchestrator.clock import engine_seconds
from orchestrator.results import estimate_note, format_measure, key_results, results_frame


def test_format_measure_keeps_two_significant_digits_of_the_error():
    assert format_measure(0.57123, 0.1312) == "0.57 ± 0.13"
    assert format_measure(123.456, 7.89, "µm") == "123.5 ± 7.9 µm"
    assert format_measure(0.001234, None) == "0.001234"
    assert format_measure(float("nan"), 1.0) == "n/a"
    assert format_measure(2.5, 0.0, "°") == "2.5 °"
    # large figures without an error written out, four significant digits, not in e-notation
    assert format_measure(16067.3, None, "s") == "16,070 s"
    assert format_measure(9999.7, None) == "10,000"
    assert format_measure(1234.5, None) == "1234"
    assert format_measure(2e9, None) == "2e+09"


def _fake_shear_cell_run(tmp_path):
    run = tmp_path / "run"
    adir = run / "analysis"
    adir.mkdir(parents=True)
    (run / "case.yaml").write_text(yaml.safe_dump({"name": "x", "scene": {"kind": "shear_cell"}}))
    (run / "params.json").write_text(json.dumps({"scene": {"x50": 30e-6}}))
    (run / "summary.json").write_text(json.dumps({
        "status": "complete", "wall_time": {"engine": 200.0}, "estimated_engine_time_s": 180.0,
        "substitutions": [{"feature": "adhesion", "mechanism": "sjkr", "note": ""}]}))
    (run / "shear_cell_checks.json").write_text(json.dumps({"lower_piston_force": {"relative_error": 0.011}}))
    asum = {"friction": {"name": "friction", "status": "ok", "scalars": {"mu_mean": 0.41, "mu_std": 0.05, "n": 30}},
            "shearband": {"name": "shearband", "status": "ok", "scalars": {}}}
    (adir / "analysis_summary.json").write_text(json.dumps(asum))
    pd.DataFrame({"r_tilde": [0.5, 0.7], "z_sb": [100e-6, 120e-6], "z_sb_err": [3e-6, 4e-6],
                  "w_sb": [200e-6, 260e-6], "w_sb_err": [10e-6, 20e-6], "n_fits": [5, 5]}
                 ).to_csv(adir / "shearband_steady.csv", index=False)
    return run


def test_shear_cell_key_results_from_the_run_files(tmp_path):
    rows = {r.quantity: r for r in key_results(_fake_shear_cell_run(tmp_path))}
    assert rows["μ_macro (steady)"].value == 0.41 and rows["μ_macro (steady)"].error == 0.05
    z = next(r for q, r in rows.items() if q.startswith("band position z_sb"))
    assert np.isclose(z.value, 110.0) and z.unit == "µm"
    # fit errors combined (2.5 µm) and radius spread std/sqrt(2) = 10 µm, in quadrature
    assert np.isclose(z.error, np.hypot(np.hypot(3, 4) / 2, np.std([100, 120], ddof=1) / np.sqrt(2)))
    assert np.isclose(rows["band width w_sb / x50"].value, 230e-6 / 30e-6)
    assert rows["band width w_sb"].seed.startswith("≈ 8 x50 = 240")
    assert rows["band fitted"].ok is True
    assert next(r for q, r in rows.items() if q.startswith("servo force vs target")).ok is True
    assert rows["substitutions"].value == "adhesion → sjkr"
    df = results_frame(tmp_path / "run")
    assert list(df.columns[:2]) == ["quantity", "text"]


def test_engine_time_of_a_resumed_run_says_it_covers_only_the_last_part(tmp_path):
    run = _fake_shear_cell_run(tmp_path)
    rows = {r.quantity: r for r in key_results(run)}
    assert rows["engine time"].seed == "estimated 180 s before the run"
    s = json.loads((run / "summary.json").read_text())
    s["resumed_from"] = {"step": 235750, "restart_file": "restart/state.235750.restart"}
    (run / "summary.json").write_text(json.dumps(s))
    rows = {r.quantity: r for r in key_results(run)}
    assert rows["engine time"].value == 200.0
    assert rows["engine time"].seed == ("resumed from step 235750: this part only; the whole run was estimated "
                                        "180 s before the run")
    # with the record of every attempt (orchestrator.attempts): the whole run's engine time
    s["steps_run"] = 400000
    s["attempts"] = [{"first_step": 0, "last_step": 240000, "wall_s": 120.0, "cpu_s": 110.0, "done": False},
                     {"first_step": 235750, "last_step": 400000, "wall_s": 200.0, "cpu_s": 190.0, "done": True}]
    (run / "summary.json").write_text(json.dumps(s))
    rows = {r.quantity: r for r in key_results(run)}
    assert rows["engine time"].value == pytest.approx(120.0 + 200.0 * 160000 / 164250)
    # one rank: the whole run's CPU time too (110 s + 190 s x the new share of the last attempt), the
    # figure the clock counts: the wall time holds whatever waiting or pausing the attempts met
    cpu = 110.0 + 190.0 * 160000 / 164250
    assert rows["engine time"].seed == (f"{cpu:.4g} s of CPU; the whole run, 2 attempts (the last, resumed from "
                                        "step 235750, 200 s); estimated 180 s before the run")
    # several ranks: no CPU figure (a rank waiting for the other polls)
    s["workers"] = 2
    (run / "summary.json").write_text(json.dumps(s))
    rows = {r.quantity: r for r in key_results(run)}
    assert rows["engine time"].seed.startswith("the whole run, 2 attempts")


def test_a_resumed_run_keeps_the_estimate_made_before_its_first_attempt(tmp_path):
    # the YADE medium shear cell of session 38: estimated 89.3 min before the run; its resumed attempt,
    # with more of the machine's speed records, estimated the whole run at 118.6 min
    run = _fake_shear_cell_run(tmp_path)
    s = json.loads((run / "summary.json").read_text())
    s.update(estimated_engine_time_s=7115.0, first_estimated_engine_time_s=5358.0,
             resumed_from={"step": 378189})
    (run / "summary.json").write_text(json.dumps(s))
    assert estimate_note(s) == "estimated 5358 s before the run (7115 s before its last attempt)"
    rows = {r.quantity: r for r in key_results(run)}
    assert rows["engine time"].seed.endswith("estimated 5358 s before the run (7115 s before its last attempt)")
    s["first_estimated_engine_time_s"] = 7115.2         # the same estimate: said once
    assert estimate_note(s) == "estimated 7115 s before the run"
    del s["first_estimated_engine_time_s"]              # a summary from before the first was kept
    assert estimate_note(s) == "estimated 7115 s before the run"
    assert estimate_note({}) == ""


def test_a_paused_engine_is_said_and_the_clock_counts_it_running(tmp_path):
    # two ranks, 200 s of wall time of which the engine spent 50 s stopped (SIGSTOP, a suspend)
    run = _fake_shear_cell_run(tmp_path)
    s = json.loads((run / "summary.json").read_text())
    s["workers"] = 2
    s["wall_time"]["engine_paused"] = 50.0
    (run / "summary.json").write_text(json.dumps(s))
    row = {r.quantity: r for r in key_results(run)}["engine time"]
    assert row.value == 200.0
    assert row.seed == "150 s running; 50 s of it paused (the engine stopped); estimated 180 s before the run"
    assert engine_seconds(s) == 150.0


def test_no_band_is_said_not_hidden(tmp_path):
    run = _fake_shear_cell_run(tmp_path)
    (run / "analysis" / "shearband_steady.csv").write_text("r_tilde,z_sb,z_sb_err,w_sb,w_sb_err,n_fits\n")
    rows = {r.quantity: r for r in key_results(run)}
    assert rows["band fitted"].ok is False


def test_analysis_names_known_without_the_analysis_stack_match_the_registry():
    from orchestrator.analysis import ANALYSES
    from orchestrator.analysis_specs import ANALYSIS_NAMES
    assert sorted(ANALYSIS_NAMES) == sorted(ANALYSES)


def test_analysis_options_known_without_the_analysis_stack_match_the_signatures():
    """The option names ``validate`` checks a case's analyses against (orchestrator.analysis_specs,
    no analysis import) are the keyword parameters of each analysis function after ``frames``; a
    misspelt option is one message naming the entry and the nearest name."""
    import inspect
    from orchestrator.analysis import ANALYSES
    from orchestrator.analysis_specs import ANALYSIS_OPTIONS, parse_specs
    for name, fn in ANALYSES.items():
        params = list(inspect.signature(fn).parameters.values())[1:]
        own = [p.name for p in params if p.kind is not inspect.Parameter.VAR_KEYWORD]
        assert list(ANALYSIS_OPTIONS[name]) == own, name
    assert parse_specs([{"shearband": {"radii": [1e-4]}}, {"clusters": {"top_fraction": 0.1, "cutoff_d50": 2,
                                                                         "interval": 0.01}}])
    with pytest.raises(ValueError, match=r"analysis\[1\] \(shearband\): option 'radiii': unknown option; "
                                         r"did you mean 'radii'\?"):
        parse_specs(["friction", {"shearband": {"radiii": 3}}])


def test_block_drift_finds_a_trend_and_its_error_covers_a_steady_series():
    """orchestrator.numerics.block_drift (issue #15 item 1: 'μ_macro is steady'): a line through 8
    block means; a steady noisy series drifts within 2 se in ~95 % of draws, a climbing one does not."""
    from orchestrator.numerics import block_drift
    rng = np.random.default_rng(3)
    steady = [abs(d) <= 2 * se for d, se in (block_drift(rng.normal(0.6, 0.1, 800)) for _ in range(400))]
    assert 0.85 <= np.mean(steady) <= 0.99
    d, se = block_drift(np.linspace(0.55, 0.68, 800) + rng.normal(0, 0.02, 800))
    assert d == pytest.approx(0.13 * 7 / 8, rel=0.1) and abs(d) > 2 * se    # centre of block 1 to block 8
    assert all(np.isnan(block_drift([1.0, 2.0])))


def test_shear_cell_results_say_whether_mu_macro_is_steady(tmp_path):
    run = _fake_shear_cell_run(tmp_path)
    p = run / "analysis" / "analysis_summary.json"
    asum = json.loads(p.read_text())
    asum["friction"]["scalars"].update({"mu_sem": 0.02, "mu_drift": 0.093, "mu_drift_se": 0.033, "mu_steady": False})
    p.write_text(json.dumps(asum))
    rows = {r.quantity: r for r in key_results(run)}
    drift = next(r for q, r in rows.items() if q.startswith("μ_macro: drift"))
    assert drift.ok is False and drift.text() == "0.093 ± 0.033"
    assert rows["μ_macro: standard error of the mean"].value == 0.02


def test_a_failed_check_says_so_in_words(tmp_path, monkeypatch):
    """The results table marks a failed check with FAIL, not only in red: a log file or a terminal
    without colour (``run --quiet`` into a file) must show it too."""
    import io
    from rich.console import Console
    import orchestrator.results as res
    monkeypatch.setattr(res, "key_results", lambda d: [res.KeyResult("a check (≤ 1 %)", 1.4, "%", ok=False),
                                                       res.KeyResult("a passed one", 0.5, "%", ok=True)])
    buf = io.StringIO()
    res.print_key_results(tmp_path, Console(file=buf, no_color=True, width=100))
    lines = buf.getvalue().splitlines()
    assert any("a check" in l and "FAIL" in l for l in lines)
    assert not any("a passed one" in l and "FAIL" in l for l in lines)


def test_a_run_outcome_shows_itself_in_one_line_and_its_results_in_a_notebook(tmp_path):
    """``run_case`` returns a RunOutcome: in a notebook it shows one line (status, engine, size,
    engine time) and the run's key results, not its whole summary dict."""
    from test_faults import synthetic_run
    from orchestrator.runner import RunOutcome
    run = synthetic_run(tmp_path / "run")
    summary = {"engine": "liggghts", "n_particles": 1025, "wall_time": {"engine": 12.345}, "stability": {"x": list(range(99))}}
    out = RunOutcome(run, "complete", summary, reused=True)
    assert repr(out) == f"<RunOutcome {run}: complete, reused, liggghts, 1,025 particles, engine 12.3 s>"
    page = out._repr_html_()
    assert "<table" in page and "substitutions" in page and "range" not in page and "99" not in page
    assert list(out.results.columns[:2]) == ["quantity", "text"]
    assert "<table" not in RunOutcome(tmp_path / "none", "failed", {})._repr_html_()


def test_a_missed_compression_says_which_case_field_fixes_it(tmp_path):
    """A compression that ended off its load names the case file, the field and its value: below the
    target (the column still collapsing when the stage's fixed length ran out) the stage's length,
    above it (the piston overshot) the piston's speed."""
    run = _fake_shear_cell_run(tmp_path)
    (run / "case.yaml").write_text(yaml.safe_dump({"name": "x", "scene": {"kind": "shear_cell",
                                                                          "travel_time_factor": 1.5}}))
    summary = json.loads((run / "summary.json").read_text())
    (run / "summary.json").write_text(json.dumps({**summary, "case_source": "/cases/mine.yaml"}))
    scene = get_scene("shear_cell")

    def row_and_problem(err):
        (run / "shear_cell_checks.json").write_text(json.dumps({"compression": {"relative_error": err}}))
        row = next(r for r in key_results(run) if r.quantity.startswith("servo force vs target"))
        return row, scene.sample_problems(run)

    row, problems = row_and_problem(-0.82)
    assert row.ok is False and "scene.travel_time_factor in /cases/mine.yaml (now 1.5)" in row.seed
    assert len(problems) == 1 and problems[0].startswith("compression ended -82.0 %") and row.seed in problems[0]
    row, problems = row_and_problem(0.55)
    assert row.ok is False and "scene.compression_inertial_number in /cases/mine.yaml (now 0.001)" in row.seed
    row, problems = row_and_problem(0.011)
    assert row.ok is True and row.seed == "" and problems == []


def test_an_unconverged_stage_1_says_which_case_field_fixes_it(tmp_path):
    """The triaxial's stage-1 row, when the loading began unconverged, names the chunk budget (and the
    servo's speed) in the case file with their values; converged, it says nothing more."""
    run = tmp_path / "run"
    run.mkdir()
    (run / "case.yaml").write_text(yaml.safe_dump({"name": "t", "scene": {"kind": "triaxial",
                                                                          "isotropic": {"max_chunks": 12}}}))
    (run / "params.json").write_text(json.dumps({"scene": {"iso": {"tolerance": 0.01}}}))
    iso = {"converged": False, "sigma1_error": -0.02, "sigma3_error": 0.004}
    (run / "summary.json").write_text(json.dumps({"status": "complete", "case_source": "/c/tri.yaml",
                                                  "scene": {"isotropic_end": iso}}))
    row = next(r for r in key_results(run) if r.quantity.startswith("stage 1 at p"))
    assert row.ok is False and row.value.startswith("0.980, 1.004: unconverged")
    assert "scene.isotropic.max_chunks in /c/tri.yaml (now 12)" in row.seed
    iso["converged"] = True
    (run / "summary.json").write_text(json.dumps({"status": "complete", "scene": {"isotropic_end": iso}}))
    row = next(r for r in key_results(run) if r.quantity.startswith("stage 1 at p"))
    assert row.ok is True and row.seed == ""
