"""Bad input to ``stability``, ``convergence``, ``sweep``, ``calibrate`` and ``clock``: one message
naming the file, the option or field and the fix, status 2, no traceback, and nothing run before
the input is known good (the entries a run would go through raise AssertionError("ran")). No engine
starts here: every input is refused before a run directory is named (its name probes the engine)."""
from __future__ import annotations

from pathlib import Path

import pytest

from cli_util import main_here

REPO = Path(__file__).resolve().parents[2]
CASES = REPO / "cases"
SHEAR = CASES / "plane_shear_smoke.yaml"


def _ran(*args, **kwargs):
    raise AssertionError("ran")


def _refused(r, *says):
    """Status 2, one message without a traceback or 'internal error', naming each of ``says``."""
    text = r.stdout + r.stderr
    assert r.returncode == 2, text
    assert "Traceback" not in text and "internal error" not in text, text
    for s in says:
        assert s in text, (s, text)
    return text


@pytest.fixture
def nothing_runs(monkeypatch):
    """Every way the commands here reach an engine or an executor raises AssertionError("ran")."""
    from orchestrator.stability import bisection, calibration, convergence, sweep
    monkeypatch.setattr(bisection, "run_case", _ran)
    monkeypatch.setattr(bisection, "bisect", _ran)
    monkeypatch.setattr(calibration, "sweep", _ran)
    monkeypatch.setattr(convergence, "get_executor", _ran)
    monkeypatch.setattr(convergence, "run_dir_for", _ran)
    monkeypatch.setattr(sweep, "get_executor", _ran)
    monkeypatch.setattr(sweep, "run_dir_for", _ran)


# 1. calibrate: a plane-shear case only ---------------------------------------------------------
def test_calibrate_refuses_a_case_that_is_not_plane_shear_before_any_run(tmp_path, nothing_runs):
    case = CASES / "triaxial_smoke.yaml"
    r = main_here("calibrate", case, "--mu", "0.1,0.3,0.6", "--runs", tmp_path / "runs")
    _refused(r, str(case), "triaxial scene", "needs a plane_shear case", "seed 000 §3.2")
    assert not (tmp_path / "runs").exists()


# 2. calibrate --mu ---------------------------------------------------------------------------
@pytest.mark.parametrize("mu, says", [("abc", "'abc' is not a number"), ("", "an empty value"),
                                      ("0.1;0.3", "'0.1;0.3' is not a number"), ("0.1,x,0.3", "'x' is not a number"),
                                      ("0.1,,0.3", "an empty value"),
                                      ("-0.1,0.2,0.4", "at least 0"), ("nan,0.2,0.4", "finite number"),
                                      ("0.2,0.4", "needs at least 3"), ("0.2,0.2,0.4", "needs at least 3")])
def test_calibrate_names_mu_and_its_form(tmp_path, nothing_runs, mu, says):
    r = main_here("calibrate", SHEAR, f"--mu={mu}", "--runs", tmp_path / "runs")
    _refused(r, "--mu", says, "e.g. --mu")
    assert not (tmp_path / "runs").exists()


def test_calibrate_names_a_target_that_is_not_a_number(tmp_path, nothing_runs):
    r = main_here("calibrate", SHEAR, "--mu", "0,0.3,0.6", "--target", "nan", "--runs", tmp_path / "runs")
    _refused(r, "--target nan", "e.g. --target 0.3")


# 3. stability --tol and every case checked first ---------------------------------------------
@pytest.mark.parametrize("tol", ["0", "-0.1", "1", "nan"])
def test_stability_refuses_a_tolerance_outside_0_1_before_any_probe(tmp_path, nothing_runs, tol):
    r = main_here("stability", SHEAR, f"--tol={tol}", "--runs", tmp_path / "runs")
    _refused(r, f"--tol {tol}", "between 0 and 1", "e.g. --tol 0.15")
    assert not (tmp_path / "runs").exists()


def test_bisect_refuses_a_tolerance_that_would_never_end(monkeypatch, tmp_path):
    from orchestrator.stability import bisection
    monkeypatch.setattr(bisection, "probe", _ran)
    for tol in (0, -1, 1.5):
        with pytest.raises(ValueError, match="--tol"):
            bisection.bisect(SHEAR, "liggghts", runs_root=tmp_path, rel_tol=tol)


