"""``crossval(case)``: run one case on both engines and compare them.

The two runs go side by side (a thread each driving its engine subprocess,
:class:`concurrent.futures.ThreadPoolExecutor`) when at least two cores are free, i.e. the number
of cores minus the 1-minute load average is ≥ 2 (``concurrent="auto"``), otherwise one after the
other; ``concurrent=True/False`` forces the choice. Each engine's wall time (total and engine loop)
is recorded; a complete run already on disk is reused (its recorded wall time is reported).
The comparison puts LIGGGHTS as A and YADE as B.
"""
from __future__ import annotations

import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from engines.base import EngineError

from ..case import Case, load_case
from ..runner import RunOutcome, run_case
from .core import Comparison, compare
from ..analysis._common import atomic_write_csv
from .report import write_compare_report

__all__ = ["CrossValidation", "crossval", "free_cores"]


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
    comparison: Comparison
    mode: str                     # "concurrent" or "sequential", with the reason
    seconds: float
    engines: list = field(default_factory=list)   # rows of the wall-time table

    @property
    def wall_times(self) -> pd.DataFrame:
        return pd.DataFrame(self.engines)


def _run_one(case, engine, runs_root, force):
    t0 = time.perf_counter()
    out = run_case(case, engine, runs_root=runs_root, force=force, progress=False)
    return out, time.perf_counter() - t0


def crossval(case, runs_root="runs", out_dir=None, concurrent="auto", force: bool = False,
             measures=None, options: dict | None = None, engines=None, **compare_kw) -> CrossValidation:
    """Run ``case`` (a Case or a YAML path) on ``engines`` (default: the engines the case lists) and
    compare them (A = first engine).

    Writes the comparison (CSV, HTML with each engine's wall time) into ``out_dir`` (default
    ``<runs_root>/<case>/crossval``). Other keyword arguments go to :func:`~orchestrator.compare.compare`.
    """
    if not isinstance(case, Case):
        case = load_case(case)
    engines = list(case.engines if engines is None else engines)
    missing = [e for e in engines if e not in case.engines]
    if missing:
        raise ValueError(f"case {case.name!r} lists engines {case.engines}; it cannot be cross-validated on {missing}")
    fc = free_cores()
    if concurrent == "auto":
        conc = fc >= 2
        mode = (f"concurrent ({fc:.1f} cores free)" if conc else
                f"sequential (only {fc:.1f} of {os.cpu_count()} cores free; concurrency needs 2)")
    else:
        conc = bool(concurrent)
        mode = "concurrent (forced)" if conc else "sequential (forced)"
    t0 = time.perf_counter()
    runs, elapsed = {}, {}
    if conc:
        with ThreadPoolExecutor(max_workers=len(engines)) as ex:
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
    cmp = compare(runs[engines[0]].run_dir, runs[engines[1]].run_dir, out_dir=None, measures=measures,
                  options=options, labels=tuple(engines), **compare_kw)
    cv = CrossValidation(case, runs, cmp, mode, time.perf_counter() - t0, rows)
    _write(cv, out_dir)
    return cv


def _write(cv: CrossValidation, out_dir: Path):
    cmp = cv.comparison
    cmp.write(out_dir, html=False)
    atomic_write_csv(cv.wall_times, out_dir / "wall_times.csv")
    cmp.files["wall_times"] = out_dir / "wall_times.csv"
    cmp.files["html"] = write_compare_report(cmp, out_dir / "report.html",
                                             crossval={"engines": cv.engines, "mode": f"runs: {cv.mode}"})
