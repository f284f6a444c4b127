"""The cross-validation ladder: one case on every engine, physics term by physics term.

Rungs (each adds one term to the one below; the top rung is the case as written)::

    L0  Hertz–Mindlin + Coulomb, restitution damping (Tsuji; both engines realise it, LIGGGHTS
        fed the inverse of its clipped law, docs/engines.md "Restitution")
    L1  + the case's damping law (seed 000: γ_n = √(4/3 E* m*), realised by its substitute)
    L2  + adhesion
    L3  + rolling friction
    L4  + torsional friction (the full case)

A rung whose term the case does not ask for is the rung below again and is not run twice. Each
rung runs on every engine for several packings (``seeds``), so that each observable has a
run-to-run scatter per engine; an engine difference is *significant* only beyond twice its standard
error. Every engine runs the same packings, so where both engines ran the same two or more seeds the
difference is taken seed by seed (paired: d_s = A_s − B_s, the scatter 2·s_d/√n with s_d the
standard deviation of the d_s), which takes the packing-to-packing spread out of the comparison (on
the small triaxial the packings' ε_v at 15 % differ by up to 0.019 on one engine); otherwise 2·√(s_A²/n_A + s_B²/n_B) (s the seed-to-seed standard
deviation, n the number of seeds). With one seed per engine there is no scatter, and a difference
is judged by its floor alone.
The first rung where a difference exceeds its floor (and, when there is a scatter, the scatter) is
where the engines *part*; the
ladder lists the substitutes that rung brings in and the single-contact difference between them
(:func:`single_contact_differences`, the same derivation as ``tests/test_shear_cell.py``).

Runs go through :mod:`orchestrator.stability.executor` (local processes or a Dask cluster) and are
reused when complete (same run hash), so a ladder can be extended with more seeds later.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from itertools import combinations
from pathlib import Path

import numpy as np
import pandas as pd

from ..case import load_case
from ..derive import derive
from ..registry import engine_names, get_engine
from ..stability.executor import get_executor, run_task
from ..stability.observables import SPREAD_SUFFIXES
from ..atomic import write_text

__all__ = ["Rung", "RUNGS", "rungs_for", "LadderResult", "run_ladder", "compare_rungs", "FLOORS",
           "single_contact_differences", "plot_ladder"]


@dataclass(frozen=True)
class Rung:
    name: str
    adds: str               # the physics term this rung adds ("" for L0)
    description: str


RUNGS = (
    Rung("L0", "", "Hertz–Mindlin + Coulomb, restitution damping realised by every engine"),
    Rung("L1", "damping", "+ the case's damping law"),
    Rung("L2", "adhesion", "+ adhesion"),
    Rung("L3", "rolling", "+ rolling friction"),
    Rung("L4", "torsion", "+ torsional friction (the full case)"),
)

#: relative floors (|A − B| / mean) per observable: issue #14 (L0: 5 % on μ_macro, band position
#: and piston height, 10 % on band width; the full model: 10 % on μ_macro and band position)
FLOORS = {
    "L0": {"mu_macro": 0.05, "shearband_z": 0.05, "piston_z": 0.05, "shearband_width": 0.10},
    "full": {"mu_macro": 0.10, "shearband_z": 0.10},
    # triaxial (issue #14 item 5): σ1/σ3 within 5 %; ε_v within 0.005 absolute (handled below)
    "triaxial": {"stress_ratio": 0.05},
}
EPS_V_FLOOR = 0.005


def rungs_for(case_path) -> list[tuple[Rung, dict]]:
    """The rungs of the ladder of ``case_path`` with the case overrides that realise each, lowest
    first; rungs that add a term the case does not ask for are left out."""
    case = load_case(case_path)
    c = case.contact
    params = derive(case)
    e_full = ((params.get("scene") or {}).get("contact") or {}).get("restitution", {}).get("target", c.restitution)
    present = {"damping": c.damping != "restitution", "adhesion": c.adhesion is not None,
               "rolling": c.rolling is not None, "torsion": c.torsion is not None}
    # walk down from the full case, dropping terms
    drops = {"L4": {}, "L3": {"torsion": None}, "L2": {"torsion": None, "rolling": None},
             "L1": {"torsion": None, "rolling": None, "adhesion": None}}
    drops["L0"] = dict(drops["L1"], damping="restitution", restitution=float(e_full))
    out = []
    for rung in RUNGS:
        if rung.adds and not present[rung.adds]:
            continue
        ov = {"contact": drops[rung.name]} if drops[rung.name] else {}
        out.append((rung, ov))
    return out


@dataclass
class LadderResult:
    case: str
    runs: pd.DataFrame                 # one row per (rung, engine, seed): status, run_dir, observables
    stats: pd.DataFrame                # per (rung, engine, observable): mean, std, n
    comparison: pd.DataFrame           # per (rung, pair, observable): difference, scatter, significant, floor, ok
    parts_at: str | None               # the first rung where the engines part (None: they never do)
    explanation: pd.DataFrame          # substitutes at that rung and the single-contact difference
    files: dict = field(default_factory=dict)

    def _repr_html_(self):
        return (f"<b>ladder {self.case}</b>: engines part at {self.parts_at or 'no rung'}"
                + self.comparison.to_html(index=False, float_format=lambda x: f"{x:.4g}"))


def _flatten(obs: dict) -> dict:
    """Scalar observables; vectors become named entries (``density_profile`` stays a list)."""
    out = {}
    for k, v in (obs or {}).items():
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            out[k] = float(v)
        elif k == "density_profile":
            out[k] = list(v)
        elif isinstance(v, dict):
            for kk, vv in v.items():
                if isinstance(vv, (int, float)):
                    out[f"{k}@{kk}"] = float(vv)
    return out


def ladder_tasks(case_path, engines=None, seeds=(1, 2, 3), runs_root="runs", rungs=None) -> list[dict]:
    """The ladder's runs: one task per rung (or those named in ``rungs``), seed and engine (default
    the case's), as :func:`orchestrator.stability.executor.run_task` takes them, with ``rung`` and
    ``seed`` beside."""
    engines = list(engines or load_case(case_path).engines)
    return [{"case": str(case_path), "overrides": dict(ov, seed=int(seed)), "engine": eng, "runs_root": str(runs_root),
             "analyze": False, "rung": rung.name, "seed": int(seed)}
            for rung, ov in rungs_for(case_path) if rungs is None or rung.name in rungs
            for seed in seeds for eng in engines]


def ladder_plan(case_path, engines=None, seeds=(1, 2, 3), runs_root="runs", rungs=None) -> pd.DataFrame:
    """What the ladder would run, before any run (``orchestrator crossval CASE --ladder --dry-run``):
    the table of :func:`orchestrator.stability.sweep.plan_table` with the columns ``rung`` and
    ``seed``: each run reused or to run, its size and estimate (no packing, mesh or run directory)."""
    from ..stability.sweep import plan_point, plan_table
    tasks = [task for t in ladder_tasks(case_path, engines, seeds, runs_root, rungs)
             for task in plan_point(case_path, {"rung": t["rung"], "seed": t["seed"]}, [t["engine"]], runs_root,
                                    overrides=t["overrides"])]
    table = plan_table(tasks)
    cols = pd.DataFrame([t["point"] for t in tasks])
    return pd.concat([table[["engine"]], cols, table.drop(columns=["engine"])], axis=1)


def run_ladder(case_path, engines=None, seeds=(1, 2, 3), runs_root="runs", scheduler=None, workers=None,
               out_dir=None, progress=None, rungs=None) -> LadderResult:
    """Run every rung of ``case_path`` (or only those named in ``rungs``) on every engine for every
    seed (reusing complete runs), then compare (:func:`compare_rungs`) and write ``ladder.csv``,
    ``ladder_runs.csv`` and ``ladder.png`` into ``out_dir`` (default ``runs/<case>/ladder``)."""
    case = load_case(case_path)
    tasks = ladder_tasks(case_path, engines, seeds, runs_root, rungs)
    rows = [None] * len(tasks)
    ex = get_executor(scheduler, workers)
    try:
        for k, res in ex.run(run_task, [{kk: vv for kk, vv in t.items() if kk not in ("rung", "seed")} for t in tasks]):
            t = tasks[k]
            rows[k] = {"rung": t["rung"], "engine": t["engine"], "seed": t["seed"], "status": res.get("status"),
                       "run_dir": res.get("run_dir"), "engine_time": res.get("engine_time"),
                       "error": res.get("error") or res.get("observables_error"),
                       **_flatten(res.get("observables"))}
            if progress:
                progress(rows[k])
    finally:
        ex.close()
    out_dir = Path(out_dir) if out_dir else Path(runs_root) / case.name / "ladder"
    runs = merge_earlier_runs(pd.DataFrame(rows), out_dir / "ladder_runs.csv")
    order = [r.name for r in RUNGS if r.name in set(runs["rung"])]
    res = compare_rungs(runs, order)
    res.case = case.name
    res.explanation = explain(case_path, res.parts_at, runs)
    res.files = write_ladder(res, out_dir)
    return res


def merge_earlier_runs(runs: pd.DataFrame, earlier_csv: Path) -> pd.DataFrame:
    """This invocation's runs plus the rows of an earlier ``ladder_runs.csv`` of the same ladder for
    (rung, engine, seed) not run now and whose run directory still exists: a ladder run one rung or
    one engine at a time accumulates into one table instead of replacing it."""
    earlier_csv = Path(earlier_csv)
    if not earlier_csv.exists():
        return runs
    old = pd.read_csv(earlier_csv)
    if "density_profile" in old.columns:
        old["density_profile"] = [json.loads(v) if isinstance(v, str) else v for v in old["density_profile"]]
    done = set(zip(runs["rung"], runs["engine"], runs["seed"].astype(int)))
    keep = [i for i, r in old.iterrows()
            if (r["rung"], r["engine"], int(r["seed"])) not in done
            and isinstance(r["run_dir"], str) and Path(r["run_dir"]).is_dir()]
    if not keep:
        return runs
    return pd.concat([old.loc[keep], runs], ignore_index=True)


def _stats(runs: pd.DataFrame) -> pd.DataFrame:
    ok = runs[runs["status"] == "complete"]
    rows = []
    for (rung, eng), g in ok.groupby(["rung", "engine"], sort=False):
        for col in g.columns:
            if col in ("rung", "engine", "seed", "status", "run_dir", "engine_time", "error") \
                    or col.endswith(SPREAD_SUFFIXES):          # a run's own spread, not an observable
                continue
            vals = g[col].dropna()
            if not len(vals):
                continue
            if col == "density_profile":
                prof = np.array([np.asarray(v, float) for v in vals])
                rows.append({"rung": rung, "engine": eng, "observable": col, "mean": prof.mean(0).tolist(),
                             "std": float(np.mean([np.linalg.norm(a - b) for a, b in combinations(prof, 2)]))
                             if len(prof) > 1 else float("nan"), "n": len(prof)})
                continue
            v = vals.to_numpy(float)
            rows.append({"rung": rung, "engine": eng, "observable": col, "mean": float(v.mean()),
                         "std": float(v.std(ddof=1)) if len(v) > 1 else float("nan"), "n": len(v)})
    return pd.DataFrame(rows, columns=["rung", "engine", "observable", "mean", "std", "n"])


def _paired(runs: pd.DataFrame, rung: str, a: str, b: str, obs: str) -> tuple[float, float, int, float] | None:
    """(mean, standard deviation, n, mean of both engines) of the seed-by-seed differences A_s − B_s
    of ``obs`` at ``rung`` over the seeds both engines ran (two or more; an engine that ran more
    seeds than the other is compared on the shared ones only); None otherwise."""
    if "seed" not in runs or obs not in runs:
        return None
    ok = runs[(runs["status"] == "complete") & (runs["rung"] == rung)]
    va = ok[ok["engine"] == a].dropna(subset=[obs]).groupby("seed")[obs].mean()
    vb = ok[ok["engine"] == b].dropna(subset=[obs]).groupby("seed")[obs].mean()
    shared = sorted(set(va.index) & set(vb.index))
    if len(shared) < 2:
        return None
    va, vb = va.loc[shared], vb.loc[shared]
    d = (va - vb).to_numpy(float)
    return float(d.mean()), float(d.std(ddof=1)), len(d), float(0.5 * (abs(va.mean()) + abs(vb.mean())))


def _floor(rung: str, top: str, obs: str) -> float | None:
    if obs.startswith("stress_ratio"):
        return FLOORS["triaxial"]["stress_ratio"]
    if rung == "L0" and obs in FLOORS["L0"]:
        return FLOORS["L0"][obs]
    if rung == top and obs in FLOORS["full"]:
        return FLOORS["full"][obs]
    return None


def compare_rungs(runs: pd.DataFrame, rung_order: list[str]) -> LadderResult:
    """Engine-vs-engine differences per rung and observable, with their significance against the
    seed-to-seed scatter and the floors of :data:`FLOORS`."""
    stats = _stats(runs)
    top = rung_order[-1] if rung_order else "L4"
    rows = []
    for rung in rung_order:
        st = stats[stats["rung"] == rung]
        engines = list(dict.fromkeys(st["engine"]))
        for a, b in combinations(engines, 2):
            for obs in dict.fromkeys(st["observable"]):
                ra = st[(st.engine == a) & (st.observable == obs)]
                rb = st[(st.engine == b) & (st.observable == obs)]
                if not len(ra) or not len(rb):
                    continue
                ra, rb = ra.iloc[0], rb.iloc[0]
                if obs == "density_profile":
                    pa, pb = np.asarray(ra["mean"]), np.asarray(rb["mean"])
                    diff = float(np.linalg.norm(pa - pb) / max(np.linalg.norm(0.5 * (pa + pb)), 1e-300))
                    stds = [v for v in (ra["std"], rb["std"]) if np.isfinite(v)]
                    scatter = float(max(stds) / max(np.linalg.norm(0.5 * (pa + pb)), 1e-300)) if stds else float("nan")
                    absdiff = diff
                    pairing = "profiles" if stds else "one seed"
                else:
                    ma, mb = float(ra["mean"]), float(rb["mean"])
                    absdiff = abs(ma - mb)
                    scale = 0.5 * (abs(ma) + abs(mb))
                    diff = absdiff / scale if scale > 0 else float("nan")
                    paired = _paired(runs, rung, a, b, obs)
                    if paired is not None:            # the same packings on both engines: seed by seed
                        dmean, sd, n, scale = paired
                        absdiff = abs(dmean)
                        diff = absdiff / scale if scale > 0 else float("nan")
                        scatter = float(2 * sd / math.sqrt(n) / scale) if scale > 0 else float("nan")
                        pairing = f"paired, {n} seeds"
                    else:
                        sem2 = (ra["std"] ** 2 / ra["n"] if np.isfinite(ra["std"]) else np.nan) + \
                               (rb["std"] ** 2 / rb["n"] if np.isfinite(rb["std"]) else np.nan)
                        scatter = float(2 * math.sqrt(sem2) / scale) if np.isfinite(sem2) and scale > 0 else float("nan")
                        pairing = "unpaired" if np.isfinite(scatter) else "one seed"
                # significant: beyond the seed-to-seed scatter; None when there is no scatter to weigh
                # the difference against (one seed per engine)
                if not np.isfinite(diff):
                    significant = False
                elif not np.isfinite(scatter):
                    significant = None
                else:
                    significant = bool(diff > scatter)
                floor = _floor(rung, top, obs)
                if obs.startswith("volumetric_strain"):
                    floor_ok = absdiff <= EPS_V_FLOOR
                    floor = EPS_V_FLOOR
                else:
                    floor_ok = None if floor is None else bool(diff <= floor)
                # a difference within the scatter is not a disagreement, whatever its size; without a
                # scatter (one seed) the floor alone decides
                ok = None if floor_ok is None else bool(floor_ok or significant is False)
                rows.append({"rung": rung, "engines": f"{a} vs {b}", "observable": obs,
                             "mean A": ra["mean"] if obs != "density_profile" else np.nan,
                             "mean B": rb["mean"] if obs != "density_profile" else np.nan,
                             "relative difference": diff, "scatter (2 sem, relative)": scatter,
                             "significant": significant, "floor": floor, "ok": ok, "scatter from": pairing})
    # the columns even without a pair (one engine: its runs and statistics, nothing to compare yet)
    comp = pd.DataFrame(rows, columns=["rung", "engines", "observable", "mean A", "mean B", "relative difference",
                                       "scatter (2 sem, relative)", "significant", "floor", "ok", "scatter from"])
    parts = None
    for rung in rung_order:
        sel = comp[(comp["rung"] == rung)] if len(comp) else comp
        if len(sel) and (sel["ok"] == False).any():       # noqa: E712 (None: no floor for that observable)
            parts = rung
            break
    return LadderResult("", runs, stats, comp, parts, pd.DataFrame())


def single_contact_differences(case_path) -> pd.DataFrame:
    """Single-contact differences between the engines' substitutes and the seed's law for one
    median pair (r_eff = x50/4) at 0.1, 1 and 10 times the overlap expected under the case's load
    (the numbers the decks use, from :func:`orchestrator.derive.derive`). Rows: term, engine,
    mechanism, ratio to the seed's value at each overlap."""
    case = load_case(case_path)
    params = derive(case)
    c = (params.get("scene") or {}).get("contact") or {}
    psd = getattr(case.scene, "psd", None)
    if not c or psd is None or "expected_overlap" not in c:
        return pd.DataFrame(columns=["term", "engine", "mechanism", "ξ/ξ_σ = 0.1", "ξ/ξ_σ = 1", "ξ/ξ_σ = 10"])
    scales = np.array([0.1, 1.0, 10.0])
    xs = c["expected_overlap"] * scales
    rows = []
    for name in engine_names():       # each engine package states how it realises the seed's terms
        for term, mechanism, ratios in get_engine(name).seed_term_ratios(case, params, xs):
            rows.append((term, name, mechanism, *ratios))
    order = {"adhesion": 0, "rolling limit": 1, "torsion limit": 2}
    rows.sort(key=lambda r: order.get(r[0], 3))          # stable: engines in name order within a term
    return pd.DataFrame(rows, columns=["term", "engine", "mechanism", "ξ/ξ_σ = 0.1", "ξ/ξ_σ = 1", "ξ/ξ_σ = 10"])


