"""Sizing a case before any work: particle count, steps, frames, memory, disk and engine time,
from the derived parameters alone (no packing, no meshes), and the refusal of a case that does
not fit the machine.

Memory per particle (order of magnitude, the engines' own data structures) is each engine's
figure (``Engine.bytes_per_particle``, ``base_bytes``, ``parse_copies``: engines/<name>/adapter.py);
every MPI rank is a process with its own ``base_bytes`` (``Engine.workers_are_processes``), threads
share one.
The orchestrator's own packing holds positions, radii and a grid index (~0.2 kB per particle).
These figures decide refusal only by orders of magnitude: a case is refused when it needs more
memory than the machine has.
"""
from __future__ import annotations

import os
import time
from typing import TYPE_CHECKING

from .clock import ASSUMED_WORDS, SPREAD_WORDS, UNMEASURED_WORDS, clock_key, estimate_engine_time, load_table, planned_steps, step_plan
from .humanize import fmt_bytes, fmt_s
from .registry import get_engine

if TYPE_CHECKING:
    from .case import Case

#: the orchestrator's packing and particle table [bytes per particle]
PACKING_BYTES_PER_PARTICLE = 200
#: fraction of the machine's memory a run may plan to use
MEMORY_FRACTION = 0.8


class SizeError(ValueError):
    """A case too big for this machine (refused unless forced)."""


def machine_memory() -> int:
    """Total memory of this machine [bytes] (/proc/meminfo MemTotal)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemTotal:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def frame_count(params: dict) -> int:
    """Frames the run writes: the scene's frame steps, else one per ``dump_every`` steps."""
    sc = params["scene"]
    if sc.get("frame_steps"):
        return len(sc["frame_steps"])
    steps = sc.get("total_steps", sc["steps"])
    return steps // max(int(sc.get("dump_every", steps) or steps), 1) + 1


def integrated_particles(params: dict) -> int:
    """Spheres the engine integrates: the scene's grains, or their member spheres when the grains
    are clumps (``n_spheres``; frames.h5 holds the members too)."""
    sc = params["scene"]
    return int(sc.get("n_spheres") or sc.get("n") or len(sc.get("ids", [])))


def step_budget(sc: dict, plan) -> int:
    """Most steps a run with the derived scene numbers ``sc`` can take [-]: the derived
    ``total_steps``, or where the scene decides its step count while it runs (triaxial stage 1), the
    maximum of its step ``plan`` (:func:`orchestrator.clock.step_plan`; None: none), whichever is larger (for the
    triaxial they agree since session 18: its derived budget counts the pressure ramp's chunks too,
    which a 2 000-grain LIGGGHTS run took besides the tested ones, 334 400 steps against the old
    budget of 311 600)."""
    steps = int(sc.get("total_steps", sc["steps"]))
    return max(steps, plan.steps(plan.max_units)) if plan is not None else steps


def estimate(case, params: dict, engine: str) -> dict:
    """Size of one run: ``particles``, ``steps`` (the budget), ``steps_expected`` (what the engine's
    measured runs of the scene took, :func:`orchestrator.clock.planned_steps`), ``frames``, ``memory_bytes`` (the larger of the
    engine and the parse), ``disk_bytes`` (frames.h5), ``engine_time_s``."""
    sc = params["scene"]
    n = integrated_particles(params)
    key, steps, plan = clock_inputs(case, sc, engine)
    frames = frame_count(params)
    o = case.output
    cols = 1 + 3 * (1 + o.velocity + o.angular_velocity + o.force + o.torque) + (7 if o.stress else 0)
    frames_bytes = frames * n * cols * 8
    eng = get_engine(engine)
    table = load_table()
    t_engine, basis = _engine_time(case, params, engine, key, steps, plan, table, machine_speed=True)
    # a scene that decides its step count while it runs (triaxial stage 1): the steps its measured runs took
    steps_expected, _ = planned_steps(table, engine, key, steps, plan)
    workers = eng.workers(case)
    # the same run on one rank or thread, where this machine's records may say it is no slower
    one = (_engine_time(case, params, engine, key, steps, plan, table, machine_speed=True, workers=1)[0]
           if speedup_workers(case, eng) > 1 and not case.engine_options.scheduler else None)
    # every MPI rank is a process with the engine's own overhead; threads share one
    engine_mem = eng.base_bytes * (workers if eng.workers_are_processes else 1) + n * eng.bytes_per_particle
    parse_mem = eng.parse_copies * frames_bytes
    return {"engine": engine, "particles": n, "steps": steps, "steps_expected": steps_expected, "frames": frames,
            "workers": workers, "workers_field": eng.workers_field,
            "packing_bytes": n * PACKING_BYTES_PER_PARTICLE,
            "memory_bytes": int(max(engine_mem, parse_mem, n * PACKING_BYTES_PER_PARTICLE)),
            "disk_bytes": int(frames_bytes), "engine_time_s": float(t_engine), "engine_time_basis": basis,
            "engine_time_one_worker_s": one}


