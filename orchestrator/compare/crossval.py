"""``crossval(case)``: run one case on two or more engines and compare them.

The runs go side by side (a thread each driving its engine subprocess, as many at once as cores are free,
:class:`concurrent.futures.ThreadPoolExecutor`) when at least two cores are free, i.e. the number
of cores minus the 1-minute load average is ≥ 2 (``concurrent="auto"``), otherwise one after the
other; ``concurrent=True/False`` forces the choice. Each engine's wall time (total and engine loop)
is recorded; a complete run already on disk is reused (its recorded wall time is reported).
The first engine is A, the reference; every other engine is compared with it.
"""
from __future__ import annotations

import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from engines.base import EngineError

from ..case import Case, CaseError, load_case
from ..derive import derive
from ..registry import engine_names
from ..runner import RunOutcome, refusal, run_case
from .core import Comparison, compare
from ..analysis._common import atomic_write_csv
from .report import write_compare_report

__all__ = ["CrossValidation", "crossval", "crossval_plan", "free_cores"]


def free_cores() -> float:
    """Cores not busy: ``os.cpu_count()`` minus the 1-minute load average (≥ 0)."""
    n = os.cpu_count() or 1
    try:
        load = os.getloadavg()[0]
    except OSError:
        load = 0.0
    return max(0.0, n - load)


@dataclass
class CrossValidation:
    case: Case
    runs: dict                    # engine -> RunOutcome
    comparisons: dict             # engine B -> Comparison of A (the first engine) with B
    mode: str                     # "concurrent" or "sequential", with the reason
    seconds: float
    engines: list = field(default_factory=list)   # rows of the wall-time table

    @property
    def comparison(self) -> Comparison:
        """The comparison of the first two engines (A with the first B)."""
        return next(iter(self.comparisons.values()))

    def __repr__(self) -> str:
        runs = ", ".join(f"{e} {'reused' if o.reused else 'ran'}" for e, o in self.runs.items())
        return (f"<CrossValidation {self.case.name}: {runs} ({self.mode}); "
                f"{'; '.join(repr(c) for c in self.comparisons.values())}>")

    def _repr_html_(self) -> str:
        """In a notebook: the engines' wall times, then each comparison as it shows itself."""
        import html
        head = (f"<p><code>CrossValidation {html.escape(self.case.name)}</code>: runs {html.escape(self.mode)}</p>"
                + self.wall_times.to_html(index=False))
        return head + "".join(c._repr_html_() for c in self.comparisons.values())

    @property
    def wall_times(self) -> pd.DataFrame:
        return pd.DataFrame(self.engines)


def _run_one(case, engine, runs_root, force):
    t0 = time.perf_counter()
    out = run_case(case, engine, runs_root=runs_root, force=force, progress=False)
    return out, time.perf_counter() - t0


def crossval(case, runs_root="runs", out_dir=None, concurrent="auto", force: bool = False,
             measures=None, options: dict | None = None, engines=None, **compare_kw) -> CrossValidation:
    """Run ``case`` (a Case or a YAML path) on ``engines`` (default: the engines the case lists; any
    installed engine may be named, as ``orchestrator run --engine`` may) and compare the first
    engine (A) with each of the others.

    Writes each comparison (CSV, HTML with each engine's wall time) into ``out_dir`` (default
    ``<runs_root>/<case>/crossval``; with three or more engines, one subdirectory ``A_vs_B`` per
    pair). Other keyword arguments go to :func:`~orchestrator.compare.compare`. Fewer than two
    engines is a ValueError, and an engine that cannot run the case as written a CaseError naming
    the case file (:func:`_refuse`), both before anything runs.
    """
    if not isinstance(case, Case):
        case = load_case(case)
    engines = checked_engines(case, engines)
    at_once, mode = _mode(concurrent, len(engines))
    t0 = time.perf_counter()
    runs, elapsed = {}, {}
    if at_once > 1:
        with ThreadPoolExecutor(max_workers=at_once) as ex:
            futs = {e: ex.submit(_run_one, case, e, runs_root, force) for e in engines}
            for e, f in futs.items():
                runs[e], elapsed[e] = f.result()
    else:
        for e in engines:
            runs[e], elapsed[e] = _run_one(case, e, runs_root, force)
    bad = {e: o for e, o in runs.items() if o.status != "complete"}
    if bad:
        msg = "; ".join(f"{e}: {o.status} ({o.run_dir})" + (
            f" — {o.summary['unstable'].get('meaning', o.summary['unstable'].get('figure'))}: "
            f"{o.summary['unstable'].get('value'):.4g} > {o.summary['unstable'].get('limit')} at step "
            f"{o.summary['unstable'].get('step')}" if isinstance(o.summary.get("unstable"), dict) else "")
            for e, o in bad.items())
        raise EngineError(f"crossval {case.name}: not every engine completed the case, nothing to compare: {msg}")
    rows = []
    for e in engines:
        o: RunOutcome = runs[e]
        wt = o.summary.get("wall_time", {})
        rows.append({"engine": e, "version": o.summary.get("engine_version", ""), "run_dir": str(o.run_dir),
                     "reused": o.reused, "wall_time_total_s": wt.get("total"), "engine_s": wt.get("engine"),
                     "engine_loop_s": wt.get("engine_loop"), "parse_s": wt.get("parse"),
                     "elapsed_here_s": round(elapsed[e], 3), "steps": o.summary.get("steps_run"),
                     "substitutions": "; ".join(f"{s['feature']} → {s['mechanism']}"
                                                for s in o.summary.get("substitutions", [])) or "none"})
    out_dir = Path(out_dir) if out_dir is not None else Path(runs_root) / case.name / "crossval"
    a = engines[0]
    cmps = {b: compare(runs[a].run_dir, runs[b].run_dir, out_dir=None, measures=measures,
                       options=options, labels=(a, b), **compare_kw) for b in engines[1:]}
    cv = CrossValidation(case, runs, cmps, mode, time.perf_counter() - t0, rows)
    for b, cmp in cmps.items():
        _write(cv, cmp, out_dir if len(cmps) == 1 else out_dir / f"{a}_vs_{b}")
    return cv


