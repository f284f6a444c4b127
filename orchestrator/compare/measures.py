"""The measures both seed papers compare, computed on two aligned frame sets with identical
options, and the distances between them.

| measure | seed | states | distances (rows of the comparison table) |
|---|---|---|---|
| ``profiles`` | 000 Fig. 1 | first and last | rel. L2 of n(z) and n(r), rel. error of mean φ |
| ``shearband`` | 000 Fig. 2, eq. 2 | consecutive | rel. error of z_sb and w_sb per increment, rel. L2 of z_sb and w_sb over the control |
| ``displacements`` | 001 Figs. 9-10 | consecutive | KS of \\|u\\| per increment, rel. error of the median |
| ``d2min`` | 001 Fig. 12 | consecutive | KS of D²min and of ε_q per increment |
| ``clusters`` | 001 Fig. 13 | consecutive, pooled | KS of cluster sizes, rel. error of τ and d_f |
| ``coordination`` | 001 Fig. 6b | first and last | KS of Z, rel. error of mean Z |
| ``fabric`` | 001 Figs. 6c-d | first and last | rel. L2 of the contact-normal rose (and branch rose with a contact list), rel. error of a_c |
| ``rdf`` | 001 Fig. 6a | first and last | rel. L2 of g(r) |
| ``friction`` | 000 (μ_macro) | wall series | rel. L2 of μ(t), rel. error of mean μ |
| ``macro`` | 001 Fig. 8 | all states + wall series | rel. L2 of every shared control (volumetric strain, stress ratio …) over the matched control, and of every shared wall series' z component (force, torque, position) and angle over time |

"States": the aligned states of :func:`orchestrator.compare.align.match_states`. Single-frame
measures use the first and last state unless ``states="all"``; incremental measures use consecutive
states (state k → k + 1). The options resolved on A (bins, centre, ranges, radii, cut-offs) are
passed to B, so both are binned identically. When either side has no contact list (CT), Z and the
fabric come from geometry on both sides with the same ``tolerance`` (default 2 % of R_i + R_j,
which absorbs the sub-voxel centroid error of segmented grains).
"""
from __future__ import annotations

import time
import traceback
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..analysis import ANALYSES
from ..analysis.plots import _fig
from .distances import Distance, ks, l2, rel_error
from ..measure_names import MEASURES

__all__ = ["MEASURES", "MeasureOutcome", "compute_measures"]

MM = 1e3


@dataclass
class MeasureOutcome:
    """One measure on both sides: the two analysis Results, the distance rows, an overlay plot."""
    name: str
    result_a: object = None
    result_b: object = None
    rows: list = field(default_factory=list)
    overlay: object = None             # matplotlib Figure with A and B on the same axes
    skipped: str | None = None         # why the measure was not computed
    error: str | None = None
    seconds: float = 0.0


class _Ctx:
    def __init__(self, alignment, fa, fb, options):
        self.al = alignment
        self.fa, self.fb = fa, fb
        self.st = alignment.states
        self.opts = options
        self.la, self.lb = alignment.a.label, alignment.b.label
        sel = options.get("states", "ends")
        st = self.st
        if sel == "all":
            idx = list(range(len(st)))
        else:
            idx = sorted({0, len(st) - 1})
        self.single = idx
        self.single_a = [int(st.frame_a[i]) for i in idx]
        self.single_b = [int(st.frame_b[i]) for i in idx]
        self.pairs_idx = [(i, i + 1) for i in range(len(st) - 1)]
        self.pairs_a = [[int(st.frame_a[i]), int(st.frame_a[j])] for i, j in self.pairs_idx]
        self.pairs_b = [[int(st.frame_b[i]), int(st.frame_b[j])] for i, j in self.pairs_idx]
        self.state_of_a = {int(f): i for i, f in enumerate(st.frame_a)}
        self.state_of_b = {int(f): i for i, f in enumerate(st.frame_b)}
        self.pair_of_a = {tuple(p): k for k, p in enumerate(self.pairs_a)}
        self.pair_of_b = {tuple(p): k for k, p in enumerate(self.pairs_b)}

    def row(self, measure, quantity, d: Distance, state=None, pair=None, unit=""):
        st = self.st
        r = {"measure": measure, "quantity": quantity, "metric": d.metric, "distance": d.value,
             "a": d.a, "b": d.b, "n_a": d.n_a, "n_b": d.n_b, "p_value": d.p_value, "unit": unit,
             "state": "", "control": self.al.control, "control_value": np.nan, "control_value_to": np.nan,
             "frame_a": "", "frame_b": ""}
        if state is not None:
            r.update(state=str(state), control_value=float(st.value[state]), frame_a=str(int(st.frame_a[state])),
                     frame_b=str(int(st.frame_b[state])))
        if pair is not None:
            i, j = self.pairs_idx[pair]
            r.update(state=f"{i}->{j}", control_value=float(st.value[i]), control_value_to=float(st.value[j]),
                     frame_a=f"{int(st.frame_a[i])}->{int(st.frame_a[j])}",
                     frame_b=f"{int(st.frame_b[i])}->{int(st.frame_b[j])}")
        if d.details.get("reason"):
            r["note"] = d.details["reason"]
        return r


