"""One plot function per measure; each takes the measure's :class:`Result` and returns a
matplotlib :class:`~matplotlib.figure.Figure` (created without pyplot, so it works headless and
never opens a window; save with ``fig.savefig``). Lengths are shown in mm or in d50 as labelled.
"""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg", force=False)
import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator
from scipy.special import zeta
from ._fits import erf_profile, fractal_dimension, log_binned
from ..numerics import BLOCKS

__all__ = ["plot_d2min", "plot_rdf", "plot_coordination", "plot_clusters", "plot_profiles", "plot_shearband",
           "plot_friction", "plot_displacements", "plot_stress", "plot_fabric", "plot_forcechains",
           "plot_energy", "plot_triaxial"]

MM = 1e3


def _fig(ncols=1, nrows=1, w=5.0, h=3.8, polar=False):
    fig = Figure(figsize=(w * ncols, h * nrows), layout="constrained")
    axes = [fig.add_subplot(nrows, ncols, k + 1, projection="polar" if polar else None) for k in range(nrows * ncols)]
    return fig, axes


def _state(control: str | None, value: float) -> str:
    """A frame's state in its control's own terms, for a legend: ``ε_a = 1 %``, ``39.5°``,
    ``t = 0.12 s`` (controls in SI: strains as fractions, angles in rad)."""
    if control == "axial_strain":
        return f"ε_a = {100 * value:.3g} %"
    if control == "angle":
        return f"{np.degrees(value):.3g}°"
    if control == "shear_strain":
        return f"γ = {value:.3g}"
    if control == "time":
        return f"t = {value:.3g} s"
    return f"{value:.4g}"


def _control_axis(control: str | None) -> tuple[str, float]:
    """An axis label for a control and the factor from its SI values to the axis' (rad to deg)."""
    return {"axial_strain": ("axial strain ε_a", 1.0), "angle": ("angle [deg]", 180 / np.pi),
            "shear_strain": ("shear strain γ", 1.0), "time": ("time [s]", 1.0)}.get(control, (control or "control", 1.0))


def _label(g, col="control1"):
    return f"{g[col].iloc[0]:.4g}" if col in g else ""


