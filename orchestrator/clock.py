"""An honest clock: engine run time predicted from throughput this project measured itself.

Model (per engine and scene, fitted from completed runs)::

    t_engine = t_start + s_n · n + steps · (a + b · n^α) / S(ranks)

- ``t_start`` [s]: process start-up and set-up (reading the packing and meshes, building the
  neighbour structures, the first dump), measured as engine time minus the engine's own loop time;
  ``s_n`` [s/particle] where runs of two sizes or more show it growing with the grains (YADE's
  triaxial: 8, 35 and 54 s with 300, 2 000 and 4 000 grains), else 0;
- the engine time of a one-rank run is its CPU time where the run recorded one
  (``wall_time.engine_cpu``, from ``os.wait4``), its wall time otherwise: on a shared machine the
  wall time grows with the load, a single process's CPU time does not (MPI ranks poll while they
  wait, so several ranks' CPU time grows with the load too: their wall time is kept);
- a run that was killed and resumed counts with the engine time of all its attempts
  (:mod:`orchestrator.attempts`: CPU time on one rank, each attempt's repeated steps taken out),
  or not at all when that record is incomplete (runs from before it existed);
- ``a`` [s/step]: cost per step independent of the particle count (mesh walls, servo and wall
  computes, Python callbacks in YADE decks, dumps amortised over the run);
- ``b`` [s/(particle·step)]: cost per particle and step (contacts, integration); ``α`` = 1, unless
  runs of three sizes or more fit a power law ``b·n^α`` (``a`` = 0) better than the line: the
  LIGGGHTS shear cell's cost per step grows as n^0.8 from 228 to 14 107 grains; beyond the
  largest run fitted (``max_particles``) a power law steeper than linear goes on linearly, at the
  cost per particle of that run: a step of a DEM engine with cell or sort-and-sweep neighbour
  search does O(n) work, and a superlinear trend over small samples (YADE's shell triaxial:
  n^1.32 over 300-4 000 grains, its data outgrowing the caches) cannot be carried 8x further;
- ``S(ranks)`` = 1 + e (ranks − 1): the speed-up on several MPI ranks (LIGGGHTS) or threads (YADE),
  with parallel efficiency ``e`` fitted from runs on more than one rank (0.7 until measured, stated
  as ``assumed``).

Where a scene decides its step count while it runs (:meth:`orchestrator.scenes.base.Scene.step_plan`:
the triaxial's stage 1 goes on chunk by chunk until the stresses converge), ``steps`` is not the
derived budget (every chunk allowed) but ``fixed`` plus the median length of the variable part the
engine's measured runs of the scene took, in the scene's time scale of that part (``units`` in the
table: the triaxial's stage 1 in pressure-ramp lengths), rounded up to whole chunks (the budget
until measured).

``a`` and ``b`` come from a non-negative least-squares fit of the loop time per step against n
over the stored runs of one engine and scene (scipy.optimize.nnls). One run fixes only the sum:
then ``a = 0`` and the fit is flagged ``one size``.

The table lives in package data (``benchmarks/throughput.json``, shipped through
``orchestrator/_data``); a user table in ``$ORCHESTRATOR_THROUGHPUT`` or
``$XDG_DATA_HOME/orchestrator/throughput.json`` takes precedence.

**This machine's speed.** The package table was measured on one machine; another runs the same
decks faster or slower (a newer 2-core machine ran the small shear cell on LIGGGHTS in 0.44 of the
table's time). Every complete run that did not share its cores records its engine time over the
package table's prediction for it, per engine, under this machine's CPU
(:func:`record_speed`, ``machine_speed.json`` beside the user table); estimates from the package
table are multiplied by their median, interpolated in the particle count between the sizes
recorded (:func:`machine_factor`, :func:`speed_at_size`), and say so. Entries of a user table (refitted on this machine) are taken as they are.
``orchestrator clock refresh RUNS…`` refits it from the ``summary.json`` of complete runs (in a
checkout, ``--package`` writes the shipped table itself).
"""
from __future__ import annotations

import functools
import json
import math
import os
import platform
import re
import sys
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

import numpy as np
import yaml

from .atomic import write_text
from .attempts import read_attempts, run_cost
from .humanize import fmt_s

from .resources import data_file

__all__ = ["Throughput", "RunSample", "load_table", "estimate_engine_time", "engine_seconds", "expected_steps", "step_plan",
           "samples_from_runs", "fit", "planned_steps",
           "refresh", "user_table_path", "package_table_path", "ASSUMED_PARALLEL_EFFICIENCY", "SPREAD_WORDS",
           "UNMEASURED_WORDS",
           "machine_id", "record_speed", "speed_records", "machine_factor", "speed_factor", "speed_at_size", "speed_table_path",
           "speed_ratio", "run_engine_seconds", "clock_key", "base_kind", "key_fallbacks", "table_entry", "table_entry_key"]

#: parallel efficiency used until a run on several ranks/threads has been measured
ASSUMED_PARALLEL_EFFICIENCY = 0.7

#: the words an estimate's basis says an assumed parallel efficiency with (sizing prints that clause)
ASSUMED_WORDS = "an assumed parallel efficiency of"

#: the words an estimate's basis gives the spread of its time with where the runs measured took
#: different step counts (the packing decides a triaxial's stage 1; sizing prints that clause)
SPREAD_WORDS = "as the runs measured took"
#: a spread of step counts narrower than this ratio of most to fewest is not printed [-]
SPREAD_NOTE = 1.2

#: the words an estimate's basis says this machine's speed is not measured yet with (sizing prints
#: that clause): the package table's figures are another machine's, and 2-core machines differ by
#: more than the estimate's ±30 % (the default case on the AMD EPYC of session 37 took 101 s where
#: the table, fitted on session 36's machine, said 237 s: docs/validation.md, the clock)
UNMEASURED_WORDS = "this machine's speed not measured yet"

#: an estimate for more than this many times the largest run its entry was fitted on says it is an
#: extrapolation: there the fitted curve's form decides the figure (docs/validation.md, the clock: YADE's
#: shear-cell entry has put its medium case at 5.1 h to 9.9 h by the runs it was fitted on)
EXTRAPOLATION_NOTE = 1.5