def _has_contacts(fr) -> bool:
    return len(getattr(fr, "contact_frames", [])) > 0


def _overlay(title, xlabel, ylabel, curves, logx=False, logy=False):
    """curves: list of (x, y, label, style)."""
    fig, (ax,) = _fig(w=5.5, h=3.8)
    for x, y, lab, sty in curves:
        ax.plot(x, y, sty, label=lab, ms=3)
    if logx:
        ax.set_xscale("log")
    if logy:
        ax.set_yscale("log")
    ax.set_title(title, fontsize=10)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=7)
    return fig


def _ecdf(x):
    x = np.sort(np.asarray(x, float)[np.isfinite(np.asarray(x, float))])
    return x, (np.arange(1, len(x) + 1) / max(len(x), 1))


# ----------------------------------------------------------------------------------- measures
def _profiles(c: _Ctx, o: MeasureOutcome, opts):
    ra = ANALYSES["profiles"](c.fa, at=c.single_a, **opts)
    ob = {k: v for k, v in ra.options.items()}
    rb = ANALYSES["profiles"](c.fb, at=c.single_b, **ob)
    o.result_a, o.result_b = ra, rb
    curves = []
    for s, ka, kb in zip(c.single, c.single_a, c.single_b):
        A, B = ra.tables["axial"], rb.tables["axial"]
        a, b = A[A.frame == ka], B[B.frame == kb]
        o.rows.append(c.row("profiles", "n(z)", l2(a.z, a.n, b.z, b.n), state=s, unit="1/m^3"))
        o.rows.append(c.row("profiles", "mean phi(z)", rel_error(a.phi.mean(), b.phi.mean()), state=s))
        Ar, Br = ra.tables["radial"], rb.tables["radial"]
        ar, br = Ar[Ar.frame == ka], Br[Br.frame == kb]
        o.rows.append(c.row("profiles", "n(r)", l2(ar.r, ar.n, br.r, br.n), state=s, unit="1/m^3"))
        v = c.st.value[s]
        curves += [(a.n * 1e-9, a.z * MM, f"{c.la} @ {v:.4g}", "-"), (b.n * 1e-9, b.z * MM, f"{c.lb} @ {v:.4g}", "--")]
    o.overlay = _overlay("number density n(z)", "n [1/mm³]", "z − z_ref [mm]", curves)


