"""One small interface for every DEM engine: capabilities, render, run, parse.

An adapter knows how to turn derived parameters into its engine's input, launch the engine and
read its dumps into frames.h5. It knows nothing of analysis.

Physics features (the vocabulary scenes use in ``required_features``):

========================  ===========================================================
``hertz``                  Hertz normal elasticity
``restitution_damping``    viscous normal/tangential damping set from e_n (Tsuji form)
``low_restitution``        e_n below 0.214 (LIGGGHTS' model hertz floor)
``seed000_damping``        γ_n = √(4/3 E* m*) with force γ_n √ξ ξ̇ (seed 000 eq. 1)
``sliding_friction``       Coulomb sliding with a tangential spring (history)
``tangential_history_displacement``  the spring keeps the total tangential displacement ξ, F_t = k_t(δ) ξ
``tangential_history_force``         the spring keeps its force, incremented by k_t(δ) Δξ (contact.tangential_history)
``adhesion``               constant pull-off F_adh · r_eff/⟨r_eff⟩ (seed 000 eq. 1)
``rolling_friction``       rolling resistance, constant μ_rol
``rolling_friction_load``  load-dependent μ_rol = √(2 r_eff ξ) (seed 000)
``torsion_friction``       twisting resistance limited by μ_tor |F_n + F_adh|
``plane_wall``             analytic plane wall
``cylinder_wall``          analytic cylinder wall
``mesh_walls``             triangulated (STL) walls
``rotating_walls``         walls rotating at a prescribed angular velocity
``servo_wall``             a wall driven to a target force
``membrane``               flexible membrane with follow-the-surface pressure
``clumps``                 rigid clumps of spheres
``placed_clumps``          rigid clumps at given positions and orientations (LIGGGHTS-PUBLIC
                           multisphere bodies only enter through ``fix insert/*``: it offers the
                           substitute ``inserted_clumps``, random places and orientations)
``particle_stress``        per-particle stress tensor
``contact_output``         contact list with forces
``periodic``               periodic boundaries
========================  ===========================================================
"""
from __future__ import annotations

import ctypes
import os
import re
import selectors
import shutil
import signal
import subprocess
import sys
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path

from orchestrator.attempts import AttemptRecord
from orchestrator.humanize import fmt_s
from orchestrator.resources import templates_dir

FEATURES = (
    "hertz", "restitution_damping", "low_restitution", "seed000_damping", "sliding_friction", "adhesion",
    "rolling_friction", "rolling_friction_load", "torsion_friction", "plane_wall",
    "cylinder_wall", "mesh_walls", "rotating_walls", "servo_wall", "membrane", "clumps",
    "placed_clumps", "particle_stress", "contact_output", "periodic", "tangential_history_displacement",
    "tangential_history_force",
)

#: features that a single case field asks for (the rest follow from the scene and its physics), named
#: in the refusal of an engine that lacks them
CASE_FIELDS = {"tangential_history_displacement": "contact.tangential_history: displacement",
               "tangential_history_force": "contact.tangential_history: force"}

#: engine version per (adapter, executable), probed once per process (Engine.version)
_VERSIONS: dict = {}
#: ``<engine>/<scene>.<ext>.j2``: the top-level templates/ folder, shipped as package data
TEMPLATES = templates_dir()
#: the line a deck prints once it knows the step its run ends at, on every engine (a triaxial's
#: stage 1 goes on until it converges, so its length is known only when the loading starts, and
#: again on each resume in the loading): the progress lines then count toward that step
RUN_ENDS = re.compile(r"^RUN ENDS at step (\d+)")


class EngineError(RuntimeError):
    """An engine that failed, with its exit status and the tail of its log."""


class UnsupportedFeature(EngineError):
    """A case asks for physics an engine lacks, and names no accepted substitute."""


@dataclass
class Substitution:
    """An engine mechanism standing in for a physics term it lacks."""
    feature: str
    mechanism: str
    note: str = ""

    def as_dict(self):
        return {"feature": self.feature, "mechanism": self.mechanism, "note": self.note}


