"""``compare(A, B)``: align two frame sets, compute the papers' measures on both, the distances,
the grain-level errors; write ``comparison.csv`` and ``report.html``.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .align import Alignment, align, open_source
from .measures import MEASURES, compute_measures
from ..frames import Frames, write_frames
from .grain import grain_errors
from ..analysis._common import atomic_write_csv, atomic_write_json
from .report import write_compare_report

__all__ = ["Comparison", "compare", "substitution_notes", "AFFECTS"]

#: physics term -> measures its substitute can change (terms not listed affect every measure)
AFFECTS = {
    "membrane": ("macro", "displacements", "d2min", "clusters", "profiles", "shearband", "coordination", "fabric",
                 "rdf"),
    "servo_wall": ("macro", "friction", "profiles", "coordination", "rdf", "fabric"),
    "rotating_walls": ("shearband", "displacements", "d2min", "clusters", "friction", "macro"),
}

COLUMNS = ["measure", "quantity", "state", "control", "control_value", "control_value_to", "metric", "distance",
           "a", "b", "unit", "n_a", "n_b", "p_value", "frame_a", "frame_b", "substitutions", "note"]


def substitution_notes(a, b) -> dict:
    """Per measure, a note naming the engine substitutes that can affect it.

    A substitute used by one side only, or differently by the two, is marked ``differs``; one used
    identically by both is marked ``both``. Returns ``{measure: note}`` ("" when nothing applies)."""
    sa = {s["feature"]: s for s in a.substitutions}
    sb = {s["feature"]: s for s in b.substitutions}
    notes = {m: [] for m in MEASURES}
    for feat in sorted(set(sa) | set(sb)):
        x, y = sa.get(feat), sb.get(feat)
        if x and y and x["mechanism"] == y["mechanism"]:
            txt = f"both: {feat} → {x['mechanism']}"
        else:
            parts = []
            for lab, s in ((a.label, x), (b.label, y)):
                parts.append(f"{lab}: {s['mechanism']}" if s else f"{lab}: exact")
            txt = f"differs: {feat} ({'; '.join(parts)})"
        for m in AFFECTS.get(feat, MEASURES):
            notes[m].append(txt)
    return {m: " | ".join(v) for m, v in notes.items()}


def _transformed_copy(fr, transform, path: Path):
    """A copy of a frame set with positions (and contact points/normals/forces) moved by (R, t)."""
    R, t = np.asarray(transform[0]), np.asarray(transform[1])
    pos = fr.position @ R.T + t
    per = {}
    for f in fr.fields:
        if f in ("velocity", "angular_velocity", "force", "torque"):
            per[f] = fr.field(f) @ R.T
    contacts = {}
    for k in fr.contact_frames:
        c = dict(fr.contact_arrays(k))
        for key in ("point",):
            if key in c:
                c[key] = c[key] @ R.T + t
        for key in ("normal", "fn", "ft"):
            if key in c:
                c[key] = c[key] @ R.T
        contacts[k] = c
    meta = {k: v for k, v in fr.meta.items()}
    meta["transformed"] = {"rotation": R.tolist(), "translation_m": t.tolist(), "from": str(fr.path)}
    write_frames(path, fr.ids, fr.radius, fr.time, pos, step=fr.step, controls=fr.controls, contacts=contacts,
                 walls=None, mass=fr.mass, shape=fr.shape, meta=meta, **per)
    return Frames(path)


@dataclass
class Comparison:
    """Result of :func:`compare`: alignment, distance table, per-measure outcomes, grain errors."""
    alignment: Alignment
    table: pd.DataFrame
    outcomes: dict
    grain: object = None
    grain_error: str | None = None
    notes: dict = field(default_factory=dict)
    seconds: float = 0.0
    out_dir: Path | None = None
    files: dict = field(default_factory=dict)

    def distances(self, measure: str | None = None) -> pd.DataFrame:
        t = self.table
        return t if measure is None else t[t.measure == measure].reset_index(drop=True)

    def max_distance(self) -> float:
        d = np.abs(self.table["distance"].to_numpy(float))
        d = d[np.isfinite(d)]
        return float(d.max()) if len(d) else float("nan")

    def __repr__(self) -> str:
        """One line: the two sides, the states matched, the measures computed, the largest distance
        and the grain-by-grain error (a dataclass's own repr printed every table)."""
        al = self.alignment
        done = [m for m, o in self.outcomes.items() if not o.skipped and not o.error]
        said = [f"{len(al.states)} states by {al.control}", f"{len(done)} of {len(self.outcomes)} measures",
                f"largest distance {self.max_distance():.3g}"]
        if self.grain is not None:
            g = self.grain.scalars
            said.append(f"grain by grain ({g.get('identity')}, {g.get('grains_identified')} grains): median "
                        f"trajectory error up to {g.get('max_median_error_d50', float('nan')):.3g} d50")
        return f"<Comparison {al.a.label} vs {al.b.label}: {', '.join(said)}>"

    def _repr_html_(self) -> str:
        """In a notebook: the line of :meth:`__repr__`, then the largest distance of every measure and
        quantity (the full table: ``.table``)."""
        import html
        t = self.table
        top = (t.assign(abs_distance=t["distance"].abs()).groupby(["measure", "quantity", "metric"], sort=False)
               ["abs_distance"].max().rename("largest |distance|").reset_index())
        return f"<p><code>{html.escape(repr(self))}</code></p>" + top.to_html(index=False, float_format="{:.3g}".format)

    def summary(self) -> dict:
        return {"alignment": self.alignment.summary(),
                "measures": {k: {"rows": len(o.rows), "skipped": o.skipped, "error": o.error,
                                 "seconds": round(o.seconds, 3)} for k, o in self.outcomes.items()},
                "grain": self.grain.scalars if self.grain is not None else None,
                "grain_error": self.grain_error, "seconds": round(self.seconds, 3)}

    def write(self, out_dir, html: bool = True) -> dict:
        """Write ``comparison.csv``, ``grains_states.csv``/``grains.csv``, ``alignment.json``,
        every analysis table of both sides (``a_<measure>_<table>.csv`` …) and ``report.html``."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        files = {"table": atomic_write_csv(self.table, out / "comparison.csv")}
        for name, o in self.outcomes.items():
            for side, res in (("a", o.result_a), ("b", o.result_b)):
                if res is not None:
                    for tname, df in res.tables.items():
                        atomic_write_csv(df, out / f"{side}_{name}_{tname}.csv")
        if self.grain is not None:
            files["grain_states"] = atomic_write_csv(self.grain.tables["states"], out / "grains_states.csv")
            files["grains"] = atomic_write_csv(self.grain.tables["grains"], out / "grains.csv")
        files["summary"] = atomic_write_json(self.summary(), out / "comparison.json")
        if html:
            files["html"] = write_compare_report(self, out / "report.html")
        self.out_dir, self.files = out, files
        return files


def compare(a, b, out_dir=None, measures=None, options: dict | None = None, control: str | None = None,
            tolerance: float | None = None, frame: str = "none", identity: bool = True,
            max_distance: float | None = None, grain_atol_d50: float = 0.1, grain_rtol: float = 0.2,
            at=None, labels=(None, None), html: bool = True) -> Comparison:
    """Compare B with A (runs, frames.h5 files or CT frame sets, any mix).

    a, b : run directories, frames.h5 paths, :class:`~orchestrator.frames.Frames` or
        :class:`~orchestrator.compare.align.Source`.
    measures : subset of :data:`~orchestrator.compare.measures.MEASURES` (default all).
    options : ``{"states": "ends"|"all", "<measure>": {analysis options}}``.
    control, tolerance, at : state matching (see :func:`~orchestrator.compare.align.match_states`).
    frame : "none", "centroid" or "rigid" (coordinate alignment of B onto A).
    identity, max_distance : grain identity (ids or position matching within max_distance [m]).
    grain_atol_d50, grain_rtol : displacement agreement tolerance of the grain comparison.
    out_dir : when given, everything is written there (see :meth:`Comparison.write`).
    """
    t0 = time.perf_counter()
    A, B = open_source(a, labels[0]), open_source(b, labels[1])
    if A.label == B.label:
        B.label = B.label + " (B)"
    al = align(A, B, control=control, tolerance=tolerance, frame=frame, identity=identity,
               max_distance=max_distance, at=at)
    fb = B.frames
    if al.transform is not None:
        if out_dir is None:
            import tempfile
            tmp = Path(tempfile.mkdtemp(prefix="compare-"))
        else:
            tmp = Path(out_dir)
            tmp.mkdir(parents=True, exist_ok=True)
        fb = _transformed_copy(B.frames, al.transform, tmp / "b_aligned.h5")
    outcomes = compute_measures(al, A.frames, fb, measures, options)
    notes = substitution_notes(A, B)
    rows = []
    for name, o in outcomes.items():
        for r in o.rows:
            r = dict(r)
            r["substitutions"] = notes.get(name, "")
            r.setdefault("note", "")
            rows.append(r)
        if o.skipped or o.error:
            rows.append({"measure": name, "quantity": "", "metric": "", "distance": np.nan,
                         "note": f"skipped: {o.skipped}" if o.skipped else f"error: {o.error}",
                         "substitutions": notes.get(name, ""), "control": al.control})
    table = pd.DataFrame(rows, columns=COLUMNS)
    grain, gerr = None, None
    if al.identity is not None and al.identity.n > 0:
        try:
            grain = grain_errors(al, A.frames, fb, grain_atol_d50, grain_rtol)
        except Exception as exc:  # noqa: BLE001
            gerr = f"{type(exc).__name__}: {exc}"
    else:
        gerr = "no grain identity (identity=False or no grain matched)"
    cmp = Comparison(al, table, outcomes, grain, gerr, notes, time.perf_counter() - t0)
    if out_dir is not None:
        cmp.write(out_dir, html=html)
    return cmp
