"""Sweeps over any case field: ``orchestrator sweep CASE --set field=v1,v2 ... [--grid]``.

Each point is the case with nested overrides (``contact.friction=0.3,0.5`` sets
``contact: {friction: ...}``; values are read as YAML, so ``5 MPa`` stays a quantity and ``0.3``
a number). Without ``--grid`` the lists are zipped (equal lengths); with it, their Cartesian
product is taken. Every run's id is the runner's hash of the resolved case, derived numbers,
engine version and templates: a finished run (complete or stopped as unstable) is reused, so a
re-run submits only what is missing (failed or never run). Results are written after every
finished run to ``<runs>/<case>/sweep-<id>.json`` (and ``.csv``), so a failure or an interrupt
never loses the other runs' results.
"""
from __future__ import annotations

import hashlib
import itertools
import json
import time
from pathlib import Path
from typing import TYPE_CHECKING

import yaml

from ..atomic import write_json, write_text
from ..case import CaseError, allowed_fields, load_case
from ..hints import unknown_name_hint
from ..clock import run_engine_seconds
from ..run_summary import read_summary
from ..runner import run_dir_for
from .executor import get_executor, run_task
from .observables import observables

if TYPE_CHECKING:
    import pandas as pd


def parse_sets(sets: list[str]) -> dict[str, list]:
    out = {}
    for s in sets:
        if "=" not in s:
            raise ValueError(f"--set {s!r}: write FIELD=V1,V2,... (e.g. contact.friction=0.3,0.5)")
        field, vals = s.split("=", 1)
        out[field.strip()] = [yaml.safe_load(v.strip()) for v in vals.split(",") if v.strip() != ""]
        if not out[field.strip()]:
            raise ValueError(f"--set {s!r}: no values")
    return out


def points(sets: dict[str, list], grid: bool = False) -> list[dict]:
    keys = list(sets)
    if grid:
        return [dict(zip(keys, combo)) for combo in itertools.product(*(sets[k] for k in keys))]
    n = {len(v) for v in sets.values()}
    if len(n) > 1:
        raise ValueError(f"--set lists have different lengths {sorted(n)}; give --grid for their product")
    return [dict(zip(keys, combo)) for combo in zip(*(sets[k] for k in keys))]


def nested(point: dict) -> dict:
    """{"contact.friction": 0.3} -> {"contact": {"friction": 0.3}}."""
    out: dict = {}
    for dotted, v in point.items():
        d = out
        parts = dotted.split(".")
        for p in parts[:-1]:
            d = d.setdefault(p, {})
        d[parts[-1]] = v
    return out


def refuse_unknown_fields(case, case_path, dotted_fields, also: tuple[str, ...] = (), flag: str = "--set") -> None:
    """Raise :class:`CaseError` for a dotted field (``--set FIELD=...``, ``--knob FIELD``) the loaded
    ``case`` (read from ``case_path``) has no place for, naming it, the closest name and the fields
    allowed there (:func:`orchestrator.case.allowed_fields`, what the case file's own validation
    says): a misspelt field would otherwise make every point an invalid row and the command end
    with status 0. Names in ``also`` (the convergence command's knobs) are accepted and offered at
    the top level. Below a mapping the point's own validation decides. ``flag``: the command-line
    option named in the message."""
    problems = []
    for dotted in dotted_fields:
        if dotted in also:
            continue
        parts = tuple(dotted.split("."))
        for k, part in enumerate(parts):
            names = allowed_fields(parts[:k + 1], case.scene.kind)
            if not names:
                break
            if part not in names:
                hint = unknown_name_hint(names + (list(also) if k == 0 else []), part)
                problems.append(f"{flag} {dotted}: {hint}" + (f" (under {'.'.join(parts[:k])})" if k else ""))
                break
    if problems:
        raise CaseError(case_path, problems)


def plan(case_path, pts: list[dict], engines: list[str], runs_root) -> list[dict]:
    """Tasks with their run directory (hash) and whether a finished run already exists."""
    return [t for pt in pts for t in plan_point(case_path, pt, engines, runs_root)]


