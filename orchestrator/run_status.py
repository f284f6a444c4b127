"""Where runs stand: how far each got, what it has cost and how long the rest should take
(``orchestrator status``; the Python API :func:`status_table`).

A medium case runs for hours, and a session, a batch job's time limit or a reboot may stop it
part-way; running the same command again resumes it from its last restart point (docs/engines.md,
Resume). This module reads, without starting anything, what a run writes as it goes: its
``summary.json`` (the case, the engine, the planned steps, the clock's estimate before the run,
whether it is complete) and its ``attempts.json`` (:mod:`orchestrator.attempts`: the steps, wall
and CPU time of every attempt, rewritten every 5 s while the engine runs).

A run found ``running`` that no live process holds is reported ``interrupted``
(:func:`orchestrator.run_summary.read_summary`, which also marks it so on disk).

The time left comes two ways, neither exact (docs/validation.md, the clock):

- ``left_pace_s``: the steps left at the latest attempt's pace over its last 10 minutes (steps per
  engine second; the attempt's ``recent`` record, :mod:`orchestrator.attempts`; the whole attempt's
  pace for a record without one, or whose last 10 minutes made no step). A later stage that costs
  more per step (a shear cell's shear stage after its compression, where the grains are denser and
  touch more; a triaxial's loading after its drag-held stage 1) makes the true figure longer;
- ``left_clock_s``: the clock's estimate before the latest attempt times the share of the steps
  left (:mod:`orchestrator.clock`), which knows nothing of how this run has gone so far.

A scene that decides its step count while it runs (a triaxial's stage 1 ends when the sample has
converged) has a budget of steps it may take and fewer it is expected to take (what the engine's
measured runs took, the steps the clock's estimate is for): the share done and the time left count
the expected steps (``steps_expected``; the budget for a run recorded before session 30, whose
summary does not say), until the deck has said the step the run ends at (a triaxial's, once its
loading starts: the attempt record's ``end_step``, engines.base.RUN_ENDS), then that step.
"""
from __future__ import annotations

from pathlib import Path

import pandas as pd

from .attempts import attempt_wall_seconds, read_attempts
from .clock import run_engine_seconds
from .run_summary import read_summary

__all__ = ["run_status", "status_table", "find_runs", "COLUMNS"]

#: the columns of :func:`status_table`, in order (times in seconds of engine time)
COLUMNS = ["run_dir", "case", "engine", "status", "n_particles", "step", "steps", "steps_expected", "done", "attempts",
           "engine_s", "pace", "left_pace_s", "left_clock_s", "estimated_s", "error"]


def find_runs(paths) -> list[Path]:
    """The run directories (those holding a ``summary.json``) among ``paths``: each path a run
    directory (or its ``summary.json``) or a tree of them (a ``--runs`` directory, a ladder's).
    Raises FileNotFoundError for a path that does not exist, ValueError for another file."""
    out: list[Path] = []
    for p in map(Path, paths):
        if not p.exists():
            raise FileNotFoundError(2, "no such run directory or runs tree", str(p))
        if p.is_file() and p.name != "summary.json":
            raise ValueError(f"{p}: a file, not a run directory; give the directory `orchestrator run` wrote "
                             "(runs/<case>/<engine>-<hash>) or the runs tree above it (--runs)")
        if p.name == "summary.json":
            out.append(p.parent)
        elif (p / "summary.json").exists():
            out.append(p)
        else:
            out.extend(sorted(s.parent for s in p.rglob("summary.json")))
    seen: set[Path] = set()
    return [d for d in out if not (d.resolve() in seen or seen.add(d.resolve()))]


def _attempt_seconds(a: dict) -> float | None:
    """An attempt's engine time [s]: its CPU time on one rank (what the clock fits; the wall time
    of a run that shared its cores is longer), its wall time on several (a rank polls while it
    waits), its paused stretches out; None when not recorded."""
    cpu, wall = a.get("cpu_s"), attempt_wall_seconds(a)
    if int(a.get("ranks") or 1) == 1 and isinstance(cpu, (int, float)) and cpu > 0:
        return float(cpu)
    return wall if wall else None