@dataclass
class RunResult:
    returncode: int
    wall_time: float
    steps: int
    log: Path
    timed_out: bool = False
    extra: dict = field(default_factory=dict)


class Engine(ABC):
    """Base class of the engine adapters."""

    name: str = ""
    executable: str = ""
    #: feature -> the engine mechanism that implements it exactly
    capabilities: dict[str, str] = {}
    #: feature -> {substitute name: description} the engine can offer instead
    substitutes: dict[str, dict[str, str]] = {}
    #: how the Mindlin spring keeps its history when the case does not say (contact.tangential_history):
    #: "displacement" or "force"; its capability ``tangential_history_<form>`` describes it
    tangential_history: str = "displacement"
    #: what a sticking contact's Coulomb test weighs against μF_n while the tangential spring has a
    #: dashpot (contact.tangential_damping): "spring" (the dashpot added on top, the total may exceed
    #: μF_n: LIGGGHTS' tangential_model_history, YADE's Law2_ScGeom_MindlinPhys_Mindlin) or "spring +
    #: dashpot" (the total capped: LAMMPS' pair granular)
    coulomb_limit_on: str = "spring"
    #: single-worker throughput [particle-steps/s] for run-time estimates when
    #: benchmarks/throughput.json holds no measurement (ENGINES.md: 2000 dense Hertz spheres)
    throughput: float = 1e6
    #: process start-up and set-up [s] (tiny verification cases: engine time minus loop time)
    startup: float = 1.0
    #: memory per particle [bytes] and fixed process overhead [bytes] (orders of magnitude, the
    #: engine's own data structures; orchestrator.sizing)
    bytes_per_particle: float = 5_000
    base_bytes: float = 300e6
    #: copies of all frames the parse holds in memory at once (frames x particles x columns doubles)
    parse_copies: int = 1

    #: the ``engine_options`` field that sets :meth:`workers` ("mpi_ranks" for an MPI engine)
    workers_field: str = "threads"
    #: whether every worker is a process of its own holding :attr:`base_bytes` (MPI ranks), rather
    #: than a thread of one process (orchestrator.sizing counts the memory so)
    workers_are_processes: bool = False

    def workers(self, case) -> int:
        """Parallel workers a run of ``case`` uses: its ``engine_options`` field
        :attr:`workers_field` (threads by default)."""
        return int(getattr(case.engine_options, self.workers_field))

    def complete_resume(self, case, run_dir: Path, resume: dict | None) -> dict | None:
        """Check and complete the resume point :meth:`resume_state` found for the case's scene
        (e.g. the stage state a deck needs to re-enter the right stage); None: start afresh. The
        default takes it as it is."""
        return resume

    # -- discovery -------------------------------------------------------------------------
    def available(self) -> bool:
        return shutil.which(self.executable) is not None

    def version(self) -> str:
        """Engine version string (e.g. ``LIGGGHTS-PUBLIC 3.8.0``), probed once per process and
        executable: get_engine() makes a new adapter every call, and a probe starts the engine
        (~0.5 s for LIGGGHTS), which every run_dir_for/run_case would otherwise pay."""
        key = (type(self).__name__, self.executable)
        if key not in _VERSIONS:
            _VERSIONS[key] = self._probe_version()
        return _VERSIONS[key]

    @abstractmethod
    def _probe_version(self) -> str:
        """Run the engine to read its version string."""

    # -- numbers -----------------------------------------------------------------------------
    def engine_params(self, case, params):
        """This engine's own numbers, derived from the shared parameters
        (:class:`orchestrator.params.Params`): a frozen dataclass the templates receive as
        ``engine`` (in ``engines/<name>/numbers.py``), None when the engine needs none. Raises
        :class:`orchestrator.contact_law.DerivationError` for a case its decks cannot realise
        (called for every engine a case names when the case is validated)."""
        return None

    def seed_term_ratios(self, case, params, overlaps) -> list[tuple[str, str, list[float]]]:
        """How this engine's decks realise seed 000's contact terms for one median pair
        (r_eff = x50/4), as (term, mechanism, [ratio to the seed's value at each overlap [m] of
        ``overlaps``]) (orchestrator.compare.ladder's single-contact table); empty: exactly."""
        return []

    def tangential_history_of(self, case) -> str:
        """The Mindlin spring's history in this engine's decks of ``case``: the case's
        ``contact.tangential_history`` or the engine's own."""
        return case.contact.tangential_history or self.tangential_history

    def required_features(self, case, params) -> list[str]:
        """The features this engine must offer for the case: the scene's (``params.features``),
        plus any its own numbers add (e.g. a restitution below what its law can be fed)."""
        return list(params.features)

    # -- capabilities ----------------------------------------------------------------------
    def check(self, features: list[str], accepted: dict[str, str]) -> list[Substitution]:
        """Refuse features the engine lacks unless ``accepted`` names a substitute it offers.

        ``accepted`` maps a feature to a substitute name (the case's ``contact.substitutes``,
        keys may be prefixed ``<engine>.`` to apply to one engine only)."""
        subs = []
        for f in features:
            if f in self.capabilities:
                continue
            offered = self.substitutes.get(f, {})
            choice = accepted.get(f"{self.name}.{f}", accepted.get(f))
            if choice is not None and choice in offered:
                subs.append(Substitution(f, choice, offered[choice]))
                continue
            if offered:
                opts = "; ".join(f"'{k}': {v}" for k, v in offered.items())
                raise UnsupportedFeature(
                    f"{self.name} has no exact mechanism for '{f}'. Accept a substitute in the case "
                    f"with contact.substitutes: {{{f}: NAME}} (or '{self.name}.{f}: NAME'); {self.name} offers {opts}")
            asked = CASE_FIELDS.get(f)
            raise UnsupportedFeature(f"{self.name} cannot simulate '{f}'"
                                     + (f" (asked by the case's {asked}; remove it to use {self.name}'s own)" if asked else "")
                                     + " and offers no substitute; run this case on another engine (`orchestrator engines` lists what "
                                       "each one simulates)")
        return subs

    def print_monitors(self, deck_text: str, overlap_limit: float) -> str:
        """The rendered deck patched so that its in-deck monitors print ``ORCH_OV <step> <overlap/r_min>
        <kinetic energy>`` at every check and trip at ``overlap_limit`` (orchestrator.stability.history)."""
        raise NotImplementedError(f"{self.name}: no monitor histories")

    # -- the three steps -------------------------------------------------------------------
    @abstractmethod
    def render(self, case, params: dict, run_dir: Path, resume: dict | None = None) -> Path:
        """Write the deck (and any input files) into ``run_dir``; return the main deck path."""

    @abstractmethod
    def command(self, deck: Path, case) -> list[str]:
        """The command line that runs ``deck``."""

    def progress_step(self, line: str) -> int | None:
        """Parse the current step from one line of engine output, or None."""
        return None

    @staticmethod
    def progress_end(line: str) -> int | None:
        """The step the run ends at, from a deck's ``RUN ENDS at step N`` line (:data:`RUN_ENDS`), or
        None: the same contract line on every engine."""
        m = RUN_ENDS.match(line)
        return int(m.group(1)) if m else None

    @abstractmethod
    def parse(self, case, params: dict, run_dir: Path, meta: dict) -> Path:
        """Read the engine's dumps in ``run_dir`` and write ``run_dir/frames.h5``."""

    def resume_state(self, run_dir: Path) -> dict | None:
        """What an interrupted run left to resume from (None: start afresh)."""
        return None

    # -- running ---------------------------------------------------------------------------
    def run(self, deck: Path, case, total_steps: int, log: Path, timeout: float,
            progress: bool | str = True, env: dict | None = None, first_step: int = 0,
            expected_steps: int | None = None, estimate_s: float | None = None) -> RunResult:
        """Run the engine on ``deck`` in its directory, streaming output into ``log``, with a
        progress bar (a string ``progress``: under that label) fed by the engine's step counter (toward ``expected_steps`` where the scene
        decides its length while it runs and fewer than ``total_steps`` are expected; beside the clock's
        ``estimate_s`` [s] for the whole run where the recent pace says otherwise), a wall-clock
        ``timeout`` [s] and a kill.
        The attempt's steps (from ``first_step``, the resume point) and engine time go into the run
        directory's ``attempts.json`` as it runs (:mod:`orchestrator.attempts`).
        Raises :class:`EngineError` with the log's last lines on failure."""
        cmd = self.command(deck, case)
        run_dir = deck.parent
        full_env = dict(os.environ)
        full_env.update(env or {})
        full_env.setdefault("OMP_NUM_THREADS", str(case.engine_options.threads))
        t0 = time.perf_counter()
        step = first_step or 0              # a resumed run's lines start at its resume point, not at 0
        timed_out = False
        usage: list[float] = []             # the engine's CPU time [s], filled when it is reaped
        with open(log, "ab") as logf:
            proc = subprocess.Popen(cmd, cwd=run_dir, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                    env=full_env, start_new_session=True, preexec_fn=_die_with_parent)
            label = progress if isinstance(progress, str) else f"{self.name} {case.name}"     # a ladder's rung names itself
            bar = _Progress(label, total_steps, enabled=bool(progress), expected=expected_steps, estimate_s=estimate_s)
            attempt = AttemptRecord(run_dir, first_step, self.workers(case))
            try:
                sel = selectors.DefaultSelector()
                sel.register(proc.stdout, selectors.EVENT_READ)
                buf = b""
                while True:
                    if time.perf_counter() - t0 > timeout:
                        timed_out = True
                        _kill(proc)
                        break
                    events = sel.select(timeout=0.5)
                    if not events:
                        if _reap(proc, 0.0, usage):
                            break
                        bar.update(step, reported=False)   # a quiet engine (setup, a long stage) still gets its lines
                        attempt.update(step, proc.pid)
                        continue
                    chunk = os.read(proc.stdout.fileno(), 65536)
                    if not chunk:
                        break
                    logf.write(chunk)
                    logf.flush()                    # `tail -f engine.log` shows a live run
                    buf += chunk
                    *lines, buf = buf.split(b"\n")
                    for raw in lines:
                        text = raw.decode(errors="replace")
                        s = self.progress_step(text)
                        if s is not None:
                            step = s
                            bar.update(step)
                        end = self.progress_end(text)
                        if end is not None:
                            bar.end_at(end)
                            attempt.end_at(end)
                    attempt.update(step, proc.pid)
                if not _reap(proc, 30.0, usage):
                    raise subprocess.TimeoutExpired(cmd, 30.0)
            except BaseException:
                _kill(proc)
                raise
            finally:
                bar.close()
                attempt.close(step, usage[0] if usage else None,
                              done=proc.returncode == 0 and not timed_out)
        wall = time.perf_counter() - t0
        extra = {"cpu_s": usage[0]} if usage else {}
        if attempt.entry["paused_s"]:
            extra["paused_s"] = attempt.entry["paused_s"]      # wall time stopped (SIGSTOP, a suspend) [s]
        res = RunResult(proc.returncode if proc.returncode is not None else -9, wall, step, log, timed_out,
                        extra=extra)
        if timed_out:
            raise EngineError(f"{self.name} exceeded its wall-clock limit of {timeout:.0f} s and was killed "
                              f"(engine_options.timeout).\n{tail(log)}")
        if proc.returncode != 0:
            raise EngineError(f"{self.name} {_exit_words(proc.returncode)} running {deck}; the run directory keeps "
                              f"its restart points: run the same command again to resume.\n{self.explain_failure(log)}")
        return res

    def explain_failure(self, log: Path) -> str:
        return tail(log)

    def loop_time(self, log: Path) -> float:
        """Seconds the engine spent integrating (its own report), or NaN when unknown."""
        return float("nan")


