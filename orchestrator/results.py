"""Key results of a run: the handful of figures a researcher reads first.

Each figure carries its unit, its uncertainty (what the ± means is stated in the row) and, where
the scene reproduces a seed paper, the paper's value or statement beside it. The same rows feed
the terminal table printed at the end of ``orchestrator run`` and the top of ``report.html``.

Sources (all written by the run itself, nothing is recomputed here):

- ``summary.json`` (status, substitutions, engine time);
- ``analysis/analysis_summary.json`` scalars and ``analysis/<label>_<table>.csv`` tables;
- ``*_checks.json`` scene checks (e.g. the shear cell's servo force against its target).

Seed values (``../shared/seeds``):

- seed 000 (vaned micro shear-tester, §4): shear band width ≈ 8 x50,3; the band sits just above
  the lower vanes, in the dilation zone z ≤ 0.2 mm; particle friction μ = 0.58 from plane-shear
  calibration (§3.2); no μ_macro is quoted for the cell.
- seed 001 (membrane triaxial of Ottawa sand, §2.1, §4.1): void ratio 0.593 at the start of axial
  loading (CT); the simulation peaks earlier than the experiment and the sample dilates after the
  peak (negative ε_v is dilation in the paper's sign convention).
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from .attempts import run_cost
from .clock import run_engine_seconds
from .scenes.shear_cell import COMPRESSION_TOLERANCE, compression_advice
from .scenes.triaxial import stage1_advice

__all__ = ["KeyResult", "key_results", "format_measure", "results_frame", "estimate_note"]


@dataclass(frozen=True)
class KeyResult:
    """One figure of a run. ``value`` and ``error`` in ``unit``; ``error`` is None when the figure
    has no uncertainty; ``error_meaning`` says what ± is (e.g. "std over the steady window")."""
    quantity: str
    value: float | str
    unit: str = ""
    error: float | None = None
    error_meaning: str = ""
    seed: str = ""
    ok: bool | None = None

    def text(self) -> str:
        """Value ± error with the unit, at a precision the error justifies."""
        if isinstance(self.value, str):
            return self.value
        return format_measure(self.value, self.error, self.unit)


def format_measure(value: float, error: float | None = None, unit: str = "") -> str:
    """``value ± error unit`` rounded so that the error keeps two significant digits (the value to
    the same decimal); without an error, four significant digits (from 10 000 to 10^9 written out, with
    thousands separators: "16,070 s", not "1.607e+04 s"). NaN prints as "n/a"."""
    u = f" {unit}" if unit else ""
    if value is None or not np.isfinite(value):
        return "n/a"
    if error is None or not np.isfinite(error) or error <= 0:
        rounded = float(f"{value:.4g}")
        return f"{rounded:,.0f}{u}" if 1e4 <= abs(rounded) < 1e9 else f"{value:.4g}{u}"
    digits = max(0, 1 - int(math.floor(math.log10(error))))
    if digits > 6 or abs(value) >= 1e6:
        return f"{value:.3e} ± {error:.2e}{u}"
    return f"{value:.{digits}f} ± {error:.{digits}f}{u}"


def _read_json(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def _table(adir: Path, label: str, table: str) -> pd.DataFrame | None:
    p = adir / f"{label}_{table}.csv"
    if not p.exists():
        return None
    try:
        return pd.read_csv(p)
    except (OSError, ValueError, pd.errors.EmptyDataError):
        return None


def _label(asum: dict, name: str) -> str | None:
    for label, entry in (asum or {}).items():
        if entry.get("name", label) == name and entry.get("status") == "ok":
            return label
    return None


def _x50(case: dict) -> float | None:
    psd = ((case or {}).get("scene") or {}).get("psd") or {}
    for k in ("median", "x50", "mean"):
        v = psd.get(k)
        if isinstance(v, (int, float)):
            return float(v)
    return None


def _shear_cell(run_dir: Path, adir: Path, asum: dict, params: dict, case: dict, summary: dict) -> list[KeyResult]:
    rows = []
    lab = _label(asum, "friction")
    if lab:
        s = asum[lab]["scalars"]
        n = s.get("n", 0)
        rows.append(KeyResult("μ_macro (steady)", s.get("mu_mean", np.nan), "", s.get("mu_std"),
                              f"std over {n} samples of the steady window", "not quoted (particle μ = 0.58, §3.2)"))
        if s.get("mu_sem") is not None:
            rows.append(KeyResult("μ_macro: standard error of the mean", float(f"{s['mu_sem']:.2g}"), "", None,
                                  "from 8 block means (the samples are correlated)"))
        if s.get("mu_drift") is not None and s.get("mu_steady") is not None:
            rows.append(KeyResult("μ_macro: drift across the steady window (steady: |drift| ≤ 2 se)",
                                  s["mu_drift"], "", s.get("mu_drift_se"),
                                  "standard error of a line through 8 block means", ok=bool(s["mu_steady"])))
    lab = _label(asum, "shearband")
    sc = params.get("scene") or {}
    x50 = sc.get("x50") or (sc.get("psd") or {}).get("median") or _x50(case)
    if lab:
        st = _table(adir, lab, "steady")
        if st is not None and len(st):
            z = st["z_sb"].to_numpy()
            w = st["w_sb"].to_numpy()
            ze = np.sqrt(np.sum(st["z_sb_err"].to_numpy() ** 2)) / len(st)
            we = np.sqrt(np.sum(st["w_sb_err"].to_numpy() ** 2)) / len(st)
            # the spread between radii is part of the uncertainty of an r̃-averaged figure
            if len(st) > 1:
                ze = float(np.hypot(ze, np.std(z, ddof=1) / np.sqrt(len(z))))
                we = float(np.hypot(we, np.std(w, ddof=1) / np.sqrt(len(w))))
            meaning = f"fit error and spread over {len(st)} radii"
            rows.append(KeyResult("band position z_sb (cell frame: lower plate face at z = 0 before compression)",
                                  float(np.mean(z)) * 1e6, "µm",
                                  float(ze) * 1e6, meaning, "just above the lower vanes, in the dilation zone z ≤ 200 µm"))
            rows.append(KeyResult("band width w_sb", float(np.mean(w)) * 1e6, "µm", float(we) * 1e6, meaning,
                                  f"≈ 8 x50 = {8 * x50 * 1e6:.0f} µm" if x50 else "≈ 8 x50"))
            if x50:
                rows.append(KeyResult("band width w_sb / x50", float(np.mean(w)) / x50, "", float(we) / x50, meaning,
                                      "≈ 8"))
            rows.append(KeyResult("band fitted", "yes" if np.all(w > 2 * np.asarray(st["w_sb_err"])) else
                                  "poorly (error ≥ width/2)", ok=bool(np.all(w > 2 * np.asarray(st["w_sb_err"])))))
        else:
            rows.append(KeyResult("band fitted", "no steady band fitted", ok=False))
    for f in sorted(run_dir.glob("*_checks.json")):
        d = _read_json(f) or {}
        for k, v in d.items():
            if isinstance(v, dict) and v.get("relative_error") is not None:
                e = float(v["relative_error"])
                rows.append(KeyResult(f"servo force vs target at the end of {k.replace('_', ' ')} (|e| ≤ 2 %)",
                                      float(f"{e * 100:.2g}"), "%", None, "",
                                      compression_advice(e, case.get("scene"), summary.get("case_source") or "")
                                      if k == "compression" else "",
                                      ok=abs(e) <= COMPRESSION_TOLERANCE))
    return rows


def _triaxial(run_dir: Path, adir: Path, asum: dict, params: dict, case: dict, summary: dict) -> list[KeyResult]:
    rows = []
    lab = _label(asum, "triaxial")
    if lab:
        s = asum[lab]["scalars"]
        rows += [
            KeyResult("peak σ1/σ3 (smoothed)", s.get("peak_stress_ratio", np.nan)),
            KeyResult("axial strain at peak", 100 * s.get("axial_strain_at_peak", np.nan), "%", None, "",
                      "simulation peaks earlier than experiment"),
            KeyResult("peak friction angle", s.get("peak_friction_angle_deg", np.nan), "°"),
            KeyResult("residual friction angle", s.get("residual_friction_angle_deg", np.nan), "°"),
            KeyResult("largest dilatancy angle", s.get("max_dilatancy_angle_deg", np.nan), "°", None, "",
                      "dilation after the peak"),
            KeyResult("final volumetric strain (compression +)", 100 * s.get("final_volumetric_strain", np.nan), "%"),
        ]
    iso = (summary.get("scene") or {}).get("isotropic_end") or summary.get("isotropic_end") or {}
    if isinstance(iso.get("converged"), bool) and isinstance(iso.get("sigma1_error"), (int, float)):
        tol = ((params.get("scene") or {}).get("iso") or {}).get("tolerance")
        rows.append(KeyResult("stage 1 at p when loading began: σ1/p, σ3/p" + (f" (within {tol:g})" if tol else ""),
                              f"{iso['sigma1_error'] + 1:.3f}, {iso.get('sigma3_error', float('nan')) + 1:.3f}"
                              + ("" if iso["converged"] else ": unconverged, loading began from this state"),
                              seed="" if iso["converged"] else stage1_advice(case.get("scene"),
                                                                             summary.get("case_source") or ""),
                              ok=iso["converged"]))
    e = iso.get("void_ratio") or {}
    if isinstance(e.get("interior"), (int, float)):
        rows.append(KeyResult("void ratio at the start of loading, interior", float(e["interior"]), "", None, "",
                              "0.593 (CT, §2.1)"))
    if isinstance(e.get("hull"), (int, float)):
        rows.append(KeyResult("void ratio at the start of loading, grains' hull", float(e["hull"]), ""))
    # the boundary's volumetric strain against the grains' own volumes while loading (issue #14:
    # within 0.01); the slab hull follows a neck, the convex hull bridges it (docs/triaxial.md)
    vm = (summary.get("scene") or {}).get("volume_methods") or {}
    slab, hull = vm.get("volumetric_strain_max_abs_diff_slab_hull"), vm.get("volumetric_strain_max_abs_diff")
    if isinstance(slab, (int, float)):
        rows.append(KeyResult("ε_v boundary vs grains' slab hull, largest while loading (≤ 1 %)",
                              float(f"{100 * slab:.2g}"), "%", None, "", "", ok=slab <= 0.01))
    if isinstance(hull, (int, float)):
        rows.append(KeyResult("ε_v boundary vs grains' convex hull, largest while loading",
                              float(f"{100 * hull:.2g}"), "%", None, "",
                              "the convex hull bridges a neck" if isinstance(slab, (int, float)) and hull > 0.01 >= slab else ""))
    return rows


def key_results(run_dir) -> list[KeyResult]:
    """The key figures of the run in ``run_dir`` (see the module docstring for sources)."""
    run_dir = Path(run_dir)
    summary = _read_json(run_dir / "summary.json") or {}
    params = _read_json(run_dir / "params.json") or {}
    adir = run_dir / "analysis"
    asum = _read_json(adir / "analysis_summary.json") or {}
    case = {}
    try:
        case = yaml.safe_load((run_dir / "case.yaml").read_text()) or {}
    except (OSError, ValueError):
        pass
    kind = ((case.get("scene") or {}).get("kind")) or ""
    rows: list[KeyResult] = []
    if kind == "shear_cell":
        rows += _shear_cell(run_dir, adir, asum, params, case, summary)
    elif kind == "triaxial":
        rows += _triaxial(run_dir, adir, asum, params, case, summary)
    subs = summary.get("substitutions") or []
    rows.append(KeyResult("substitutions", "; ".join(f"{s['feature']} → {s['mechanism']}" for s in subs) or "none"))
    wt = (summary.get("wall_time") or {}).get("engine")
    if isinstance(wt, (int, float)):
        note = estimate_note(summary)
        paused = paused_seconds(summary)
        paused_words = f"{format_measure(paused, None, 's')} of it paused (the engine stopped)"
        resumed = summary.get("resumed_from") or {}
        if resumed:
            # the summary's engine time covers only the last attempt; the record of every attempt
            # (orchestrator.attempts) gives the whole run's, with the steps a resume repeated and the
            # attempts' paused stretches taken out
            attempts = summary.get("attempts") or []
            whole = run_cost(attempts, int(summary.get("steps_run") or 0), use_cpu=False)
            start = resumed.get("step") if isinstance(resumed, dict) else None
            where = f"resumed from step {start}" if start is not None else "resumed"
            if whole is not None:
                note = (f"the whole run, {len(attempts)} attempts (the last, {where}, {wt:.0f} s)"
                        + (f", not counting {format_measure(paused, None, 's')} paused" if paused else "")
                        + (f"; {note}" if note else ""))
                wt, paused = whole, 0.0
            else:          # no complete record (a run from before it existed)
                note = f"{where}: this part only" + (f"; the whole run was {note}" if note else "")
        if paused:
            note = paused_words + (f"; {note}" if note else "")
        # a one-rank run's CPU time (the figure the clock learns from): its wall time also holds
        # whatever waiting for a shared core or pausing the attempts met; on several ranks the
        # wall time less the pauses (a rank polls while it waits)
        quiet = run_engine_seconds(run_dir, summary)
        if quiet is not None and quiet < wt:
            what = "of CPU" if max(int(summary.get("workers") or 1), 1) == 1 else "running"
            note = f"{format_measure(quiet, None, 's')} {what}" + (f"; {note}" if note else "")
        rows.append(KeyResult("engine time", float(wt), "s", None, "", note))
    return rows


def paused_seconds(summary: dict) -> float:
    """The wall time [s] the run's engine spent stopped (SIGSTOP, a scheduler's suspend), over every
    attempt on record (:mod:`orchestrator.attempts`), else the summary's last attempt; 0 without."""
    attempts = summary.get("attempts") or []
    if attempts:
        return float(sum(a.get("paused_s") or 0.0 for a in attempts if isinstance(a, dict)))
    return float((summary.get("wall_time") or {}).get("engine_paused") or 0.0)


