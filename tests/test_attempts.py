"""The engine time of a killed and resumed run, from the record of its attempts
(orchestrator.attempts): what the clock fits a resumed run with."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from orchestrator.attempts import AttemptRecord, attempt_wall_seconds, process_tree_cpu_seconds, read_attempts, run_cost


def _a(first, last, t, done=False):
    return {"first_step": first, "last_step": last, "wall_s": t, "cpu_s": t / 2, "ranks": 1, "done": done}


def test_one_attempt_is_its_own_time():
    assert run_cost([_a(0, 1000, 10.0, True)], 1000, use_cpu=False) == pytest.approx(10.0)
    assert run_cost([_a(0, 1000, 10.0, True)], 1000, use_cpu=True) == pytest.approx(5.0)


def test_repeated_steps_are_taken_out():
    """Killed at 600 after a checkpoint at 400: the second attempt repeats 400-600, which an
    uninterrupted run would not have done (its rate: 600 steps in 6 s)."""
    cost = run_cost([_a(0, 600, 6.0), _a(400, 1000, 6.0, True)], 1000, use_cpu=False)
    assert cost == pytest.approx(6.0 + 6.0 * 400 / 600)


def test_a_small_gap_is_bridged_at_the_next_rate_and_a_large_one_is_not():
    """The record lags the engine by up to one write interval, and a YADE resume is first seen at
    its first progress line: a gap of up to 2 % of the run counts at the next attempt's rate."""
    ok = run_cost([_a(0, 490, 4.9), _a(500, 1000, 5.0, True)], 1000, use_cpu=False)
    assert ok == pytest.approx(4.9 + 5.0 * 510 / 500)
    assert run_cost([_a(0, 400, 4.0), _a(500, 1000, 5.0, True)], 1000, use_cpu=False) is None


@pytest.mark.parametrize("attempts, steps", [
    ([], 1000),                                            # no record (a run from before it existed)
    ([_a(100, 1000, 9.0, True)], 1000),                    # the record does not start at step 0
    ([_a(0, 500, 5.0)], 1000),                             # stops half-way
    ([_a(0, 500, 0.0), _a(500, 1000, 5.0, True)], 1000),   # an attempt without time
    ([_a(0, 500, 5.0), "garbage"], 1000),                  # not a record this module wrote
])
def test_an_incomplete_record_gives_no_figure(attempts, steps):
    assert run_cost(attempts, steps, use_cpu=False) is None


def test_an_attempt_killed_before_its_first_step_adds_nothing():
    att = [_a(0, 500, 5.0), {"first_step": None, "last_step": None, "wall_s": 3.0, "cpu_s": 1.0, "done": False},
           _a(500, 1000, 5.0, True)]
    assert run_cost(att, 1000, use_cpu=False) == pytest.approx(10.0)


def test_the_record_follows_a_real_process(tmp_path, monkeypatch):
    """A child process burning CPU: the record holds its CPU time while it runs, and the second
    attempt is appended to the first."""
    monkeypatch.setattr(AttemptRecord, "EVERY", 0.0)
    burn = "import time\nt = time.process_time()\nwhile time.process_time() - t < 0.3: pass\ntime.sleep(5)\n"
    proc = subprocess.Popen([sys.executable, "-c", burn], start_new_session=True)
    try:
        rec = AttemptRecord(tmp_path, 0)
        for _ in range(100):
            rec.update(1234, proc.pid)
            if (rec.entry["cpu_s"] or 0) >= 0.3:
                break
            time.sleep(0.05)
        assert 0.3 <= read_attempts(tmp_path)[0]["cpu_s"] < 2.0
        assert process_tree_cpu_seconds(proc.pid) >= 0.3
    finally:
        proc.kill()
        proc.wait()
    rec.close(2000, 0.31, done=False)
    AttemptRecord(tmp_path, None).close(3000, 0.2, done=True)
    att = json.loads((tmp_path / "attempts.json").read_text())
    assert [(a["first_step"], a["last_step"], a["done"]) for a in att] == [(0, 2000, False), (3000, 3000, True)]
    # the machine's load while the first attempt ran, beside its cores (a shared machine: its wall time is long)
    assert att[0]["load"] >= 0 and att[0]["cores"] == os.cpu_count()
    assert oct(os.stat(tmp_path / "attempts.json").st_mode & 0o777) == oct(0o666 & ~_umask())


def test_a_stopped_engine_is_counted_paused_and_its_pause_left_out_of_the_cost(tmp_path, monkeypatch):
    """A process computing, stopped with SIGSTOP for 2 s (as `kill -STOP` or Slurm's suspend do),
    then computing again: the record counts the stop as paused, and the attempt's engine time on
    several ranks (its wall time) leaves it out; its CPU time never held it. The bounds are the
    stop and the attempt as this test timed them, within a write interval or two: on a loaded
    machine the test's own loop overruns (a 3.5 s attempt took 4.9 s beside three busy processes)."""
    every = 0.25               # s between writes: at 10 ms a CPU tick, 2 % of a core is half a tick
    monkeypatch.setattr(AttemptRecord, "EVERY", every)
    proc = subprocess.Popen([sys.executable, "-c", "while True: pass"], start_new_session=True)
    try:
        t0 = time.perf_counter()
        rec = AttemptRecord(tmp_path, 0, ranks=2)

        def run_for(seconds, step):
            t = time.perf_counter()
            while time.perf_counter() - t < seconds:
                rec.update(step, proc.pid)
                time.sleep(0.02)

        run_for(1.0, 100)
        assert rec.entry["paused_s"] <= every                # computing: not paused
        os.kill(proc.pid, signal.SIGSTOP)
        stop = time.perf_counter()
        run_for(2.0, 100)
        os.kill(proc.pid, signal.SIGCONT)
        stopped = time.perf_counter() - stop
        run_for(1.0, 200)
    finally:
        proc.kill()
        proc.wait()
    rec.close(200, None, done=True)
    elapsed = time.perf_counter() - t0
    a = read_attempts(tmp_path)[0]
    assert stopped - 2 * every <= a["paused_s"] <= stopped + every, (a["paused_s"], stopped)
    assert elapsed - 0.5 < a["wall_s"] <= elapsed, (a["wall_s"], elapsed)
    assert attempt_wall_seconds(a) == pytest.approx(a["wall_s"] - a["paused_s"])
    assert run_cost([a], 200, use_cpu=False) == pytest.approx(a["wall_s"] - a["paused_s"])


