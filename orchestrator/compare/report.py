"""Self-contained HTML reports: one page per run (``orchestrator report RUN``) and one per comparison.

Pages hold everything inline: CSS in a ``<style>`` element, plots as base64 PNG ``data:`` URIs,
no script, no web font, no CDN, no network request of any kind. They open from a file, offline.
"""
from __future__ import annotations

import base64
import datetime as _dt
import html
import io
import json
from pathlib import Path

import numpy as np
import pandas as pd

from ..atomic import write_text
from ..case import yaml_or_case_error
from ..clock import run_step_plan
from ..results import estimate_note, key_results
from ..analysis.plots import _fig
from ..frames import Frames
from ..runner import analyze_run

__all__ = ["fig_to_data_uri", "write_run_report", "write_compare_report", "run_checks", "DEFAULT_ANALYSES"]

#: analyses run by ``orchestrator report`` when neither the case nor the command line names any
DEFAULT_ANALYSES = {
    "shear_cell": ["profiles", "shearband", "friction", "displacements", "d2min", "rdf", "coordination", "fabric"],
    "triaxial": ["triaxial", "energy", "displacements", "d2min", "clusters", "rdf", "coordination", "fabric", "stress"],
    "impact": [],
}

CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Helvetica,Arial,sans-serif;margin:1.5em auto;max-width:1250px;
color:#222;line-height:1.4;padding:0 1em}
h1{font-size:1.5em;border-bottom:2px solid #345;padding-bottom:.2em}h2{font-size:1.2em;margin-top:1.6em;color:#234}
h3{font-size:1.02em;margin-bottom:.3em}
table{border-collapse:collapse;font-size:.82em;margin:.4em 0}th,td{border:1px solid #ccc;padding:2px 6px;text-align:left;
vertical-align:top}th{background:#eef2f6}td.num{text-align:right;font-variant-numeric:tabular-nums}
.ok{color:#11731b;font-weight:600}.bad{color:#b00020;font-weight:600}.warn{color:#a35b00;font-weight:600}
.muted{color:#666}.sub{background:#fff6d8}figure{margin:.4em 0;display:inline-block;vertical-align:top}
figure img{max-width:100%;border:1px solid #ddd}.side{display:flex;gap:12px;flex-wrap:wrap}
.side figure{flex:1 1 380px}pre{background:#f6f8fa;padding:.6em;overflow-x:auto;font-size:.8em}
details{margin:.3em 0}
"""


def _e(x) -> str:
    return html.escape(str(x))


def fig_to_data_uri(fig, dpi: int = 90) -> str:
    """A matplotlib Figure as a ``data:image/png;base64,…`` URI."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode()


def _png_file_uri(path) -> str:
    return "data:image/png;base64," + base64.b64encode(Path(path).read_bytes()).decode()


def _img(uri: str, caption: str = "") -> str:
    cap = f"<figcaption class='muted'>{_e(caption)}</figcaption>" if caption else ""
    return f"<figure><img alt='{_e(caption or 'plot')}' src='{uri}'>{cap}</figure>"


def _fmt(v) -> str:
    if v is None:
        return ""
    if isinstance(v, (float, np.floating)):
        if not np.isfinite(v):
            return "" if np.isnan(v) else str(v)
        a = abs(v)
        return f"{v:.4g}" if (a == 0 or 1e-3 <= a < 1e5) else f"{v:.3e}"
    if isinstance(v, dict):      # never a raw mapping in a cell: "key value; key value"
        return "; ".join(f"{k} {_fmt(x)}" for k, x in v.items())
    if isinstance(v, (list, tuple)):
        return ", ".join(_fmt(x) for x in v)
    return str(v)


def _table(df: pd.DataFrame, classes: dict | None = None, max_rows: int = 400) -> str:
    cols = list(df.columns)
    out = ["<table><tr>" + "".join(f"<th>{_e(c)}</th>" for c in cols) + "</tr>"]
    for _, r in df.head(max_rows).iterrows():
        cells = []
        for c in cols:
            v = r[c]
            cls = "num" if isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) else ""
            extra = (classes or {}).get(c)
            if extra:
                cls = (cls + " " + extra(v)).strip()
            cells.append(f"<td class='{cls}'>{_e(_fmt(v))}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</table>")
    if len(df) > max_rows:
        out.append(f"<p class='muted'>{len(df) - max_rows} more rows in the CSV file</p>")
    return "".join(out)


def _kv(d: dict) -> str:
    return _table(pd.DataFrame({"": list(d.keys()), "value": [_fmt(v) for v in d.values()]}))


def _page(title: str, body: list[str]) -> str:
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    return ("<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
            "<meta name='viewport' content='width=device-width,initial-scale=1'>"
            f"<title>{_e(title)}</title><link rel='icon' href='data:,'><style>{CSS}</style></head><body>"
            f"<h1>{_e(title)}</h1><p class='muted'>generated {stamp} by orchestrator</p>"
            + "\n".join(body) + "</body></html>")


def _write(path, text: str) -> Path:
    """Write the page (UTF-8) atomically, its folder made if missing (:func:`orchestrator.atomic.write_text`)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_text(path, text)


def _subs_html(subs: list) -> str:
    if not subs:
        return "<p>None: every physics term of the case is implemented exactly by the engine.</p>"
    return _table(pd.DataFrame([{"physics term": s.get("feature"), "engine mechanism": s.get("mechanism"),
                                 "note": s.get("note", "")} for s in subs]))


# ------------------------------------------------------------------------------------ run report
def _steps_row(run_dir: Path, run: int, planned: int) -> dict:
    """The check that a run took the steps it should: all of them for a fixed step count; for a
    scene that decides its length while it runs (:func:`orchestrator.clock.run_step_plan`: the
    triaxial's stage 1 goes on chunk by chunk until it converges) the plan's fixed part and a
    whole number of its chunks, at most the budget (YADE's last step may be one past a chunk's
    end). A triaxial that converged early used to read FAIL here (88 320 of a 222 720-step budget)."""
    row = {"check": "steps run / steps planned", "value": f"{run:,} / {planned:,}", "limit": "equal",
           "status": "ok" if run >= planned else "FAIL", "source": "summary.json"}
    if run >= planned:
        return row
    plan = run_step_plan(run_dir)
    if plan is None:
        return row
    chunks = plan.chunks_of(run)
    whole = abs(chunks - round(chunks)) * plan.unit <= 2 and 1 <= round(chunks) <= plan.max_units
    return row | {"check": "steps run (the scene ends a stage when it converges)",
                  "value": f"{run:,} = {plan.fixed:,} + {chunks:.2f} chunks of {plan.unit:,}",
                  "limit": f"{plan.fixed:,} + 1 to {plan.max_units} whole chunks (at most {planned:,})",
                  "status": "ok" if whole else "FAIL"}


def _json_record(path: Path) -> dict:
    """A run's JSON record (``summary.json``, ``analysis_summary.json``) as a mapping, or a
    ValueError naming the file and the fix (a damaged record, not a parser's message)."""
    try:
        data = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        data = exc
    if not isinstance(data, dict):
        why = f"not JSON ({data})" if isinstance(data, Exception) else f"a JSON {type(data).__name__}, not a record"
        fix = (f"`orchestrator analyze {path.parent.parent}` writes it again" if path.name == "analysis_summary.json"
               else "run the case again: the same `orchestrator run` command resumes or redoes it")
        raise ValueError(f"{path}: damaged: {why}; {fix}")
    return data


def run_checks(run_dir, frames=None, summary: dict | None = None) -> pd.DataFrame:
    """Stability and protocol checks of a run, from summary.json, ``*_checks.json`` and the frames.

    Columns: check, value, limit, status ("ok", "FAIL", "info"), source.
    """
    run_dir = Path(run_dir)
    summary = summary or {}
    rows = []
    if "dt" in summary and "dt_critical" in summary:
        f = summary["dt"] / summary["dt_critical"]
        rows.append({"check": "time step / critical time step", "value": f, "limit": "< 1",
                     "status": "ok" if f < 1 else "FAIL", "source": "summary.json"})
    rows.append({"check": "run status", "value": summary.get("status", "?"), "limit": "complete",
                 "status": "ok" if summary.get("status") == "complete" else "FAIL", "source": "summary.json"})
    if summary.get("steps") is not None and summary.get("steps_run") is not None:
        rows.append(_steps_row(run_dir, int(summary["steps_run"]), int(summary["steps"])))
    if isinstance(summary.get("unstable"), dict):
        u = summary["unstable"]
        rows.append({"check": f"in-deck monitor: {u.get('meaning', u.get('figure'))}", "value": u.get("value"),
                     "limit": u.get("limit"), "status": "FAIL", "source": f"summary.json (step {u.get('step')})"})
    stab = summary.get("stability") or summary.get("checks")
    if isinstance(stab, dict):
        rows += _stability_rows(stab)
    for f in sorted(run_dir.glob("*_checks.json")):
        try:
            d = json.loads(f.read_text())
        except ValueError:
            continue
        for k, v in d.items():
            if isinstance(v, dict) and "relative_error" in v:
                e = v["relative_error"]
                st = "info" if e is None else ("ok" if abs(e) <= 0.02 else "FAIL")
                rows.append({"check": f"{k}: servo force vs target (relative error)", "value": e, "limit": "|e| ≤ 0.02",
                             "status": st, "source": f.name})
            else:
                rows.append({"check": k, "value": _fmt(v), "limit": "", "status": "info", "source": f.name})
    if frames is not None:
        pos = frames.position
        present = np.isfinite(pos).all(-1)
        n0 = int(present[0].sum())
        lost = int((present[0] & ~present[-1]).sum())
        rows.append({"check": "particles present in first / last frame", "value": f"{n0} / {int(present[-1].sum())}",
                     "limit": "no loss", "status": "ok" if lost == 0 else "FAIL", "source": "frames.h5"})
        if "velocity" in frames.fields:
            v = np.linalg.norm(frames.velocity, axis=-1)
            vmax = float(np.nanmax(v)) if np.isfinite(v).any() else float("nan")
            rows.append({"check": "largest particle speed [m/s]", "value": vmax, "limit": "finite",
                         "status": "ok" if np.isfinite(vmax) else "FAIL", "source": "frames.h5"})
        lo, hi = np.nanmin(pos[present]), np.nanmax(pos[present])
        rows.append({"check": "positions finite and bounded [m]", "value": f"{lo:.3g} .. {hi:.3g}", "limit": "",
                     "status": "ok" if np.isfinite([lo, hi]).all() else "FAIL", "source": "frames.h5"})
    return pd.DataFrame(rows, columns=["check", "value", "limit", "status", "source"])


def _stability_rows(stab: dict) -> list[dict]:
    """The pre-run time-step report as check rows: one row per critical-step limit (the limit in
    seconds and the fraction of it the run's dt uses), the binding limit and the safe maximum.
    No cell holds a raw mapping."""
    rows = []
    limits, fractions = stab.get("limits") or {}, stab.get("fractions") or {}
    binding = stab.get("binding")
    for name in sorted(limits, key=lambda k: -(fractions.get(k) or 0)):
        f = fractions.get(name)
        rows.append({"check": f"dt / {name.replace('_', ' ')} limit ({limits[name]:.3g} s)"
                              + (" — binding" if name == binding else ""),
                     "value": f"{f:.3f}" if isinstance(f, (int, float)) else "", "limit": "< 1",
                     "status": "info" if f is None else ("ok" if f < 1 else "FAIL"), "source": "summary.json stability"})
    if isinstance(stab.get("dt_max_safe"), (int, float)):
        rows.append({"check": "largest safe time step", "value": f"{stab['dt_max_safe']:.3g} s", "limit": "",
                     "status": "info", "source": "summary.json stability"})
    if stab.get("forced"):
        rows.append({"check": "time-step check overridden (--force)", "value": "yes", "limit": "", "status": "FAIL",
                     "source": "summary.json stability"})
    for k, v in stab.items():
        if k in ("limits", "fractions", "binding", "dt_max_safe", "forced", "ok"):
            continue
        if isinstance(v, dict):
            ok = v.get("ok", v.get("pass"))
            val = v.get("value")
            if val is None:
                val = ", ".join(f"{kk} {_fmt(vv)}" for kk, vv in v.items() if kk not in ("ok", "pass", "limit"))
            rows.append({"check": k.replace("_", " "), "value": _fmt(val), "limit": _fmt(v.get("limit", "")),
                         "status": "info" if ok is None else ("ok" if ok else "FAIL"), "source": "summary.json stability"})
        else:
            rows.append({"check": k.replace("_", " "), "value": _fmt(v), "limit": "", "status": "info",
                         "source": "summary.json"})
    return rows


def _results_html(run_dir) -> str:
    """The run's key figures (orchestrator.results) with the seed paper's value beside each."""
    rows = key_results(run_dir)
    if not rows:
        return ""
    df = pd.DataFrame({"quantity": [r.quantity for r in rows], "value": [r.text() for r in rows],
                       "± means": [r.error_meaning for r in rows], "seed paper": [r.seed for r in rows],
                       "check": ["" if r.ok is None else ("ok" if r.ok else "FAIL") for r in rows]})
    return _table(df, {"check": _status_class})


def _status_class(v):
    return {"ok": "ok", "FAIL": "bad"}.get(str(v), "muted")


def _walltime_fig(wt: dict):
    # wall-time phases only: the engine's CPU time and the wall time it spent stopped are in the table
    parts = {k: v for k, v in wt.items() if k not in ("total", "engine_loop", "engine_cpu", "engine_paused")
             and isinstance(v, (int, float))}
    if "engine" in parts and isinstance(wt.get("engine_loop"), (int, float)):
        loop = wt["engine_loop"]
        parts["engine (start-up, I/O)"] = max(parts.pop("engine") - loop, 0.0)
        parts["engine (integration loop)"] = loop
    fig, (ax,) = _fig(w=6, h=2.6)
    names = list(parts)
    ax.barh(names, [parts[n] for n in names], color="#4a78a8")
    ax.set_xlabel("wall time [s]")
    for k, n in enumerate(names):
        ax.text(parts[n], k, f" {parts[n]:.2f} s", va="center", fontsize=8)
    return fig


def write_run_report(run_dir, out=None, analyses=None, rerun: bool = False) -> Path:
    """Write ``<run_dir>/report.html`` (or ``out``): case, substitutions, stability checks,
    run-time split, the analyses with their plots.

    ``analyses``: list of analysis specs to run (into ``<run_dir>/analysis``); default the case's
    ``analysis:`` list if any result is missing, else the results already there; when the case lists
    none, :data:`DEFAULT_ANALYSES` of the scene. ``rerun`` recomputes them.
    """
    run_dir = Path(run_dir)
    if run_dir.name == "frames.h5":
        run_dir = run_dir.parent
    fr = Frames(run_dir)
    summ_path = run_dir / "summary.json"
    summary = _json_record(summ_path) if summ_path.exists() else {}
    case_file = run_dir / "case.yaml"
    case_text = case_file.read_text() if case_file.exists() else None
    # a damaged case.yaml is a CaseError naming it (not a YAML parser's traceback)
    case = yaml_or_case_error(case_file) if case_text else (fr.meta.get("case") if isinstance(fr.meta.get("case"), dict) else {})
    kind = ((case or {}).get("scene") or {}).get("kind", "")
    adir = run_dir / "analysis"
    asum_path = adir / "analysis_summary.json"
    specs = analyses if analyses is not None else ((case or {}).get("analysis") or DEFAULT_ANALYSES.get(kind, []))
    asum = _json_record(asum_path) if asum_path.exists() else None
    if specs and (rerun or analyses is not None or asum is None):
        # analyses named for the report join the run's record; the case's own list replaces it
        _, asum = analyze_run(run_dir, specs, by_name=analyses is not None)
    title = f"Run report — {summary.get('case', case.get('name', run_dir.parent.name) if case else run_dir.name)} " \
            f"on {summary.get('engine', fr.meta.get('engine', '?'))}"
    body = []
    # results first (key figures with errors and the seed's values, then the analyses' plots),
    # then the checks, then the bookkeeping
    body.append("<h2>Results</h2>" + (_results_html(run_dir) or "<p class='muted'>no key figures for this scene</p>"))
    if not asum:
        body.append("<p class='muted'>No analyses asked for (the case lists none and the scene has no default set).</p>")
    for label, entry in (asum or {}).items():
        body.append(f"<h3>{_e(label)}</h3>")
        if entry.get("status") != "ok":
            body.append(f"<p class='bad'>failed: {_e(entry.get('error', ''))}</p>")
            continue
        for f in entry.get("files", []):
            if f.endswith(".png") and (adir / f).exists():
                body.append(_img(_png_file_uri(adir / f), f))
        sc = entry.get("scalars") or {}
        if sc:
            body.append("<details><summary>figures of this analysis</summary>" + _kv(sc) + "</details>")
        csvs = [f for f in entry.get("files", []) if f.endswith(".csv")]
        if csvs:
            body.append(f"<p class='muted'>tables: {_e(', '.join(csvs))} (in {_e(adir)})</p>")
    chk = run_checks(run_dir, fr, summary)
    nfail = int((chk.status == "FAIL").sum())
    body.append(f"<h2>Stability and protocol checks</h2><p class='{'bad' if nfail else 'ok'}'>"
                f"{'%d check(s) failed' % nfail if nfail else 'all checks passed'}</p>"
                + _table(chk, {"status": _status_class}))
    body.append("<h2>Substitutions</h2>" + _subs_html(summary.get("substitutions", fr.meta.get("substitutions", []) or [])))
    dt, dtc = summary.get("dt"), summary.get("dt_critical")
    info = {"run directory": str(run_dir.resolve()), "engine": f"{summary.get('engine', fr.meta.get('engine', ''))} "
                                                            f"{summary.get('engine_version', fr.meta.get('engine_version', ''))}",
            "status": summary.get("status", "?"), "scene": kind, "particles": fr.n_particles, "frames": fr.n_frames,
            "fields": ", ".join(fr.fields), "controls": ", ".join(fr.controls), "walls": ", ".join(fr.wall_names),
            "time step": f"{dt:.4g} s" if isinstance(dt, (int, float)) else "",
            "critical time step": f"{dtc:.4g} s" if isinstance(dtc, (int, float)) else "",
            "steps": summary.get("steps_run", summary.get("steps")), "source": fr.meta.get("source", "")}
    body.append("<h2>Run</h2>" + _kv(info))
    if fr.controls:
        ct = pd.DataFrame({"frame": np.arange(fr.n_frames), "time [s]": fr.time, **{k: v for k, v in fr.controls.items()}})
        if "angle" in ct:
            ct["angle [deg]"] = np.degrees(ct.pop("angle"))
        body.append("<details><summary>frames and control values</summary>" + _table(ct) + "</details>")
    wt = summary.get("wall_time") or {}
    if wt:
        resumed = summary.get("resumed_from")
        body.append("<h2>Run time</h2>"
                    + ("<p class='muted'>the last attempt's (the run was resumed"
                       + (f" from step {resumed['step']}" if isinstance(resumed, dict) and resumed.get("step") is not None else "")
                       + "); the whole run's engine time is the results' <i>engine time</i></p>" if resumed else "")
                    + _kv({k: (f"{v:.3f} s" if isinstance(v, (int, float)) else v) for k, v in wt.items()}))
        body.append(_img(fig_to_data_uri(_walltime_fig(wt)), "wall-time split"))
        said = estimate_note(summary)
        if said:
            body.append(f"<p class='muted'>engine time {_e(said)}</p>")
    if case_text:
        body.append("<h2>Resolved case</h2><details><summary>case.yaml</summary><pre>" + _e(case_text) + "</pre></details>")
    out = Path(out) if out else run_dir / "report.html"
    return _write(out, _page(title, body))


# -------------------------------------------------------------------------------- compare report
def _dist_class(v):
    try:
        v = abs(float(v))
    except (TypeError, ValueError):
        return ""
    if not np.isfinite(v):
        return "muted"
    return "ok" if v <= 0.05 else ("warn" if v <= 0.2 else "bad")


def write_compare_report(cmp, path, crossval: dict | None = None) -> Path:
    """HTML page of a :class:`~orchestrator.compare.core.Comparison`: alignment, substitutions,
    the distance table (substitutions beside the numbers they can affect), side-by-side plots."""
    al = cmp.alignment
    A, B = al.a, al.b
    body = []
    info = {"A": f"{A.label} ({A.kind}) — {A.path}", "B": f"{B.label} ({B.kind}) — {B.path}",
            "states matched by": al.control, "coordinate frame": al.frame,
            "grain identity": json.dumps(al.identity.summary()) if al.identity is not None else "none",
            "computed in": f"{cmp.seconds:.1f} s"}
    body.append("<h2>Alignment</h2>" + _kv(info))
    st = al.states.copy()
    if al.control == "angle":
        st["angle [deg]"] = np.degrees(st["value"])
    body.append("<details open><summary>matched states</summary>" + _table(st) + "</details>")
    if crossval:
        body.append("<h2>Engines: wall time</h2>" + _table(pd.DataFrame(crossval["engines"])))
        body.append(f"<p class='muted'>{_e(crossval.get('mode', ''))}</p>")
    body.append("<h2>Substitutions</h2>")
    for src in (A, B):
        body.append(f"<h3>{_e(src.label)}</h3>" + (_subs_html(src.substitutions) if src.kind == "simulation"
                                                    else "<p class='muted'>CT frame set: no engine, no substitutes.</p>"))
    diff = {m: n for m, n in cmp.notes.items() if "differs" in n}
    if diff:
        body.append("<p class='warn'>The engines use different substitutes; the affected numbers carry the note in the "
                    "'substitutions' column below.</p>")
    t = cmp.table.copy()
    body.append("<h2>Distances</h2><p class='muted'>rel_L2: ‖y_B − y_A‖/‖y_A‖ on A's grid; KS: two-sample "
                "Kolmogorov–Smirnov statistic; rel_error: (B − A)/|A|. Colours: ≤ 0.05 green, ≤ 0.2 amber, "
                "above red. CSV: comparison.csv.</p>")
    show = t[["measure", "quantity", "state", "control_value", "control_value_to", "metric", "distance", "a", "b",
              "p_value", "substitutions", "note"]]
    body.append(_table(show, {"distance": _dist_class, "substitutions": lambda v: "sub" if str(v) else ""}, 1000))
    if cmp.grain is not None:
        g = cmp.grain
        body.append("<h2>Grain by grain</h2>" + _kv(g.scalars))
        body.append(_img(fig_to_data_uri(g.plot()), "per-grain trajectory error and displacement agreement"))
        body.append(_table(g.tables["states"]))
    elif cmp.grain_error:
        body.append(f"<h2>Grain by grain</h2><p class='muted'>not computed: {_e(cmp.grain_error)}</p>")
    body.append("<h2>Measures</h2>")
    for name, o in cmp.outcomes.items():
        note = cmp.notes.get(name, "")
        body.append(f"<h3>{_e(name)} <span class='muted'>({o.seconds:.2f} s)</span></h3>")
        if note:
            body.append(f"<p class='sub'>substitutions that can affect these numbers: {_e(note)}</p>")
        if o.skipped:
            body.append(f"<p class='muted'>skipped: {_e(o.skipped)}</p>")
            continue
        if o.error:
            body.append(f"<p class='bad'>error: {_e(o.error)}</p>")
            continue
        figs = []
        if o.overlay is not None:
            figs.append(_img(fig_to_data_uri(o.overlay), f"{name}: A and B overlaid"))
        for lab, res in ((A.label, o.result_a), (B.label, o.result_b)):
            if res is None:                 # e.g. 'macro': series compared directly, overlay only
                continue
            try:
                figs.append(_img(fig_to_data_uri(res.plot()), f"{name}: {lab}"))
            except Exception as exc:  # noqa: BLE001 - a plot that cannot be drawn is reported, not fatal
                figs.append(f"<p class='muted'>{_e(lab)}: no plot ({_e(exc)})</p>")
        body.append("<div class='side'>" + "".join(figs) + "</div>")
    title = f"Comparison — {A.label} vs {B.label}"
    return _write(path, _page(title, body))