def explain(case_path, rung: str | None, runs: pd.DataFrame) -> pd.DataFrame:
    """The substitutes the parting rung brings in (from the runs' summaries) and their
    single-contact difference to the seed's law."""
    if rung is None:
        return pd.DataFrame()
    term = next(r.adds for r in RUNGS if r.name == rung)
    subs = []
    for _, row in runs[(runs["rung"] == rung) & (runs["status"] == "complete")].drop_duplicates("engine").iterrows():
        try:
            s = json.loads((Path(row["run_dir"]) / "summary.json").read_text())
        except (OSError, ValueError, TypeError):
            continue
        for sub in s.get("substitutions") or []:
            subs.append({"term": sub["feature"], "engine": row["engine"], "mechanism": sub["mechanism"],
                         "note": sub.get("note", "")})
    if not term:
        engines = runs[runs["rung"] == rung]["engine"].unique()
        subs += tangential_history_rows(case_path, engines) + tangential_dashpot_rows(case_path, engines)
    sc = single_contact_differences(case_path)
    key = {"adhesion": "adhesion", "rolling": "rolling limit", "torsion": "torsion limit"}.get(term)
    if key is not None and len(sc):
        sc = sc[sc["term"] == key]
    else:
        sc = sc.iloc[0:0]
    return pd.concat([pd.DataFrame(subs), sc], ignore_index=True)


