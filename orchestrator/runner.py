"""Run a case on an engine: ``runs/<case>/<engine>-<hash>/`` with the resolved case, derived
parameters, rendered deck, engine log, frames.h5 and summary.json.

The hash covers the resolved case, the engine and its version, and the templates. A complete run
is reused unless ``force``; an interrupted run resumes from its last restart/checkpoint. Every
file is written under a temporary name and renamed.
"""
from __future__ import annotations

import fcntl
import hashlib
import json
import os
import sys
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import yaml

from engines.base import EngineError, UnsupportedFeature
from engines.render import templates_hash

from .atomic import remove_stale_temp_files, write_json, write_text
from .attempts import clear_attempts, read_attempts
from .clock import record_speed
from .case import Case, case_from_dict
from .derive import derive
from .sizing import run_estimate
from .frames import Frames
from .initial_packing import apply_initial_packing, packing_digest, verify_written
from .params import Params, thaw
from .registry import get_engine, get_scene
from .run_summary import lock_held, read_summary
from .stability.monitors import read_verdict
from .integrity import verify_run, run_record
from .twins import adopt_twin, find_twin


@dataclass
class RunOutcome:
    run_dir: Path
    status: str
    summary: dict
    reused: bool = False

    @property
    def frames(self):
        return Frames(self.run_dir / "frames.h5")

    @property
    def results(self):
        """The run's key figures with their errors, units and the seed's values, as a DataFrame
        (:func:`orchestrator.results.results_frame`; empty for a run that is not complete)."""
        from .results import results_frame          # on demand: pandas
        return results_frame(self.run_dir)

    def __repr__(self) -> str:
        s = self.summary or {}
        said = [self.status + (", reused" if self.reused else "")]
        if s.get("engine"):
            said.append(str(s["engine"]))
        if isinstance(s.get("n_particles"), int):
            said.append(f"{s['n_particles']:,} particles")
        engine_s = (s.get("wall_time") or {}).get("engine")
        if isinstance(engine_s, (int, float)):
            said.append(f"engine {engine_s:.1f} s")
        return f"<RunOutcome {self.run_dir}: {', '.join(said)}>"

    def _repr_html_(self) -> str:
        """In a notebook: the line of :meth:`__repr__`, then the key results of a complete run."""
        import html
        head = f"<p><code>{html.escape(repr(self))}</code></p>"
        if self.status != "complete" or not (self.run_dir / "frames.h5").exists():
            return head
        df = self.results
        return head + (df[["quantity", "text", "seed"]].to_html(index=False) if len(df) else "")


def run_hash(case: Case, engine_name: str, engine_version: str, params: dict | None = None) -> str:
    """Hash of what determines a run: the resolved case, the derived numbers handed to the
    engine (so a change in orchestrator.derive makes a new run), the engine and its version,
    and the templates the scene's deck is rendered from."""
    h = hashlib.sha256()
    h.update(case.hash_input().encode())
    params = derive(case) if params is None else params
    h.update(json.dumps(hash_params(case, engine_name, params), sort_keys=True, default=str).encode())
    h.update(engine_name.encode())
    h.update(engine_version.encode())
    h.update(templates_hash(engine_name, case.scene.kind).encode())
    if getattr(case, "initial_packing", None) is not None:
        h.update(packing_digest(case.initial_packing).encode())
    return h.hexdigest()[:12]


def hash_params(case: Case, engine_name: str, params: Params) -> dict:
    """The numbers a run hash covers: the shared parameters and the engine's own
    (``Engine.engine_params``). Not hashed: file names, and the pre-run stability report
    (diagnostics and their wording; the time step and the monitor limits it leads to are hashed
    under their own keys)."""
    d = {k: v for k, v in params.to_dict().items() if k not in ("files", "stability")}
    own = get_engine(engine_name).engine_params(case, params)
    if own is not None:
        d["engine"] = thaw(own)
    return d


def run_dir_for(case: Case, engine_name: str, runs_root="runs") -> Path:
    eng = get_engine(engine_name)
    return Path(runs_root) / case.name / f"{engine_name}-{run_hash(case, engine_name, eng.version())}"


def engine_substitutions(case: Case, engine_name: str, params) -> list:
    """The substitutions ``engine_name`` makes for the case's features (``Engine.check``); raises
    :class:`engines.base.UnsupportedFeature` for a feature it lacks with no substitute the case
    accepts. What a run checks before it starts, and ``validate`` / ``run --dry-run`` with it."""
    eng = get_engine(engine_name)
    return eng.check(eng.required_features(case, params), case.contact.substitutes)


