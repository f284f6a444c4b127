"""``orchestrator status`` (orchestrator.run_status): how far a run got, its engine time so far and
the time left, read from the run's summary.json and attempts.json as the runner writes them. The
runs here are such records written by hand; tests/test_resume.py reads a real engine's, killed and
resumed."""
from __future__ import annotations

import fcntl
import json
import math
import os
import subprocess
import sys

import pandas as pd
import pytest

import orchestrator
from orchestrator.attempts import run_cost
from orchestrator.cli import main
from orchestrator.run_status import COLUMNS, run_status, status_table


def write_run(d, summary: dict, attempts: list[dict]):
    d.mkdir(parents=True)
    (d / "summary.json").write_text(json.dumps({"case": "c", "engine": "yade", "n_particles": 100, **summary}))
    (d / "attempts.json").write_text(json.dumps(attempts))
    return d


def attempt(first, last, cpu, wall, ranks=1, done=False):
    return {"first_step": first, "last_step": last, "cpu_s": cpu, "wall_s": wall, "ranks": ranks, "done": done}


#: killed at step 1 000, resumed from the checkpoint at 900 and killed again at 1 500 (one rank)
KILLED_TWICE = [attempt(0, 1000, 10.0, 30.0), attempt(900, 1500, 5.0, 6.0)]


def test_interrupted_run_steps_time_so_far_and_left(tmp_path):
    d = write_run(tmp_path / "runs" / "c" / "yade-1", {"status": "running", "steps": 3000,
                                                        "estimated_engine_time_s": 60.0}, KILLED_TWICE)
    st = run_status(d)
    assert st["status"] == "interrupted"              # 'running' on disk, no live process holds it
    assert (st["step"], st["steps"], st["attempts"]) == (1500, 3000, 2)
    assert st["done"] == pytest.approx(0.5)
    assert st["engine_s"] == pytest.approx(15.0)      # CPU on one rank, the repeated 100 steps included
    assert st["pace"] == pytest.approx(600 / 5.0)     # the latest attempt's steps per CPU second
    assert st["left_pace_s"] == pytest.approx(1500 / 120.0)
    assert st["left_clock_s"] == pytest.approx(60.0 * 1500 / 3000)
    assert st["estimated_s"] == 60.0


def test_the_time_left_takes_the_latest_estimate_and_the_whole_run_the_first(tmp_path):
    d = write_run(tmp_path / "runs" / "c" / "yade-1", {"status": "running", "steps": 3000, "estimated_engine_time_s": 80.0,
                                                        "first_estimated_engine_time_s": 60.0}, KILLED_TWICE)
    st = run_status(d)
    assert st["left_clock_s"] == pytest.approx(80.0 * 1500 / 3000) and st["estimated_s"] == 60.0


def test_a_stage_that_ends_when_converged_counts_the_expected_steps(tmp_path):
    """A triaxial's budget (the most its stage 1 may take) is not what it is expected to take; the
    share done and the time left count the steps the clock's estimate is for."""
    d = write_run(tmp_path / "r", {"status": "running", "steps": 222720, "estimated_steps": 92160,
                                    "estimated_engine_time_s": 258.0}, [attempt(0, 46080, 100.0, 101.0)])
    st = run_status(d)
    assert st["steps"] == 222720 and st["steps_expected"] == 92160 and st["done"] == pytest.approx(0.5)
    assert st["left_clock_s"] == pytest.approx(129.0) and st["left_pace_s"] == pytest.approx(100.0)
    out = orc("status", d)
    assert "46,080/~92,160 (50 %)" in out.stdout, out.stdout


def test_the_steps_the_deck_says_the_run_ends_at_replace_the_expected_ones(tmp_path):
    """Once a triaxial's loading starts its deck prints the step the run ends at (engines.base.RUN_ENDS,
    kept as the attempt's ``end_step``): the share done and the time left count toward it, exactly
    (YADE's medium clump run: its stage 1 took longer than LIGGGHTS' clumps, whose steps the clock
    counts, so the clock's ~528 000 steps were 704 001), and the clock's time left keeps its cost per step."""
    d = write_run(tmp_path / "r", {"status": "running", "steps": 1008000, "estimated_steps": 528000,
                                    "estimated_engine_time_s": 5280.0},
                  [attempt(0, 496000, 4960.0, 5000.0), {**attempt(496000, 504000, 80.0, 81.0), "end_step": 704001}])
    st = run_status(d)
    assert st["steps"] == st["steps_expected"] == 704001 and st["done"] == pytest.approx(504000 / 704001)
    assert st["left_pace_s"] == pytest.approx(200001 / 100.0)
    assert st["left_clock_s"] == pytest.approx(5280.0 * 200001 / 528000)
    out = orc("status", d)
    assert "504,000/704,001 (72 %)" in out.stdout, out.stdout


def test_running_run_is_reported_running(tmp_path):
    d = write_run(tmp_path / "r", {"status": "running", "steps": 3000}, KILLED_TWICE[:1])
    with open(d / ".lock", "w") as fh:                 # a live owner, as the runner holds it
        fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        st = run_status(d)
    assert st["status"] == "running" and st["step"] == 1000
    assert math.isnan(st["left_clock_s"])              # no estimate recorded: not made up