def estimate_note(summary: dict) -> str:
    """What the clock estimated for the whole run before it started, and, for a resumed run whose
    last attempt estimated otherwise (the machine's speed records grew meanwhile), that estimate
    too: "estimated 5358 s before the run (7115 s before its last attempt)"; "" without one."""
    first = summary.get("first_estimated_engine_time_s", summary.get("estimated_engine_time_s"))
    last = summary.get("estimated_engine_time_s")
    if not isinstance(first, (int, float)):
        return ""
    note = f"estimated {first:.0f} s before the run"
    if isinstance(last, (int, float)) and round(last) != round(first):
        note += f" ({last:.0f} s before its last attempt)"
    return note


def results_frame(run_dir) -> pd.DataFrame:
    """:func:`key_results` as a DataFrame (columns quantity, text, value, error, unit, error_meaning,
    seed, ok): convenient in a notebook."""
    rows = key_results(run_dir)
    df = pd.DataFrame([asdict(r) for r in rows])
    if len(df):
        df.insert(1, "text", [r.text() for r in rows])
    return df


def print_key_results(run_dir, console) -> None:
    """Print the key results of ``run_dir`` as a short table on a rich ``console``, followed by
    where the frames, the figures and the report are."""
    from rich.table import Table
    run_dir = Path(run_dir)
    rows = key_results(run_dir)
    t = Table(title=f"results: {run_dir}", title_justify="left", show_lines=False)
    for col in ("quantity", "value", "seed paper / note"):
        t.add_column(col)
    for r in rows:
        val = r.text()
        if r.ok is False:          # in words too: a log file or a plain terminal shows no colour
            val = f"[red]{val}  FAIL[/red]"
        t.add_row(r.quantity, val, r.seed)
    console.print(t)
    adir = run_dir / "analysis"
    pngs = sorted(p.name for p in adir.glob("*.png")) if adir.is_dir() else []
    console.print(f"  frames:  {run_dir / 'frames.h5'}")
    if pngs:
        console.print(f"  figures: {adir}/ ({', '.join(pngs)})")
    if (run_dir / "report.html").exists():
        console.print(f"  report:  {run_dir / 'report.html'}")