def describe(size: dict) -> str:
    expected = size.get("steps_expected", size["steps"])
    steps = (f"{size['steps']:,} steps" if expected >= size["steps"]
             else f"~{expected:,} steps (at most {size['steps']:,})")
    return (f"{size['particles']:,} particles, {steps}, {size['frames']} frames; memory "
            f"~{fmt_bytes(size['memory_bytes'])}, frames.h5 ~{fmt_bytes(size['disk_bytes'])}, engine time "
            f"~{fmt_s(size['engine_time_s'])}" + _basis_note(size.get("engine_time_basis", "")))


def _basis_note(basis: str) -> str:
    """The estimate's basis after the figure, unless it is the engine's and scene's own runs at sizes
    near the case's on the ranks they were measured on (then only its caveats: an extrapolation,
    :data:`orchestrator.clock.EXTRAPOLATION_NOTE`, an assumed parallel efficiency, or the spread
    of the steps the runs measured took, :data:`orchestrator.clock.SPREAD_WORDS`, or this machine's speed
    not measured yet, :data:`orchestrator.clock.UNMEASURED_WORDS`)."""
    if not basis:
        return ""
    if basis.startswith("measured"):
        caveats = [clause for clause in basis.split(", ")
                   if clause.endswith("an extrapolation") or ASSUMED_WORDS in clause or SPREAD_WORDS in clause
                   or UNMEASURED_WORDS in clause]
        return f" ({', '.join(caveats)})" if caveats else ""
    return f" ({basis})"


def problems(case, size: dict) -> list[str]:
    """Why the run does not fit this machine (empty when it does), and warnings prefixed 'warning:'."""
    out = []
    mem = machine_memory()
    if size["memory_bytes"] > MEMORY_FRACTION * mem:
        ranks = size.get("workers", 1) if size.get("workers_field") == "mpi_ranks" else 1
        out.append(f"needs ~{fmt_bytes(size['memory_bytes'])} of memory for {size['particles']:,} particles"
                   + (f" on {ranks:,} MPI ranks (each a process of the engine's own)" if ranks > 1 else "")
                   + f"; this machine has {fmt_bytes(mem)}")
    workers, cores = size.get("workers", 1), os.cpu_count() or 1
    if workers > cores and not case.engine_options.scheduler:
        field = size.get("workers_field", "threads")
        out.append(f"warning: engine_options.{field} = {workers} is more than this machine's {cores} cores: the "
                   f"{'ranks' if field == 'mpi_ranks' else 'threads'} would share them, which makes the run slower, "
                   f"not faster (the estimate counts {cores}); set engine_options.{field} to at most {cores}, or "
                   "send the run to a cluster (engine_options.scheduler)")
    one = size.get("engine_time_one_worker_s")
    if one is not None and one < size["engine_time_s"]:
        field = size.get("workers_field", "threads")
        unit = "rank" if field == "mpi_ranks" else "thread"
        out.append(f"warning: on one {unit} this run is estimated at ~{fmt_s(one)}, less than the "
                   f"~{fmt_s(size['engine_time_s'])} on engine_options.{field} = {workers}: this machine's "
                   f"{size['engine']} runs on {workers} {unit}s and on one (`orchestrator clock show`) predict "
                   f"no speed-up from the others (docs/engines.md); set engine_options.{field} to 1 to run it "
                   "faster and leave the other cores free")
    timeout = case.engine_options.timeout
    if size["engine_time_s"] > timeout:
        out.append(f"warning: the estimated engine time {fmt_s(size['engine_time_s'])} exceeds "
                   f"engine_options.timeout = {fmt_s(timeout)}; the run would be stopped there (raise the timeout "
                   "or shrink the case)")
    return out


def busy_cores(sample_s: float = 0.25) -> float | None:
    """Cores [-] the machine's other processes keep busy now: the share of non-idle time over
    ``sample_s`` seconds of /proc/stat's aggregate ``cpu`` line, times the cores; None where there
    is no /proc/stat. Not the load average, which lags by minutes (a fresh clone's set-up that has
    just finished reads as a busy machine for a minute after it)."""
    def read():
        with open("/proc/stat") as f:
            v = [float(x) for x in f.readline().split()[1:]]
        return sum(v), v[3] + (v[4] if len(v) > 4 else 0.0)          # total, idle + iowait
    try:
        t0, i0 = read()
        time.sleep(sample_s)
        t1, i1 = read()
    except (OSError, ValueError, IndexError):
        return None
    dt = t1 - t0
    return (1.0 - (i1 - i0) / dt) * (os.cpu_count() or 1) if dt > 0 else None