def finished(run_dir) -> bool:
    """Whether a sweep or ladder reuses the run in ``run_dir`` rather than running it: complete
    with its frames, or stopped as unstable (running it again would stop the same way)."""
    s = read_summary(run_dir) or {}
    return (s.get("status") == "complete" and (Path(run_dir) / "frames.h5").exists()) or s.get("status") == "unstable"


def plan_point(case_path, pt: dict, engines: list[str], runs_root, overrides: dict | None = None) -> list[dict]:
    """The tasks of one point (one per engine); an invalid point gives tasks marked ``invalid``.
    ``pt`` holds the point's dotted fields, made the case's overrides, unless ``overrides`` are
    given (a ladder's rung and seed: ``pt`` then only labels the point)."""
    ov = nested(pt) if overrides is None else overrides
    try:
        case = load_case(case_path, overrides=ov)
    except CaseError as exc:                 # an invalid point fails alone, the others still run
        return [{"case": str(case_path), "overrides": ov, "engine": eng, "runs_root": str(runs_root),
                 "point": pt, "run_dir": None, "run_id": None, "done": False, "invalid": str(exc)}
                for eng in (engines or load_case(case_path).engines)]     # the case's own engines
    tasks = []
    for eng in (engines or case.engines):
        rd = run_dir_for(case, eng, runs_root)
        tasks.append({"case": str(case_path), "overrides": ov, "engine": eng, "runs_root": str(runs_root),
                      "point": pt, "run_dir": str(rd), "run_id": rd.name, "done": finished(rd)})
    return tasks


def run_label(task: dict) -> str:
    """A run's name in its progress lines when a sweep or ladder runs one at a time: engine, case,
    the point's values and the seed (``liggghts shear_cell_small rate_scale=0.5 seed 2``)."""
    point = ", ".join(f"{k}={v}" for k, v in task["point"].items())
    return (f"{task['engine']} {Path(task['case']).stem} {point}"
            + (f" seed {task['seed']}" if task.get("seed") is not None else ""))


def plan_table(tasks: list[dict]):
    """The runs of a sweep or ladder before any of them (``--dry-run``), as a DataFrame with a row
    per task: ``engine``, ``status`` (``reused``: :func:`finished` under its runs root; ``to run``, its
    ``note`` saying when it was started before and resumes from its last restart point;
    ``refused``: the loader refused the point's case, the reason in ``note``), the run's
    ``particles``, ``steps`` (expected: a triaxial's stage 1 as the engine's measured runs took
    it), ``engine_time_s`` (:func:`orchestrator.sizing.estimate`: no packing, mesh or run
    directory) and ``run_dir``."""
    import pandas as pd

    from ..derive import derive
    from ..sizing import estimate
    rows = []
    for t in tasks:
        why = t.get("refused") or t.get("invalid")
        row = {"engine": t["engine"], "status": "refused", "particles": None, "steps": None,
               "engine_time_s": float("nan"), "note": why or "", "run_dir": t["run_dir"]}
        if not why:
            case = load_case(t["case"], overrides=t["overrides"] or None)
            size = estimate(case, derive(case), t["engine"])
            done = finished(t["run_dir"])
            started = (Path(t["run_dir"]) / "summary.json").exists()
            row.update(status="reused" if done else "to run", particles=size["particles"],
                       steps=size.get("steps_expected", size["steps"]), engine_time_s=size["engine_time_s"],
                       note="" if done or not started else "started before: resumes from its last restart point "
                                                     "(`orchestrator status` says how far it got)")
        rows.append(row)
    return pd.DataFrame(rows, columns=["engine", "status", "particles", "steps", "engine_time_s", "note", "run_dir"]
                        ).astype({"particles": "Int64", "steps": "Int64"})


def sweep_plan(case_path, sets: dict[str, list] | list[str], grid: bool = False, engines: list[str] | None = None,
               runs_root="runs"):
    """What a sweep would run, before any run (``orchestrator sweep ... --dry-run``): the table of
    :func:`plan_table` with a column per swept field."""
    import pandas as pd
    if isinstance(sets, list):
        sets = parse_sets(sets)
    refuse_unknown_fields(load_case(case_path), case_path, list(sets))
    tasks = [t for pt in points(sets, grid) for t in plan_point(case_path, pt, engines, runs_root)]
    table = plan_table(tasks)
    cols = pd.DataFrame([t["point"] for t in tasks])
    return pd.concat([table[["engine"]], cols, table.drop(columns=["engine"])], axis=1)