def _latest_pace(attempts: list[dict]) -> float:
    """Steps per engine second [1/s] of the latest attempt that made progress, over its last 10
    minutes where recorded (its ``recent`` entry), else over the whole attempt; NaN without one."""
    for a in reversed(attempts):
        recent = a.get("recent")
        if isinstance(recent, dict) and isinstance(recent.get("steps"), int) and recent["steps"] > 0:
            t = _attempt_seconds({**recent, "ranks": a.get("ranks")})
            if t:
                return recent["steps"] / t
        first, last, t = a.get("first_step"), a.get("last_step"), _attempt_seconds(a)
        if isinstance(first, int) and isinstance(last, int) and last > first and t:
            return (last - first) / t
    return float("nan")


def run_status(run_dir) -> dict:
    """One run's state (the keys of :data:`COLUMNS`; NaN where a figure is not known):

    - ``status``: ``complete``, ``running`` (a live process holds the run), ``interrupted`` (resume
      it by running the same command again), ``failed``, ``unstable``, ...;
    - ``step``: the furthest step reached [-]; ``steps``: the run's step budget, or the step it ends
      at once the deck has said it (``end_step``, the module docstring) [-];
      ``steps_expected``: the steps it is expected to take (the module docstring); ``done``: step
      over steps_expected;
    - ``attempts``: how many times the engine was started on it;
    - ``engine_s``: the engine time spent so far [s], the steps a resume repeated included (a
      complete run's: :func:`orchestrator.clock.run_engine_seconds`, what an uninterrupted run would
      have taken);
    - ``pace``: steps per engine second of the latest attempt, over its last 10 minutes [1/s];
    - ``left_pace_s``, ``left_clock_s``: the engine time left [s] at that pace and by the clock's
      estimate before the run (the module docstring); 0 for a complete run;
    - ``estimated_s``: the clock's estimate of the whole run before its first attempt [s] (the
      latest attempt's, which ``left_clock_s`` takes, knows more of the machine);
    - ``error``: what the summary says went wrong (a run that failed, or a summary.json that cannot
      be read: :func:`orchestrator.run_summary.read_summary`), else None.
    """
    run_dir = Path(run_dir)
    s = read_summary(run_dir) or {}
    nan = float("nan")
    attempts = read_attempts(run_dir)
    end = next((a["end_step"] for a in reversed(attempts) if isinstance(a.get("end_step"), int)), None)
    known = s.get("steps_run") or end                      # the step the run ended, or ends, at
    steps = int(known or s.get("steps") or 0) or None
    expected = int(known or s.get("estimated_steps") or steps or 0) or None
    status = s.get("status", "unknown")
    reached = max((a["last_step"] for a in attempts if isinstance(a.get("last_step"), int)), default=None)
    est = s.get("estimated_engine_time_s")
    est = float(est) if isinstance(est, (int, float)) else nan
    first = s.get("first_estimated_engine_time_s")
    first = float(first) if isinstance(first, (int, float)) else est
    pace = _latest_pace(attempts)
    if status == "complete":
        reached = steps
        spent = run_engine_seconds(run_dir, s)
        left_pace = left_clock = 0.0
    else:
        times = [_attempt_seconds(a) for a in attempts]
        spent = sum(times) if times and None not in times else None
        left = max(expected - reached, 0) if expected and reached is not None else None
        left_pace = left / pace if left is not None and pace == pace else nan
        per = s.get("estimated_steps") or expected              # the steps the clock's estimate is for
        left_clock = est * left / int(per) if left is not None and per else nan
    return {
        "run_dir": str(run_dir), "case": s.get("case", ""), "engine": s.get("engine", ""), "status": status,
        "n_particles": s.get("n_particles"), "step": reached, "steps": steps, "steps_expected": expected,
        "done": reached / expected if expected and reached is not None else nan,
        "attempts": len(attempts), "engine_s": nan if spent is None else float(spent), "pace": pace,
        "left_pace_s": left_pace, "left_clock_s": left_clock, "estimated_s": first, "error": s.get("error"),
    }


def status_table(paths="runs") -> pd.DataFrame:
    """Every run under ``paths`` (a run directory, a runs tree, or a list of them), a row each
    (:func:`run_status`), as a plain DataFrame with the :data:`COLUMNS`::

        import orchestrator.run_status as rs
        rs.status_table("runs").query("status != 'complete'")[["case", "engine", "done", "left_pace_s"]]
    """
    dirs = find_runs([paths] if isinstance(paths, (str, Path)) else paths)
    return pd.DataFrame([run_status(d) for d in dirs], columns=COLUMNS)