def refusal(case: Case, engine_name: str, params) -> str | None:
    """Why ``engine_name`` cannot run the case as written (a feature it lacks with no substitute the
    case accepts: :func:`engine_substitutions`), or None. ``validate``, ``run`` and ``crossval``
    ask it for every engine before the first run starts."""
    try:
        engine_substitutions(case, engine_name, params)
    except UnsupportedFeature as exc:
        return str(exc)
    return None


def prepare(case: Case, engine_name: str, run_dir: Path, params: Params | None = None) -> tuple[Params, list]:
    """Derive parameters (unless given), check capabilities, write case/params/particles.
    Returns (params completed with the scene's files and packed geometry, subs)."""
    eng = get_engine(engine_name)
    params = derive(case) if params is None else params
    subs = engine_substitutions(case, engine_name, params)
    run_dir.mkdir(parents=True, exist_ok=True)
    write_text(run_dir / "case.yaml", yaml.safe_dump(case.resolved(), sort_keys=False))
    packing = apply_initial_packing(case, params, run_dir)      # None without case.initial_packing
    if packing is not None:
        params = params.replace(scene=params.scene.replace(n=int(packing["grains"])))
    files, scene_part = get_scene(case.scene.kind).prepare(case, params, run_dir)
    params = params.replace(files=files or {}, scene=scene_part)
    if packing is not None:
        verify_written(case, run_dir, packing)
        params = params.replace(initial_packing=packing)
    own = eng.engine_params(case, params)
    write_json(run_dir / "params.json", {**params.to_dict(), **({"engine": thaw(own)} if own is not None else {})})
    return params, subs