def _shearband(c: _Ctx, o: MeasureOutcome, opts):
    if c.al.control != "angle":
        o.skipped = f"needs the drive angle as matching control (states are matched by '{c.al.control}')"
        return
    if not c.pairs_a:
        o.skipped = "needs at least two aligned states"
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ra = ANALYSES["shearband"](c.fa, pairs=c.pairs_a, **opts)
        ob = dict(opts)
        ob.update({k: ra.options[k] for k in ("radii", "dr", "z_ref", "bins_z") if k in ra.options})
        rb = ANALYSES["shearband"](c.fb, pairs=c.pairs_b, **ob)
    o.result_a, o.result_b = ra, rb
    A, B = ra.tables["band"], rb.tables["band"]
    ba = {c.pair_of_a.get((int(r.frame0), int(r.frame1))): r for r in A.itertuples()}
    bb = {c.pair_of_b.get((int(r.frame0), int(r.frame1))): r for r in B.itertuples()}
    xs, za, zb, wa, wb = [], [], [], [], []
    for k in range(len(c.pairs_a)):
        if k in ba and k in bb:
            o.rows.append(c.row("shearband", "z_sb", rel_error(ba[k].z_sb, bb[k].z_sb), pair=k, unit="m"))
            o.rows.append(c.row("shearband", "w_sb", rel_error(ba[k].w_sb, bb[k].w_sb), pair=k, unit="m"))
            xs.append(c.st.value[c.pairs_idx[k][1]])
            za.append(ba[k].z_sb); zb.append(bb[k].z_sb); wa.append(ba[k].w_sb); wb.append(bb[k].w_sb)
        else:
            miss = [lab for lab, d in ((c.la, ba), (c.lb, bb)) if k not in d]
            o.rows.append(c.row("shearband", "z_sb", Distance("rel_error", np.nan, details={
                "reason": f"no successful erf fit in {', '.join(miss)}"}), pair=k, unit="m"))
    if len(xs) >= 2:
        o.rows.append(c.row("shearband", "z_sb over control", l2(xs, za, xs, zb), unit="m"))
        o.rows.append(c.row("shearband", "w_sb over control", l2(xs, wa, xs, wb), unit="m"))
    x = np.degrees(xs)
    o.overlay = _overlay("shear band position and width", "rotation angle [deg]", "[mm]",
                         [(x, np.array(za) * MM, f"z_sb {c.la}", "o-"), (x, np.array(zb) * MM, f"z_sb {c.lb}", "s--"),
                          (x, np.array(wa) * MM, f"w_sb {c.la}", "o-"), (x, np.array(wb) * MM, f"w_sb {c.lb}", "s--")])


def _per_pair_samples(c, o, name, res_a, res_b, table, columns, unit=""):
    A, B = res_a.tables[table], res_b.tables[table]
    ga = {c.pair_of_a.get((int(k0), int(k1))): g for (k0, k1), g in A.groupby(["frame0", "frame1"])}
    gb = {c.pair_of_b.get((int(k0), int(k1))): g for (k0, k1), g in B.groupby(["frame0", "frame1"])}
    last = None
    for k in range(len(c.pairs_a)):
        for col in columns:
            if k in ga and k in gb:
                o.rows.append(c.row(name, col, ks(ga[k][col], gb[k][col]), pair=k, unit=unit))
                last = k
    return ga, gb, last


def _run_pairs(c: _Ctx, o: MeasureOutcome, name: str, opts, shared=()):
    """Run analysis ``name`` on both sides over their aligned frame pairs. Options resolved on A
    (``shared``, e.g. the D²min cutoff from A's d50) are handed to B so both are measured alike."""
    ra = ANALYSES[name](c.fa, pairs=c.pairs_a, **opts)
    ob = dict(opts)
    for key in shared:
        ob.setdefault(key, ra.options[key])
    rb = ANALYSES[name](c.fb, pairs=c.pairs_b, **ob)
    o.result_a, o.result_b = ra, rb
    return ra, rb


def _displacements(c: _Ctx, o: MeasureOutcome, opts):
    if not c.pairs_a:
        o.skipped = "needs at least two aligned states"
        return
    ra, rb = _run_pairs(c, o, "displacements", opts)
    ga, gb, last = _per_pair_samples(c, o, "displacements", ra, rb, "particles", ["u"], "m")
    for k in range(len(c.pairs_a)):
        if k in ga and k in gb:
            o.rows.append(c.row("displacements", "median |u|", rel_error(np.nanmedian(ga[k].u), np.nanmedian(gb[k].u)),
                                pair=k, unit="m"))
    curves = []
    for k in ([last] if last is not None else []):
        for g, lab, sty in ((ga[k], c.la, "-"), (gb[k], c.lb, "--")):
            x, y = _ecdf(g.u_d50)
            curves.append((x, y, f"{lab} {c.pairs_idx[k]}", sty))
    o.overlay = _overlay("incremental displacement (last increment)", "|u| / d50", "CDF", curves, logx=True)