def _finished(task: dict) -> dict:
    """The result of a run that is already there (no engine started)."""
    s = read_summary(task["run_dir"])
    res = {"status": s["status"], "run_dir": task["run_dir"], "reused": True,
           "engine_time": run_engine_seconds(task["run_dir"], s), "total_time": s.get("wall_time", {}).get("total"),
           "unstable": s.get("unstable"), "dt": s.get("dt"), "dt_fraction": s.get("dt_fraction")}
    if s["status"] == "complete":
        try:
            res["observables"] = observables(load_case(task["case"], overrides=task["overrides"] or None),
                                             task["run_dir"])
        except Exception as exc:
            res["observables_error"] = f"{type(exc).__name__}: {exc}"
    return res


def sweep(case_path, sets: dict[str, list] | list[str], grid: bool = False, engines: list[str] | None = None,
          runs_root="runs", scheduler=None, workers: int | None = None, executor=None, on_result=None,
          force: bool = False) -> "pd.DataFrame":
    """Run (or reuse) every point on every engine; returns one row per run. ``scheduler``: a Dask
    address, Client or cluster (else local processes, ``workers`` of them, default one per core).
    ``force`` re-runs even finished runs."""
    if isinstance(sets, list):
        sets = parse_sets(sets)
    case0 = load_case(case_path)
    refuse_unknown_fields(case0, case_path, list(sets))
    pts = points(sets, grid)
    sid = hashlib.sha256(json.dumps([str(case_path), sets, grid, engines], sort_keys=True, default=str)
                         .encode()).hexdigest()[:10]
    name = case0.name
    out_dir = Path(runs_root) / name
    out_dir.mkdir(parents=True, exist_ok=True)
    out_json = out_dir / f"sweep-{sid}.json"
    tasks: list[dict] = []
    results: list[dict | None] = []
    t0 = time.perf_counter()

    def record(k, res):
        results[k] = res
        if on_result:
            on_result(tasks[k], res)
        _write(out_json, tasks, results, sets, grid, time.perf_counter() - t0)

    todo: list[int] = []

    def to_run():
        """Plans point after point and hands the runs to do to the executor as they are found, so
        that the first runs start (and the workers warm up) while the rest is being planned."""
        for pt in pts:
            for t in plan_point(case_path, pt, engines, runs_root):
                k = len(tasks)
                tasks.append(t)
                results.append(None)
                if t.get("invalid"):
                    record(k, {"status": "failed", "error": t["invalid"]})
                elif t["done"] and not force:
                    record(k, _finished(t))
                else:
                    todo.append(k)
                    # one run at a time on this machine: its progress lines show, under its name
                    yield dict(t, force=force) | ({"progress": run_label(t)} if sequential else {})

    ex = executor or get_executor(scheduler, workers)
    sequential = executor is None and scheduler is None and ex.workers == 1
    try:
        for j, res in ex.run(run_task, to_run()):
            record(todo[j], res)
    finally:
        if executor is None:
            ex.close()
    _write(out_json, tasks, results, sets, grid, time.perf_counter() - t0)
    return table(tasks, results)


def table(tasks, results) -> "pd.DataFrame":
    import pandas as pd
    rows = []
    for t, r in zip(tasks, results):
        r = r or {"status": "missing"}
        row = {**t["point"], "engine": t["engine"], "run_id": t["run_id"], "status": r.get("status"),
               "reused": r.get("reused", False), "engine_time_s": r.get("engine_time"),
               "error": r.get("error") or (r.get("unstable") or {}).get("figure")}
        for k, v in (r.get("observables") or {}).items():
            if not isinstance(v, list):
                row[k] = v
        rows.append(row)
    return pd.DataFrame(rows)


def _write(path: Path, tasks, results, sets, grid, elapsed):
    data = {"sets": sets, "grid": grid, "elapsed_s": elapsed,
            "runs": [{**{k: v for k, v in t.items() if k != "done"}, "result": r} for t, r in zip(tasks, results)]}
    write_json(path, json.loads(json.dumps(data, default=str)))
    write_text(path.with_suffix(".csv"), table(tasks, results).to_csv(index=False))
