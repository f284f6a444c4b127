"""The engine time of every attempt at a run, so that a run that was killed and resumed still tells
the clock (:mod:`orchestrator.clock`) what it cost.

A run that resumes from a checkpoint used to drop out of the run-time model: its summary's engine
time covers only the last attempt. The long runs (medium cases, hours) are exactly the ones that
get interrupted, and exactly the ones the model needs. While the engine runs, ``attempts.json`` in
the run directory holds one entry per attempt, rewritten every :attr:`AttemptRecord.EVERY` seconds
(5; atomically; a SIGKILL loses at most that much)::

    {"first_step": 101680, "last_step": 236160, "wall_s": 1933.0, "cpu_s": 1911.2, "ranks": 1,
     "load": 2.9, "cores": 2, "done": false,
     "recent": {"steps": 15040, "wall_s": 601.2, "cpu_s": 598.7}}

``cpu_s`` is the CPU time (user + system) of the engine and its descendants, read with psutil
while it runs (a rank that exited is counted in its parent's children times), and the ``os.wait4``
figure once it is reaped. ``load`` is the machine's one-minute load average, averaged over the
samples taken at each write (the attempt's own ranks included), beside the machine's ``cores``: a
run whose ``load`` exceeds its ``cores`` shared the machine, and its wall time is longer than a
quiet machine's (``benchmarks/bench_estimate.py`` marks it). ``recent`` holds the steps, wall and CPU
time of the attempt's latest :attr:`AttemptRecord.WINDOW` seconds (10 min), from the first report
of one step to that of another: the pace now, which ``orchestrator status`` divides the steps left
by (a run slows as a shear cell's sample densifies; a stretch that shared the machine or was paused
with SIGSTOP weighs on it for one window, not for the rest of the attempt). ``paused_s`` is the
wall time the engine spent stopped: every stretch between two writes in which its processes used
less than :data:`IDLE_CPU_SHARE` of a core (SIGSTOP, a scheduler's suspend such as Slurm's
``scontrol suspend``; a rank waiting for another polls, so it counts as running). The attempt's
engine time on several ranks is its wall time less that (:func:`attempt_wall_seconds`). A fresh
start clears the file.

:func:`run_cost` turns the record into the engine time an uninterrupted run would have taken: each
attempt's time scaled by the share of its steps that were new (a resume repeats the steps since the
checkpoint), summed; ``None`` when the record does not cover the run from step 0 without a gap.
"""
from __future__ import annotations

import json
import os
import time
from collections import deque
from pathlib import Path

import psutil

from .atomic import write_json

__all__ = ["AttemptRecord", "read_attempts", "run_cost", "clear_attempts", "attempt_wall_seconds", "FILE"]

#: the record's file name in a run directory
FILE = "attempts.json"

#: CPU time [share of one core] below which the engine's processes count as paused over a stretch
#: between two writes: a running engine, even one waiting on another rank, uses a whole core
IDLE_CPU_SHARE = 0.02

def read_attempts(run_dir) -> list[dict]:
    """The attempts recorded in ``run_dir`` (oldest first); [] when none or unreadable."""
    try:
        data = json.loads((Path(run_dir) / FILE).read_text())
    except (OSError, ValueError):
        return []
    return data if isinstance(data, list) else []


def attempt_wall_seconds(a: dict) -> float | None:
    """An attempt's wall time [s] with its paused stretches (``paused_s``) taken out; None when not
    recorded."""
    wall = a.get("wall_s")
    if not isinstance(wall, (int, float)):
        return None
    paused = a.get("paused_s")
    return max(float(wall) - (float(paused) if isinstance(paused, (int, float)) else 0.0), 0.0)


def clear_attempts(run_dir) -> None:
    """Forget the attempts of an earlier try (a fresh start)."""
    try:
        (Path(run_dir) / FILE).unlink()
    except FileNotFoundError:
        pass