def _d2min(c: _Ctx, o: MeasureOutcome, opts):
    if not c.pairs_a:
        o.skipped = "needs at least two aligned states"
        return
    ra, rb = _run_pairs(c, o, "d2min", opts, shared=("cutoff",))
    ga, gb, last = _per_pair_samples(c, o, "d2min", ra, rb, "particles", ["d2min", "eps_q"])
    curves = []
    if last is not None:
        for g, lab, sty in ((ga[last], c.la, "-"), (gb[last], c.lb, "--")):
            x, y = _ecdf(g.d2min_d50)
            curves.append((x, y, f"D²min {lab}", sty))
            x, y = _ecdf(g.eps_q)
            curves.append((x, y, f"ε_q {lab}", sty))
    o.overlay = _overlay("D²min/d50² and ε_q (last increment)", "value", "CDF", curves, logx=True)


def _clusters(c: _Ctx, o: MeasureOutcome, opts):
    if not c.pairs_a:
        o.skipped = "needs at least two aligned states"
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ra, rb = _run_pairs(c, o, "clusters", opts, shared=("cutoff",))
    o.rows.append(c.row("clusters", "cluster size s (pooled)", ks(ra.tables["clusters"]["size"], rb.tables["clusters"]["size"])))
    for q in ("tau", "d_f"):
        o.rows.append(c.row("clusters", q, rel_error(ra.scalars.get(q, np.nan), rb.scalars.get(q, np.nan))))
    curves = []
    for res, lab, sty in ((ra, c.la, "o-"), (rb, c.lb, "s--")):
        sd = res.tables["size_distribution"]
        curves.append((sd.s, sd.p, lab, sty))
    o.overlay = _overlay("cluster size distribution P(s)", "s", "P(s)", curves, logx=True, logy=True)


def _geom_opts(c: _Ctx, opts):
    o = dict(opts)
    if not (_has_contacts(c.fa) and _has_contacts(c.fb)):
        o.setdefault("source", "geometry")
        o.setdefault("tolerance", 0.02)
    return o


def _coordination(c: _Ctx, o: MeasureOutcome, opts):
    opts = _geom_opts(c, opts)
    ra = ANALYSES["coordination"](c.fa, at=c.single_a, **opts)
    rb = ANALYSES["coordination"](c.fb, at=c.single_b, **opts)
    o.result_a, o.result_b = ra, rb
    curves = []
    for s, ka, kb in zip(c.single, c.single_a, c.single_b):
        pa, pb = ra.tables["particles"], rb.tables["particles"]
        o.rows.append(c.row("coordination", "Z", ks(pa[pa.frame == ka].z, pb[pb.frame == kb].z), state=s))
        sa, sb = ra.tables["summary"], rb.tables["summary"]
        o.rows.append(c.row("coordination", "mean Z", rel_error(sa[sa.frame == ka].mean_z.iloc[0],
                                                                sb[sb.frame == kb].mean_z.iloc[0]), state=s))
        da, db = ra.tables["distribution"], rb.tables["distribution"]
        v = c.st.value[s]
        curves += [(da[da.frame == ka].z, da[da.frame == ka].p, f"{c.la} @ {v:.4g}", "o-"),
                   (db[db.frame == kb].z, db[db.frame == kb].p, f"{c.lb} @ {v:.4g}", "s--")]
    o.overlay = _overlay(f"coordination number ({opts.get('source', 'auto')})", "Z", "P(Z)", curves)