def busy_note(workers: int = 1, busy: float | None = None, cores: int | None = None) -> str | None:
    """A note when this machine is busy enough to slow the run past its estimate (None when
    quiet): ``busy`` cores in use by other processes (default: :func:`busy_cores`, measured now)
    above the cores the run leaves free by more than half a core. The estimate is for a quiet
    machine; on the 2-core machine of 28 Nov 2026 a one-rank run beside other runs took 8-15 % more
    CPU time on LIGGGHTS and LAMMPS and 12-36 % more on YADE (twice as much beside another YADE
    run), and two MPI ranks beside three other runs took 5-11x the wall time (docs/validation.md,
    "This machine's speed")."""
    if busy is None:
        busy = busy_cores()
        if busy is None:
            return None
    cores = cores or os.cpu_count() or 1
    if busy <= cores - workers + 0.5:
        return None
    return (f"note: this machine is busy ({busy:.1f} of its {cores} cores in use, the run adds {workers}): the "
            f"estimate is for a quiet machine, and sharing the cores makes the run slower (one rank: 8-36 % more "
            f"CPU time measured here, up to twice as much for two YADE runs; several ranks: several times the wall time)")


def check_fits(case, size: dict, force: bool = False) -> list[str]:
    """Raise :class:`SizeError` when the case does not fit (unless ``force``); return warnings."""
    probs = problems(case, size)
    hard = [p for p in probs if not p.startswith("warning:")]
    if hard and not force:
        src = case.source or case.name
        ranks = size.get("workers", 1) if size.get("workers_field") == "mpi_ranks" else 1
        fewer = f"fewer engine_options.mpi_ranks than {ranks:,}, " if ranks > 1 else ""
        raise SizeError(f"{src}: case '{case.name}' on {size['engine']} is too big for this machine: "
                        + "; ".join(hard) + f" ({describe(size)}). Shrink the case ({fewer}scene size, particle "
                        "size distribution) or give --force to run it anyway")
    return [p for p in probs if p.startswith("warning:")] + (["warning: forced past: " + "; ".join(hard)]
                                                             if hard else [])


def run_estimate(case: Case, params: dict, engine_name: str) -> tuple[float, int]:
    """(engine time [s], steps [-]) a run is estimated to take, from one read of the table: the
    time of :func:`_engine_time` and the steps it is for, the budget or, for a scene that
    decides its step count while it runs (triaxial stage 1), the steps the engine's measured runs
    took (:func:`orchestrator.clock.planned_steps`). What a run's summary.json records at its start:
    the figure the dry run prints (:func:`estimate`), this machine's speed factor included (passing
    the table it read without ``machine_speed`` lost it from session 30 to 33: YADE's clump triaxial
    recorded 10.7 h where its dry run said 7.5 h)."""
    key, steps, plan = clock_inputs(case, params["scene"], engine_name)
    table = load_table()
    seconds = _engine_time(case, params, engine_name, key, steps, plan, table, machine_speed=True)[0]
    return seconds, int(planned_steps(table, engine_name, key, steps, plan)[0])


#: the basis :func:`_engine_time` gives when no run of the engine was ever measured
BARE_BASIS = "from the bare engine's throughput, no run of this engine measured: a lower bound, decks run slower"


def clock_inputs(case: Case, sc: dict, engine_name: str) -> tuple:
    """(throughput-table key, step budget, step plan or None) of a run of ``case`` on ``engine_name``
    with the scene's numbers ``sc`` (:func:`orchestrator.clock.clock_key`, :func:`step_budget`,
    :func:`orchestrator.clock.step_plan`)."""
    kind = case.scene.kind
    plan = step_plan(kind, sc)
    return (clock_key(kind, engine_name, case.contact.substitutes, case.scene.model_dump(mode="json")),
            step_budget(sc, plan), plan)


def _engine_time(case: Case, params: dict, engine_name: str, key: str, steps: int, plan, table: dict | None,
                 machine_speed: bool | None, workers: int | None = None) -> tuple[float, str]:
    """(engine wall time [s], basis) of a run of ``case`` on ``engine_name`` with its
    :func:`clock_inputs`, from the cost model the project fitted to its own runs
    (:func:`orchestrator.clock.estimate_engine_time`: start-up + steps (a + b n) / S(workers) per
    engine and scene; ``table``: the throughput table, default :func:`orchestrator.clock.load_table`;
    ``machine_speed``: scale a package entry by this machine's measured speed). An engine never
    measured falls back to the adapter's bare throughput (:attr:`engines.base.Engine.throughput`),
    which underestimates deck runs (the basis says so: :data:`BARE_BASIS`). ``workers``: the ranks
    or threads to estimate for instead of the case's (:func:`speedup_workers`)."""
    eng = get_engine(engine_name)
    n = integrated_particles(params)
    workers = speedup_workers(case, eng) if workers is None else workers
    t, basis = estimate_engine_time(engine_name, key, max(n, 1), steps, workers,
                                    table=table, plan=plan, machine_speed=machine_speed)
    if t == t:         # not NaN: a measured model
        return t, basis
    return eng.startup + steps * max(n, 1) / (eng.throughput * workers), BARE_BASIS


def speedup_workers(case: Case, eng) -> int:
    """The workers [-] a run's estimate counts for its speed-up: the engine's ranks or threads,
    at most this machine's cores for a run on it (more share the cores and run no faster:
    :func:`problems` warns), all of them for a run sent to a cluster (``engine_options.scheduler``)."""
    workers = eng.workers(case)
    return workers if case.engine_options.scheduler else min(workers, os.cpu_count() or 1)
