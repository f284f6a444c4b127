"""Bad input on the command line (an audit's findings): each is one message naming the file, the
field or option and the fix, exit status 2, no traceback, and nothing run or left behind. Engine-free:
small frame sets written here, and cases refused before any engine starts."""
from __future__ import annotations

import inspect
import json
from pathlib import Path

import numpy as np
import pytest

from cli_util import main_here
from orchestrator.frames import write_frames

SCHEDULE_MINUTES = 0.1   #: engine-free tests, ~10 s quiet

REPO = Path(__file__).resolve().parents[1]


def bad_input(r, *says):
    """Exit status 2, one error message holding every one of ``says``, no traceback."""
    assert r.returncode == 2, (r.returncode, r.stdout[-2000:], r.stderr[-2000:])
    assert "Traceback" not in r.stderr and "internal error" not in r.stderr, r.stderr
    assert r.stderr.startswith("error: "), r.stderr
    for s in says:
        assert s in r.stderr, (s, r.stderr)


@pytest.fixture
def run(tmp_path) -> Path:
    """A run directory holding a frames.h5 of 300 grains over 3 frames (control axial_strain)."""
    rng = np.random.default_rng(0)
    n, T = 300, 3
    p0 = rng.uniform(0, 1e-3, (n, 3))
    d = tmp_path / "run"
    d.mkdir()
    write_frames(d / "frames.h5", np.arange(n), np.full(n, 2e-5), np.arange(T),
                 np.stack([p0 * (1 + 0.001 * k) for k in range(T)]), controls={"axial_strain": 0.001 * np.arange(T)})
    return d


def test_crossval_refuses_an_engine_that_cannot_run_the_case_before_any_run(tmp_path):
    """YADE lacks the displacement tangential history: before, LIGGGHTS ran the case to its end and
    the command then stopped with exit 1; now both are checked first and nothing runs."""
    case = tmp_path / "history.yaml"
    case.write_text(f"extends: {REPO / 'cases' / 'shear_cell_smoke.yaml'}\n"
                    "contact:\n  tangential_history: displacement\n")
    r = main_here("crossval", case, "--engine", "liggghts", "--engine", "yade", "--runs", tmp_path / "runs")
    bad_input(r, str(case), "engine yade", "tangential_history", "Nothing was run", "contact.substitutes",
              "--engine")
    assert not (tmp_path / "runs").exists()


def test_an_unknown_control_names_the_option_and_the_controls(run, tmp_path):
    bad_input(main_here("compare", run, run, "--control", "nosuch", "--out", tmp_path / "cmp"),
              "--control 'nosuch'", str(run / "frames.h5"), "['axial_strain']", "'time'")
    bad_input(main_here("analyze", run, "--analysis", 'coordination:{"control": "nosuch"}', "--out", tmp_path / "an"),
              "--analysis[0] (coordination): control 'nosuch'", "['axial_strain']")
    assert not (tmp_path / "an" / "analysis_summary.json").exists()          # refused before any analysis


def test_option_of_the_wrong_form_names_the_form(run, tmp_path):
    bad_input(main_here("compare", run, run, "--option", "badoption", "--out", tmp_path / "cmp"),
              "--option 'badoption'", "MEASURE.KEY=VALUE")
    bad_input(main_here("compare", run, run, "--option", "d2mn.cutoff_d50=2", "--out", tmp_path / "cmp"),
              "--option 'd2mn.cutoff_d50=2'", "unknown measure", "did you mean 'd2min'")
    bad_input(main_here("crossval", REPO / "cases" / "shear_cell_smoke.yaml", "--option", "nodot=1",
                        "--runs", tmp_path / "runs"), "--option 'nodot=1'", "MEASURE.KEY=VALUE")
    assert not (tmp_path / "runs").exists()


def test_analysis_option_values_are_checked(run, tmp_path):
    bad_input(main_here("analyze", run, "--analysis", 'coordination:{"cutoff": "abc"}'),
              "--analysis[0] (coordination): option 'cutoff' must be a number > 0, got 'abc'")
    bad_input(main_here("analyze", run, "--analysis", 'coordination:{"cutoff_d50": -2}'),
              "option 'cutoff_d50' must be a number > 0, got -2")
    bad_input(main_here("analyze", run, "--analysis", 'rdf:{"bins": 2.5}'), "option 'bins' must be a whole number > 0")
    assert not (run / "analysis").exists()
    case = tmp_path / "case.yaml"          # a case's list too, when it loads
    case.write_text(f"extends: {REPO / 'cases' / 'shear_cell_smoke.yaml'}\nanalysis:\n  - rdf: {{r_max_d50: 0}}\n")
    bad_input(main_here("validate", case), str(case), "option 'r_max_d50' must be a number > 0, got 0")
    from orchestrator.analysis_specs import parse_specs
    # YAML 1.1 reads 1e-3 (no dot) as a string: taken as the number it says
    assert parse_specs([{"d2min": {"cutoff": "1e-3", "stride": 2.0, "control": None}}]) == \
        [("d2min", {"cutoff": 1e-3, "stride": 2, "control": None})]