def _exit_words(code: int) -> str:
    """'failed with exit status N' or 'was killed by signal SIGSEGV (11)' (a negative code, or 128 + the
    signal from a shell or mpirun)."""
    sig = -code if code < 0 else code - 128 if 128 < code < 160 else None
    if sig:
        try:
            return f"was killed by signal {signal.Signals(sig).name} ({sig})"
        except ValueError:
            pass
    return f"failed with exit status {code}"


def _die_with_parent():
    """In the child: ask Linux to send SIGTERM when the orchestrator dies (PR_SET_PDEATHSIG), so a
    killed orchestrator never leaves an engine writing into a run directory."""
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)
    except OSError:  # pragma: no cover - not Linux
        pass


def _reap(proc, timeout: float, usage: list) -> bool:
    """Wait up to ``timeout`` [s] for the engine to exit and reap it with ``os.wait4``, which also
    gives its resource usage: the CPU time (user + system) [s] of the engine process and of every
    descendant it waited for (mpirun's ranks), appended to ``usage``. Unlike the wall time, the CPU
    time hardly changes when other work shares the cores, so the run-time model (orchestrator.clock)
    is fitted on it. Returns whether the process has exited (its returncode then set)."""
    if proc.returncode is not None:
        return True
    deadline = time.perf_counter() + timeout
    while True:
        try:
            pid, status, ru = os.wait4(proc.pid, os.WNOHANG)
        except ChildProcessError:                  # reaped elsewhere: no usage, status from Popen
            return proc.poll() is not None
        if pid:
            proc.returncode = os.waitstatus_to_exitcode(status)
            usage.append(ru.ru_utime + ru.ru_stime)
            return True
        if time.perf_counter() >= deadline:
            return False
        time.sleep(0.02)