def test_a_pause_is_taken_out_of_the_whole_runs_cost_and_a_records_without_one_are_kept():
    att = [{**_a(0, 600, 16.0), "paused_s": 10.0}, _a(400, 1000, 6.0, True)]      # 6 s computing, 10 s stopped
    assert run_cost(att, 1000, use_cpu=False) == pytest.approx(6.0 + 6.0 * 400 / 600)
    assert attempt_wall_seconds(_a(0, 600, 16.0)) == 16.0                           # a record from before
    assert attempt_wall_seconds({"wall_s": None}) is None


def test_the_recent_pace_spans_the_latest_window(tmp_path, monkeypatch):
    """A run that slows (a shear cell's sample densifying) or was paused: ``recent`` holds the steps
    and times of the latest WINDOW seconds only, which ``orchestrator status`` paces the rest by."""
    now = [0.0]
    monkeypatch.setattr(AttemptRecord, "clock", staticmethod(lambda: now[0]))
    monkeypatch.setattr(AttemptRecord, "EVERY", 10.0)
    monkeypatch.setattr(AttemptRecord, "WINDOW", 100.0)
    rec = AttemptRecord(tmp_path, 1000)
    assert "recent" not in read_attempts(tmp_path)[0]
    step = 1000
    for t in range(10, 1001, 10):                   # 10 steps/s for 500 s, then 2 steps/s
        now[0] = float(t)
        step += 100 if t <= 500 else 20
        rec.update(step)
    (entry,) = read_attempts(tmp_path)
    assert (entry["first_step"], entry["last_step"], entry["wall_s"]) == (1000, 7000, 1000.0)
    assert entry["recent"]["wall_s"] == 100.0 and entry["recent"]["steps"] == 200   # 2 steps/s, not 6
    assert entry["recent"]["cpu_s"] is None         # no process given: no CPU time
    for t in range(1010, 1201, 10):                 # stalled: the record says so, no stale pace
        now[0] = float(t)
        rec.update(step)
    assert read_attempts(tmp_path)[0]["recent"]["steps"] == 0
    rec.close(7000, None, done=False)
    assert read_attempts(tmp_path)[0]["recent"] == {"steps": 0, "wall_s": 200.0, "cpu_s": None}


def test_the_recent_pace_of_an_engine_that_reports_sparsely(tmp_path, monkeypatch):
    """An engine reports its step every 400 s at a steady 10 steps/s (YADE's triaxial on the medium
    clumps: every 5 040 steps) while the record is written every 10 s: the recent pace is 10 steps/s
    wherever the window falls, not 4 000 steps over a window of writes around one report (6.7) or
    8 000 around two (13)."""
    now = [0.0]
    monkeypatch.setattr(AttemptRecord, "clock", staticmethod(lambda: now[0]))
    monkeypatch.setattr(AttemptRecord, "EVERY", 10.0)
    monkeypatch.setattr(AttemptRecord, "WINDOW", 600.0)
    rec = AttemptRecord(tmp_path, 0)
    paces = []
    for t in range(10, 2401, 10):
        now[0] = float(t)
        rec.update(4000 * (t // 400))
        if t >= 1200 and t % 50 == 0:
            r = read_attempts(tmp_path)[0].get("recent")
            paces.append(r["steps"] / r["wall_s"])
    assert paces and all(p == 10.0 for p in paces)


def _umask() -> int:
    m = os.umask(0)
    os.umask(m)
    return m


def test_a_multi_rank_run_that_shared_the_machine_is_left_out_of_the_fit():
    """Two-rank runs poll while they wait, so only their wall time counts, and beside other runs it
    measures those too: a run at load 4.1 on 2 cores is marked shared and the fit uses the quiet
    one; one-rank runs (counted in CPU time) are never shared."""
    from orchestrator.clock import RunSample, _machine_load, fit
    assert _machine_load([{"load": 1.0, "wall_s": 30.0, "cores": 2}, {"load": 3.0, "wall_s": 10.0, "cores": 2}]) == (1.5, 2)
    assert _machine_load([_a(0, 10, 1.0)]) == (None, None)
    quiet = RunSample("liggghts", "shear_cell", 1000, 10000, 2, 100.0, 100.0, "quiet", load=2.1, cores=2)
    shared = RunSample("liggghts", "shear_cell", 1000, 10000, 2, 300.0, 300.0, "shared", load=4.1, cores=2)
    one = RunSample("liggghts", "shear_cell", 1000, 10000, 1, 150.0, 150.0, "one", load=4.1, cores=2)
    assert shared.shared and not quiet.shared and not one.shared
    assert fit([quiet, shared]).engine_time(1000, 10000, 2) == pytest.approx(fit([quiet]).engine_time(1000, 10000, 2))