def test_number_options_follow_the_analyses_defaults():
    """Every option whose default is a number is checked as one (a whole number when the default
    is an int), and every option checked is one an analysis takes."""
    from orchestrator.analysis import ANALYSES
    from orchestrator.analysis_specs import _COUNTS, _POSITIVE, NUMBER_OPTIONS
    taken = set()
    for name, fn in ANALYSES.items():
        for key, p in list(inspect.signature(fn).parameters.items())[1:]:
            taken.add(key)
            d = p.default
            if isinstance(d, (int, float)) and not isinstance(d, bool):
                assert key in NUMBER_OPTIONS, (name, key)
                assert (key in _COUNTS) == isinstance(d, int), (name, key)
                if key in _POSITIVE:
                    assert d > 0, (name, key)
    assert NUMBER_OPTIONS <= taken and set(_POSITIVE) <= NUMBER_OPTIONS


def test_a_damaged_case_yaml_in_a_run_directory_is_named(run, tmp_path):
    (run / "case.yaml").write_text("scene: [shear_cell\n")
    bad_input(main_here("analyze", run), f"{run / 'case.yaml'}: 1 problem(s)", "not valid YAML")
    bad_input(main_here("report", run, "--out", tmp_path / "r.html"), f"{run / 'case.yaml'}: 1 problem(s)",
              "not valid YAML")


def test_status_shows_a_run_with_missing_figures_and_names_a_damaged_summary(run, tmp_path):
    (run / "summary.json").write_text(json.dumps({"status": "complete", "case": "c", "engine": "liggghts",
                                                  "steps": None, "n_particles": None}))
    damaged = tmp_path / "runs" / "c" / "yade-0"
    damaged.mkdir(parents=True)
    (damaged / "summary.json").write_text('{"status": "compl')
    not_a_summary = tmp_path / "runs" / "c" / "yade-1"                 # valid JSON, not a mapping
    not_a_summary.mkdir(parents=True)
    (not_a_summary / "summary.json").write_text('["complete"]')
    r = main_here("status", run, damaged, not_a_summary)
    assert r.returncode == 0 and "Traceback" not in r.stderr + r.stdout, r.stdout + r.stderr
    assert "complete" in r.stdout and "interrupted" in r.stdout
    for d in (damaged, not_a_summary):
        assert f"damaged: {d / 'summary.json'}: unreadable" in r.stdout


def test_an_output_file_that_is_a_directory_is_named_and_nothing_is_left(run, tmp_path):
    (run / "summary.json").write_text(json.dumps({"status": "complete", "case": "c", "engine": "liggghts"}))
    out = tmp_path / "somedir"
    out.mkdir()
    bad_input(main_here("status", run, "--csv", out), f"{out}: is a directory; give a file")
    bad_input(main_here("report", run, "--out", out), f"{out}: is a directory; give a file")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run", "somedir"]        # no somedir.partial
    from orchestrator.atomic import write_text
    with pytest.raises(UnicodeEncodeError):          # a write failed part-way leaves no temporary file either
        write_text(tmp_path / "x.txt", "\ud800")
    assert not list(tmp_path.glob("x.txt*"))


def test_an_output_directory_that_is_a_file_is_named_with_the_fix(run, tmp_path):
    f = tmp_path / "existing"
    f.write_text("")
    for args in (("vtk", run, "--frame", "0", "--out", f), ("analyze", run, "--analysis", "coordination", "--out", f)):
        bad_input(main_here(*args), f"{f}: exists and is not a directory", "give --out", "an existing directory")


def test_report_names_a_damaged_summary_and_the_fix(run):
    for text, why in (('{"status": "compl', "not JSON"), ('["complete"]', "a JSON list, not a record")):
        (run / "summary.json").write_text(text)
        bad_input(main_here("report", run, "--out", run / "r.html"), f"{run / 'summary.json'}: damaged: {why}",
                  "the same `orchestrator run` command")


def test_a_missing_path_and_a_run_without_frames_are_told_apart(tmp_path):
    bad_input(main_here("vtk", tmp_path / "nosuch"), f"{tmp_path / 'nosuch'}: no such run directory or frames.h5 file")
    bad_input(main_here("vtk", tmp_path), f"{tmp_path / 'frames.h5'}: no frames.h5 here", "orchestrator status")


def test_verify_names_the_cases_when_none_matches():
    r = main_here("verify", "--case", "nosuch")
    assert r.returncode == 2 and "--case nosuch" in r.stderr and "chung_ooi_4_oblique" in r.stderr


def test_analyze_of_a_run_without_frames_says_so(tmp_path):
    bad_input(main_here("analyze", tmp_path, "--analysis", "coordination"), f"{tmp_path}: no frames.h5 here",
              "orchestrator status")