def test_the_time_left_follows_the_latest_ten_minutes(tmp_path):
    """The attempt averaged 10 steps per CPU second, its last 10 minutes 2: the rest takes 5x the
    whole attempt's pace; a record without ``recent`` (written before session 32) keeps the average."""
    slowing = {**attempt(0, 6000, 600.0, 610.0), "recent": {"steps": 1200, "wall_s": 601.0, "cpu_s": 600.0}}
    d = write_run(tmp_path / "r", {"status": "running", "steps": 10000}, [slowing])
    st = run_status(d)
    assert st["pace"] == pytest.approx(2.0) and st["left_pace_s"] == pytest.approx(2000.0)
    threads = {**slowing, "ranks": 2}               # several ranks or threads: the wall clock
    d2 = write_run(tmp_path / "r2", {"status": "running", "steps": 10000}, [threads])
    assert run_status(d2)["pace"] == pytest.approx(1200 / 601.0)
    d3 = write_run(tmp_path / "r3", {"status": "running", "steps": 10000}, [attempt(0, 6000, 600.0, 610.0)])
    assert run_status(d3)["pace"] == pytest.approx(10.0)
    stalled = {**slowing, "recent": {"steps": 0, "wall_s": 600.0, "cpu_s": 0.1}}
    d4 = write_run(tmp_path / "r4", {"status": "running", "steps": 10000}, [stalled])
    assert run_status(d4)["pace"] == pytest.approx(10.0)   # no step in 10 minutes: the attempt's pace


def test_several_ranks_are_timed_by_the_wall_clock(tmp_path):
    d = write_run(tmp_path / "r", {"status": "failed", "steps": 2000},
                  [attempt(0, 1000, 38.0, 20.0, ranks=2)])
    st = run_status(d)
    assert st["engine_s"] == pytest.approx(20.0) and st["pace"] == pytest.approx(50.0)


def test_complete_resumed_run_costs_what_an_uninterrupted_one_would(tmp_path):
    att = [attempt(0, 1000, 10.0, 30.0), attempt(900, 3000, 21.0, 22.0, done=True)]
    d = write_run(tmp_path / "r", {"status": "complete", "steps": 3000, "steps_run": 3000, "attempts": att,
                                    "resumed_from": {"checkpoint": "checkpoint.yade.gz"},
                                    "wall_time": {"engine": 22.0, "engine_cpu": 21.0}}, att)
    st = run_status(d)
    assert st["status"] == "complete" and st["done"] == 1.0 and st["step"] == 3000
    assert st["engine_s"] == pytest.approx(run_cost(att, 3000, use_cpu=True))   # 10 + 21 * 2000/2100
    assert st["left_pace_s"] == 0 and st["left_clock_s"] == 0


def test_table_finds_every_run_of_a_tree_once(tmp_path):
    a = write_run(tmp_path / "runs" / "c" / "yade-1", {"status": "running", "steps": 3000}, KILLED_TWICE)
    write_run(tmp_path / "runs" / "c" / "yade-2", {"status": "running", "steps": 3000}, KILLED_TWICE)
    df = status_table([tmp_path / "runs", a])         # a run named twice is one row
    assert isinstance(df, pd.DataFrame) and list(df.columns) == COLUMNS and len(df) == 2
    assert status_table(tmp_path / "runs" / "c" / "yade-1").shape[0] == 1
    assert orchestrator.status(tmp_path / "runs").equals(status_table(tmp_path / "runs"))   # the notebook name


def orc(*args):
    """The command in a 160-column terminal (an 80-column one folds the table's cells)."""
    return subprocess.run([sys.executable, "-m", "orchestrator", *map(str, args)], capture_output=True,
                          text=True, timeout=60, env={**os.environ, "COLUMNS": "160"})


def test_cli_prints_the_runs_and_writes_csv(tmp_path):
    write_run(tmp_path / "runs" / "c" / "yade-1", {"status": "running", "steps": 3000,
                                                   "estimated_engine_time_s": 60.0}, KILLED_TWICE)
    out = orc("status", tmp_path / "runs", "--csv", tmp_path / "s.csv")
    assert out.returncode == 0, out.stderr
    assert "interrupted" in out.stdout and "1,500/3,000 (50 %)" in out.stdout
    assert "run again" in out.stdout
    assert pd.read_csv(tmp_path / "s.csv")["step"].tolist() == [1500]


def test_cli_bad_and_empty_paths(tmp_path, capsys, monkeypatch):
    """The command's own entry point in this process (the subprocess above proves the command)."""
    def status(*args):
        code = main(["status", *map(str, args)])
        out = capsys.readouterr()
        return code, out.out, out.err

    code, _, err = status(tmp_path / "nowhere")
    assert code == 2 and "nowhere" in err and "Traceback" not in err
    (tmp_path / "empty").mkdir()
    code, out, _ = status(tmp_path / "empty")
    assert code == 0 and "no runs under" in out
    monkeypatch.chdir(tmp_path / "empty")
    code, out, _ = status()                              # no ./runs yet: said, not an error
    assert code == 0 and "no runs here yet" in out
    (tmp_path / "case.yaml").write_text("name: x\n")
    code, _, err = status(tmp_path / "case.yaml")
    assert code == 2 and "case.yaml" in err and "Traceback" not in err