def _log_pdf(ax, x, label, bins=40, color=None, floor_quantile=0.01):
    """Log-binned PDF of the positive finite values of ``x``, from their ``floor_quantile`` quantile
    up: below it lie the round-off values of grains that moved affinely (D²min ~ 1e-30), which
    would stretch the axis over tens of decades."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x) & (x > 0)]
    if x.size < 2:
        return
    lo = max(x.min(), float(np.quantile(x, floor_quantile)))
    x = x[x >= lo]
    if x.size < 2 or lo == x.max():
        return
    edges = np.geomspace(lo, x.max(), bins + 1)
    h, _ = np.histogram(x, edges, density=True)
    c = np.sqrt(edges[1:] * edges[:-1])
    ax.loglog(c[h > 0], h[h > 0], "o-", ms=3, label=label, color=color)


#: frame pairs drawn in a PDF plot at most (evenly spaced over the run; the tables keep them all)
MAX_CURVES = 8


def _spread(items, n=MAX_CURVES):
    """At most ``n`` of ``items``, evenly spaced, the first and the last kept."""
    items = list(items)
    if len(items) <= n:
        return items
    return [items[int(round(k))] for k in np.linspace(0, len(items) - 1, n)]


def plot_d2min(res, **kw):
    """PDFs of D²min/d50² and ε_q per frame pair (seed 001, Fig. 12): at most :data:`MAX_CURVES`
    pairs, evenly spaced, coloured from the first (dark) to the last."""
    t = res.tables["particles"]
    fig, (a1, a2) = _fig(2)
    pairs = _spread(t.groupby(["frame0", "frame1"]))
    colors = matplotlib.colormaps["viridis"](np.linspace(0, 0.9, max(len(pairs), 1)))
    for ((k0, k1), g), col in zip(pairs, colors):
        lab = f"{g['control0'].iloc[0]:.4g}→{g['control1'].iloc[0]:.4g}"
        _log_pdf(a1, g["d2min_d50"], lab, color=col)
        _log_pdf(a2, g["eps_q"], lab, color=col)
    a1.set_xlabel(r"$D^2_{min}/d_{50}^2$"); a1.set_ylabel("PDF")
    a2.set_xlabel(r"local deviatoric strain $\varepsilon_q$"); a2.set_ylabel("PDF")
    if a1.get_legend_handles_labels()[0]:     # no curve when every D²min vanished (an affine motion)
        a1.legend(fontsize=7, title=res.scalars.get("control", ""))
    return fig


def plot_rdf(res, **kw):
    """g(r) against r/d50 (seed 001, Fig. 6a)."""
    t = res.tables["rdf"]
    fig, (ax,) = _fig()
    for k, g in t.groupby("frame"):
        ax.errorbar(g["r_d50"], g["g"], yerr=g["g_err"], lw=1,
                    label=f"frame {k} ({_state(res.scalars.get('control'), g['control'].iloc[0])})")
    ax.axhline(1, color="k", lw=0.5)
    ax.set_xlabel(r"$r/d_{50}$"); ax.set_ylabel("g(r)")
    ax.set_title("edge-corrected" if res.scalars.get("edge_correction") else "no edge correction", fontsize=9)
    ax.legend(fontsize=7)
    return fig


def plot_coordination(res, **kw):
    """P(Z) per frame (seed 001, Fig. 6b)."""
    t = res.tables["distribution"]
    fig, (ax,) = _fig()
    ks = sorted(t["frame"].unique())
    w = 0.8 / max(len(ks), 1)
    for n, k in enumerate(ks):
        g = t[t["frame"] == k]
        ax.bar(g["z"] + (n - (len(ks) - 1) / 2) * w, g["p"], width=w,
               label=f"frame {k} ({_state(res.scalars.get('control'), g['control'].iloc[0])})")
    ax.set_xlabel("coordination number Z"); ax.set_ylabel("P(Z)")
    ax.legend(fontsize=7)
    return fig


def plot_clusters(res, **kw):
    """P(s) with the power-law fit and R_g(s) with the fractal fit (seed 001, Fig. 13c-d)."""
    sd = res.tables["size_distribution"]
    ct = res.tables["clusters"]
    fig, (a1, a2) = _fig(2)
    if len(sd):
        # every size as counted (its tail a floor of sizes seen once), and averaged over log bins
        a1.loglog(sd["s"], sd["p"], ".", ms=3, color="0.6", label="per size")
        a1.loglog(*log_binned(sd["s"], sd["p"]), "o", ms=5, color="C0", label="log-binned")
        tau = res.scalars.get("tau")
        if tau is not None and np.isfinite(tau):
            s = np.geomspace(max(sd["s"].min(), 1), sd["s"].max(), 50)
            smin = res.options.get("s_min", 1)
            frac = sd.loc[sd["s"] >= smin, "p"].sum()
            a1.loglog(s, frac * s ** (-tau) / zeta(tau, smin), "-", color="C1",
                      label=rf"$\tau$ = {tau:.2f} ± {res.scalars['tau_err']:.2f}")
        a1.legend(fontsize=8)
    a1.set_xlabel("cluster size s"); a1.set_ylabel("P(s)")
    if len(ct):
        # a one-grain cluster has R_g = 0 (its round-off, ~1e-15 mm, would stretch the axis): s >= 2
        m = (ct["rg"] > 0) & (ct["size"] >= 2)
        a2.loglog(ct.loc[m, "size"], ct.loc[m, "rg"] * MM, ".", ms=3, alpha=0.5)
        df = res.scalars.get("d_f")
        if df is not None and np.isfinite(df):
            f = fractal_dimension(ct["size"], ct["rg"], res.options.get("s_min_rg", 3))
            s = np.geomspace(max(res.options.get("s_min_rg", 3), 1), ct["size"].max(), 20)
            x, y = np.log(ct.loc[m & (ct["size"] >= res.options.get("s_min_rg", 3)), "size"]), np.log(ct.loc[m & (ct["size"] >= res.options.get("s_min_rg", 3)), "rg"])
            icpt = float(np.mean(y - f["slope"] * x)) if len(x) else 0.0
            a2.loglog(s, np.exp(icpt) * s ** f["slope"] * MM, "-", label=rf"$d_f$ = {df:.2f} ± {res.scalars['d_f_err']:.2f}")
            a2.legend(fontsize=8)
    a2.set_xlabel("cluster size s"); a2.set_ylabel(r"$R_g$ [mm]")
    return fig


def plot_profiles(res, **kw):
    """Axial and radial number density and volume fraction (seed 000, Fig. 1)."""
    ax_t, rad = res.tables["axial"], res.tables["radial"]
    fig, (a1, a2) = _fig(2)
    control = res.scalars.get("control", "")
    for k, g in ax_t.groupby("frame"):
        c = g["control"].iloc[0]
        # an angle control is stored in rad (frames.h5 is SI), shown in degrees
        lab = f"{np.degrees(c):.1f}°" if control == "angle" else f"{control} {c:.4g}".strip()
        a1.plot(g["n"] * 1e-9, g["z"] * MM, label=f"frame {k} ({lab})")
    a1.xaxis.set_major_locator(MaxNLocator(4))        # densities of 1e4-1e5 /mm³: few, readable ticks
    for k, g in rad.groupby("frame"):
        a2.plot(g["r"] * MM, g["n"] * 1e-9, label=f"frame {k}")
    a1.set_xlabel(r"n [1/mm$^3$]"); a1.set_ylabel("z [mm]"); a1.legend(fontsize=7)
    a2.set_xlabel("r [mm]"); a2.set_ylabel(r"n [1/mm$^3$]")
    a2b = a2.twinx()
    for k, g in rad.groupby("frame"):
        a2b.plot(g["r"] * MM, g["phi"], ":", lw=1)
    a2b.set_ylabel(r"$\phi$ (dotted)")
    return fig


def plot_shearband(res, **kw):
    """Profiles with erf fits at the last pair, z_sb and w_sb over the control, z_sb(r̃) at steady state (seed 000, Fig. 2)."""
    pr, ft, bd, st = (res.tables[k] for k in ("profiles", "fits", "band", "steady"))
    fig, (a1, a2, a3) = _fig(3, w=4.2)
    if len(pr):
        last = pr[pr["frame1"] == pr["frame1"].max()]
        for rt, g in last.groupby("r_tilde"):
            l = a1.errorbar(g["v"], g["z"] * MM, xerr=g["v_err"], fmt="o", ms=3, label=f"r̃={rt * MM:.2f} mm")
            f = ft[(ft["frame1"] == g["frame1"].iloc[0]) & (ft["r_tilde"] == rt)]
            if len(f) and f["ok"].iloc[0]:
                z = np.linspace(g["z"].min(), g["z"].max(), 200)
                a1.plot(erf_profile(z, f["z_sb"].iloc[0], f["w_sb"].iloc[0]), z * MM, "-", color=l[0].get_color())
        a1.legend(fontsize=7)
    a1.set_xlabel(r"$v_{\tilde\varphi}$"); a1.set_ylabel("z [mm]")
    control = res.scalars.get("control", "control")
    if len(bd):
        # an angle control is stored in rad (frames.h5 is SI); shown in degrees as seed 000's Fig. 2
        x = np.degrees(bd["control"]) if control == "angle" else bd["control"]
        a2.errorbar(x, bd["z_sb"] * MM, yerr=bd["z_sb_err"] * MM, fmt="o-", label=r"$z_{sb}$")
        a2.errorbar(x, bd["w_sb"] * MM, yerr=bd["w_sb_err"] * MM, fmt="s-", label=r"$w_{sb}$")
        a2.legend(fontsize=8)
    a2.set_xlabel("angle [deg]" if control == "angle" else control); a2.set_ylabel("mm")
    if len(st):
        a3.errorbar(st["r_tilde"] * MM, st["z_sb"] * MM, yerr=st["z_sb_err"] * MM, fmt="o-")
    a3.set_xlabel("r̃ [mm]"); a3.set_ylabel(r"steady $z_{sb}$ [mm]")
    return fig


def plot_friction(res, **kw):
    """μ_macro over time (or angle) with its steady-state mean."""
    t = res.tables["friction"]
    fig, (ax,) = _fig()
    x = "angle" if "angle" in t else "time"
    if x == "angle":                 # the stages before the rotation (angle 0) are not friction
        t = t[t["angle"] > 0]
    ax.plot(np.degrees(t[x]) if x == "angle" else t[x], t["mu"], lw=1)
    m = res.scalars.get("mu_mean")
    if m is not None and np.isfinite(m):
        ax.axhline(m, color="k", ls="--", lw=0.8, label=rf"$\mu_{{macro}}$ = {m:.3f} ± {res.scalars['mu_std']:.3f}")
        start = res.options.get("steady_from")
        if start is not None and len(t):      # the window the mean and its ± are taken over
            s0 = np.degrees(start) if res.options.get("steady_control") == "angle" else start
            s1 = np.degrees(t[x].max()) if x == "angle" else t[x].max()
            d, se, steady = (res.scalars.get(k) for k in ("mu_drift", "mu_drift_se", "mu_steady"))
            label = "steady window"
            if steady is not None:
                # the line through the window's block means (orchestrator.numerics.block_drift): its
                # drift runs from the first block's centre to the last's, nb - 1 of the nb blocks
                label += f": drift {d:+.3f} ± {se:.3f} ({'steady' if steady else 'not steady'})"
                nb = min(BLOCKS, int(res.scalars.get("n", BLOCKS)))
                half = 0.5 * d * nb / (nb - 1)
                ax.plot([s0, s1], [m - half, m + half], color="C3", lw=1, ls=":")
            ax.axvspan(s0, s1, color="0.9", zorder=0, label=label)
        ax.legend(fontsize=8)
    ax.set_xlabel("angle [deg]" if x == "angle" else "time [s]"); ax.set_ylabel(r"$\mu_{macro}$")
    return fig


def plot_displacements(res, **kw):
    """PDF of incremental displacement |u|/d50 and a box chart per increment (seed 001, Fig. 10)."""
    pdf, stt = res.tables["pdf"], res.tables["stats"]
    fig, (a1, a2) = _fig(2)
    for (k0, k1), g in pdf.groupby(["frame0", "frame1"]):
        m = g["pdf"] > 0
        a1.loglog(g.loc[m, "u_d50"], g.loc[m, "pdf"], "-", label=f"{k0}→{k1}")
    a1.set_xlabel(r"$|u|/d_{50}$"); a1.set_ylabel("PDF"); a1.legend(fontsize=7)
    d = res.scalars["d50_m"]
    stats = [{"med": r.median / d, "q1": r.p25 / d, "q3": r.p75 / d, "whislo": r.p05 / d, "whishi": r.p95 / d,
              "mean": r.mean / d, "label": f"{r.control0:.3g}–{r.control1:.3g}"} for r in stt.itertuples()]
    if stats:
        a2.bxp(stats, showfliers=False, showmeans=True)
        a2.tick_params(axis="x", labelrotation=45, labelsize=7)
    a2.set_ylabel(r"$|u|/d_{50}$")
    return fig


def plot_stress(res, **kw):
    """V against D²min with the correlation coefficient (seed 001, Fig. 16)."""
    v = res.tables["volatility"]
    fig, (ax,) = _fig()
    m = v["d2min"] > 0
    ax.hexbin(v.loc[m, "d2min"], v.loc[m, "V"], xscale="log", gridsize=40, mincnt=1, cmap="viridis")
    r = res.scalars.get("pearson_r")
    if r is not None:
        ax.set_title(f"Pearson r = {r:.3f} (p = {res.scalars['pearson_p']:.2g}), n = {res.scalars['n']}", fontsize=9)
    ax.set_xlabel(r"$D^2_{min}$ [m$^2$]"); ax.set_ylabel("stress volatility V")
    return fig


def plot_fabric(res, **kw):
    """Rose diagrams of branch vectors, contact normals and mean normal force (seed 001, Figs. 6c-d, 15a)."""
    r = res.tables["rose"]
    qs = [q for q in ("branch", "normal", "force") if q in set(r["quantity"])]
    fig, axes = _fig(len(qs), w=3.6, h=3.6, polar=True)
    for ax, q in zip(axes, qs):
        for k, g in r[r["quantity"] == q].groupby("frame"):
            y = g["mean"] if q == "force" else g["density"]
            ax.plot(np.r_[g["psi"], g["psi"].iloc[0]], np.r_[y, y.iloc[0]], label=f"frame {k}")
        ax.set_title({"branch": "branch vectors", "normal": "contact normals", "force": "mean normal force [N]"}[q], fontsize=9)
        ax.yaxis.set_major_locator(MaxNLocator(3))     # radial labels: a few, not one per grid circle
        ax.tick_params(axis="y", labelsize=7)
    axes[0].legend(fontsize=7, loc="lower left")
    fig.suptitle(f"plane {res.scalars.get('plane', '')} (angle from the first axis)", fontsize=9)
    return fig


def plot_forcechains(res, **kw):
    """Chain links projected on a plane, line width ∝ normal force (seed 001, Fig. 15b-c)."""
    L = res.tables["links"]
    plane = res.options.get("plane", "xz")
    a, b = plane[0], plane[1]
    ks = sorted(L["frame"].unique()) or [0]
    fig, axes = _fig(len(ks), w=4, h=4)
    from matplotlib.collections import LineCollection
    for ax, k in zip(axes, ks):
        g = L[L["frame"] == k]
        if len(g):
            seg = np.stack([np.c_[g[f"{a}_i"], g[f"{b}_i"]], np.c_[g[f"{a}_j"], g[f"{b}_j"]]], 1) * MM
            f = g["fn"].to_numpy()
            lw = 0.5 + 3 * (f / np.nanmax(f) if np.isfinite(f).any() and np.nanmax(f) > 0 else np.ones_like(f))
            ax.add_collection(LineCollection(seg, linewidths=np.nan_to_num(lw, nan=1.0), colors="k"))
            ax.autoscale()
        ax.set_aspect("equal")
        ax.set_xlabel(f"{a} [mm]"); ax.set_ylabel(f"{b} [mm]"); ax.set_title(f"frame {k}", fontsize=9)
    return fig


def plot_energy(res, **kw):
    """K/U per frame (log scale) against the control, with the seed's quasi-static bound."""
    s = res.tables["summary"]
    fig, (ax,) = _fig()
    xlabel, scale = _control_axis(res.scalars.get("control"))
    ax.semilogy(s["control"] * scale, s["ratio"], "o-", ms=3, label="K / U (kinetic / Hertz elastic)")
    ax.semilogy(s["control"] * scale, s["ratio_nonaffine"], "s-", ms=3, label="K' / U (non-affine kinetic)")
    ax.axhline(res.scalars["limit"], color="k", ls="--", lw=1, label=f"seed 001 §3.2 bound {res.scalars['limit']:g}")
    ax.set_xlabel(xlabel); ax.set_ylabel("K / U")
    ax.legend(fontsize=8)
    return fig