@dataclass(frozen=True)
class Throughput:
    """Fitted cost model of one engine on one scene (see the module docstring)."""
    startup_s: float
    per_step_s: float
    per_particle_step_s: float
    parallel_efficiency: float = ASSUMED_PARALLEL_EFFICIENCY
    runs: int = 0
    note: str = ""
    #: median units (StepPlan) the runs took, e.g. a triaxial's stage 1 in pressure-ramp lengths [-];
    #: None: not measured
    units: float | None = None
    #: α of the per-particle term b·n^α [-]: 1 (linear) unless runs of three or more sizes fitted a
    #: power law better (then a = 0 and b is in s/(step·particle^α))
    exponent: float = 1.0
    #: :func:`machine_id` of the machine whose runs the entry was fitted on ("" before entries said
    #: so): an estimate from an entry fitted on this machine takes it as it is, like a user table's
    machine: str = ""
    #: start-up per particle [s]: set-up that reads, places and records every grain (YADE's
    #: triaxial decks: 8 s with 300 grains, 35 s with 2 000, 54 s with 4 000); 0 when the runs were
    #: of one size or their start-up did not grow with n
    startup_per_particle_s: float = 0.0
    #: the largest particle count of the runs fitted (0: not recorded, entries before session 27);
    #: beyond it a power law with α > 1 continues linearly (:meth:`step_time`)
    max_particles: int = 0
    #: [fewest, most] units the runs took [-] (None: fewer than two runs measured): the packing
    #: decides them (YADE's triaxial smoke, seeds 1 and 2 of one case: 2.5 and 8.0 pressure-ramp
    #: lengths, 194.6 and 357.8 s), so the estimate says what this spread makes of its time
    units_range: tuple[float, float] | None = None

    @classmethod
    def from_dict(cls, entry: dict) -> "Throughput":
        """An entry of a table as stored; a term a later version added is left out, so that a run
        started before the table was refitted (a ladder of several hours) still reads it: session
        26's new start-up term failed two rungs of a running ladder with "unexpected keyword"."""
        known = {f.name for f in fields(cls)}
        kw = {k: v for k, v in entry.items() if k in known}
        if kw.get("units_range") is not None:          # a JSON list
            kw["units_range"] = tuple(float(x) for x in kw["units_range"])
        return cls(**kw)

    @property
    def efficiency_measured(self) -> bool:
        """Whether :attr:`parallel_efficiency` was fitted from runs on several ranks or threads
        (:func:`fit` says so in the note) or set to another value than the assumed one (a user's
        table), not assumed: YADE's two OpenMP threads ran the 4 108-grain shear cell 1.33-1.52x
        faster than one (docs/engines.md), where the assumed 0.7 says 1.7x."""
        return "parallel efficiency from" in self.note or self.parallel_efficiency != ASSUMED_PARALLEL_EFFICIENCY

    def startup_time(self, n_particles: int) -> float:
        """Start-up and set-up [s] with ``n_particles``."""
        return self.startup_s + self.startup_per_particle_s * max(n_particles, 0)

    def step_time(self, n_particles: int) -> float:
        """One rank's time per step [s] with ``n_particles``: ``a + b n^α``, continued linearly from
        ``max_particles`` on where α > 1 (the module docstring)."""
        n = max(n_particles, 1)
        top = self.max_particles
        if self.exponent > 1 and 0 < top < n:
            return self.per_step_s + self.per_particle_step_s * top ** self.exponent * (n / top)
        return self.per_step_s + self.per_particle_step_s * n ** self.exponent

    def engine_time(self, n_particles: int, steps: int, ranks: int = 1) -> float:
        """Predicted engine wall time [s] of ``steps`` steps with ``n_particles`` on ``ranks``."""
        speedup = 1.0 + self.parallel_efficiency * (max(int(ranks), 1) - 1)
        return self.startup_time(n_particles) + steps * self.step_time(n_particles) / speedup


@dataclass(frozen=True)
class RunSample:
    """What one complete run tells about throughput."""
    engine: str
    scene: str
    n_particles: int
    steps: int
    ranks: int
    engine_s: float
    loop_s: float
    source: str = field(default="", compare=False)
    #: the run's StepPlan (scenes whose step count is decided while they run), None otherwise
    plan: object = field(default=None, compare=False)
    #: the machine's mean one-minute load average while it ran, its own ranks included, and the
    #: machine's cores (orchestrator.attempts); None for runs made before the record had them
    load: float | None = field(default=None, compare=False)
    cores: int | None = field(default=None, compare=False)
    #: the units the run took as a table entry stored them (:meth:`to_row`); the plan is not stored
    stored_units: float | None = field(default=None, compare=False)

    def to_row(self) -> dict:
        """What a table entry keeps of the run it was fitted on (``samples``), so that a later
        ``clock refresh --add`` fits the new runs together with it after its directory is gone:
        the run's name (its hash), size, steps, ranks, engine and loop time [s], the machine's load
        and cores while it ran, and the units of its step plan."""
        return {"run": Path(self.source).name, "n": self.n_particles, "steps": self.steps, "ranks": self.ranks,
                "engine_s": round(self.engine_s, 3), "loop_s": round(self.loop_s, 3), "load": self.load,
                "cores": self.cores, "units": self.units}

    @classmethod
    def from_row(cls, engine: str, scene: str, row: dict) -> "RunSample":
        """A run as a table entry stored it (:meth:`to_row`)."""
        return cls(engine, scene, int(row["n"]), int(row["steps"]), int(row.get("ranks") or 1), float(row["engine_s"]),
                   float(row["loop_s"]), str(row.get("run", "")), None, row.get("load"), row.get("cores"),
                   row.get("units"))

    @property
    def shared(self) -> bool:
        """A multi-rank run that shared the machine (load above its cores by more than half a
        core): its wall time, the only time that counts for ranks that poll while they wait, is
        longer than a quiet machine's, so the fit leaves it out (one-rank runs count in CPU time)."""
        return self.ranks > 1 and self.load is not None and bool(self.cores) and self.load > self.cores + 0.5

    @property
    def quiet(self) -> bool:
        """Nothing else ran beside it: its mean load at most its own ranks and half a core (True
        when the load was not recorded). A one-rank run's CPU time beside another run is longer too,
        by 8-36 %, and up to 2x for two YADE runs side by side (docs/validation.md), so the machine's
        speed prefers quiet runs (:func:`speed_factor`)."""
        return self.load is None or self.load <= self.ranks + 0.5

    @property
    def units(self) -> float | None:
        """Units (StepPlan) this run took [-]; None without a plan, or when the run did not follow it
        (e.g. a triaxial whose stage 1 ran out of chunks and skipped the drag ramp)."""
        if self.plan is None:
            return self.stored_units
        k = self.plan.chunks_of(self.steps)
        return self.plan.units_of(self.steps) if 0.5 <= k <= self.plan.max_units + 0.5 else None


def package_table_path() -> Path:
    """The shipped table (``benchmarks/throughput.json`` of the project, package data)."""
    return data_file("benchmarks/throughput.json")


def _package_table() -> dict:
    p = package_table_path()
    return json.loads(p.read_text()) if p.is_file() else {}