def test_stability_checks_every_case_before_the_first_bisection(tmp_path, nothing_runs):
    bad = tmp_path / "bad.yaml"
    bad.write_text(f"extends: {SHEAR}\ncontact: {{friction: -1}}\n")
    r = main_here("stability", SHEAR, bad, "--runs", tmp_path / "runs")
    _refused(r, str(bad), "contact.friction")
    assert not (tmp_path / "runs").exists()


def test_stability_refuses_a_csv_in_a_missing_folder_before_any_probe(tmp_path, nothing_runs):
    r = main_here("stability", SHEAR, "--csv", tmp_path / "no" / "t.csv", "--runs", tmp_path / "runs")
    _refused(r, "--csv", "does not exist", "mkdir -p")


# 4. convergence --reference, --full, integer knobs -------------------------------------------
@pytest.mark.parametrize("dry", [True, False])
def test_convergence_reference_not_among_the_values_is_refused_before_any_rung(tmp_path, nothing_runs, dry):
    r = main_here("convergence", SHEAR, "--knob", "dt_fraction", "--values", "0.1", "0.2", "--reference", "0.7",
                  "--runs", tmp_path / "runs", *(["--dry-run"] if dry else []))
    _refused(r, "--reference 0.7", "not one of the ladder's --values (0.1 0.2)", "leave --reference out")
    assert not (tmp_path / "runs").exists()


def test_reference_matches_the_rung_of_the_same_number():
    from orchestrator.stability.convergence import reference_value
    assert reference_value([0.1, 0.5], "0.50") == 0.5
    assert reference_value([0.1, 0.5], None) == 0.5
    assert reference_value([1, 2], 1.0) == 1
    with pytest.raises(ValueError, match="--reference"):
        reference_value([0.1, 0.5], "abc")


@pytest.mark.parametrize("dry", [True, False])
@pytest.mark.parametrize("value", ["1.5", "abc", "true"])
def test_convergence_count_takes_whole_numbers_only(tmp_path, nothing_runs, dry, value):
    r = main_here("convergence", SHEAR, "--knob", "count", "--values", value, "100",
                  "--runs", tmp_path / "runs", *(["--dry-run"] if dry else []))
    _refused(r, str(SHEAR), "--knob count --values", value, "not a whole number of grains", "e.g. --values 100")
    assert not (tmp_path / "runs").exists()


def test_count_knob_reads_a_whole_float_as_its_integer():
    from orchestrator.stability.convergence import checked_value
    assert checked_value(SHEAR, "count", 100.0) == 100 and isinstance(checked_value(SHEAR, "count", "2e2"), int)
    assert checked_value(SHEAR, "dt_fraction", "1e-1") == pytest.approx(0.1)


@pytest.mark.parametrize("knob, full", [("stiffness_scale", "0"), ("dt_fraction", "-1"), ("rate_scale", "inf")])
def test_convergence_full_out_of_reach_is_refused(tmp_path, nothing_runs, knob, full):
    r = main_here("convergence", SHEAR, "--knob", knob, "--values", "0.5", "1", "--full", full,
                  "--runs", tmp_path / "runs", "--dry-run")
    _refused(r, f"--full {float(full):g}", "leave --full out")


def test_convergence_refuses_a_target_error_of_zero(tmp_path, nothing_runs):
    r = main_here("convergence", SHEAR, "--knob", "dt_fraction", "--values", "0.1", "0.2", "--target-error", "0",
                  "--runs", tmp_path / "runs")
    _refused(r, "--target-error 0", "above 0")


# 5. sweep --set: the value is blamed on the overrides, not on the parent case ------------------
def test_an_override_value_is_blamed_on_the_overrides_not_on_the_parent_case():
    from orchestrator.case import CaseError, load_case
    for ov, shown in (({"contact": {"friction": "abc"}}, "contact.friction=abc"),
                      ({"contact": {"friction": -1}}, "contact.friction=-1"),
                      ({"material": {"youngs_modulus": "5kg"}}, "material.youngs_modulus=5kg")):
        with pytest.raises(CaseError) as exc:
            load_case(SHEAR, overrides=ov)
        msg = str(exc.value)
        assert msg.startswith(f"{SHEAR}:") and "extended by" not in msg and "plane_shear_seed" not in msg, msg
        assert f"the value comes from the overrides ({shown}, e.g. --set), not from the case file" in msg, msg