def _fabric(c: _Ctx, o: MeasureOutcome, opts):
    opts = _geom_opts(c, opts)
    ra = ANALYSES["fabric"](c.fa, at=c.single_a, **opts)
    ob = dict(opts)
    ob.update({k: ra.options[k] for k in ("plane", "bins") if k in ra.options})
    rb = ANALYSES["fabric"](c.fb, at=c.single_b, **ob)
    o.result_a, o.result_b = ra, rb
    curves = []
    for s, ka, kb in zip(c.single, c.single_a, c.single_b):
        A, B = ra.tables["rose"], rb.tables["rose"]
        geometric = opts.get("source") == "geometry"       # normals are branch directions then
        for q in (("normal",) if geometric else ("normal", "branch")):
            a = A[(A.frame == ka) & (A.quantity == q)]
            b = B[(B.frame == kb) & (B.quantity == q)]
            if len(a) and len(b):
                o.rows.append(c.row("fabric", f"{q} rose", l2(a.psi, a.fraction, b.psi, b.fraction), state=s))
        ta, tb = ra.tables["tensor"], rb.tables["tensor"]
        o.rows.append(c.row("fabric", "a_c", rel_error(ta[ta.frame == ka].a_c.iloc[0], tb[tb.frame == kb].a_c.iloc[0]),
                            state=s))
        if s == c.single[-1]:
            a = A[(A.frame == ka) & (A.quantity == "normal")]
            b = B[(B.frame == kb) & (B.quantity == "normal")]
            curves = [(np.degrees(a.psi), a.fraction, c.la, "o-"), (np.degrees(b.psi), b.fraction, c.lb, "s--")]
    o.overlay = _overlay("contact-normal rose (last state)", "ψ [deg]", "fraction", curves)


def _rdf(c: _Ctx, o: MeasureOutcome, opts):
    ra = ANALYSES["rdf"](c.fa, at=c.single_a, **opts)
    ob = dict(opts)
    ob.update({k: ra.options[k] for k in ("r_max", "bins") if k in ra.options})
    rb = ANALYSES["rdf"](c.fb, at=c.single_b, **ob)
    o.result_a, o.result_b = ra, rb
    curves = []
    for s, ka, kb in zip(c.single, c.single_a, c.single_b):
        A, B = ra.tables["rdf"], rb.tables["rdf"]
        a, b = A[A.frame == ka], B[B.frame == kb]
        o.rows.append(c.row("rdf", "g(r)", l2(a.r, a.g, b.r, b.g), state=s))
        if s == c.single[-1]:
            curves = [(a.r_d50, a.g, c.la, "-"), (b.r_d50, b.g, c.lb, "--")]
    o.overlay = _overlay("pair correlation g(r) (last state)", "r / d50", "g(r)", curves)


def _friction(c: _Ctx, o: MeasureOutcome, opts):
    missing = [lab for lab, fr in ((c.la, c.fa), (c.lb, c.fb)) if not fr.wall_names]
    if missing:
        o.skipped = f"no wall force/torque series in {', '.join(missing)}"
        return
    ra = ANALYSES["friction"](c.fa, **opts)
    ob = dict(opts)
    ob.update({k: ra.options[k] for k in ("radius", "torque_wall", "force_wall", "geometry") if k in ra.options})
    if ob.get("torque_wall") not in c.fb.wall_names or ob.get("force_wall") not in c.fb.wall_names:
        o.skipped = f"{c.lb} lacks the walls {ob.get('torque_wall')}/{ob.get('force_wall')} used for {c.la}"
        return
    rb = ANALYSES["friction"](c.fb, **ob)
    o.result_a, o.result_b = ra, rb
    A, B = ra.tables["friction"], rb.tables["friction"]
    o.rows.append(c.row("friction", "mu_macro(t)", l2(A.time, A.mu, B.time, B.mu)))
    o.rows.append(c.row("friction", "mean mu_macro", rel_error(ra.scalars.get("mu_mean", np.nan),
                                                               rb.scalars.get("mu_mean", np.nan))))
    o.overlay = _overlay("macroscopic friction μ(t)", "t [s]", "μ_macro", [(A.time, A.mu, c.la, "-"), (B.time, B.mu, c.lb, "--")])