def user_table_path() -> Path:
    """Where ``refresh`` writes and where a user table is looked up first."""
    if os.environ.get("ORCHESTRATOR_THROUGHPUT"):
        return Path(os.environ["ORCHESTRATOR_THROUGHPUT"])
    base = Path(os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share")
    return base / "orchestrator" / "throughput.json"


#: (file, mtime, size) of the damaged tables already warned of in this process (an estimate reads
#: the tables again for every run of a sweep: one warning a file is enough)
_WARNED: set = set()


def _warn_damaged(path: Path, why: str, fix: str) -> None:
    """One line on stderr, once per file and version: ``path`` cannot be used (``why``), what was
    done instead and the ``fix``: a damaged table was ignored without a word (``clock show`` listed
    the package table as if the user's were not there)."""
    try:
        st = path.stat()
        key = (str(path), st.st_mtime_ns, st.st_size)
    except OSError:
        key = (str(path), None, None)
    if key in _WARNED:
        return
    _WARNED.add(key)
    print(f"warning: {path}: {why}; {fix}", file=sys.stderr)


class TableError(ValueError):
    """A table file that is not a table: ``why`` says what is wrong, the message names the file and the fix."""

    def __init__(self, path, why: str):
        self.path, self.why = Path(path), why
        super().__init__(f"{path}: {why}; delete it or move it aside")


def read_table(path: Path) -> dict:
    """A throughput or speed table as stored (a JSON mapping; {} when there is none), or a
    :class:`TableError` (a ValueError) naming the file, what is wrong and the fix."""
    path = Path(path)
    if not path.is_file():
        return {}
    text = path.read_text()
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise TableError(path, f"not a JSON table ({exc})") from None
    if not isinstance(data, dict):
        raise TableError(path, f"a JSON {type(data).__name__}, not a table (a JSON mapping)")
    return data


#: what to do about a damaged user table (the estimates meanwhile use the package table alone)
_USER_TABLE_FIX = ("the estimates use the package table instead. Fix: delete the file (or move it aside) and refit "
                   "it from your complete runs with `orchestrator clock refresh RUNS`")


def _usable_entry(d) -> bool:
    """Whether a table entry gives a time (its numbers are numbers)."""
    try:
        return math.isfinite(Throughput.from_dict(d).engine_time(1000, 1000, 2))
    except (TypeError, ValueError, AttributeError, KeyError, OverflowError, ZeroDivisionError):
        return False


def _user_table() -> dict:
    """The user table as stored, the entries it cannot use left out with a warning (a damaged file:
    all of it, with a warning naming it and the fix)."""
    user = user_table_path()
    try:
        if not user.is_file():
            return {}
        data = read_table(user)
    except OSError:                 # another user's table (HOME kept under sudo/su): not ours to read
        return {}
    except TableError as exc:
        _warn_damaged(user, f"the user throughput table cannot be read: {exc.why}", _USER_TABLE_FIX)
        return {}
    out, bad = {}, []
    for eng, scenes in data.items():
        if eng.startswith("_"):
            continue
        if not isinstance(scenes, dict):
            bad.append(f"{eng}: not a mapping of scenes")
            continue
        for sc, d in scenes.items():
            if not sc.startswith("_") and not _usable_entry(d):
                bad.append(f"{eng} {sc}: not a throughput entry")
                continue
            out.setdefault(eng, {})[sc] = d
    if bad:
        _warn_damaged(user, f"the user throughput table has entries it cannot use ({'; '.join(bad)}): left out",
                      _USER_TABLE_FIX.replace("the estimates use the package table instead",
                                              "their estimates use the package table"))
    return out


def _as_throughputs(table: dict) -> dict:
    return {eng: {sc: Throughput.from_dict(d) for sc, d in scenes.items() if not sc.startswith("_")}
            for eng, scenes in table.items() if not eng.startswith("_")}


def load_table(user: dict | None = None) -> dict:
    """``{engine: {scene: Throughput}}``: the package table, overridden entry by entry by the
    user table (``user``: that table as read already, default: read it)."""
    table = _package_table()
    for eng, scenes in (_user_table() if user is None else user).items():
        table.setdefault(eng, {}).update(scenes)
    return _as_throughputs(table)


#: runs per engine, scene and size whose speed ratio :func:`machine_factor` keeps (the most recent)
SPEED_KEEP = 12


@functools.lru_cache(maxsize=1)
def machine_id() -> str:
    """This machine's CPU (``/proc/cpuinfo``: model name, and its family and model numbers where the
    name alone does not tell the generation) and core count: the key of its speed record and the
    ``machine`` of the entries fitted on it. A virtual machine's CPU may call itself "AMD EPYC" on
    every generation: on the second such 2-core machine of this project's, the first one's table read
    0.91-1.46 of the smoke cases' run times (session 29, ``benchmarks/bench_estimate.py``), so the name
    alone would take one's table as fitted on the other."""
    info: dict = {}
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            info.setdefault(key.strip(), value.strip())
            if not line.strip():                  # the first processor's block is enough
                break
    except OSError:
        pass
    model = info.get("model name") or platform.processor() or platform.machine()
    if info.get("cpu family") and info.get("model"):
        model += f" (family {info['cpu family']}, model {info['model']})"
    return f"{model} x{os.cpu_count()}"


def speed_table_path() -> Path:
    """``$ORCHESTRATOR_MACHINE_SPEED``, or ``machine_speed.json`` beside the user table."""
    if os.environ.get("ORCHESTRATOR_MACHINE_SPEED"):
        return Path(os.environ["ORCHESTRATOR_MACHINE_SPEED"])
    return user_table_path().with_name("machine_speed.json")


def _speed_table() -> dict:
    """The machines' speed records as stored; a damaged file is ignored with a warning naming it
    (the next record a complete run makes rewrites it)."""
    p = speed_table_path()
    try:
        data = read_table(p)
    except OSError:
        return {}
    except TableError as exc:
        _warn_damaged(p, f"the machine-speed record cannot be read: {exc.why}",
                      "the estimates take this machine as the package table's speed. Fix: delete the file (or move "
                      "it aside); the next complete run records this machine's speed afresh")
        return {}
    ok = {m: engs for m, engs in data.items() if isinstance(engs, dict)
          and all(isinstance(rows, list) and all(isinstance(r, dict) for r in rows) for rows in engs.values())}
    if len(ok) < len(data):
        _warn_damaged(p, f"the machine-speed record has machine entries it cannot use "
                         f"({', '.join(m for m in data if m not in ok)}): left out",
                      "Fix: delete the file (or move it aside); the next complete run records this machine's "
                      "speed afresh")
    return ok


def speed_records() -> list[dict]:
    """This machine's speed records (:func:`record_speed`), each with its ``engine``: what ``orchestrator
    clock show`` lists under the factors (run, scene, particles, ranks or threads, ratio to the
    package table, whether the machine was quiet)."""
    rows = _speed_table().get(machine_id(), {})
    return [dict(r, engine=eng) for eng, recs in sorted(rows.items()) for r in recs]


def speed_ratio(smp: RunSample, package: dict | None = None) -> float | None:
    """The run ``smp``'s engine time over the package table's prediction for it (its engine, scene,
    particles, steps run and ranks); None when it does not tell (shared its cores, no package entry).
    ``package``: the package table as :class:`Throughput` entries, if already read."""
    if smp is None or smp.shared or smp.engine_s <= 0:
        return None
    package = _as_throughputs(_package_table()) if package is None else package
    tp = table_entry(package.get(smp.engine, {}), smp.scene)
    if tp is None or tp.machine == machine_id():     # an entry fitted here says nothing of this machine's speed
        return None
    predicted = tp.engine_time(smp.n_particles, smp.steps, smp.ranks)
    return smp.engine_s / predicted if predicted > 0 else None


def _against(package: dict, engine: str, scene: str) -> str | None:
    """Which package entry a speed ratio of ``scene`` on ``engine`` is taken against: its key and
    costs. A refit of the package table (``orchestrator clock refresh --package``, a new variant's
    own entry where its fallback stood in) changes it, and the ratios recorded against the old entry
    no longer say this machine's speed (:func:`machine_factor` leaves them out)."""
    key = table_entry_key(package.get(engine, {}), scene) if scene else None
    if key is None:
        return None
    tp = package[engine][key]
    grows = f" {tp.startup_per_particle_s:.6g}" if tp.startup_per_particle_s else ""    # older records stay valid
    if tp.exponent > 1 and tp.max_particles:
        grows += f" linear>{tp.max_particles}"
    return f"{key} {tp.startup_s:.6g} {tp.per_step_s:.6g} {tp.per_particle_step_s:.6g} {tp.exponent:.6g}{grows}"


def record_speed(run_dir) -> float | None:
    """Record the complete run ``run_dir``'s :func:`speed_ratio` under this machine, with its scene,
    particle count and ranks or threads; returns it, or None when the run does not tell (not
    complete, shared its cores, or no package entry). The last :data:`SPEED_KEEP` runs of each
    engine, scene and size (:func:`_size_groups`) are kept."""
    smp = _sample(Path(run_dir))
    ratio = speed_ratio(smp) if smp is not None else None
    if ratio is None:
        return None
    table = _speed_table()
    rows = table.setdefault(machine_id(), {}).setdefault(smp.engine, [])
    against = _against(_as_throughputs(_package_table()), smp.engine, smp.scene)
    where = str(Path(run_dir).resolve())      # the same relative path names other runs elsewhere
    rows[:] = [r for r in rows if r.get("run") != where] + [{"run": where, "scene": smp.scene,
                                                                      "n": int(smp.n_particles),
                                                                      "ratio": round(ratio, 4),
                                                                      "quiet": smp.quiet,
                                                                      "ranks": int(smp.ranks),
                                                                      "against": against}]
    rows[:] = _keep_recent(rows)
    out = speed_table_path()
    out.parent.mkdir(parents=True, exist_ok=True)
    write_text(out, json.dumps(table, indent=1, sort_keys=True) + "\n")
    return ratio


def _keep_recent(rows: list) -> list:
    """The last :data:`SPEED_KEEP` rows of each scene and size group (rows without a count: one
    group per scene), in their order."""
    group = _count_groups([r.get("n") for r in rows])
    keys = [(r.get("scene"), int(g)) for r, g in zip(rows, group)]
    return [r for i, r in enumerate(rows) if keys[i + 1:].count(keys[i]) < SPEED_KEEP]


def _count_groups(counts) -> np.ndarray:
    """Each record's size group (:func:`_size_groups`) from its particle count, -1 without one."""
    ns = np.array([float(c or 0) for c in counts])
    group = np.full(len(ns), -1)
    if (ns > 0).any():
        group[ns > 0] = _size_groups(ns[ns > 0])
    return group


def _group_medians(ns, ratios) -> tuple[np.ndarray, np.ndarray]:
    """(size of each size group [-], its median ratio [-]) of runs with counts ``ns`` > 0, by size."""
    x, r = np.asarray(ns, float), np.asarray(ratios, float)
    group = _size_groups(x)
    gn = np.array([np.exp(np.median(np.log(x[group == g]))) for g in range(group.max() + 1)])
    gr = np.array([np.median(r[group == g]) for g in range(group.max() + 1)])
    order = np.argsort(gn)
    return gn[order], gr[order]


def size_trend(records) -> tuple[float, float, float] | None:
    """(slope β [-], smallest n, largest n) of how this machine's speed ratio changes with the size,
    ratio ∝ n^β, from ``records`` ``(scene, n, ratio)`` of one engine: the median over the scenes
    with two sizes or more of each scene's least-squares slope of log(group median) against log n,
    and the sizes those scenes span; None without such a scene. A machine's speed-up over the table's
    depends on the size in much the same way in every scene of an engine (cache and memory against
    the per-step overheads: on the 2-core machine of 28 Nov 2026, YADE's shear cell read 0.24 of
    the table at 228 grains and 0.51 at 1 025, β = 0.5, and its triaxial 0.29 at 300 grains and
    0.76 at 2 000), so a scene measured at one size borrows it (:func:`speed_at_size`)."""
    slopes, lo, hi = [], math.inf, 0.0
    for scene in {r[0] for r in records}:
        sub = [r for r in records if r[0] == scene and r[1] and r[2]]
        if len(sub) < 2:
            continue
        gn, gr = _group_medians([r[1] for r in sub], [r[2] for r in sub])
        if len(gn) < 2:
            continue
        slopes.append(float(np.polyfit(np.log(gn), np.log(gr), 1)[0]))
        lo, hi = min(lo, gn[0]), max(hi, gn[-1])
    return (float(np.median(slopes)), lo, hi) if slopes else None


def speed_at_size(ns, ratios, n: int | None, trend: tuple[float, float, float] | None = None) -> float:
    """This machine's speed ratio [-] for a run of ``n`` particles, from recorded runs of ``ns``
    particles and their ``ratios`` (one engine and scene): the median ratio of each size group
    (:func:`_size_groups`), interpolated linearly in log n between the groups. Beyond the smallest
    and largest group the ratio is held, or with the engine's ``trend`` (:func:`size_trend`: slope β
    over the sizes [lo, hi] other scenes measured) carried from the nearest group as n^β over the
    part of the way that lies within [lo, hi], and held beyond: never extrapolated past what some
    scene measured. A machine's speed-up over the table's differs with the size (a newer machine
    ran LIGGGHTS' 228-grain smoke shear cell in 0.26-0.33 of the table's time and its 1 025-grain
    small cell in 0.44, 27 Nov 2026), so one median carried across sizes missed by up to 2.2x
    (docs/validation.md); YADE's 2 000-grain triaxial, predicted from its 300-grain smoke runs
    held, by 2.6x. Without counts or with one size and no trend: the median of all."""
    r = np.asarray(ratios, float)
    x = np.asarray([float(v) if v else 0.0 for v in ns], float)
    ok = x > 0
    if n is None or ok.sum() == 0:
        return float(np.median(r))
    gn, gr = _group_medians(x[ok], r[ok])
    ln = np.log(max(n, 1))
    value = float(np.exp(np.interp(ln, np.log(gn), np.log(gr))))
    if trend is not None and not gn[0] <= n <= gn[-1]:
        beta, lo, hi = trend
        edge = gn[0] if n < gn[0] else gn[-1]
        a, b = (np.clip(np.log(v), np.log(lo), np.log(hi)) for v in (edge, max(n, 1)))
        value *= float(np.exp(beta * (b - a)))
    return value


def _prefer_quiet(records: list) -> list:
    """``records`` ``(scene, n, ratio[, quiet])`` without the runs that shared the machine where a
    quiet run of the same scene and size group stands in for them (one YADE run beside another read
    1.22 of the table where a quiet one would read about 0.6). Records without the flag count as
    quiet."""
    def quiet(r):
        return len(r) < 4 or r[3] is None or bool(r[3])
    keep = []
    for scene in {r[0] for r in records}:
        sub = [r for r in records if r[0] == scene]
        group = _count_groups([r[1] for r in sub])
        for g in set(group.tolist()):
            members = [r for r, k in zip(sub, group) if k == g]
            calm = [r for r in members if quiet(r)]
            keep += calm or members
    return keep


def _ranks_of(record) -> int:
    """The ranks or threads of a speed record ``(scene, n, ratio, quiet, ranks)`` [-]: 1 where the
    record does not say (records of before session 38)."""
    return max(int(record[4]), 1) if len(record) > 4 and record[4] else 1


def _same_ranks(records: list, scene: str | None, ranks: int) -> tuple[list, bool]:
    """(the records that speak for a run on ``ranks`` ranks or threads, whether they ran on as many
    ranks, more than one: then they measured this machine's parallel speed-up as well).
    A record is the run's time over the package table's prediction, which divides a run on several
    ranks by the table's parallel speed-up (assumed 0.7 per added rank until measured): such a
    record measures this machine's speed and that speed-up together. YADE's small shear cell (1 025
    grains) took 315 s on one thread and 366 s on two here (session 38), 0.30 and 0.59 of the
    table, so one median of both says neither. A run on ``ranks`` takes the records of as many
    ranks where its scene (or the scene it falls back to) has any, else the one-rank records (the
    machine's speed, the table's speed-up); a one-rank run takes the one-rank records, or all where
    there are none."""
    want = max(int(ranks or 1), 1)
    same = [r for r in records if _ranks_of(r) == want]
    if want == 1:
        return (same or records), False
    keys = set(key_fallbacks(scene)) if scene is not None else set()
    if any(r[0] in keys for r in same):
        return same, True
    single = [r for r in records if _ranks_of(r) == 1]
    return (single, False) if single else (records, False)


def speed_factor(records, scene: str | None = None, n_particles: int | None = None,
                 ranks: int = 1) -> tuple[float, int] | None:
    """(speed ratio [-], records it rests on) for a run of ``scene`` with ``n_particles`` on
    ``ranks`` ranks or threads, from ``records`` of one engine, each ``(scene, particle count or
    None, ratio[, quiet[, ranks]])``: those of as many ranks (:func:`_same_ranks`), the runs that
    shared the machine left out where a quiet run of the same size stands in; of them those of
    ``scene`` where there are any, at ``n_particles`` (:func:`speed_at_size`, beyond their sizes with
    the engine's :func:`size_trend` from the other scenes); else all of them, their median (the ratio
    differs by scene: YADE's smoke shear cell 0.23 of the table, its plane shear 0.42). None without
    a record. The one rule :func:`machine_factor` and ``benchmarks/bench_estimate.py`` apply."""
    found = _speed_factor(records, scene, n_particles, ranks)
    return found[:2] if found else None


def _speed_factor(records, scene, n_particles, ranks) -> tuple[float, int, bool] | None:
    """:func:`speed_factor` and whether its records ran on as many ranks (:func:`_same_ranks`)."""
    records = [r for r in records if r[2] is not None and r[2] > 0]
    records, same_ranks = _same_ranks(records, scene, ranks)
    records = _prefer_quiet(records)
    same = []
    for key in key_fallbacks(scene) if scene is not None else []:     # a variant not measured yet
        same = [r for r in records if r[0] == key]
        if same:
            scene = key
            break
    use = same or records
    if not use:
        return None
    if not same:
        return speed_at_size([r[1] for r in use], [r[2] for r in use], None), len(use), same_ranks
    trend = size_trend([r for r in records if r[0] != scene])
    return speed_at_size([r[1] for r in use], [r[2] for r in use], n_particles, trend), len(use), same_ranks


def machine_factor(engine: str, scene: str | None = None, n_particles: int | None = None,
                   ranks: int = 1) -> tuple[float, int] | None:
    """(ratio of engine time to the package table's prediction, runs it rests on) of ``engine`` on
    this machine (:func:`record_speed`) for a run on ``ranks`` ranks or threads, by
    :func:`speed_factor`; None before a run has been recorded."""
    found = _machine_factor(engine, scene, n_particles, ranks)
    return found[:2] if found else None


def _machine_factor(engine: str, scene: str | None, n_particles: int | None,
                    ranks: int) -> tuple[float, int, bool] | None:
    """:func:`machine_factor` and whether its runs ran on as many ranks (:func:`_same_ranks`)."""
    rows = _speed_table().get(machine_id(), {}).get(engine) or []
    package = _as_throughputs(_package_table())
    # a ratio recorded against a package entry since refitted says nothing of this machine (rows of
    # before the record kept its entry have no "against")
    rows = [r for r in rows if r.get("against") is None or r["against"] == _against(package, engine, r.get("scene"))]
    return _speed_factor([(r.get("scene"), r.get("n"), r["ratio"], r.get("quiet"), r.get("ranks")) for r in rows
                          if isinstance(r.get("ratio"), (int, float))], scene, n_particles, ranks)


def estimate_engine_time(engine: str, scene: str, n_particles: int, steps: int, ranks: int = 1,
                         table: dict | None = None, plan=None, machine_speed: bool | None = None) -> tuple[float, str]:
    """(engine wall time [s], basis) for one run of at most ``steps`` steps. ``basis`` says where the
    figures came from: the fitted (engine, scene) entry, or the engine's entry of another scene, or
    nothing. With the scene's ``plan`` (:func:`step_plan`) the steps are those the measured runs
    took (:func:`expected_steps`). ``machine_speed``: scale an entry of the package table by this
    machine's measured speed (:func:`machine_factor`); default: when ``table`` is the default one."""
    scale, note = 1.0, ""
    ranks_measured = False          # this machine's runs on as many ranks measured the speed-up too
    if machine_speed is None:
        machine_speed = table is None
    user = _user_table()
    table = load_table(user) if table is None else table
    scenes = table.get(engine, {})
    used = table_entry_key(scenes, scene)
    if machine_speed and (used or scene) not in user.get(engine, {}) and not fitted_here(scenes, scene):   # a user entry is this machine's
        mf = _machine_factor(engine, scene, n_particles, ranks)
        if mf is not None:
            scale, note = mf[0], f", × {mf[0]:.2f} for this machine's speed ({mf[1]} run(s))"
            if mf[2]:
                note = f", × {mf[0]:.2f} for this machine's speed on {ranks} ranks or threads ({mf[1]} run(s))"
                ranks_measured = True
        elif used is not None:       # an entry without a machine was fitted before entries said so: elsewhere
            whose = f"{scenes[used].machine}'s" if scenes[used].machine else "an earlier machine's"
            note = (f", {UNMEASURED_WORDS} (the table's is {whose}; 2-core machines differ by 2x): the "
                    f"first complete {engine} run here measures it")
    if used is not None:
        tp = scenes[used]
        basis = (f"measured on {tp.runs} {engine} {scene} run(s)" if used == scene else
                 f"no {scene} run measured on {engine}: the {used} entry, {tp.runs} run(s)")
        n_steps, lead = planned_steps(table, engine, scene, steps, plan)
        if lead is not None:
            basis += f", its steps as {lead[0]} took them ({lead[1]:.1f} plan units)"
        if tp.max_particles and n_particles > EXTRAPOLATION_NOTE * tp.max_particles:
            basis += (f", {n_particles / tp.max_particles:.1f}x the largest run fitted ({tp.max_particles:,} "
                      "particles): an extrapolation")
        if ranks > 1 and not tp.efficiency_measured and not ranks_measured:
            basis += (f", {ranks} ranks or threads at {ASSUMED_WORDS} {tp.parallel_efficiency:g} "
                      "(no run of this entry on several measured)")
        basis += _spread_clause(tp, plan, lead, n_particles, steps, ranks, scale)
        return scale * tp.engine_time(n_particles, n_steps, ranks), basis + note
    if scenes:     # the slowest per-particle rate of the engine's other scenes: an upper estimate
        tp = max(scenes.values(), key=lambda t: t.step_time(n_particles))
        return (scale * tp.engine_time(n_particles, steps, ranks),
                f"no {scene} run measured on {engine}: slowest other scene{note}")
    return float("nan"), f"no throughput measured for {engine}"


def _spread_clause(tp: Throughput, plan, lead, n_particles: int, budget: int, ranks: int, scale: float) -> str:
    """The basis's clause for the time a run takes at the fewest and at the most units the entry's
    runs took (:attr:`Throughput.units_range`), when they differ by more than :data:`SPREAD_NOTE`
    ("" otherwise, or when the steps are another engine's, ``lead``): an estimate made before the
    packing exists cannot know which end it will meet (YADE's triaxial smoke: 194.6 and 357.8 s
    from one case file on two seeds, docs/validation.md)."""
    if plan is None or lead is not None or not tp.units_range:
        return ""
    lo, hi = tp.units_range
    if lo <= 0 or hi < SPREAD_NOTE * lo:
        return ""
    t_lo, t_hi = (scale * tp.engine_time(n_particles, min(int(budget), plan.steps(u)), ranks) for u in (lo, hi))
    return f", {fmt_s(t_lo)} to {fmt_s(t_hi)} {SPREAD_WORDS} {lo:.1f} to {hi:.1f} {plan.what}"


def engine_seconds(summary: dict) -> float | None:
    """A run's engine time as a quiet machine would have taken it [s], from its ``summary.json``:
    a one-rank run's CPU time (``wall_time.engine_cpu``, from ``os.wait4``) where it is shorter than
    the wall time, else the wall time (``wall_time.engine``); None without one. The wall time of a
    one-rank run that shared its cores (other runs, a test suite, a paused process) is longer by the
    load; its CPU time is not, to within 8-36 % on a 2-core machine (docs/validation.md). Not so on
    several MPI ranks: a rank polls while it waits for one the load has descheduled (the default
    case, 2 ranks: 201 s quiet; beside a YADE run 636 s wall and 806 s CPU, 403 s per rank), so
    their wall time is kept, less the stretches the engine spent stopped (``wall_time.engine_paused``:
    SIGSTOP, a scheduler's suspend; :mod:`orchestrator.attempts`)."""
    wt = summary.get("wall_time") or {}
    wall, cpu, paused = wt.get("engine"), wt.get("engine_cpu"), wt.get("engine_paused")
    if not isinstance(wall, (int, float)):
        return None
    if isinstance(paused, (int, float)) and 0 < paused < wall:
        wall = wall - paused
    if isinstance(cpu, (int, float)) and cpu > 0 and max(int(summary.get("workers") or 1), 1) == 1:
        return min(float(cpu), float(wall))
    return float(wall)


def run_engine_seconds(run_dir, summary: dict | None = None) -> float | None:
    """The whole run's engine time as a quiet machine would have taken it [s]: :func:`engine_seconds`
    of its ``summary.json``, or for a run that was resumed (its summary times the last attempt only)
    the cost of an uninterrupted run from the record of every attempt
    (:func:`orchestrator.attempts.run_cost`); None without either. ``summary``: the run's summary,
    if already read. What ladders and sweeps put beside each run (a rung killed and resumed read
    115 s for its last attempt where it had cost ~1 300 s)."""
    run_dir = Path(run_dir)
    if summary is None:
        try:
            summary = json.loads((run_dir / "summary.json").read_text())
        except (OSError, ValueError):
            return None
    if not summary.get("resumed_from"):
        return engine_seconds(summary)
    steps = int(summary.get("steps_run") or summary.get("steps") or 0)
    ranks = max(int(summary.get("workers") or 1), 1)
    return run_cost(summary.get("attempts") or read_attempts(run_dir), steps, use_cpu=ranks == 1)


def _sample(run_dir: Path) -> RunSample | None:
    try:
        s = json.loads((run_dir / "summary.json").read_text())
        p = json.loads((run_dir / "params.json").read_text())
    except (OSError, ValueError):
        return None
    if s.get("status") != "complete":
        return None
    wt = s.get("wall_time") or {}
    if not isinstance(wt.get("engine"), (int, float)):
        return None
    sc = p.get("scene") or {}
    # the spheres the engine integrated, as the estimate counts them (sizing.integrated_particles):
    # a clump sample's member spheres (``n_spheres``), not its grains (summary.json's n_particles)
    n = int(sc.get("n_spheres") or s.get("n_particles") or sc.get("n") or len(sc.get("ids") or []) or 0)
    steps = int(s.get("steps_run") or s.get("steps") or 0)
    if n <= 0 or steps <= 0:
        return None
    # the scene's kind from the run's case (summary.json's "scene" is the scene's results for some
    # scenes, e.g. the triaxial's stage figures, and the kind's name for others)
    try:
        case = yaml.safe_load((run_dir / "case.yaml").read_text()) or {}
        scene_section = case.get("scene") or {}
        kind = scene_section.get("kind", "")
        substitutes = (case.get("contact") or {}).get("substitutes") or {}
    except (OSError, ValueError, AttributeError):
        kind, substitutes, scene_section = "", {}, {}
    if not kind and isinstance(s.get("scene"), str):
        kind = s["scene"]
    ranks = max(int(s.get("workers") or 1), 1)
    plan = step_plan(kind, sc)
    key = clock_key(kind, s["engine"], substitutes, scene_section if isinstance(scene_section, dict) else {})
    engine_s = float(wt["engine"])
    # the engine's own loop time where its log gives one (0 or absent: not measured, e.g. YADE's)
    loop = float(wt["engine_loop"]) if isinstance(wt.get("engine_loop"), (int, float)) and wt["engine_loop"] > 0 \
        else engine_s
    startup = max(engine_s - loop, 0.0)
    attempts = s.get("attempts") or read_attempts(run_dir)
    load, cores = _machine_load(attempts)
    if s.get("resumed_from"):
        # the summary's engine time covers only the last attempt: the record of every attempt
        # (orchestrator.attempts) gives the whole run's, or the run does not count
        cost = run_engine_seconds(run_dir, s)
        if cost is None:
            return None
        return RunSample(s["engine"], key, n, steps, ranks, cost, max(cost - startup, 0.0), str(run_dir), plan,
                         load, cores)
    quiet_s = engine_seconds(s)
    if quiet_s < engine_s:          # a one-rank run's CPU time, or the wall time less its pauses (engine_seconds)
        engine_s = quiet_s
        loop = engine_s - startup if startup < engine_s else engine_s
    return RunSample(s["engine"], key, n, steps, ranks, engine_s, loop, str(run_dir), plan, load, cores)


def _machine_load(attempts: list) -> tuple[float | None, int | None]:
    """The attempts' load averages weighted by their wall times, and the machine's cores (the
    largest recorded); (None, None) without a record of them."""
    rows = [a for a in attempts if isinstance(a, dict) and isinstance(a.get("load"), (int, float))
            and isinstance(a.get("wall_s"), (int, float)) and a["wall_s"] > 0]
    if not rows:
        return None, None
    wall = sum(a["wall_s"] for a in rows)
    cores = max((int(a["cores"]) for a in rows if isinstance(a.get("cores"), int)), default=None)
    return sum(a["load"] * a["wall_s"] for a in rows) / wall, cores


def planned_steps(table: dict, engine: str, key: str, budget: int, plan) -> tuple[int, tuple[str, float] | None]:
    """(steps a run of ``key`` on ``engine`` is expected to take [-], the (engine, units) they were
    counted from when another engine's runs of exactly ``key`` stand in for this one's, else None):
    :func:`expected_steps` with the engine's own entry for ``key``, or, while ``key`` has none on
    it (:func:`table_entry_key` falls back to a plainer variant), the units another engine measured
    on ``key`` itself (:func:`_units_measured_elsewhere`)."""
    entries = table.get(engine, {})
    used = table_entry_key(entries, key)
    tp = entries[used] if used else None
    lead = _units_measured_elsewhere(table, key, engine) if plan is not None and used != key else None
    if lead is not None:
        tp = replace(tp, units=lead[1]) if tp is not None else Throughput(0.0, 0.0, 0.0, units=lead[1])
    return expected_steps(budget, plan, tp), lead


def _units_measured_elsewhere(table: dict, key: str, engine: str) -> tuple[str, float] | None:
    """(engine, units) of another engine's runs of exactly ``key`` whose step plan was measured:
    how many steps a scene takes to converge is the scene's physics (a clump sample's stage 1 took
    9.7 pressure-ramp lengths on LIGGGHTS, the sphere samples' 2.5-4.5 on either engine), so an
    engine that has not run that variant yet counts its steps from the one that has, and its cost
    per step from its own nearest entry. The engine with the most such runs leads; None without."""
    found = [(tp.runs, e, tp.units) for e, entries in table.items() if e != engine and isinstance(entries, dict)
             for tp in [entries.get(key)] if tp is not None and tp.units is not None]
    if not found:
        return None
    _, e, units = max(found)
    return e, float(units)


def clock_key(kind: str, engine: str, substitutes: dict | None = None, scene: dict | None = None) -> str:
    """The throughput table's key for a run of scene ``kind`` on ``engine`` with the case's
    ``contact.substitutes`` and ``scene:`` section (a plain mapping): the kind, or ``kind:variant``
    where the scene's deck on that engine costs differently per step
    (:meth:`~orchestrator.scenes.base.Scene.clock_variant`: YADE's triaxial on the shell pressure
    runs 1.3-1.7 ms a step on 2 000 grains, on its PFacet membrane 5.3 ms, docs/validation.md; a
    clump sample of 32 000 member spheres runs at 40-60 steps/s on YADE where the sphere entry
    predicts 91)."""
    from .registry import get_scene
    try:
        variant = get_scene(kind).clock_variant(engine, dict(substitutes or {}), dict(scene or {}))
    except (LookupError, TypeError, ValueError):
        variant = None
    return f"{kind}:{variant}" if variant else kind


def base_kind(key: str) -> str:
    """The scene kind of a table key (:func:`clock_key`)."""
    return key.split(":", 1)[0]


def key_fallbacks(key: str) -> list[str]:
    """``key`` and the keys that stand in for it while it has no runs, nearest first: the variant
    without its last "+" part, and so on down to the scene kind
    (``triaxial:shell_pressure+clumps`` -> ``triaxial:shell_pressure`` -> ``triaxial``)."""
    out = [key]
    kind, _, variant = key.partition(":")
    parts = variant.split("+") if variant else []
    while parts:
        parts.pop()
        out.append(f"{kind}:{'+'.join(parts)}" if parts else kind)
    return out


def table_entry_key(entries: dict, key: str) -> str | None:
    """The key of the entry among one engine's table ``entries`` that serves ``key``: its own, or
    the nearest of :func:`key_fallbacks` for a variant not measured yet; None without one."""
    return next((k for k in key_fallbacks(key) if entries.get(k)), None)


def fitted_here(entries: dict, key: str) -> bool:
    """Whether the entry serving ``key`` among one engine's table ``entries`` (:func:`table_entry_key`)
    was fitted on this machine (:func:`machine_id`): its figures are this machine's speed already,
    so :func:`estimate_engine_time` does not scale them by :func:`machine_factor`."""
    k = table_entry_key(entries, key)
    return k is not None and entries[k].machine == machine_id()


def table_entry(entries: dict, key: str):
    """The entry of ``key`` among one engine's table ``entries``, or for a variant not measured
    yet the nearest that stands in (:func:`table_entry_key`); None without one."""
    k = table_entry_key(entries, key)
    return entries[k] if k else None


def step_plan(kind: str, scene_params: dict):
    """The scene's :class:`~orchestrator.scenes.base.StepPlan` for these numbers, or None (fixed
    step count, unknown scene, numbers of an older version)."""
    from .registry import get_scene      # the scenes import the case models: not needed to read the table
    try:
        return get_scene(base_kind(kind)).step_plan(scene_params)
    except (LookupError, TypeError, ValueError):     # an unknown kind (RegistryError), numbers without the keys
        return None


def run_step_plan(run_dir):
    """The step plan (:func:`step_plan`) of the run in ``run_dir``, from its ``params.json`` and the
    scene kind of its ``case.yaml``; None for a fixed step count or a run without those files."""
    run_dir = Path(run_dir)
    try:
        params = json.loads((run_dir / "params.json").read_text())
        kind = ((yaml.safe_load((run_dir / "case.yaml").read_text()) or {}).get("scene") or {}).get("kind", "")
    except (OSError, ValueError, AttributeError):
        return None
    return step_plan(kind, params.get("scene") or {})


def expected_steps(budget: int, plan, tp: Throughput | None) -> int:
    """Steps a run is expected to take [-]: the derived ``budget`` for a fixed step count, else the
    plan's fixed part plus the units the engine's measured runs took (the budget until measured)."""
    if plan is None or tp is None or tp.units is None:
        return int(budget)
    return min(int(budget), plan.steps(tp.units))


def samples_from_runs(paths) -> list[RunSample]:
    """Every complete run under ``paths`` (run directories or runs/ trees; a resumed run costed from
    its attempts' record, :func:`run_engine_seconds`), each once: a directory with the name (the run's hash: engine, case, derived numbers, templates) and the
    engine time of one already read is a copy of that run (e.g. a ladder's rung copied into another
    ladder's tree to be reused) and would count it twice; a rerun of the same case elsewhere took
    its own time and counts."""
    out, seen = [], set()
    for root in paths:
        root = Path(root)
        dirs = [root] if (root / "summary.json").exists() else [p.parent for p in root.rglob("summary.json")]
        for d in sorted(dirs):
            smp = _sample(d)
            if smp is not None and (d.name, smp.engine_s) not in seen:
                out.append(smp)
                seen.add((d.name, smp.engine_s))
    return out


def _size_groups(ns: np.ndarray) -> np.ndarray:
    """Each run's size group (0, 1, ...) [-]: counts within a factor 1.5 of the group's smallest are
    one size (a packing's count drifts by a few grains with the seed, and such counts cannot
    separate the per-step from the per-particle cost)."""
    order = np.argsort(ns)
    group = np.empty(len(ns), int)
    g, lo = -1, None
    for i in order:
        if lo is None or ns[i] > 1.5 * lo:
            g, lo = g + 1, ns[i]
        group[i] = g
    return group


def fit(samples: list[RunSample]) -> Throughput:
    """Fit one engine+scene's cost model to its runs (see the module docstring)."""
    if not samples:
        raise ValueError("no runs to fit")
    # a multi-rank run that shared the machine measured the other runs too (RunSample.shared)
    samples = [s for s in samples if not s.shared] or samples
    single = [s for s in samples if s.ranks == 1]
    # without a one-rank run the multi-rank runs stand in, scaled to one rank with the assumed
    # efficiency (they cannot measure the efficiency against themselves)
    base = single or samples
    scale = [1.0 if s.ranks == 1 else 1 + ASSUMED_PARALLEL_EFFICIENCY * (s.ranks - 1) for s in base]
    starts = np.array([max(s.engine_s - s.loop_s, 0.0) for s in base])
    ns = np.array([s.n_particles for s in base], float)
    tps = np.array([s.loop_s * k / s.steps for s, k in zip(base, scale)])
    group = _size_groups(ns)
    sizes = int(group.max()) + 1
    startup, startup_n = _fit_startup(ns, starts, sizes)
    alpha = 1.0
    if sizes >= 2:
        a, b = _nonnegative_line(ns, tps)
        note = f"{sizes} sizes"
        if sizes >= 3:
            # three sizes or more can tell a straight line from a curve: the cost per step of the
            # LIGGGHTS shear cell grows as n^0.8 over 228-14 107 grains (mesh-wall work that does not
            # grow with every grain), and a + b n put the 14 107-grain run at 1.26x and the 228-grain
            # one at 1.35x. A power law c n^alpha (log-linear least squares) replaces the line
            # where it fits better; each size weighted once, however many runs it has
            w = 1.0 / np.sqrt(np.bincount(group)[group])
            alpha_p, log_c = np.linalg.lstsq(np.column_stack([np.log(ns), np.ones_like(ns)]) * w[:, None],
                                             np.log(tps) * w, rcond=None)[0]
            rel_line = ((a + b * ns) / tps - 1) * w
            rel_power = (np.exp(log_c) * ns ** alpha_p / tps - 1) * w
            if np.sum(rel_power ** 2) < np.sum(rel_line ** 2) and 0 < alpha_p <= 1.5:
                a, b, alpha = 0.0, float(np.exp(log_c)), float(alpha_p)
                note += f"; power law n^{alpha:.2f}"
    else:
        a, b = 0.0, float(np.median(tps / ns))
        note = "one size: per-step overhead not separated"
    eff = ASSUMED_PARALLEL_EFFICIENCY
    multi = [s for s in samples if s.ranks > 1]
    if multi and single:
        effs = []
        for s in multi:
            t1 = s.steps * (a + b * s.n_particles ** alpha)
            speedup = t1 / max(s.loop_s, 1e-12)
            effs.append((speedup - 1) / (s.ranks - 1))
        eff = float(np.clip(np.median(effs), 0.05, 1.0))
        note += f"; parallel efficiency from {len(multi)} run(s)"
    else:
        note += "; parallel efficiency assumed" + ("" if single else " (no one-rank run)")
    units = [s.units for s in samples if s.units is not None]
    med_units = float(np.median(units)) if units else None
    if units:
        note += _units_note(units)
    if startup_n > 0:
        note += f"; start-up {startup:.3g} s + {startup_n:.3g} s per particle"
    if alpha > 1:
        note += f"; linear beyond {int(ns.max())} particles"
    return Throughput(startup, float(a), float(b), eff, len(samples), note, med_units, alpha,
                      startup_per_particle_s=startup_n, max_particles=int(ns.max()), units_range=units_range(units))


def units_range(units) -> tuple[float, float] | None:
    """(fewest, most) units [-] of two runs or more, else None (:attr:`Throughput.units_range`)."""
    units = [float(u) for u in units if u is not None]
    return (min(units), max(units)) if len(units) >= 2 else None


def _units_note(units, extra: str = "") -> str:
    """The note's clause on the units the runs took: their median, how many, their range."""
    span = f", {min(units):g}-{max(units):g}" if len(units) > 1 else ""
    return f"; {float(np.median(units)):g} units (median of {len(units)}{span}{extra})"


def _nonnegative_line(ns, y) -> tuple[float, float]:
    """(c0, c1) >= 0 of y ≈ c0 + c1 n in relative residuals (scipy.optimize.nnls): every run weighs
    the same whatever its size."""
    from scipy.optimize import nnls       # here: not needed to read the table (validate, #16)
    A = np.column_stack([np.ones_like(ns), ns])
    (c0, c1), _ = nnls(A / y[:, None], np.ones_like(y))
    return float(c0), float(c1)


def _fit_startup(ns, starts, sizes: int) -> tuple[float, float]:
    """(start-up [s], start-up per particle [s]) from the runs' particle counts ``ns`` and their
    start-up times ``starts``: the median for runs of one size; over two sizes or more a
    non-negative line s0 + s1 n (scipy.optimize.nnls, relative residuals) where it fits the runs
    better than their median, as YADE's set-up does (8, 35 and 54 s with 300, 2 000 and 4 000
    grains; the median, 35 s, put the 300-grain run's estimate 36 % long)."""
    median = float(np.median(starts))
    if sizes < 2 or not np.all(starts > 0):
        return median, 0.0
    s0, s1 = _nonnegative_line(ns, starts)
    rel_line = np.sum(((s0 + s1 * ns) / starts - 1) ** 2)
    rel_median = np.sum((median / starts - 1) ** 2)
    return (float(s0), float(s1)) if s1 > 0 and rel_line < rel_median else (median, 0.0)


def refresh(paths, out: Path | None = None, steps_only: bool = False, add: bool = False) -> dict:
    """Refit the table from the complete runs under ``paths`` and write it (default: the user
    table, :func:`user_table_path`). Returns ``{engine: {scene: Throughput}}`` of what was fitted.

    Each entry refitted keeps the runs it was fitted on (``samples``, :meth:`RunSample.to_row`).
    ``add``: fit the new runs together with those an entry kept (a run met again counts once), so
    that runs made on machines that are gone still count; refused for an entry fitted on another
    machine than this one (:func:`machine_id`: two machines' speeds in one fit). Without it the
    runs given replace an entry's (a change to a deck makes its earlier runs stale).

    ``steps_only``: refresh only how many steps the runs took (the step plan's ``units``, the same
    on every machine: e.g. a new stage-1 servo law that converges in fewer chunks) of the entries
    already in the table, and keep the costs per step it was fitted with on its machine (the other
    machines' speed records are ratios to them). Returns the entries changed."""
    groups: dict = {}
    for s in samples_from_runs(paths):
        groups.setdefault((s.engine, s.scene), []).append(s)
    out = Path(out) if out else user_table_path()
    old = read_table(out)           # a damaged table: a ValueError naming it, nothing written
    fitted: dict = {}
    entries: dict = {}          # (engine, scene) -> the table entry to write, the runs it keeps included
    for (eng, sc), smp in sorted(groups.items()):
        if not steps_only:
            if add:
                smp = _with_kept_samples(smp, (old.get(eng) or {}).get(sc), f"{eng} {sc}")
            tp = replace(fit(smp), machine=machine_id())
            fitted.setdefault(eng, {})[sc] = tp
            entries[eng, sc] = asdict(tp) | {"samples": [x.to_row() for x in smp]}
            continue
        units = [x.units for x in smp if x.units is not None]
        entry = (old.get(eng) or {}).get(sc)
        if not units or not entry:
            continue
        med = float(np.median(units))
        entry["units"] = med
        entry["units_range"] = units_range(units)
        entry["note"] = (re.sub(r"; [\d.e+-]+ units \(median of \d+[^)]*\)", "", entry.get("note", ""))
                         + _units_note(units, ", steps refreshed alone"))
        fitted.setdefault(eng, {})[sc] = Throughput.from_dict(entry)
        entries[eng, sc] = entry             # its costs and the runs it keeps unchanged
    for (eng, sc), entry in entries.items():
        old.setdefault(eng, {})[sc] = entry
    out.parent.mkdir(parents=True, exist_ok=True)
    write_text(out, json.dumps(old, indent=1, sort_keys=True) + "\n")     # atomic, keeps the umask
    return fitted


def _with_kept_samples(new: list, entry: dict | None, what: str) -> list:
    """``new`` runs and the runs a table ``entry`` kept (``samples``), each run once (by its name
    and engine time, as :func:`samples_from_runs` counts them)."""
    if not entry:
        return new
    here = machine_id()
    if entry.get("machine") and entry["machine"] != here:
        raise ValueError(f"clock refresh --add: the {what} entry was fitted on {entry['machine']}, this machine is "
                         f"{here}: refit it from this machine's runs alone (without --add)")
    seen = {(Path(x.source).name, round(x.engine_s, 3)) for x in new}
    eng, sc = new[0].engine, new[0].scene
    older = [RunSample.from_row(eng, sc, r) for r in entry.get("samples") or []]
    return [x for x in older if (x.source, round(x.engine_s, 3)) not in seen] + list(new)
