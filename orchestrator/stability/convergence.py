"""Error against run time: ``orchestrator convergence CASE --knob KNOB --values ...``.

A ladder of runs over one knob (through the sweep machinery, so finished runs are reused and
the ladder can run on a Dask cluster). The reference is the finest run (the last value given,
for every knob here ordered from cheap to expensive) unless ``reference`` names a value. For each
run: the engine wall time and the relative error of every key observable of the case
(:mod:`.observables`: μ_macro, shear-band position and width, density profile, solid fraction …;
profiles by their relative L2 norm). The error of a run is the largest of its observables'
errors. Output: a table, a log-log plot of error against wall time with the Pareto front (runs
no other run beats in both), and the cheapest setting whose error is below ``target_error``.

Knobs (``--knob``): ``dt_fraction`` (timestep.fraction), ``stiffness_scale`` (Young's modulus ×,
walls too when they are a material), ``rate_scale`` (the scene's inertial/quasi-static numbers ×),
``particle_scale`` (PSD diameters ×, keeping the count), ``count`` (the scene's grain count:
``scene.n_particles``, the triaxial's ``scene.grains``), ``size_scale`` (the system's size ×
at the same grains, as the scene defines it: the shear cell's diameter, the triaxial sample's
diameter and height, the plane-shear box side; :meth:`orchestrator.scenes.base.Scene.size_overrides`),
or any dotted case field (``scene.width``).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..case import CaseError, load_case
from ..registry import get_scene
from ..runner import run_dir_for
from .executor import get_executor, run_task
from .extrapolation import extrapolate, fidelity_distance
from .observables import SPREAD_SUFFIXES
from .sweep import _finished, finished, nested, plan_table, refuse_unknown_fields, run_label
from ..analysis._common import save_figure

KNOBS = ("dt_fraction", "stiffness_scale", "rate_scale", "particle_scale", "count", "size_scale")
_RATE_FIELDS = ("inertial_number", "compression_inertial_number", "quasi_static_number")


def checked_value(case_path, knob: str, value):
    """``value`` as the knob ``knob`` takes it: a finite number for the knobs of :data:`KNOBS`, a
    whole one (an int) for ``count``; anything for a dotted field (the case's validation decides).
    A :class:`CaseError` naming the case, the knob and the value otherwise: ``--values 1.5`` of
    ``count`` was read as 1 grain."""
    if knob not in KNOBS:
        return value
    try:
        if isinstance(value, bool):
            raise ValueError
        x = float(value)
        if not math.isfinite(x) or (knob == "count" and not x.is_integer()):
            raise ValueError
    except (TypeError, ValueError):
        say = ("is not a whole number of grains; give whole numbers, e.g. --values 100 200 400" if knob == "count"
               else "is not a number; give finite numbers, e.g. --values 0.5 1 2")
        shown = str(value).lower() if isinstance(value, bool) else repr(value)      # as written: true, not True
        raise CaseError(case_path, [f"--knob {knob} --values: {shown} {say}"]) from None
    return int(x) if knob == "count" else x


def knob_overrides(case_path, knob: str, value) -> dict:
    """The nested overrides that set ``knob`` to ``value`` on the case at ``case_path``."""
    value = checked_value(case_path, knob, value)
    if knob == "dt_fraction":
        return {"timestep": {"fraction": float(value)}}
    base = load_case(case_path)
    if knob == "stiffness_scale":
        out = {"material": {"youngs_modulus": f"{base.material.youngs_modulus * float(value)!r} Pa"}}
        if hasattr(base.wall, "youngs_modulus"):
            out["wall"] = {"youngs_modulus": f"{base.wall.youngs_modulus * float(value)!r} Pa"}
        return out
    if knob == "rate_scale":
        sc = {f: getattr(base.scene, f) * float(value) for f in _RATE_FIELDS if hasattr(base.scene, f)}
        return {"scene": sc}
    if knob == "particle_scale":
        p = base.scene.psd
        return {"scene": {"psd": {k: f"{getattr(p, k) * float(value)!r} m" for k in ("median", "d_min", "d_max")}}}
    if knob == "size_scale":
        sized = get_scene(base.scene.kind).size_overrides(base.scene, float(value))
        if sized is None:
            raise CaseError(case_path, [f"--knob size_scale: the {base.scene.kind} scene has no size_scale knob; "
                                        "ladder one of its size fields instead (--knob scene.FIELD)"])
        return {"scene": sized}
    if knob == "count":
        field = get_scene(base.scene.kind).count_field
        if field is None:
            raise CaseError(case_path, [f"--knob count: the {base.scene.kind} scene has no grain count"])
        return {"scene": {field: int(value)}}
    return nested({knob: value})


def relative_error(value, ref) -> float:
    if isinstance(ref, list) or isinstance(value, list):
        a, b = np.asarray(value, float), np.asarray(ref, float)
        if a.shape != b.shape:
            return float("nan")
        n = np.linalg.norm(b)
        return float(np.linalg.norm(a - b) / n) if n > 0 else float("nan")
    if value is None or ref is None:
        return float("nan")
    if not np.isfinite(ref) or ref == 0:
        return abs(value - ref) if np.isfinite(ref) else float("nan")
    return abs(value - ref) / abs(ref)


def pareto(times, errors) -> list[int]:
    """Indices of the runs no other run beats in both wall time and error (sorted by time)."""
    idx = [k for k in np.argsort(times) if np.isfinite(errors[k]) and np.isfinite(times[k])]
    front, best = [], math.inf
    for k in idx:
        if errors[k] < best:
            front.append(int(k))
            best = errors[k]
    return front


def ladder_tasks(case_path, knob: str, values: list, engine: str, runs_root="runs",
                 seeds: list[int] | None = None) -> list[dict]:
    """The runs of a ladder on one ``engine``, rung by rung and seed by seed: each a task of
    :func:`.executor.run_task` (case, overrides, engine, runs root, its point and run directory),
    or, for a rung whose case the loader refuses (e.g. a dt the pre-run check calls unsafe), a
    task with the reason under ``refused`` and no run directory: a row, not a crash."""
    tasks = []
    for v, seed in [(v, sd) for v in values for sd in (seeds or [None])]:
        ov = knob_overrides(case_path, knob, v)
        if seed is not None:
            ov = dict(ov, seed=int(seed))
        try:
            c = load_case(case_path, overrides=ov)
        except CaseError as exc:
            tasks.append({"case": str(case_path), "overrides": ov, "engine": engine, "point": {knob: v},
                          "run_dir": None, "run_id": None, "refused": str(exc), "seed": seed})
            continue
        rd = run_dir_for(c, engine, runs_root)
        tasks.append({"case": str(case_path), "overrides": ov, "engine": engine, "runs_root": str(runs_root),
                      "point": {knob: v}, "run_dir": str(rd), "run_id": rd.name, "seed": seed})
    return tasks


def _number(v) -> float | None:
    try:
        return None if isinstance(v, bool) else float(v)
    except (TypeError, ValueError):
        return None


def reference_value(values: list, reference=None):
    """The rung of ``values`` that is the reference: the last, or the one ``reference`` names (as
    written, or the same number: ``--reference 0.50`` is the rung 0.5); a ValueError naming
    ``--reference`` and the values when it is none of them."""
    if not values:
        raise ValueError("--values: no values; give the ladder's values, cheapest first, e.g. --values 0.4 0.2 0.1")
    if reference is None:
        return values[-1]
    for v in values:
        if str(v) == str(reference):
            return v
    r = _number(reference)
    for v in values:
        if r is not None and _number(v) == r:
            return v
    raise ValueError(f"--reference {reference}: not one of the ladder's --values ({' '.join(map(str, values))}); "
                     f"give one of them, or leave --reference out for the last ({values[-1]})")


#: knobs whose ideal limit is at 0 (h = value) and those whose ideal limit is infinity (h = value^-p)
_LIMIT_AT_ZERO = ("dt_fraction", "rate_scale")
_LIMIT_AT_INFINITY = ("stiffness_scale", "count", "size_scale")


def check_ladder(case_path, knob: str, values: list, reference=None, full=None, target_error: float = 0.05):
    """Check a ladder's inputs before anything is planned or run: every value (:func:`checked_value`),
    ``reference`` among them (:func:`reference_value`), ``full`` a value the extrapolation can reach
    and ``target_error`` a positive number. Returns the reference rung's value."""
    for v in values:
        checked_value(case_path, knob, v)
    ref = reference_value(values, reference)
    if full is not None:
        f = _number(full)
        if f is None or not math.isfinite(f) or (knob in _LIMIT_AT_INFINITY and f <= 0) or \
                (knob in _LIMIT_AT_ZERO and f < 0):
            least = " above 0" if knob in _LIMIT_AT_INFINITY else " of at least 0" if knob in _LIMIT_AT_ZERO else ""
            raise ValueError(f"--full {full}: the knob {knob}'s full-fidelity value must be a finite number{least}; "
                             f"give the {knob} of the setting to extrapolate to, or leave --full out for the ideal "
                             f"limit")
    t = _number(target_error)
    if t is None or not math.isfinite(t) or t <= 0:
        raise ValueError(f"--target-error {target_error}: the relative error to stay within must be a number above 0, "
                         f"e.g. --target-error 0.05 (5 %)")
    return ref


def ladder_plan(case_path, knob: str, values: list, engines: list[str] | None = None, runs_root="runs",
                seeds: list[int] | None = None, reference=None, full=None, target_error: float = 0.05):
    """What a ladder would run, before any run (``orchestrator convergence ... --dry-run``): the
    table of :func:`.sweep.plan_table`, a row per engine, rung (column ``knob``) and seed. The
    inputs a real ladder would refuse (:func:`check_ladder`) are refused here too."""
    import pandas as pd
    case0 = load_case(case_path)
    refuse_unknown_fields(case0, case_path, [knob], also=KNOBS, flag="--knob")
    check_ladder(case_path, knob, values, reference, full, target_error)
    tasks = [t for eng in engines or case0.engines for t in ladder_tasks(case_path, knob, values, eng, runs_root, seeds)]
    table = plan_table(tasks)
    cols = pd.DataFrame({knob: [t["point"][knob] for t in tasks], "seed": [t["seed"] for t in tasks]})
    return pd.concat([table[["engine"]], cols, table.drop(columns=["engine"])], axis=1)


def ladder(case_path, knob: str, values: list, engines: list[str] | None = None, runs_root="runs",
           reference=None, target_error: float = 0.05, scheduler=None, workers: int | None = 1,
           observables_used: list[str] | None = None, plot: str | Path | None = None, full=None,
           seeds: list[int] | None = None, on_result=None) -> dict:
    """Run the ladder and compare; returns {"table": DataFrame, "recommendation": {...},
    "extrapolation": DataFrame, "plot": path}. ``full``: the knob's full-fidelity value for the
    extrapolation (:mod:`.extrapolation`; None: the ideal limit). ``seeds``: run every rung on each
    of these packings (the case's ``seed``), so that each rung's mean carries its run-to-run
    standard error into the extrapolation; each run is compared with the reference rung's run of
    the same seed. ``on_result(task, result)`` is called for each run as it ends or is found complete (as in
    :func:`.sweep.sweep`).
    """
    import pandas as pd
    case0 = load_case(case_path)
    refuse_unknown_fields(case0, case_path, [knob], also=KNOBS, flag="--knob")
    ref_v = check_ladder(case_path, knob, values, reference, full, target_error)    # before any executor starts
    scene = get_scene(case0.scene.kind)
    engines = engines or case0.engines
    rows = []
    ex = get_executor(scheduler, workers)
    try:
        for eng in engines:
            tasks = ladder_tasks(case_path, knob, values, eng, runs_root, seeds)
            results = [None] * len(tasks)
            todo = []
            for k, t in enumerate(tasks):
                if t.get("refused"):
                    results[k] = {"status": "refused", "error": t["refused"]}
                    if on_result:                    # said as the other rungs are, with the reason
                        on_result(t, results[k])
                    continue
                if finished(t["run_dir"]):
                    results[k] = _finished(t)
                    if on_result:
                        on_result(t, results[k])
                else:
                    todo.append(k)
            # one rung at a time on this machine: each shows its progress lines, named by its rung
            sequential = ex.workers == 1 and scheduler is None
            for j, res in ex.run(run_task, [{kk: vv for kk, vv in tasks[k].items() if kk != "seed"}
                                            | ({"progress": run_label(tasks[k])} if sequential else {}) for k in todo]):
                results[todo[j]] = res
                if on_result:
                    on_result(tasks[todo[j]], res)
            # the reference rung's run of each seed (the ladder's one run without seeds)
            ref_of = {t["seed"]: k for k, t in enumerate(tasks) if str(t["point"][knob]) == str(ref_v)}
            ref_obs_of = {sd: (results[k] or {}).get("observables") or {} for sd, k in ref_of.items()}
            keys = sorted({k for o in ref_obs_of.values() for k in o if not k.endswith(SPREAD_SUFFIXES + ("_error",))
                           and (observables_used is None or k in observables_used)})
            for k, (t, r) in enumerate(zip(tasks, results)):
                obs = r.get("observables") or {}
                ref_obs = ref_obs_of.get(t["seed"], {})
                problems = scene.sample_problems(Path(t["run_dir"])) if r.get("status") == "complete" else []
                row = {"engine": eng, knob: t["point"][knob], "seed": t["seed"], "status": r.get("status"),
                       "sample": "; ".join(problems) or ("ok" if r.get("status") == "complete" else
                                                         (r.get("error") or "") if r.get("status") == "refused" else ""),
                       "engine_time_s": r.get("engine_time"), "total_time_s": r.get("total_time"),
                       "reference": k == ref_of.get(t["seed"]), "run_id": t["run_id"]}
                errs = []
                for key in keys:
                    v = obs.get(key)
                    if not isinstance(v, list):
                        row[key] = v
                        row[f"{key}_sem"] = obs.get(f"{key}_sem")
                    e = relative_error(v, ref_obs.get(key)) if v is not None else float("nan")
                    row[f"err_{key}"] = e
                    if np.isfinite(e):
                        errs.append(e)
                row["error"] = max(errs) if errs and r.get("status") == "complete" else float("nan")
                rows.append(row)
    finally:
        ex.close()
    df = pd.DataFrame(rows)
    rec = recommend(df, knob, target_error)
    ext = extrapolations(df, knob, full=full, tolerance=target_error)
    for eng, r in rec.items():
        r["full_fidelity"] = full_fidelity_setting(ext[ext["engine"] == eng], knob)
    out = {"table": df, "recommendation": rec, "extrapolation": ext}
    if plot:
        out["plot"] = plot_ladder(df, knob, plot, target_error, ext=ext)
    return out


def extrapolations(df, knob: str, full=None, tolerance: float = 0.05):
    """Per engine and scalar observable: the ladder extrapolated to ``full`` and the cheapest
    setting predicted within ``tolerance`` of it (:func:`.extrapolation.extrapolate`), from the
    complete rungs."""
    import pandas as pd
    rows = []
    skip = {"engine", knob, "seed", "status", "sample", "engine_time_s", "total_time_s", "reference", "run_id", "error"}
    for eng, g in df.groupby("engine"):
        g = usable(g)
        for key in [c for c in g.columns if c not in skip and not c.startswith("err_") and not c.endswith("_sem")]:
            vals, y, sem, times = rung_means(g, knob, key)
            r = extrapolate(knob, vals, y, y_sem=sem, full=full, tolerance=tolerance, times=times)
            if r["rungs"] >= 2:
                rows.append({"engine": eng, "observable": key, **r})
    return pd.DataFrame(rows, columns=["engine", "observable", "rungs", "h_full", "value_full", "sem_full", "slope",
                                       "cheapest", "cheapest_time_s", "where", "note"])


def usable(g):
    """The complete runs whose sample is the case's (column ``sample`` "ok", or absent): what the
    extrapolation and the recommendation rest on. A run whose scene reports a problem with its
    sample (:meth:`orchestrator.scenes.base.Scene.sample_problems`, e.g. a triaxial whose stage 1
    ended unconverged) stays in the table, marked."""
    g = g[g["status"] == "complete"]
    return g[g["sample"] == "ok"] if "sample" in g else g


def rung_means(g, knob: str, key: str):
    """(values, mean, standard error, mean engine time) of observable ``key`` per rung of one
    engine's complete runs: over the rung's seeds where it has several (sem = std/√n), else the
    run's own ``KEY_sem`` where it reports one."""
    import pandas as pd
    vals, ys, sems, ts = [], [], [], []
    for v, r in g.groupby(knob, sort=False):
        y = pd.to_numeric(r[key], errors="coerce").to_numpy(float)
        y = y[np.isfinite(y)]
        if not y.size:
            continue
        vals.append(float(v))
        ys.append(float(y.mean()))
        if y.size > 1:
            sems.append(float(y.std(ddof=1) / math.sqrt(y.size)))
        else:
            own = pd.to_numeric(r.get(f"{key}_sem", pd.Series([np.nan])), errors="coerce").to_numpy(float)
            sems.append(float(own[0]) if own.size else float("nan"))
        ts.append(float(pd.to_numeric(r["engine_time_s"], errors="coerce").mean()))
    return np.array(vals), np.array(ys), np.array(sems), np.array(ts)


def full_fidelity_setting(ext, knob: str) -> dict:
    """The cheapest setting predicted within tolerance for *every* observable of one engine's
    extrapolation table: the most demanding observable's (smallest fidelity distance h)."""
    ok = ext[np.isfinite(ext["cheapest"].to_numpy(float))] if len(ext) else ext
    if not len(ok):
        return {"value": None, "observable": None, "note": "no observable could be extrapolated"}
    h = fidelity_distance(knob, ok["cheapest"].to_numpy(float))
    k = int(np.argmin(h))
    row = ok.iloc[k]
    return {"value": _py(row["cheapest"]), "observable": row["observable"],
            "engine_time_s": _py(row["cheapest_time_s"]), "where": row["where"]}


def _py(v):
    return v.item() if hasattr(v, "item") else v


def recommend(df, knob: str, target_error: float) -> dict:
    """Per engine: the cheapest (engine time) non-reference run with error ≤ target (else the
    reference) and its Pareto front."""
    import pandas as pd
    out = {}
    for eng, g in df.groupby("engine"):
        g = g.reset_index(drop=True)
        t = pd.to_numeric(g["engine_time_s"], errors="coerce").to_numpy(float)
        e = pd.to_numeric(g["error"], errors="coerce").to_numpy(float)
        e_plot = np.where(g["reference"], 0.0, e)
        front = pareto(t, e_plot)
        ok = usable(g[~g["reference"]])
        ok = ok[ok["error"] <= target_error]
        if len(ok):
            best = ok.loc[ok["engine_time_s"].astype(float).idxmin()]
            out[eng] = {knob: _py(best[knob]), "error": float(best["error"]), "engine_time_s": float(best["engine_time_s"]),
                        "speed_up_vs_reference": float(g.loc[g["reference"], "engine_time_s"].iloc[0] / best["engine_time_s"]),
                        "pareto": [_py(g.loc[k, knob]) for k in front]}
        else:
            ref = g[g["reference"]].iloc[0]
            if ref["status"] != "complete":
                out[eng] = {knob: None, "error": float("nan"), "engine_time_s": float("nan"),
                            "note": f"the reference did not complete ({ref['status']})", "pareto": []}
                continue
            out[eng] = {knob: _py(ref[knob]), "error": 0.0, "engine_time_s": float(ref["engine_time_s"]),
                        "note": f"no cheaper setting within {target_error:g}: keep the reference",
                        "pareto": [_py(g.loc[k, knob]) for k in front]}
    return out


def plot_ladder(df, knob: str, path, target_error: float, ext=None):
    """Left: error against engine time with the Pareto front. Right (with an extrapolation table):
    every scalar observable over its extrapolated full-fidelity value against the fidelity distance
    h, the fitted lines, the full-fidelity point with its 68 % interval and the ± target band."""
    import pandas as pd
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    with_ext = ext is not None and len(ext) > 0
    fig, axes = plt.subplots(1, 2 if with_ext else 1, figsize=(11.5 if with_ext else 6, 4.5))
    ax = axes[0] if with_ext else axes
    for eng, g in df.groupby("engine"):
        ref = g[g["reference"]]
        t_ref = pd.to_numeric(ref["engine_time_s"], errors="coerce").to_numpy(float)
        if len(t_ref) and np.isfinite(t_ref[0]):     # error 0 by definition: its cost as a line
            ax.axvline(t_ref[0], ls=":", color="grey",
                       label=f"{eng} reference ({knob} {ref[knob].iloc[0]}): {t_ref[0]:.3g} s")
        g = g[~g["reference"]]
        if not len(g):
            continue
        t = pd.to_numeric(g["engine_time_s"], errors="coerce").to_numpy(float)
        e = pd.to_numeric(g["error"], errors="coerce").to_numpy(float)
        good = g.index.isin(usable(g).index)
        bad = np.isfinite(e) & (e > 0) & ~good
        if bad.any():        # runs whose sample is not the case's: shown, out of the front
            ax.loglog(t[bad], e[bad], "x", color="grey", label=f"{eng}: sample not the case's (left out)")
        e = np.where(good, e, np.nan)
        ok = np.isfinite(e) & (e > 0)
        ax.loglog(t[ok], e[ok], "o", label=eng)
        for tt, ee, v in zip(t[ok], e[ok], g[knob].to_numpy()[ok]):
            ax.annotate(f"{v}", (tt, ee), textcoords="offset points", xytext=(4, 4), fontsize=8)
        front = pareto(t, np.where(ok, e, np.nan))
        if front:
            ax.loglog(t[front], e[front], "-", alpha=0.6, label=f"{eng} Pareto front")
    ax.axhline(target_error, ls="--", color="grey", label=f"target {target_error:g}")
    ax.set_xlabel("engine time [s] (one rank: its CPU time)")
    ax.set_ylabel("largest relative error of the key observables [-]")
    ax.set_title(f"error against run time, knob {knob} (reference = finest)")
    ax.legend(fontsize=8)
    if with_ext:
        bx = axes[1]
        for (eng, obs), e in ext.groupby(["engine", "observable"]):
            e = e.iloc[0]
            y_full = e["value_full"]
            g = usable(df[df["engine"] == eng])
            if not np.isfinite(y_full) or y_full == 0 or obs not in g:
                continue
            h = fidelity_distance(knob, g[knob].to_numpy(float))
            y = pd.to_numeric(g[obs], errors="coerce").to_numpy(float) / y_full
            line = bx.plot(h, y, "o", label=f"{eng}: {obs}")[0]
            hh = np.linspace(min(e["h_full"], h.min()), h.max(), 50)
            bx.plot(hh, 1 + e["slope"] * (hh - e["h_full"]) / y_full, "-", color=line.get_color(), alpha=0.6)
            if np.isfinite(e["sem_full"]):
                bx.errorbar([e["h_full"]], [1.0], yerr=[abs(e["sem_full"] / y_full)], fmt="s", color=line.get_color())
        bx.axhspan(1 - target_error, 1 + target_error, color="grey", alpha=0.15, label=f"± {target_error:g}")
        bx.set_xlabel(f"fidelity distance h({knob}) [-] (0: ideal limit)")
        bx.set_ylabel("observable / extrapolated full-fidelity value [-]")
        bx.set_title("extrapolation to full fidelity (square: ±68 % interval)")
        bx.legend(fontsize=7)
    fig.tight_layout()
    return save_figure(fig, path)