def plot_triaxial(res, others=(), label=None, **kw):
    """σ1/σ3 (smoothed; raw rows faint) and ε_v against ε_a; ``others``: (label, Result) pairs to overlay."""
    fig, (a1, a2) = _fig(ncols=2)
    for k, (lab, r) in enumerate([(label, res), *others]):
        c = r.tables["curves"]
        col = f"C{k}"
        a1.plot(c["axial_strain"], c["stress_ratio"], color=col, alpha=0.2, lw=0.5)
        a1.plot(c["axial_strain"], c["stress_ratio_smoothed"], color=col, lw=1.5,
                label=f"{lab + ': ' if lab else ''}peak {r.scalars['peak_stress_ratio']:.2f} "
                      f"(φ {r.scalars['peak_friction_angle_deg']:.1f}°)")
        a2.plot(c["axial_strain"], c["volumetric_strain_smoothed"], color=col, lw=1.5, label=lab)
    a1.set_xlabel("axial strain ε_a"); a1.set_ylabel("σ1/σ3")
    a2.set_xlabel("axial strain ε_a"); a2.set_ylabel("volumetric strain ε_v (compression > 0)")
    a2.axhline(0, color="k", lw=0.5)
    a1.legend(fontsize=8)
    if others:
        a2.legend(fontsize=8)
    return fig