def process_tree_cpu_seconds(pid: int) -> float | None:
    """CPU time (user + system) [s] of process ``pid``, of its live descendants (mpirun's ranks) and
    of the children it has reaped (psutil's ``children_user``/``children_system``); None when the
    process is gone."""
    try:
        root = psutil.Process(pid)
        procs = [root] + root.children(recursive=True)
    except psutil.Error:
        return None
    total = 0.0
    for proc in procs:
        try:
            t = proc.cpu_times()
        except psutil.Error:            # exited meanwhile
            continue
        total += t.user + t.system + t.children_user + t.children_system
    return total


class AttemptRecord:
    """Keeps this attempt's entry of ``run_dir/attempts.json`` up to date (see the module
    docstring). ``update`` is cheap to call often: it writes every :attr:`EVERY` seconds."""

    #: seconds between two writes of the record (ORCHESTRATOR_ATTEMPT_EVERY overrides it, e.g. for a
    #: test that kills a run after a few seconds)
    EVERY = float(os.environ.get("ORCHESTRATOR_ATTEMPT_EVERY", "5"))
    #: seconds of wall time the ``recent`` pace spans (at least; the oldest sample kept is the
    #: latest one this old)
    WINDOW = 600.0
    #: the wall clock [s] (a test steps a fake one)
    clock = staticmethod(time.perf_counter)

    def __init__(self, run_dir, first_step: int | None, ranks: int = 1):
        """``first_step``: the step the attempt starts from (0 for a fresh start); None when the
        resume point does not say (YADE's checkpoint): the first step the engine reports, later by
        at most one progress interval."""
        self.path = Path(run_dir) / FILE
        self.t0 = self.clock()
        self.next = self.t0 + self.EVERY
        first = None if first_step is None else int(first_step)
        self.entry = {"first_step": first, "last_step": first, "wall_s": 0.0,
                      "cpu_s": None, "ranks": int(ranks), "load": None, "cores": os.cpu_count(), "done": False,
                      "paused_s": 0.0}
        self._last_cpu: tuple[float, float] | None = None     # (wall [s], CPU [s]) at the last write
        self._load_sum, self._load_n = 0.0, 0
        self._samples: deque = deque()      # (wall [s], step, cpu [s] or None) at each write
        self.earlier = read_attempts(run_dir)
        self._write()

    def _write(self) -> None:
        try:
            write_json(self.path, self.earlier + [self.entry])
        except OSError:            # a full disk must not kill the run it describes
            pass

    def _note(self, step: int) -> None:
        if not step:
            return
        if self.entry["first_step"] is None:
            self.entry["first_step"] = int(step)
        self.entry["last_step"] = max(self.entry["last_step"] or 0, int(step))

    def end_at(self, step: int) -> None:
        """Note the step the run ends at, once the deck has said it (``end_step``; a triaxial's
        loading end, engines.base.RUN_ENDS): ``orchestrator status`` counts toward it (written with
        the next update)."""
        self.entry["end_step"] = int(step)

    def update(self, step: int, pid: int | None = None, force: bool = False) -> None:
        """Note the engine's current ``step`` and, every EVERY seconds, write the record with the
        wall time and the CPU time of process ``pid`` and its descendants so far."""
        self._note(step)
        now = self.clock()
        if not force and now < self.next:
            return
        self.next = now + self.EVERY
        self.entry["wall_s"] = now - self.t0
        self._sample_load()
        if pid is not None:
            cpu = process_tree_cpu_seconds(pid)
            if cpu is not None:
                self._note_pause(self.entry["wall_s"], cpu)
                self.entry["cpu_s"] = cpu
        self._note_recent()
        self._write()

    def _note_pause(self, wall: float, cpu: float) -> None:
        """Count the stretch since the last write as paused when the engine's processes used less
        than IDLE_CPU_SHARE of a core in it (``wall``, ``cpu``: the attempt's times so far [s])."""
        if self._last_cpu is not None:
            dw, dc = wall - self._last_cpu[0], cpu - self._last_cpu[1]
            if dw > 0 and dc < IDLE_CPU_SHARE * dw:
                self.entry["paused_s"] = round(self.entry["paused_s"] + dw, 3)
        self._last_cpu = (wall, cpu)

    def _note_recent(self) -> None:
        """Record the steps, wall and CPU time between the first reports of two steps, the latest
        WINDOW seconds of them (and the one just before), as ``recent``; a run with no new step for
        a whole WINDOW records 0 steps over the time since its last one (stalled or paused).

        The samples are taken when a step is first reported, not at every write: an engine that
        reports sparsely (YADE's triaxial on the medium clumps: every 5 040 steps) put
        a window of writes around one report or two, and its pace read 12 or 31 steps per CPU
        second from the same steady run."""
        e = self.entry
        if e["last_step"] is None:
            return
        sample = (e["wall_s"], e["last_step"], e["cpu_s"])
        if not self._samples or sample[1] != self._samples[-1][1]:
            self._samples.append(sample)            # the moment this step was first reported
        while len(self._samples) > 2 and self._samples[-1][0] - self._samples[1][0] >= self.WINDOW:
            self._samples.popleft()
        (w0, s0, c0), (w1, s1, c1) = self._samples[0], self._samples[-1]
        if sample[0] - w1 >= self.WINDOW:           # no new step for a window: status paces by the attempt
            e["recent"] = {"steps": 0, "wall_s": round(sample[0] - w1, 3),
                           "cpu_s": None if c1 is None or sample[2] is None else round(sample[2] - c1, 3)}
        elif len(self._samples) > 1:
            e["recent"] = {"steps": s1 - s0, "wall_s": round(w1 - w0, 3),
                           "cpu_s": None if c0 is None or c1 is None else round(c1 - c0, 3)}

    def _sample_load(self) -> None:
        try:
            self._load_sum += os.getloadavg()[0]
        except OSError:                 # no load average on this platform
            return
        self._load_n += 1
        self.entry["load"] = round(self._load_sum / self._load_n, 2)

    def close(self, step: int, cpu_s: float | None, done: bool) -> None:
        """The attempt ended at ``step`` with the engine's reaped CPU time ``cpu_s`` [s]; ``done``:
        the engine finished the run."""
        self._note(step)
        self.entry["wall_s"] = self.clock() - self.t0
        if cpu_s is not None:
            self.entry["cpu_s"] = float(cpu_s)
        self.entry["done"] = bool(done)
        self._write()


