"""The command line as a user meets it: help, validate, engines, dry-run, verify, vtk, errors."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from cli_util import main_here

SCHEDULE_MINUTES = 0.1   #: engine-free tests, ~5 s quiet: early in the fast tier (tests/conftest.py schedule_groups)

REPO = Path(__file__).resolve().parents[1]
VER = REPO / "cases" / "verification"


def cli(*args, timeout=900):
    return subprocess.run([sys.executable, "-m", "orchestrator", *map(str, args)], capture_output=True,
                          text=True, timeout=timeout, cwd=REPO)


@pytest.mark.parametrize("sub", ["run", "validate", "engines", "verify", "analyze", "vtk"])
def test_help_on_each_command(sub):
    out = cli(sub, "--help")
    assert out.returncode == 0 and "usage: orchestrator " + sub in out.stdout


def test_the_command_table_loads_no_analysis_or_imaging_stack():
    """``orchestrator --help`` lists every command group (ct, compare, stability) without importing
    what their commands run: the analysis stack behind ``compare`` and the CT's imaging once made it
    take 5.7 s (3.4 s of CPU); the handlers import their modules when they run (the compare group's
    parsers live outside the package, orchestrator/cli_compare.py)."""
    probe = ("import sys, contextlib, io\n"
             "from orchestrator.cli import build_parser\n"
             "with contextlib.redirect_stdout(io.StringIO()) as out:\n"
             "    try:\n"
             "        build_parser(['--help']).parse_args(['--help'])\n"
             "    except SystemExit:\n"
             "        pass\n"
             "heavy = sorted(m for m in sys.modules if m in ('orchestrator.analysis', 'orchestrator.compare') or\n"
             "               m.startswith(('orchestrator.analysis.', 'orchestrator.compare.', 'orchestrator.ct.segment',\n"
             "                             'orchestrator.ct.commands', 'skimage', 'matplotlib')))\n"
             "print(heavy)\n"
             "print(all(c in out.getvalue() for c in ('ct', 'compare', 'crossval', 'stability', 'convergence')))\n")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, cwd=REPO)
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines() == ["[]", "True"]
    # (the compare package's own __init__ stays eager: lazily, ``from orchestrator.compare import align``
    # gave the submodule of that name once imported; tests/compare/test_compare.py calls it)


def test_validate_good_and_bad(tmp_path):
    ok = main_here("validate", VER / "chung_ooi_4_oblique.yaml")
    assert ok.returncode == 0 and "valid" in ok.stdout and "dt =" in ok.stdout
    bad = tmp_path / "bad.yaml"
    bad.write_text((VER / "chung_ooi_4_oblique.yaml").read_text().replace("radius: 2.5 mm", "radius: 2.5")
                   .replace("extends: _base_impact.yaml", f"extends: {VER / '_base_impact.yaml'}"))
    out = main_here("validate", bad)
    assert out.returncode == 2
    assert str(bad) in out.stderr and "scene.radius" in out.stderr and "has no unit" in out.stderr
    assert "Traceback" not in out.stderr


def test_missing_case_file_is_a_clear_error(tmp_path):
    out = cli("run", tmp_path / "nope.yaml")
    assert out.returncode == 2 and "file not found" in out.stderr and "Traceback" not in out.stderr


def test_analyze_takes_options_and_says_what_is_wrong_with_them(tmp_path, capsys):
    """``--analysis 'name:{JSON}'`` runs the analysis with those options; a bad name or JSON is one
    message naming it, no traceback."""
    import json
    import numpy as np
    from orchestrator.frames import write_frames
    rng = np.random.default_rng(0)
    n, T = 300, 3
    p0 = rng.uniform(0, 1e-3, (n, 3))
    pos = np.stack([p0 * (1 + 0.001 * k) for k in range(T)])
    run = tmp_path / "run"
    run.mkdir()
    write_frames(run / "frames.h5", np.arange(n), np.full(n, 2e-5), np.arange(T), pos,
                 controls={"axial_strain": 0.001 * np.arange(T)})
    from orchestrator.cli import main       # in this process: the analysis stack is imported once
    assert main(["analyze", str(run), "--out", str(tmp_path / "out"), "--analysis", 'd2min:{"pairs": [[0, 2]]}']) == 0
    d2 = json.loads((tmp_path / "out" / "analysis_summary.json").read_text())["d2min"]
    assert d2["status"] == "ok" and d2["options"] == {"pairs": [[0, 2]]}
    capsys.readouterr()
    for bad, says in (('d2min:{"pairs": [[0, 2]]', "not JSON"), ("d2mn", "unknown analysis 'd2mn'"),
                      ("d2min:[1]", "must be a JSON object")):
        assert main(["analyze", str(run), "--analysis", bad]) == 2
        err = capsys.readouterr().err
        assert says in err and "Traceback" not in err, err


@pytest.mark.engine
def test_engines_lists_versions_and_capabilities(engines_installed):
    out = cli("engines")
    assert out.returncode == 0
    assert "LIGGGHTS-PUBLIC 3.8" in out.stdout and "YADE 2023.02" in out.stdout  \
        and "lammps: LAMMPS 22 Jul 2025" in out.stdout
    assert "membrane" in out.stdout and "substitute" in out.stdout


def test_dry_run_sizes_without_work(tmp_path):
    """--dry-run prints each engine's particles, steps, memory and engine time, and does no work:
    no packing, no run directory (issue #16; decks are rendered by run_case(dry_run=True))."""
    out = main_here("run", VER / "chung_ooi_4_oblique.yaml", "--dry-run", "--runs", tmp_path / "runs")
    assert out.returncode == 0, out.stderr
    assert out.stdout.count("17 particles") == 3 and out.stdout.count("engine time") == 3
    assert not (tmp_path / "runs").exists()


def test_validate_and_dry_run_refuse_what_an_engine_cannot_run(tmp_path):
    """A clump triaxial on LIGGGHTS without the inserted_clumps substitute: the run itself would stop
    before it starts, so validate and --dry-run say so too (the file, the engine, the substitute to
    accept), exit 2 and create nothing; the engine that can run it is still sized."""
    case = tmp_path / "clumps.yaml"
    case.write_text(f"extends: {REPO / 'cases' / 'triaxial_smoke.yaml'}\nscene:\n  particles:\n    shape: clumps\n"
                    f"    library: {REPO / 'tests' / 'data' / 'clumps_smoke.yaml'}\n"
                    "contact:\n  substitutes:\n    liggghts.membrane: shell_pressure\n")
    out = main_here("validate", case)
    assert out.returncode == 2 and "not runnable on liggghts" in out.stdout, out.stdout + out.stderr
    assert "liggghts: cannot run this case" in out.stdout and "inserted_clumps" in out.stdout
    assert "yade: 919 particles" in out.stdout
    dry = main_here("run", case, "--engine", "liggghts", "--dry-run", "--runs", tmp_path / "runs")
    assert dry.returncode == 2 and str(case) in dry.stderr and "engine liggghts" in dry.stderr
    assert "contact.substitutes" in dry.stderr and "Traceback" not in dry.stderr
    assert not (tmp_path / "runs").exists()
    assert main_here("run", case, "--engine", "yade", "--dry-run", "--runs", tmp_path / "runs").returncode == 0


@pytest.mark.engine
def test_verify_prints_a_table_per_engine(runs_root, engines_installed, tmp_path):
    # the command end to end on test 1 and test 4 (tests/test_verification.py covers every case)
    out = cli("verify", "--runs", runs_root, "--csv", tmp_path / "verify.csv", "--case", "_1_sphere_sphere_glass",
              "--case", "oblique", timeout=1800)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    assert "— liggghts" in out.stdout and "— yade" in out.stdout and "— lammps" in out.stdout
    assert "checks within tolerance" in out.stdout
    import pandas as pd
    t = pd.read_csv(tmp_path / "verify.csv")
    assert set(t.engine) == {"liggghts", "yade", "lammps"} and t["pass"].all()
    assert {"contact_time", "peak_force", "e_n", "e_t", "max_overlap"} <= set(t.quantity)
    assert set(t.case) == {"chung_ooi_1_sphere_sphere_glass", "chung_ooi_4_oblique"}
    assert cli("verify", "--case", "no_such_case").returncode == 2


@pytest.mark.engine
def test_vtk_export_of_a_run(runs_root, engines_installed):
    out = cli("run", VER / "chung_ooi_1_sphere_sphere_glass.yaml", "--engine", "yade", "--runs", runs_root, "--quiet")
    assert out.returncode == 0, out.stderr
    run = next(Path(runs_root).glob("chung_ooi_1_sphere_sphere_glass/yade-*"))
    out = cli("vtk", run, "--frame", "0")
    assert out.returncode == 0 and (run / "vtk" / "frame_00000.vtu").exists()


def test_crossval_of_a_one_engine_case_names_the_fix_before_running(tmp_path):
    r = main_here("crossval", REPO / "cases" / "shear_cell_default.yaml", "--runs", tmp_path)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "shear_cell_default.yaml: `engines` lists ['liggghts']" in r.stderr
    assert "--engine liggghts --engine yade" in r.stderr
    assert not any(tmp_path.iterdir())                                  # nothing ran


def test_crossval_dry_run_lists_each_engines_run_and_runs_nothing(tmp_path):
    r = main_here("crossval", REPO / "cases" / "shear_cell_smoke.yaml", "--engine", "liggghts", "--engine", "yade",
                  "--dry-run", "--concurrent", "no", "--runs", tmp_path)
    assert r.returncode == 0, r.stderr
    assert "2 run(s) to do, 0 reused, 0 refused" in r.stdout and "runs: sequential (forced)" in r.stdout
    assert "liggghts" in r.stdout and "yade" in r.stdout and "228" in r.stdout
    r = main_here("crossval", REPO / "cases" / "shear_cell_smoke.yaml", "--ladder", "--rung", "L0", "--seeds", "1", "2",
                  "--engine", "liggghts", "--engine", "yade", "--dry-run", "--runs", tmp_path)
    assert r.returncode == 0, r.stderr
    assert "4 run(s) to do" in r.stdout and "L0" in r.stdout               # 1 rung x 2 seeds x 2 engines
    assert not any(tmp_path.iterdir())                                    # nothing packed, no run directory


@pytest.mark.engine
def test_crossval_command_writes_table_report_and_wall_times(runs_root, engines_installed):
    """In the session's runs directory: the engine runs the verification tests made of this case are
    reused (a reused run brings its recorded wall times); the crossval folder is this test's alone."""
    out = cli("crossval", VER / "chung_ooi_1_sphere_sphere_glass.yaml", "--runs", runs_root,
              "--measure", "displacements", "--states", "ends")
    assert out.returncode == 0, out.stderr[-2000:]
    # the case lists three engines: the first (liggghts) against each of the others, a folder a pair
    root = Path(runs_root) / "chung_ooi_1_sphere_sphere_glass" / "crossval"
    assert sorted(p.name for p in root.iterdir()) == ["liggghts_vs_lammps", "liggghts_vs_yade"]
    import pandas as pd
    for d in root.iterdir():
        for name in ("comparison.csv", "report.html", "wall_times.csv", "grains.csv"):
            assert (d / name).stat().st_size > 0, name
        wt = pd.read_csv(d / "wall_times.csv")
        assert list(wt.engine) == ["liggghts", "yade", "lammps"]
        g = pd.read_csv(d / "grains.csv")
        assert len(g) >= 1
    assert out.stdout.count("wrote ") == 2
