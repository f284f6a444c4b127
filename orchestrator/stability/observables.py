"""The key observables of a run, per scene, for sweeps, convergence ladders and calibration.

- ``plane_shear``: steady-state μ_macro = |F_x|/|F_z| on the top wall (and its standard error),
  sample height and solid fraction in the steady state;
- ``shear_cell``: steady μ_macro (3T/(2RF) over the last half of the shear) and its block standard
  error, shear-band position and width (the steady fits averaged over the radii, with their spread
  over the radii), the final piston height, the axial density profile of the last frame;
- ``impact``: rebound speeds of every sphere.
Every observable is a float or a list of floats (profiles), SI units. Keys ending in ``_sem``,
``_std`` or ``_spread`` are a run's own uncertainty of the observable they extend (:data:`SPREAD_SUFFIXES`),
not observables to compare.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from ..frames import Frames
from ..scenes.plane_shear import mu_macro_series, steady_mu
from ..analysis.friction import analyze_friction
from ..analysis import parse_specs
from ..analysis.shearband import analyze_shearband
from ..analysis.triaxial import analyze_triaxial


#: suffixes of the keys that carry an observable's in-run uncertainty
SPREAD_SUFFIXES = ("_sem", "_std", "_spread")


def observables(case, run_dir) -> dict:
    run_dir = Path(run_dir)
    fr = Frames(run_dir / "frames.h5")
    params = json.loads((run_dir / "params.json").read_text())
    kind = case.scene.kind
    if kind == "plane_shear":
        return _plane_shear(case, fr, params)
    if kind == "shear_cell":
        return _shear_cell(case, fr, params)
    if kind == "triaxial":
        return _triaxial(case, fr)
    if kind == "impact":
        v = fr.velocity[-1]
        return {"rebound_speed": [float(x) for x in np.linalg.norm(v, axis=1)]}
    return {}


def _plane_shear(case, fr, params) -> dict:
    st = steady_mu(fr, params)
    df = mu_macro_series(fr)
    sc = params["scene"]
    sel = df[df.strain >= sc["steady_from_strain"]]
    g = sc["geometry"]
    H = float(sel["z_top"].mean() - g["z_bottom"] - g["d_wall"]) if len(sel) else float("nan")
    r = fr.radius[: sc["n_mobile"]]
    phi = float(np.sum(4 / 3 * np.pi * r ** 3) / (g["L"] ** 2 * H)) if H > 0 else float("nan")
    return {"mu_macro": st["mu"], "mu_macro_sem": st["sem"], "mu_macro_std": st["std"], "height": H,
            "solid_fraction_nominal": phi, "normal_stress_error": st.get("normal_stress_rel_error", float("nan"))}


def _shear_cell(case, fr, params) -> dict:
    out = {}
    sc = params["scene"]
    # mu_macro as the case's own `friction` analysis computes it (same radius: the sample's, by
    # default; same steady window), so that the ladder and the run report print the same number
    opts = {"torque_wall": "rotating", "force_wall": "lower_piston", "steady_control": "angle",
            "steady_from": 0.5 * case.scene.final_angle}
    opts.update(next((o for n, o in parse_specs(case.analysis) if n == "friction"), {}))
    try:
        res = analyze_friction(fr, **opts)
        out["mu_macro"] = float(res.scalars["mu_mean"])
        out["mu_macro_std"] = float(res.scalars["mu_std"])          # in-run spreads: of the samples,
        out["mu_macro_sem"] = float(res.scalars["mu_sem"])          # of their mean (block means)
    except Exception as exc:
        out["mu_macro_error"] = str(exc)
    try:
        res = analyze_shearband(fr, **next((o for n, o in parse_specs(case.analysis) if n == "shearband"), {}))
        # steady band (seed 000 Fig. 2): the r-averaged steady position and width; a single
        # frame pair's fit (z_sb_last) scatters by ~20 um on the small case
        st = res.tables.get("steady")
        if st is not None and len(st) and np.isfinite(st["z_sb"]).any():
            out["shearband_z"] = float(np.nanmean(st["z_sb"]))
            out["shearband_width"] = float(np.nanmean(st["w_sb"]))
            # in-run spread: the steady fits' scatter over the radii r̃
            out["shearband_z_spread"] = float(np.nanstd(st["z_sb"], ddof=1)) if len(st) > 1 else float("nan")
            out["shearband_width_spread"] = float(np.nanstd(st["w_sb"], ddof=1)) if len(st) > 1 else float("nan")
        else:
            out["shearband_z"] = float(res.scalars.get("z_sb_last", float("nan")))
            out["shearband_width"] = float(res.scalars.get("w_sb_last", float("nan")))
    except Exception as exc:
        out["shearband_error"] = str(exc)
    # axial number-density profile of the last frame (10 bins between the plate faces)
    p = fr.position[-1]
    ok = ~np.isnan(p).any(1)
    z = p[ok, 2]
    # bins between the lower piston face at the end and the upper face: comparable across runs
    z_lo = 0.0
    try:
        z_lo = float(fr.wall("lower_piston")["position_z"].iloc[-1])
        out["piston_z"] = z_lo          # final lower-piston face height [m] (piston travel)
    except Exception:
        pass
    edges = np.linspace(z_lo, sc["geometry"]["z_upper_face"], 11)
    h, _ = np.histogram(z, edges)
    out["density_profile"] = [float(x) for x in h / max(1, ok.sum())]
    return out


#: axial strains at which the triaxial ladder compares σ1/σ3 and ε_v (issue #14)
TRIAXIAL_STRAINS = (0.01, 0.02, 0.05, 0.10, 0.15)


def _triaxial(case, fr) -> dict:
    """σ1/σ3 (smoothed) and ε_v (compression positive) at the axial strains of
    :data:`TRIAXIAL_STRAINS` reached by the run, and the peak and residual friction angles [deg]."""
    res = analyze_triaxial(fr)
    c = res.tables["curves"]
    ea = c["axial_strain"].to_numpy()
    out = {"peak_friction_angle_deg": res.scalars["peak_friction_angle_deg"],
           "residual_friction_angle_deg": res.scalars["residual_friction_angle_deg"]}
    for e in TRIAXIAL_STRAINS:
        if ea.size and ea.max() >= e * (1 - 1e-3):       # a run to e measures e within ~1e-5 (platen position)
            out[f"stress_ratio@{e:g}"] = float(np.interp(e, ea, c["stress_ratio_smoothed"].to_numpy()))
            out[f"volumetric_strain@{e:g}"] = float(np.interp(e, ea, c["volumetric_strain"].to_numpy()))
    return out