def run_case(case: Case, engine_name: str, runs_root="runs", force: bool = False, dry_run: bool = False,
             progress: bool | str | None = None, analyze: bool = True) -> RunOutcome:
    """Render, run, parse (and analyse) one case on one engine. With
    ``case.engine_options.scheduler`` set, the run goes to a Dask worker (:func:`run_on_cluster`).
    ``progress``: the engine's progress bar or lines (None: ``engine_options.progress``), a string
    to show them under that label (a ladder's rung: the engine, case and knob value)."""
    if case.engine_options.scheduler and not dry_run:
        return run_on_cluster(case, engine_name, case.engine_options.scheduler, runs_root=runs_root, force=force,
                              analyze=analyze)
    eng = get_engine(engine_name)
    if not eng.available():
        raise EngineError(f"{engine_name} is not installed (no '{eng.executable}' on PATH); "
                          "run the README's set-up command")
    version = eng.version()
    params = derive(case)
    run_dir = Path(runs_root) / case.name / f"{engine_name}-{run_hash(case, engine_name, version, params)}"
    if dry_run:
        run_dir.mkdir(parents=True, exist_ok=True)
        with _RunLock(run_dir):
            return _run_locked(case, eng, engine_name, version, run_dir, dry_run, progress, analyze, params)
    if force and run_dir.exists():
        if lock_held(run_dir):
            raise EngineError(f"{run_dir} is being run by another process; wait for it or stop it before --force")
        if run_dir.is_symlink():        # a link to a run with the same engine input (orchestrator.twins)
            run_dir.unlink()
        else:
            shutil.rmtree(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    # under the lock (waiting for a process that runs the same case: its result is then reused)
    with _RunLock(run_dir, wait=True):
        old = read_summary(run_dir)
        if old and old.get("status") == "complete" and not force:
            damaged = verify_run(run_dir, old)
            if any(not name.startswith("analysis") for name, _ in damaged):
                _say(f"{run_dir}: the complete run is damaged, so it is redone: "
                     + "; ".join(msg for _, msg in damaged))
                old = dict(old, status="damaged", damaged=[m for _, m in damaged])
                _clear_results(run_dir)
            elif damaged:
                _say(f"{run_dir}: analysis outputs damaged, so the analyses are redone: "
                     + "; ".join(msg for _, msg in damaged))
                old["analysis_specs"] = None
        if old and old.get("status") == "complete" and (run_dir / "frames.h5").exists() and not force:
            return _reuse(case, run_dir, old, analyze)
        if old and old.get("status") == "unstable" and not force:
            return RunOutcome(run_dir, "unstable", old, reused=True)     # stopped by its monitors: a result
        return _run_locked(case, eng, engine_name, version, run_dir, dry_run, progress, analyze, params,
                           twins=not force)


def _reuse(case: Case, run_dir: Path, old: dict, analyze: bool) -> RunOutcome:
    """The outcome of the complete run in ``run_dir`` (summary ``old``), its analyses (re)done when
    the case asks for one its record lacks, or all of them when their outputs were damaged
    (``analysis_specs`` None). Analyses added by name (``orchestrator analyze RUN --analysis NAME``)
    stay on record beside the case's and do not make every later ``orchestrator run`` redo them."""
    done = old.get("analysis_specs")
    if analyze and case.analysis and (done is None or any(spec not in done for spec in case.analysis)):
        analyze_run(run_dir, case.analysis, by_name=done is not None)   # a damaged record is replaced
        old = read_summary(run_dir) or old
    return RunOutcome(run_dir, "complete", old, reused=True)


def merge_analyses(done: dict, done_specs: list, new: dict, new_specs: list) -> tuple[dict, list]:
    """The analyses of a directory after more were run on it by name (``orchestrator analyze RUN
    --analysis NAME``): the new results replace every result of the same analysis name; the others
    stay. ``done``/``new`` are ``{label: {"name", ...}}`` as :func:`orchestrator.analysis.run_analyses`
    returns them, ``done_specs``/``new_specs`` the ``analysis:`` lists that made them. Returns the
    results and the spec list that makes them."""
    names = {v.get("name", label) for label, v in new.items()}
    kept = {label: v for label, v in done.items() if v.get("name", label) not in names}
    specs = [s for s in done_specs if (s if isinstance(s, str) else next(iter(s))) not in names] + list(new_specs)
    return {**kept, **new}, specs


def analyze_run(run_dir, specs, out_dir=None, by_name: bool = False, frames=None) -> tuple[dict, dict]:
    """Run analyses on a run directory's frames and keep the directory's record whole.

    The one path by which ``orchestrator analyze`` and ``orchestrator report --analysis`` (re)do
    analyses: ``specs`` run into ``out_dir`` (default ``run_dir/analysis``). With ``by_name``, the
    analyses asked for join what the directory held (:func:`merge_analyses`: the case's others stay
    on record); otherwise they are the record. When the output is the run's own and the run is
    complete, its ``summary.json`` and integrity record follow (:func:`record_analyses`), so that the
    next ``orchestrator run`` reuses them rather than reading the changed files as damage.

    ``frames``: where the frames are read (default ``run_dir``; a frames file given for its run).

    Returns ``(new, record)``: the results just computed and the whole record now in
    ``out_dir/analysis_summary.json`` (both ``{label: {...}}``, as
    :func:`orchestrator.analysis.run_analyses` returns them).
    """
    from .analysis import atomic_write_json, run_analyses   # on demand: the analysis stack is heavy
    from .grains import frames_for_analysis
    run_dir = Path(run_dir)
    out_dir = Path(out_dir) if out_dir is not None else run_dir / "analysis"
    own = out_dir.resolve() == (run_dir / "analysis").resolve()
    record_path = out_dir / "analysis_summary.json"
    before = json.loads(record_path.read_text()) if by_name and record_path.exists() else {}
    t0 = time.perf_counter()
    new = run_analyses(frames_for_analysis(frames if frames is not None else run_dir), specs, out_dir)
    seconds = time.perf_counter() - t0
    summary = read_summary(run_dir) if own else None
    if by_name:
        done_specs = (summary or {}).get("analysis_specs") or []
        record, record_specs = merge_analyses(before, done_specs, new, specs)
        atomic_write_json(record, record_path)
    else:
        record, record_specs = new, specs
    if summary and summary.get("status") == "complete":
        # the analysis time on record is that of the whole list, not of a few analyses added to it
        record_analyses(run_dir, summary, record, record_specs, None if by_name else seconds)
    return new, record


def record_analyses(run_dir: Path, summary: dict, analysis: dict, specs, seconds: float | None = None) -> dict:
    """Put analyses just (re)done in ``run_dir/analysis`` into the complete run's ``summary`` and
    its integrity record (so that the next ``orchestrator run`` of the case reuses them rather than
    reading changed files as damage), and write ``summary.json``. Returns the summary."""
    summary["analysis"] = analysis
    summary["analysis_specs"] = specs
    if seconds is not None:
        summary.setdefault("wall_time", {})["analysis"] = seconds
    summary["integrity"] = run_record(run_dir, analysis)
    write_json(Path(run_dir) / "summary.json", summary)
    return summary


class _RunLock:
    """An exclusive lock on a run directory (flock), so two processes never drive one run."""

    def __init__(self, run_dir: Path, wait: bool = False):
        self.path = run_dir / ".lock"
        self.wait = wait

    def __enter__(self):
        self.fh = open(self.path, "w")
        try:
            fcntl.flock(self.fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            if not self.wait:
                self.fh.close()
                raise EngineError(f"{self.path.parent} is being run by another process; wait for it or stop it") from None
            _say(f"{self.path.parent} is being run by another process; waiting for it (its result is then reused)")
            fcntl.flock(self.fh, fcntl.LOCK_EX)
        return self

    def __exit__(self, *exc):
        fcntl.flock(self.fh, fcntl.LOCK_UN)
        self.fh.close()


def _run_locked(case, eng, engine_name, version, run_dir, dry_run, progress, analyze, params,
                twins: bool = True) -> RunOutcome:
    """Prepare, render, run and parse in the locked ``run_dir``. ``twins``: reuse a complete sibling
    run whose engine input is identical (orchestrator.twins; not under --force, which redoes)."""
    timings = {}
    t0 = time.perf_counter()
    # a killed attempt's half-written temporary files: only the analyses' writers make them
    # (analysis._common, atomic.temp_file), so the sweep skips dump/ and restart/ (the lock is ours)
    remove_stale_temp_files(run_dir / "analysis")
    params, subs = prepare(case, engine_name, run_dir, params)
    prior = read_summary(run_dir) or {}
    resume = None if dry_run or prior.get("status") not in ("running", "failed", "interrupted") else eng.resume_state(run_dir)
    if not dry_run:
        resume = _scene_resume(case, engine_name, run_dir, resume)
    if resume and hasattr(eng, "prepare_resume"):
        eng.prepare_resume(run_dir, resume)
    deck = eng.render(case, params, run_dir, resume=resume)
    timings["render"] = time.perf_counter() - t0
    if twins and resume is None and not dry_run and not prior:
        # a complete run that read exactly these files is this run, whatever its hash (orchestrator.twins)
        twin = find_twin(run_dir, engine_name, version)
        if twin is not None:
            _say(f"{run_dir.name}: the engine input is byte for byte that of the complete run {twin.name}; "
                 "it is reused")
            adopt_twin(run_dir, twin)
            return _reuse(case, run_dir, read_summary(run_dir), analyze)
    estimate, estimated_steps = run_estimate(case, params, engine_name)
    summary = {
        "case": case.name, "case_source": case.source, "engine": engine_name, "engine_version": version,
        "run_dir": str(run_dir), "deck": deck.name, "status": "rendered" if dry_run else "running",
        "steps": params["scene"].get("total_steps", params["scene"]["steps"]),
        "dt": params["dt"], "dt_critical": params["dt_critical"], "dt_fraction": params["dt_fraction"],
        "stability": {k: thaw(params.stability[k]) for k in ("limits", "fractions", "binding", "dt_max_safe", "ok",
                                                             "forced")} if params.stability is not None else None,
        "estimated_engine_time_s": estimate,
        # the estimate before the run's first attempt (a resumed attempt's own, above, knows more
        # of the machine: the results table gives both)
        "first_estimated_engine_time_s": _first_estimate(prior, resume, estimate),
        # the steps that estimate is for (a triaxial's stage 1: what the engine's measured runs took)
        "estimated_steps": estimated_steps,
        # what the run-time model (orchestrator.clock) is fitted on
        "scene": case.scene.kind, "n_particles": int(params["scene"].get("n", len(params["scene"].get("ids", [])))),
        "workers": eng.workers(case),
        "substitutions": [s.as_dict() for s in subs],
        "wall_time": timings, "resumed_from": resume, "pid": os.getpid(),
    }
    if dry_run:
        write_json(run_dir / "summary.json", summary)
        return RunOutcome(run_dir, "rendered", summary)
    write_json(run_dir / "summary.json", summary)
    progress = case.engine_options.progress if progress is None else progress
    t1 = time.perf_counter()
    try:
        res, resume = _run_with_fallback(eng, case, params, run_dir, deck, resume, progress,
                                         expected=estimated_steps, estimate=estimate)
        summary["resumed_from"] = resume
        if resume is None:                  # the resume failed and the run started afresh
            summary["first_estimated_engine_time_s"] = estimate
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
    if res.extra.get("cpu_s") is not None:
        timings["engine_cpu"] = res.extra["cpu_s"]      # CPU time of the engine and its ranks [s]
    if res.extra.get("paused_s"):
        timings["engine_paused"] = res.extra["paused_s"]    # of the engine's wall time, stopped [s] (attempts.py)
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
    if summary.get("resumed_from"):
        # the engine time of every attempt (the clock's figure for a resumed run, orchestrator.attempts)
        summary["attempts"] = read_attempts(run_dir)
    if analyze and case.analysis:
        t3 = time.perf_counter()
        summary["analysis"] = run_case_analyses(case, run_dir)
        summary["analysis_specs"] = case.analysis
        timings["analysis"] = time.perf_counter() - t3
    timings["total"] = _total(timings)
    summary["wall_time"] = timings
    summary["integrity"] = run_record(run_dir, summary.get("analysis"))
    write_json(run_dir / "summary.json", summary)
    # only now, with the complete summary on disk, are the resume points no longer needed
    summary["resume_points_removed_bytes"] = drop_resume_points(run_dir)
    write_json(run_dir / "summary.json", summary)
    try:                        # this machine's speed for the next estimates (orchestrator.clock)
        record_speed(run_dir)
    except (OSError, ValueError, TypeError) as exc:
        _say(f"the run's speed was not recorded for the run-time estimates: {exc}")
    return RunOutcome(run_dir, "complete", summary)


def _first_estimate(prior: dict, resume: dict | None, estimate: float | None) -> float | None:
    """The clock's estimate of the whole run's engine time [s] before its first attempt: this
    attempt's ``estimate`` on a fresh start, the earlier summary's on a resume (for a summary written
    before it kept one, its last attempt's estimate: the earliest left)."""
    if resume is None:
        return estimate
    first = prior.get("first_estimated_engine_time_s", prior.get("estimated_engine_time_s"))
    return first if isinstance(first, (int, float)) else estimate


def _say(msg: str) -> None:
    """A note for the user on stderr (the runner has no console of its own)."""
    print(f"note: {msg}", file=sys.stderr)


def _clear_results(run_dir: Path) -> None:
    """Empty a damaged complete run's directory (all but its lock, which the caller holds) so that
    it is redone from the start: its resume points were dropped when it completed, and what is left
    of its engine output must not mix into the new run."""
    for f in run_dir.iterdir():
        if f.name == ".lock":
            continue
        if f.is_dir() and not f.is_symlink():
            shutil.rmtree(f, ignore_errors=True)
        else:
            f.unlink(missing_ok=True)


def drop_resume_points(run_dir: Path) -> int:
    """Delete a complete run's LIGGGHTS restart files and YADE checkpoints (a complete run is
    reused, never resumed; on the seed triaxial case they would hold ~60 x 6 MB). Returns the bytes
    freed."""
    freed = 0
    for f in [*Path(run_dir).glob("restart/*.restart"), *Path(run_dir).glob("restart/*.restart.partial"),
              *Path(run_dir).glob("checkpoint*.yade.gz"),
              *Path(run_dir).glob("restart_forced_*")]:       # LIGGGHTS' own restart when killed
        try:
            freed += f.stat().st_size
            f.unlink()
        except FileNotFoundError:
            pass
    return freed


def _total(timings: dict) -> float:
    """The run's wall time [s]: its parts (render, engine, parse, analysis), not the engine's own
    loop time or its CPU time, which are figures about the engine part."""
    return sum(v for k, v in timings.items() if k not in ("total", "engine_loop", "engine_cpu"))


def _mark_unstable(run_dir, summary, unstable: dict, engine_time: float) -> RunOutcome:
    """The monitors stopped the run (orchestrator.stability.monitors): status 'unstable', with the
    figure that tripped, its value and limit, and the step and time."""
    summary["status"] = "unstable"
    summary["unstable"] = unstable
    summary["wall_time"]["engine"] = engine_time
    summary["wall_time"]["total"] = _total(summary["wall_time"])
    write_json(run_dir / "summary.json", summary)
    return RunOutcome(run_dir, "unstable", summary)


def _run_with_fallback(eng, case, params, run_dir, deck, resume, progress, expected=None, estimate=None):
    """Run; if resuming from the newest restart fails (e.g. it was half-written when the run was
    killed), try the older ones, then start afresh. ``expected``: the steps the run is expected to
    take (the progress lines count toward them); ``estimate``: the clock's engine time for the run [s]
    (the lines give it where the recent pace says otherwise)."""
    log = run_dir / "engine.log"
    total = params["scene"].get("total_steps", params["scene"]["steps"])
    timeout = case.engine_options.timeout
    candidates = (resume or {}).get("candidates", [])
    if resume is None:
        clear_attempts(run_dir)                             # a fresh start: the engine time starts at 0
        if hasattr(eng, "prepare_resume"):
            eng.prepare_resume(run_dir, {"step": -1})       # no frame segment of an older try
    for cand in candidates[1:] + [None]:
        try:
            # the step the attempt starts from (None: the resume point does not say, e.g. YADE's checkpoint)
            first = 0 if resume is None else resume.get("step")
            return eng.run(deck, case, total, log, timeout, progress, first_step=first,
                           expected_steps=expected, estimate_s=estimate), resume
        except EngineError:
            if resume is None:
                raise
            write_text(log.with_suffix(".resume-failed.log"), log.read_text(errors="replace") if log.exists() else "")
            resume = None if cand is None else dict(resume, restart_file=cand, checkpoint=cand,
                                                    step=_restart_step(cand, resume))
            resume = _scene_resume(case, eng.name, run_dir, resume)
            if resume is None:
                clear_attempts(run_dir)
            if hasattr(eng, "prepare_resume"):
                eng.prepare_resume(run_dir, resume or {"step": -1})
            deck = eng.render(case, params, run_dir, resume=resume)
    raise EngineError("unreachable")  # pragma: no cover


def _scene_resume(case, engine_name: str, run_dir: Path, resume: dict | None) -> dict | None:
    """Let the engine check and complete its resume point for the case's scene
    (:meth:`engines.base.Engine.complete_resume`: e.g. the stage state a deck needs to re-enter
    the right stage); it may return None (start afresh) and tidies the run directory."""
    return get_engine(engine_name).complete_resume(case, Path(run_dir), resume)


def _restart_step(cand: str, resume: dict) -> int:
    """Step of a LIGGGHTS restart file named state.<step>.restart (YADE: the checkpoint's own)."""
    parts = Path(cand).name.split(".")
    return int(parts[1]) if len(parts) > 2 and parts[1].isdigit() else resume.get("step", 0)


def run_case_analyses(case: Case, run_dir: Path) -> dict:
    """Run the case's ``analysis:`` list on the run's frames (orchestrator.analysis)."""
    try:
        from .analysis import run_analyses       # on demand: the analysis stack (scikit-image, pyvista) is heavy
        from .grains import frames_for_analysis
    except ImportError as exc:  # analysis package not available
        return {"error": f"analysis unavailable: {exc}"}
    return run_analyses(frames_for_analysis(run_dir), case.analysis, run_dir / "analysis")


def _run_resolved(data: dict, source: str, engine_name: str, runs_root: str, force: bool, analyze: bool) -> dict:
    """Worker side of :func:`run_on_cluster`: rebuild the case from its resolved data (without the
    scheduler, so the worker runs it itself) and run it. Returns the outcome as plain data."""
    data = dict(data, engine_options=dict(data.get("engine_options") or {}, scheduler=None))
    case = case_from_dict(data, source=source)
    out = run_case(case, engine_name, runs_root=runs_root, force=force, progress=False, analyze=analyze)
    return {"run_dir": str(out.run_dir), "status": out.status, "summary": out.summary, "reused": out.reused,
            "worker_pid": os.getpid()}


def run_on_cluster(case: Case, engine_name: str, scheduler, runs_root="runs", force: bool = False,
                   analyze: bool = True) -> RunOutcome:
    """Run one case on one engine on a worker of a Dask cluster (``scheduler``: an address, a
    ``distributed.Client`` or a cluster object such as LocalCluster or dask-jobqueue's
    SLURMCluster). The worker needs the engines and this package installed, and ``runs_root``
    must be a path it shares with this process; the run's MPI ranks or threads are its own."""
    from distributed import Client
    own = not isinstance(scheduler, Client)
    client = Client(scheduler) if own else scheduler
    try:
        fut = client.submit(_run_resolved, case.resolved(), str(case.source), engine_name,
                            str(Path(runs_root).resolve()), force, analyze, pure=False)
        res = fut.result()
    finally:
        if own:
            client.close()
    out = RunOutcome(Path(res["run_dir"]), res["status"], res["summary"], res["reused"])
    out.summary.setdefault("ran_on", {"scheduler": str(getattr(client, "scheduler", scheduler)),
                                      "worker_pid": res["worker_pid"]})
    return out