def _macro(c: _Ctx, o: MeasureOutcome, opts):
    skip = {c.al.control, "stage", "time", "step"}
    ctl = [k for k in c.fa.controls if k in c.fb.controls and k not in skip
           and np.isfinite(c.fa.controls[k]).any() and np.isfinite(c.fb.controls[k]).any()]
    walls = [w for w in c.fa.wall_names if w in c.fb.wall_names]
    if not ctl and not walls:
        o.skipped = "no control or wall series shared by both sides"
        return
    st = c.st
    curves = []
    x = st.value.to_numpy()
    for k in ctl:
        ya = np.asarray(c.fa.controls[k])[st.frame_a.to_numpy()]
        yb = np.asarray(c.fb.controls[k])[st.frame_b.to_numpy()]
        o.rows.append(c.row("macro", f"{k} vs {c.al.control}", l2(x, ya, x, yb)))
        curves += [(x, ya, f"{k} {c.la}", "o-"), (x, yb, f"{k} {c.lb}", "s--")]
    wall_curves = []
    for w in walls:
        A, B = c.fa.wall(w), c.fb.wall(w)
        for col in A.columns:
            # the loading-axis components and the drive: x/y components of a wall on the axis are noise
            if col == "time" or col not in B.columns or not (col.endswith("_z") or col == "angle"):
                continue
            a, b = A[col].to_numpy(float), B[col].to_numpy(float)
            if not (np.isfinite(a).any() and np.nanmax(np.abs(a)) > 0):
                continue
            o.rows.append(c.row("macro", f"wall {w}.{col}(t)", l2(A.time, a, B.time, b)))
            if col.endswith("_z") and len(wall_curves) < 6:
                wall_curves += [(A.time, a, f"{w}.{col} {c.la}", "-"), (B.time, b, f"{w}.{col} {c.lb}", "--")]
    if curves:
        o.overlay = _overlay(f"state variables vs {c.al.control}", c.al.control, "value", curves)
    else:
        fig, axes = _fig(ncols=max(1, len(wall_curves) // 2), w=4.2)
        for ax, (ca, cb) in zip(axes, zip(wall_curves[::2], wall_curves[1::2])):
            for xx, yy, lab, sty in (ca, cb):
                ax.plot(xx, yy, sty, label=lab)
            ax.set_xlabel("t [s]")
            ax.legend(fontsize=6)
        fig.suptitle("wall series (z components)", fontsize=10)
        o.overlay = fig


_FUNCS = {"profiles": _profiles, "shearband": _shearband, "displacements": _displacements, "d2min": _d2min,
          "clusters": _clusters, "coordination": _coordination, "fabric": _fabric, "rdf": _rdf,
          "friction": _friction, "macro": _macro}


def compute_measures(alignment, frames_a=None, frames_b=None, measures=None, options: dict | None = None,
                     raise_errors: bool = False) -> dict:
    """Compute ``measures`` (default :data:`MEASURES`) on both sides of an :class:`Alignment`.

    ``frames_a``/``frames_b`` default to the alignment's frames (give B's transformed copy when the
    alignment moved B). ``options``: ``{"states": "ends"|"all", "<measure>": {analysis options}}``.
    A measure that fails is recorded with its error and the others still run.
    Returns ``{name: MeasureOutcome}``.
    """
    options = dict(options or {})
    fa = frames_a if frames_a is not None else alignment.a.frames
    fb = frames_b if frames_b is not None else alignment.b.frames
    ctx = _Ctx(alignment, fa, fb, options)
    names = list(MEASURES if measures is None else measures)
    unknown = [m for m in names if m not in _FUNCS]
    if unknown:
        raise ValueError(f"unknown measure(s) {unknown}; known: {', '.join(MEASURES)}")
    out = {}
    for name in names:
        o = MeasureOutcome(name)
        t0 = time.perf_counter()
        try:
            _FUNCS[name](ctx, o, dict(options.get(name, {}) or {}))
        except Exception as exc:  # noqa: BLE001 - recorded in the report, the others still run
            if raise_errors:
                raise
            o.error = f"{type(exc).__name__}: {exc}"
            o.rows = []
            o.traceback = traceback.format_exc(limit=4)
        o.seconds = time.perf_counter() - t0
        out[name] = o
    return out