#: largest gap between two attempts' recorded steps [fraction of the run] that counts as covered
#: (an attempt's record lags its engine by up to EVERY seconds; a resume without a stated step is
#: first seen at the engine's first progress line); its time is taken at the next attempt's rate
GAP_TOLERANCE = 0.02


def run_cost(attempts: list[dict], steps_run: int, use_cpu: bool) -> float | None:
    """Engine time [s] an uninterrupted run of ``steps_run`` steps would have taken, from the record
    of its attempts: each attempt's CPU time (``use_cpu``, where recorded) or wall time (its paused
    stretches out: :func:`attempt_wall_seconds`), times the
    share of its steps that were new, summed (a gap of up to :data:`GAP_TOLERANCE` of the run
    between two attempts counted at the later one's rate). None when the record does not start at
    step 0, leaves a larger gap, stops short of ``steps_run`` by more than that, or has an attempt
    without time."""
    if not attempts or attempts[0].get("first_step") != 0 or steps_run <= 0:
        return None
    reached, total = 0, 0.0
    for a in attempts:
        if not isinstance(a, dict):
            return None                  # not a record this module wrote
        first, last = a.get("first_step"), a.get("last_step")
        if first is None and last is None:
            continue                     # killed before its first step: start-up an uninterrupted run has once
        t = a.get("cpu_s") if use_cpu and a.get("cpu_s") else attempt_wall_seconds(a)
        if not isinstance(first, int) or not isinstance(last, int) or not isinstance(t, (int, float)) or t <= 0:
            return None
        if first - reached > GAP_TOLERANCE * steps_run:
            return None
        if last > first:
            rate = t / (last - first)
            total += rate * (max(last - reached, 0) if first <= reached else (last - first) + (first - reached))
        reached = max(reached, last)
    if reached < (1 - GAP_TOLERANCE) * steps_run:
        return None
    return total
