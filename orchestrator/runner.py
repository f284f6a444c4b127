"""Run a case on an engine: ``runs/<case>/<engine>-<hash>/`` with the resolved case, derived
parameters, rendered deck, engine log, frames.h5 and summary.json.

The hash covers the resolved case, the engine and its version, and the templates. A complete run
is reused unless ``force``; an interrupted run resumes from its last restart/checkpoint. Every
file is written under a temporary name and renamed.
"""
from __future__ import annotations

import hashlib
import json
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import yaml

from engines import get_engine
from engines.base import EngineError
from engines.render import templates_hash

from .atomic import write_json, write_text
from .case import Case
from .derive import derive
from .particles_io import write_particle_table

#: measured single-core throughput [particle-steps/s] used for run-time estimates when no
#: benchmark result is stored (ENGINES.md: 2000 dense Hertz spheres on this machine).
#: LAMMPS: LIGGGHTS' figure times the ratio measured on plane_shear_smoke (150 grains, 17 391 steps,
#: both engines' loop times in one session: 7.13e5 / 6.98e5 particle-steps/s = 1.02; docs/lammps.md)
DEFAULT_THROUGHPUT = {"liggghts": 6e6, "yade": 1.5e6, "lammps": 6e6}
#: process start-up and set-up [s] measured on this machine (tiny verification cases: total engine
#: time minus the engines' own loop time)
DEFAULT_STARTUP = {"liggghts": 0.5, "yade": 2.0, "lammps": 0.5}   # LAMMPS: 1.03 s vs LIGGGHTS 1.22 s, same session


@dataclass
class RunOutcome:
    run_dir: Path
    status: str
    summary: dict
    reused: bool = False

    @property
    def frames(self):
        from .frames import Frames
        return Frames(self.run_dir / "frames.h5")


def run_hash(case: Case, engine_name: str, engine_version: str, params: dict | None = None) -> str:
    """Hash of what determines a run: the resolved case, the derived numbers handed to the
    engine (so a change in orchestrator.derive makes a new run), the engine and its version,
    and the templates the scene's deck is rendered from."""
    h = hashlib.sha256()
    h.update(case.hash_input().encode())
    params = derive(case) if params is None else params
    # not hashed: file names, and the pre-run stability report (diagnostics and their wording; the
    # time step and the monitor limits it leads to are hashed under their own keys)
    h.update(json.dumps({k: v for k, v in params.items() if k not in ("files", "stability")}, sort_keys=True,
                        default=str).encode())
    h.update(engine_name.encode())
    h.update(engine_version.encode())
    h.update(templates_hash(engine_name, case.scene.kind).encode())
    if getattr(case, "initial_packing", None) is not None:
        from .initial_packing import packing_digest
        h.update(packing_digest(case.initial_packing).encode())
    return h.hexdigest()[:12]


def run_dir_for(case: Case, engine_name: str, runs_root="runs") -> Path:
    eng = get_engine(engine_name)
    return Path(runs_root) / case.name / f"{engine_name}-{run_hash(case, engine_name, eng.version())}"


def read_summary(run_dir) -> dict | None:
    p = Path(run_dir) / "summary.json"
    if not p.exists():
        return None
    return json.loads(p.read_text())


def estimate_wall_time(case: Case, params: dict, engine_name: str) -> float:
    """Engine wall time [s] estimated from the derived step count, particle count and the
    engine's throughput (benchmarks/throughput.json when measured, else ENGINES.md figures)."""
    tp = dict(DEFAULT_THROUGHPUT)
    stored = Path(__file__).resolve().parents[1] / "benchmarks" / "throughput.json"
    if stored.exists():
        tp.update(json.loads(stored.read_text()))
    sc = params["scene"]
    n = sc.get("n", len(sc.get("ids", [])))
    steps = sc.get("total_steps", sc["steps"])
    ranks = case.engine_options.mpi_ranks if engine_name in ("liggghts", "lammps") else case.engine_options.threads
    return DEFAULT_STARTUP[engine_name] + steps * max(n, 1) / (tp[engine_name] * ranks)


def prepare(case: Case, engine_name: str, run_dir: Path, params: dict | None = None) -> tuple[dict, list]:
    """Derive parameters (unless given), check capabilities, write case/params/particles.
    Returns (params, subs)."""
    from .scenes import scene_module
    eng = get_engine(engine_name)
    params = derive(case) if params is None else params
    subs = eng.check(params["features"], case.contact.substitutes)
    run_dir.mkdir(parents=True, exist_ok=True)
    write_text(run_dir / "case.yaml", yaml.safe_dump(case.resolved(), sort_keys=False))
    mod = scene_module(case.scene.kind)
    from .initial_packing import apply_initial_packing, verify_written
    packing = apply_initial_packing(case, params, run_dir)      # None without case.initial_packing
    if hasattr(mod, "prepare"):
        params["files"] = mod.prepare(case, params, run_dir) or {}
    elif not (run_dir / "particles.txt").exists():
        sc = params["scene"]
        write_particle_table(run_dir / "particles.txt", sc["ids"], sc["radius"], case.material.density,
                             sc["position"], sc.get("velocity"))
    if packing is not None:
        verify_written(case, run_dir, packing)
        params["initial_packing"] = packing
    write_json(run_dir / "params.json", params)
    return params, subs