def tangential_history_rows(case_path, engines) -> list[dict]:
    """At L0 no substitute differs, but the Mindlin spring's history may: one row per engine with
    its form (``Engine.tangential_history_of``) when the engines do not share one. The forms part
    where a contact's overlap changes under a tangential load (oblique impact at 5°: tangential
    restitution 0.956 with the displacement, 0.905 with the force; tests/test_tangential_history.py)."""
    case = load_case(case_path)
    forms = {e: get_engine(e).tangential_history_of(case) for e in engines}
    if len(set(forms.values())) < 2:
        return []
    return [{"term": "tangential history", "engine": e, "mechanism": get_engine(e).capabilities.get(
                f"tangential_history_{f}", f),
             "note": f"{f}; the other form on LAMMPS: contact.tangential_history (docs/crossval.md)"}
            for e, f in forms.items()]


def tangential_dashpot_rows(case_path, engines) -> list[dict]:
    """At L0 the engines may also cap a sticking contact differently: with a tangential dashpot,
    LIGGGHTS and YADE test the spring alone against μF_n and add the dashpot on top, LAMMPS caps spring
    + dashpot (``Engine.coulomb_limit_on``). One row per engine when the case has a damped, frictional
    tangential spring and the engines do not share the cap. Oblique impact at e_n = 0.5: tangential
    restitution up to 0.09 apart with the dashpot, within 0.002 without it
    (tests/test_tangential_damping.py); ``contact.tangential_damping: false`` runs the same law on all."""
    c = load_case(case_path).contact
    if c.tangential_damping is False or c.friction == 0 or (c.damping == "restitution" and c.restitution >= 1):
        return []
    caps = {e: get_engine(e).coulomb_limit_on for e in engines}
    if len(set(caps.values())) < 2:
        return []
    return [{"term": "tangential dashpot", "engine": e, "mechanism": f"Coulomb limit on the {cap}",
             "note": "contact.tangential_damping: false gives every engine the same law (docs/crossval.md)"}
            for e, cap in caps.items()]