def test_a_bad_value_of_a_parent_case_is_still_the_parents(tmp_path):
    from orchestrator.case import CaseError, load_case
    parent = tmp_path / "parent.yaml"
    parent.write_text(f"extends: {SHEAR}\ncontact: {{friction: -1}}\n")
    child = tmp_path / "child.yaml"
    child.write_text("extends: parent.yaml\n")
    with pytest.raises(CaseError, match=rf"^{parent} \(extended by {child}\)"):
        load_case(child)
    # the override of the same field is the override's, whatever the parent says
    with pytest.raises(CaseError, match=r"from the overrides \(contact.friction=abc"):
        load_case(child, overrides={"contact": {"friction": "abc"}})


@pytest.mark.parametrize("dry", [True, False])
@pytest.mark.parametrize("sets", ["contact.friction=abc,-1", "material.youngs_modulus=5kg"])
def test_a_sweep_whose_every_point_is_refused_is_bad_input(tmp_path, nothing_runs, dry, sets):
    r = main_here("sweep", SHEAR, "--set", sets, "--runs", tmp_path / "runs", *(["--dry-run"] if dry else []))
    text = _refused(r, "refused", sets.split("=")[0])
    assert "extended by" not in text
    assert not (tmp_path / "runs").exists()


def test_a_sweep_with_some_points_refused_plans_the_others(tmp_path, monkeypatch):
    """docs/stability.md: an invalid point fails alone. The dry run lists it as refused, with its
    reason, says so under the table and ends with status 0 (the valid point is planned)."""
    from orchestrator.stability import sweep
    monkeypatch.setattr(sweep, "run_dir_for", lambda case, eng, root: Path(root) / case.name / f"{eng}-x")
    monkeypatch.setattr(sweep, "get_executor", _ran)
    plan = sweep.sweep_plan(SHEAR, ["contact.friction=abc,0.5"], engines=["liggghts"], runs_root=tmp_path)
    assert list(plan["status"]) == ["refused", "to run"]
    assert "contact.friction=abc" in plan["note"].iloc[0] and "plane_shear_seed" not in plan["note"].iloc[0]
    r = main_here("sweep", SHEAR, "--set", "contact.friction=abc,0.5", "--engine", "liggghts",
                  "--runs", tmp_path, "--dry-run")
    assert r.returncode == 0 and "1 run(s) refused" in r.stdout and "runs the others" in r.stdout, r.stdout + r.stderr
    assert not any(tmp_path.iterdir())


# 7. a damaged user throughput table: a warning naming it and the fix -------------------------
@pytest.mark.parametrize("text, says", [("garbage{", "not a JSON table"), ("[1, 2]", "a JSON list"),
                                        ('{"liggghts": {"plane_shear": {"bogus": 1}}}', "liggghts plane_shear")])
def test_clock_show_warns_of_a_damaged_user_table(tmp_path, monkeypatch, text, says):
    table = tmp_path / "throughput.json"
    table.write_text(text)
    monkeypatch.setenv("ORCHESTRATOR_THROUGHPUT", str(table))
    monkeypatch.setenv("ORCHESTRATOR_MACHINE_SPEED", str(tmp_path / "speed.json"))
    r = main_here("clock", "show")
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr and "internal error" not in r.stderr
    assert r.stderr.count(f"warning: {table}:") == 1, r.stderr       # once, though the table is read twice
    assert says in r.stderr and "delete the file" in r.stderr and "orchestrator clock refresh" in r.stderr
    assert table.read_text() == text                                 # the user's file is left as it was


def test_clock_warns_of_a_damaged_speed_record(tmp_path, monkeypatch):
    speed = tmp_path / "speed.json"
    speed.write_text("x{")
    monkeypatch.setenv("ORCHESTRATOR_THROUGHPUT", str(tmp_path / "throughput.json"))
    monkeypatch.setenv("ORCHESTRATOR_MACHINE_SPEED", str(speed))
    r = main_here("clock", "show")
    assert r.returncode == 0 and f"warning: {speed}:" in r.stderr and "delete the file" in r.stderr, r.stderr


def test_refresh_refuses_to_overwrite_a_damaged_table_naming_it(tmp_path):
    from orchestrator.clock import refresh
    table = tmp_path / "throughput.json"
    table.write_text("garbage{")
    (tmp_path / "runs").mkdir()
    with pytest.raises(ValueError, match=rf"{table}: not a JSON table .*delete it or move it aside"):
        refresh([tmp_path / "runs"], out=table)
    assert table.read_text() == "garbage{"