def checked_engines(case: Case, engines=None) -> list:
    """The engines a cross-validation of ``case`` runs (default the case's), checked before anything
    runs: installed, at least two, and each able to run the case as written (:func:`_refuse`)."""
    engines = list(dict.fromkeys(case.engines if engines is None else engines))
    unknown = [e for e in engines if e not in engine_names()]
    if unknown:
        raise ValueError(f"crossval: unknown engine(s) {unknown}; installed engines: {', '.join(engine_names())}")
    if len(engines) < 2:
        where = case.source or case.name
        raise ValueError(
            f"{where}: `engines` lists {engines or 'no engine'}, and cross-validation needs two; name them "
            f"with --engine (e.g. `orchestrator crossval {where} --engine liggghts --engine yade`) or list "
            f"two in the case's `engines`")
    _refuse(case, engines)
    return engines


def _mode(concurrent, n_engines: int) -> tuple[int, str]:
    """How many of ``n_engines`` runs go at once, and why: ``"auto"`` runs side by side when two
    cores are free, as many at once as there are free cores (three engines on two free cores: two
    at once); ``True`` all at once, ``False`` one after the other."""
    if concurrent == "auto":
        fc = free_cores()
        if fc >= 2:
            at_once = min(n_engines, int(fc))
            return at_once, f"concurrent, {at_once} at once ({fc:.1f} cores free)"
        return 1, f"sequential (only {fc:.1f} of {os.cpu_count()} cores free; concurrency needs 2)"
    return (n_engines, "concurrent (forced)") if concurrent else (1, "sequential (forced)")


def crossval_plan(case_path, engines=None, runs_root="runs", concurrent="auto"):
    """What :func:`crossval` would run, before any run (``orchestrator crossval CASE --dry-run``):
    the engines checked as it checks them, the table of
    :func:`orchestrator.stability.sweep.plan_table` (each run reused or to run, its size and
    estimate; no packing, mesh or run directory), and how many run at once (the engines side by
    side, or one after the other)."""
    from ..stability.sweep import plan_point, plan_table
    engines = checked_engines(load_case(case_path), engines)
    at_once, mode = _mode(concurrent, len(engines))
    return plan_table(plan_point(case_path, {}, engines, runs_root)), at_once, mode


def _refuse(case: Case, engines: list) -> None:
    """Raise CaseError naming the case file when any of ``engines`` lacks a term the case asks for
    with no substitute it accepts (:func:`orchestrator.runner.refusal`, what each run
    checks before it starts, and ``orchestrator run`` for every engine before the first): a
    cross-validation compares only once every engine has run, so one refused after the others have
    run for hours would waste them."""
    params = derive(case)
    refused = {e: why for e in engines if (why := refusal(case, e, params))}
    if refused:
        able = [e for e in engines if e not in refused]
        drop = (f"cross-validate on {' and '.join(able)} (`--engine {' --engine '.join(able)}`)" if len(able) >= 2
                else "name two engines that can run it with --engine")
        problems = [f"engine {e}: {why}" for e, why in refused.items()]
        problems[-1] += (f". Nothing was run (crossval): accept a substitute in contact.substitutes where one is "
                         f"offered, or {drop}")
        raise CaseError(case.source or case.name, problems)


def _write(cv: CrossValidation, cmp: Comparison, out_dir: Path):
    cmp.write(out_dir, html=False)
    atomic_write_csv(cv.wall_times, out_dir / "wall_times.csv")
    cmp.files["wall_times"] = out_dir / "wall_times.csv"
    cmp.files["html"] = write_compare_report(cmp, out_dir / "report.html",
                                             crossval={"engines": cv.engines, "mode": f"runs: {cv.mode}"})