def plot_ladder(res: LadderResult):
    """Relative engine difference per rung and observable, one panel per engine pair (three
    engines: three panels on one y scale), each with its scatter (2 sem) as a band from 0 and as an
    error bar, and the 5 % and 10 % floors."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    comp = res.comparison
    pairs = list(dict.fromkeys(comp["engines"])) if len(comp) else [""]
    fig, axes = plt.subplots(1, len(pairs), figsize=(2.2 + 3.2 * len(pairs), 3.6), sharey=True,
                             constrained_layout=True, squeeze=False)
    rungs = list(dict.fromkeys(comp["rung"])) if len(comp) else []
    x = {r: k for k, r in enumerate(rungs)}
    colors = {}
    for ax, pair in zip(axes[0], pairs):
        sel = comp[comp["engines"] == pair] if len(comp) else comp
        for j, (obs, g) in enumerate(sel.groupby("observable", sort=False)):
            xs = [x[r] + 0.04 * (j - 2) for r in g["rung"]]       # side by side within a rung
            line, = ax.plot(xs, 100 * g["relative difference"], "o-", color=colors.get(obs), label=obs)
            colors.setdefault(obs, line.get_color())
            scatter = 100 * g["scatter (2 sem, relative)"].astype(float).fillna(0)
            ax.fill_between(xs, 0, scatter, alpha=0.08, color=colors[obs])
            # the difference ± its scatter: a bar that reaches 0 is not significant
            ax.errorbar(xs, 100 * g["relative difference"], yerr=scatter, fmt="none", ecolor=colors[obs],
                        alpha=0.6, capsize=3, lw=1)
        ax.set_xticks(range(len(rungs)), rungs)
        if len(rungs) == 1:
            ax.set_xlim(-0.5, 0.5)
        ax.axhline(5, color="grey", lw=0.8, ls="--")
        ax.axhline(10, color="grey", lw=0.8, ls="--")
        if res.parts_at:
            ax.axvline(x[res.parts_at], color="k", ls=":", lw=1)
        ax.set_title(pair, fontsize=9)
    axes[0][0].set_ylabel("|A − B| / mean [%]")
    if axes[0][-1].get_legend_handles_labels()[0]:
        axes[0][-1].legend(fontsize=7)
    fig.suptitle(f"cross-validation ladder: {res.case}"
                 + (f" (engines part at {res.parts_at})" if res.parts_at else ""), fontsize=10)
    return fig


def write_ladder(res: LadderResult, out_dir: Path) -> dict:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    files = {"comparison": write_text(out_dir / "ladder.csv", res.comparison.to_csv(index=False)),
             "runs": write_text(out_dir / "ladder_runs.csv", res.runs.to_csv(index=False)),
             "stats": write_text(out_dir / "ladder_stats.csv", res.stats.to_csv(index=False))}
    if len(res.explanation):
        files["explanation"] = write_text(out_dir / "ladder_explanation.csv", res.explanation.to_csv(index=False))
    fig = plot_ladder(res)
    png = out_dir / "ladder.png"
    fig.savefig(png, dpi=110)
    files["plot"] = png
    return {k: str(v) for k, v in files.items()}