def run_case(case: Case, engine_name: str, runs_root="runs", force: bool = False, dry_run: bool = False,
             progress: bool | None = None, analyze: bool = True) -> RunOutcome:
    """Render, run, parse (and analyse) one case on one engine."""
    eng = get_engine(engine_name)
    if not eng.available():
        raise EngineError(f"{engine_name} is not installed (no '{eng.executable}' on PATH); "
                          "run the README's set-up command")
    version = eng.version()
    params = derive(case)
    run_dir = Path(runs_root) / case.name / f"{engine_name}-{run_hash(case, engine_name, version, params)}"
    old = read_summary(run_dir)
    if old and old.get("status") == "complete" and (run_dir / "frames.h5").exists() and not force and not dry_run:
        if analyze and case.analysis and old.get("analysis_specs") != case.analysis:
            with _RunLock(run_dir):               # the run is reused; its analyses are (re)done
                t0 = time.perf_counter()
                old["analysis"] = run_case_analyses(case, run_dir)
                old["analysis_specs"] = case.analysis
                old.setdefault("wall_time", {})["analysis"] = time.perf_counter() - t0
                write_json(run_dir / "summary.json", old)
        return RunOutcome(run_dir, "complete", old, reused=True)
    if old and old.get("status") == "unstable" and not force and not dry_run:
        return RunOutcome(run_dir, "unstable", old, reused=True)     # stopped by its monitors: a result
    if force and run_dir.exists():
        shutil.rmtree(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    with _RunLock(run_dir):
        return _run_locked(case, eng, engine_name, version, run_dir, dry_run, progress, analyze, params)


class _RunLock:
    """An exclusive lock on a run directory (flock), so two processes never drive one run."""

    def __init__(self, run_dir: Path):
        self.path = run_dir / ".lock"

    def __enter__(self):
        import fcntl
        self.fh = open(self.path, "w")
        try:
            fcntl.flock(self.fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self.fh.close()
            raise EngineError(f"{self.path.parent} is being run by another process; wait for it or stop it") from None
        return self

    def __exit__(self, *exc):
        import fcntl
        fcntl.flock(self.fh, fcntl.LOCK_UN)
        self.fh.close()


def _run_locked(case, eng, engine_name, version, run_dir, dry_run, progress, analyze, params) -> RunOutcome:
    timings = {}
    t0 = time.perf_counter()
    params, subs = prepare(case, engine_name, run_dir, params)
    prior = read_summary(run_dir) or {}
    resume = None if dry_run or prior.get("status") not in ("running", "failed") else eng.resume_state(run_dir)
    if not dry_run:
        resume = _scene_resume(case, engine_name, run_dir, resume)
    if resume and hasattr(eng, "prepare_resume"):
        eng.prepare_resume(run_dir, resume)
    deck = eng.render(case, params, run_dir, resume=resume)
    timings["render"] = time.perf_counter() - t0
    estimate = estimate_wall_time(case, params, engine_name)
    summary = {
        "case": case.name, "case_source": case.source, "engine": engine_name, "engine_version": version,
        "run_dir": str(run_dir), "deck": deck.name, "status": "rendered" if dry_run else "running",
        "steps": params["scene"].get("total_steps", params["scene"]["steps"]),
        "dt": params["dt"], "dt_critical": params["dt_critical"], "dt_fraction": params["dt_fraction"],
        "stability": {k: params["stability"][k] for k in ("limits", "fractions", "binding", "dt_max_safe", "ok",
                                                          "forced")} if "stability" in params else None,
        "estimated_engine_time_s": estimate,
        "substitutions": [s.as_dict() for s in subs],
        "wall_time": timings, "resumed_from": resume,
    }
    if dry_run:
        write_json(run_dir / "summary.json", summary)
        return RunOutcome(run_dir, "rendered", summary)
    write_json(run_dir / "summary.json", summary)
    progress = case.engine_options.progress if progress is None else progress
    t1 = time.perf_counter()
    from .stability.monitors import read_verdict
    try:
        res, resume = _run_with_fallback(eng, case, params, run_dir, deck, resume, progress)
        summary["resumed_from"] = resume
    except EngineError as exc:
        unstable = read_verdict(run_dir, params["dt"], failed=True)
        if unstable is not None:
            return _mark_unstable(run_dir, summary, unstable, time.perf_counter() - t1)
        summary["status"] = "failed"
        summary["error"] = str(exc)
        summary["wall_time"]["engine"] = time.perf_counter() - t1
        write_json(run_dir / "summary.json", summary)
        raise
    timings["engine"] = time.perf_counter() - t1
    unstable = read_verdict(run_dir, params["dt"])
    if unstable is not None:
        return _mark_unstable(run_dir, summary, unstable, timings["engine"])
    # the engine's own integration time: engine - loop = process start-up, reading, writing
    timings["engine_loop"] = eng.loop_time(run_dir / "engine.log")
    t2 = time.perf_counter()
    meta = {
        "engine": engine_name, "engine_version": version, "case": case.resolved(),
        "deck_hash": hashlib.sha256(deck.read_bytes()).hexdigest(),
        "template_hash": templates_hash(engine_name, case.scene.kind), "source": "simulation",
        "substitutions": [s.as_dict() for s in subs], "dt": params["dt"],
    }
    eng.parse(case, params, run_dir, meta)
    scene_summary = run_dir / "scene_summary.json"      # written by a scene's extras hook, if any
    if scene_summary.exists():
        summary["scene"] = json.loads(scene_summary.read_text())
    timings["parse"] = time.perf_counter() - t2
    summary["status"] = "complete"
    summary["steps_run"] = res.steps
    if analyze and case.analysis:
        t3 = time.perf_counter()
        summary["analysis"] = run_case_analyses(case, run_dir)
        summary["analysis_specs"] = case.analysis
        timings["analysis"] = time.perf_counter() - t3
    timings["total"] = sum(v for k, v in timings.items() if k not in ("total", "engine_loop"))
    summary["wall_time"] = timings
    write_json(run_dir / "summary.json", summary)
    # only now, with the complete summary on disk, are the resume points no longer needed
    summary["resume_points_removed_bytes"] = drop_resume_points(run_dir)
    write_json(run_dir / "summary.json", summary)
    return RunOutcome(run_dir, "complete", summary)


def drop_resume_points(run_dir: Path) -> int:
    """Delete a complete run's LIGGGHTS restart files and YADE checkpoints (a complete run is
    reused, never resumed; on the seed triaxial case they would hold ~60 x 6 MB). Returns the bytes
    freed."""
    freed = 0
    for f in [*Path(run_dir).glob("restart/*.restart"), *Path(run_dir).glob("checkpoint*.yade.gz")]:
        try:
            freed += f.stat().st_size
            f.unlink()
        except FileNotFoundError:
            pass
    return freed


def _mark_unstable(run_dir, summary, unstable: dict, engine_time: float) -> RunOutcome:
    """The monitors stopped the run (orchestrator.stability.monitors): status 'unstable', with the
    figure that tripped, its value and limit, and the step and time."""
    summary["status"] = "unstable"
    summary["unstable"] = unstable
    summary["wall_time"]["engine"] = engine_time
    summary["wall_time"]["total"] = sum(v for k, v in summary["wall_time"].items() if k != "total")
    write_json(run_dir / "summary.json", summary)
    return RunOutcome(run_dir, "unstable", summary)


def _run_with_fallback(eng, case, params, run_dir, deck, resume, progress):
    """Run; if resuming from the newest restart fails (e.g. it was half-written when the run was
    killed), try the older ones, then start afresh."""
    log = run_dir / "engine.log"
    total = params["scene"].get("total_steps", params["scene"]["steps"])
    timeout = case.engine_options.timeout
    candidates = (resume or {}).get("candidates", [])
    for cand in candidates[1:] + [None]:
        try:
            return eng.run(deck, case, total, log, timeout, progress), resume
        except EngineError:
            if resume is None:
                raise
            write_text(log.with_suffix(".resume-failed.log"), log.read_text(errors="replace") if log.exists() else "")
            resume = None if cand is None else dict(resume, restart_file=cand, checkpoint=cand,
                                                    step=_restart_step(cand, resume))
            resume = _scene_resume(case, eng.name, run_dir, resume)
            if resume is not None and hasattr(eng, "prepare_resume"):
                eng.prepare_resume(run_dir, resume)
            deck = eng.render(case, params, run_dir, resume=resume)
    raise EngineError("unreachable")  # pragma: no cover


def _scene_resume(case, engine_name: str, run_dir: Path, resume: dict | None) -> dict | None:
    """Let the scene check and complete the engine's resume point (``resume_point(engine, run_dir,
    resume)`` in the scene module: e.g. the stage state a deck needs to re-enter the right stage);
    it may return None (start afresh) and tidies the run directory for the chosen point."""
    from .scenes import scene_module
    hook = getattr(scene_module(case.scene.kind), "resume_point", None)
    return hook(engine_name, Path(run_dir), resume) if hook else resume


def _restart_step(cand: str, resume: dict) -> int:
    """Step of a LIGGGHTS restart file named state.<step>.restart (YADE: the checkpoint's own)."""
    parts = Path(cand).name.split(".")
    return int(parts[1]) if len(parts) > 2 and parts[1].isdigit() else resume.get("step", 0)


def run_case_analyses(case: Case, run_dir: Path) -> dict:
    """Run the case's ``analysis:`` list on the run's frames (orchestrator.analysis)."""
    from .frames import Frames
    try:
        from .analysis import run_analyses
    except ImportError as exc:  # analysis package not available
        return {"error": f"analysis unavailable: {exc}"}
    return run_analyses(Frames(run_dir / "frames.h5"), case.analysis, run_dir / "analysis")