def _kill(proc):
    try:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(timeout=5)
    except Exception:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except Exception:
            pass
        proc.wait()


def tail(path: Path, n: int = 25) -> str:
    """The last ``n`` lines of a log, indented, for error messages."""
    try:
        lines = Path(path).read_text(errors="replace").splitlines()[-n:]
    except OSError:
        return f"(no log at {path})"
    return "last lines of " + str(path) + ":\n" + "\n".join("    " + l for l in lines)


class _Progress:
    """A rich progress bar with ETA, fed with the engine's step counter; not on a terminal (a log,
    a batch job), one line on stderr every :attr:`EVERY` seconds instead."""

    #: seconds between two progress lines when stderr is not a terminal (ORCHESTRATOR_PROGRESS_EVERY
    #: overrides it, e.g. for a test or a batch system that wants fewer lines)
    EVERY = float(os.environ.get("ORCHESTRATOR_PROGRESS_EVERY", "30"))
    #: the ETA extrapolates the rate of the last this many seconds: a run's step rate changes
    #: between stages (a loose packing runs fast, a sheared dense one slowly) and with the load
    #: of the machine, so the mean rate since the start under-estimates the rest
    RATE_WINDOW = 120.0
    #: the lines give the clock's time left beside the ETA when one is more than this times the other
    CLOCK_APART = 1.5

    def __init__(self, label: str, total: int, enabled: bool = True, expected: int | None = None,
                 estimate_s: float | None = None):
        self.p = None
        #: the clock's engine time for the whole run [s] (orchestrator.clock, before the run): the
        #: recent pace of a run whose steps get dearer as it goes promises too little (YADE's medium
        #: shear cell on two threads: "ETA 16.6 min" at step 37 584, 90.3 s in, in the loose packing;
        #: "ETA 2.1 h" at step 173 826, 33.7 min in, once packed), so the lines give both where they differ
        self.estimate_s = float(estimate_s) if estimate_s and estimate_s > 0 else None
        self.lines = False
        if not enabled or total <= 0:
            return
        self.label, self.total, self.t0 = label, total, time.perf_counter()
        #: the steps the run is expected to take, where its scene decides its length while it runs
        #: (a triaxial's stage 1 goes on until it converges: the budget allows every chunk, the
        #: engine's measured runs took about half of it, orchestrator.clock.planned_steps); the
        #: lines count toward it, and toward the budget once the run has gone past it
        self.expected = int(expected) if expected and 0 < expected < total else None
        self.first = None                        # (time, step) of the first report: a resumed run starts late
        self.samples = []                        # (time, step) of the last reports, for the ETA
        self.next = self.t0 + self.EVERY
        if not sys.stderr.isatty():
            self.lines = True
            goal = f"{total:,} steps" + (f" at most, ~{self.expected:,} expected" if self.expected else "")
            print(f"{label}: started, {goal}; a progress line every {self.EVERY:.0f} s", file=sys.stderr,
                  flush=True)
            return
        try:
            from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                                       TimeElapsedColumn, TimeRemainingColumn)
            self.p = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                              TimeElapsedColumn(), TimeRemainingColumn(), TextColumn("{task.fields[clock]}"),
                              transient=True, get_time=lambda: time.perf_counter())    # the lines' clock
            self.p.start()
            self.task = self.p.add_task(label, total=self.expected or total, clock="")
        except Exception:
            self.p = None

    def end_at(self, step: int):
        """The run ends at ``step`` (the deck has said so, :data:`RUN_ENDS`): the lines count toward it,
        no longer toward the expected steps (the clock's guess at a triaxial's stage 1: YADE's medium
        clump run read "step 496,000/~528,000 expected (94 %), ETA 14.5 min" with its loading running
        to step 704 001)."""
        if step <= 0 or (self.p is None and not self.lines):
            return
        self.expected, self.total = None, int(step)
        if self.p is not None:
            self.p.update(self.task, total=self.total)

    def goal(self, step: int) -> int:
        """The step count the progress is measured against [-]: the expected steps until the run
        passes them, then the budget."""
        return self.expected if self.expected and step <= self.expected else self.total

    def update(self, step: int, reported: bool = True):
        """Show ``step``; ``reported``: the engine has just said it (False: the lines go on while the
        engine is quiet, e.g. loading a resumed run's checkpoint, which the step rate must not count)."""
        if self.p is not None:
            goal = self.goal(step)
            self.p.update(self.task, completed=step, total=goal)
            task = next(t for t in self.p.tasks if t.id == self.task)
            self.p.update(self.task, clock=self._clock_clause(step, goal, task.time_remaining))
        elif self.lines:
            now = time.perf_counter()
            if self.first is None and reported and step > 0:   # the first report (a resumed run starts late)
                self.first = (now, step)
                self.samples.append(self.first)
            if now >= self.next:
                self.next = now + self.EVERY
                if self.samples:
                    self.samples.append((now, step))
                    while len(self.samples) > 2 and now - self.samples[1][0] >= self.RATE_WINDOW:
                        self.samples.pop(0)
                t, s0 = self.samples[0] if self.samples else (now, step)
                rate = (step - s0) / (now - t) if now > t and step > s0 else 0.0
                goal = self.goal(step)
                of = f"~{goal:,} expected (at most {self.total:,})" if goal != self.total else f"{goal:,}"
                eta = f", ETA {fmt_s((goal - step) / rate)}" if rate > 0 else ""
                eta += self._clock_clause(step, goal, (goal - step) / rate if rate > 0 else None)
                print(f"{self.label}: step {step:,}/{of} ({100 * step / goal:.0f} %), "
                      f"{fmt_s(now - self.t0)}{eta}", file=sys.stderr, flush=True)

    def _clock_clause(self, step: int, goal: int, left_pace: float | None) -> str:
        """" (the clock's estimate: X left)" where the clock's time for the steps left (its estimate
        for the whole run, shared evenly over the steps) and the ETA at the recent pace differ by more
        than :attr:`CLOCK_APART` times, or there is no pace yet; "" otherwise or without an estimate."""
        if self.estimate_s is None or goal <= 0:
            return ""
        left_clock = self.estimate_s * max(goal - step, 0) / goal
        if left_pace is not None and max(left_clock, left_pace) <= self.CLOCK_APART * min(left_clock, left_pace):
            return ""
        return f" (the clock's estimate: {fmt_s(left_clock)} left)"

    def close(self):
        if self.p is not None:
            self.p.stop()
