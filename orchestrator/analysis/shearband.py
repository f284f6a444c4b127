"""Shear-band position and width from normalised angular-velocity profiles (seed 000, eq. 2).

For a frame pair (k0, k1) each particle's rotation Δθ_i about the rotation centre c (which may be
off the cell axis: give it, or let it be fitted from the displacements) is divided by the
driving rotation Δθ_drive (the ``angle`` control of the frames, or the largest bin value), giving
v_φ̃ = ω_i / ω_drive. At fixed radial distances r̃ (rings of half-width ``dr``) the mean v_φ̃ in
height bins is fitted with

    v_φ̃(z) = ½ + ½ erf((z − z_sb) / w_sb)                                (eq. 2)

by weighted least squares (weights: standard error of each bin mean), giving z_sb and w_sb [m]
with standard errors. Over time, the fits are averaged over r̃ (inverse-variance weights); at
steady state (control >= ``steady_from``, seed 000: ωt = 10°) z_sb(r̃) is averaged over frames.
If velocities are in the frames (``use_velocity=True``), ω_i = (r × v)_z / r² at one frame
replaces the finite difference.
"""
from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
from scipy import optimize

from ._fits import erf_profile
from ._common import Result, control_values, frame_pairs, present
from .plots import plot_shearband

__all__ = ["erf_profile", "fit_erf_profile", "rotation_center", "angular_profiles", "analyze_shearband"]


def fit_erf_profile(z, v, sigma=None) -> dict:
    """Weighted least-squares fit of eq. 2 to a profile v(z).

    ``sigma``: standard errors of v (absolute); if None, unweighted and the parameter errors are
    scaled by the residual variance. Returns ``z_sb``, ``z_sb_err``, ``w_sb``, ``w_sb_err`` [m],
    ``chi2_red`` and ``ok`` (False when the fit failed or the profile does not span the band).
    """
    z = np.asarray(z, float)
    v = np.asarray(v, float)
    m = np.isfinite(z) & np.isfinite(v)
    if sigma is not None:
        sigma = np.asarray(sigma, float)
        m &= np.isfinite(sigma) & (sigma > 0)
        sigma = sigma[m]
    z, v = z[m], v[m]
    bad = {"z_sb": np.nan, "z_sb_err": np.nan, "w_sb": np.nan, "w_sb_err": np.nan, "chi2_red": np.nan, "ok": False}
    if len(z) < 4:
        return bad
    span = np.ptp(z)
    # initial guess: where the profile crosses 1/2, width from the 16–84 % rise
    order = np.argsort(z)
    zs, vs = z[order], v[order]
    z0 = float(zs[np.argmin(np.abs(vs - 0.5))])
    w0 = max(span / 10, 1e-12)
    try:
        with warnings.catch_warnings():      # an undetermined fit is reported by `ok`, not a warning
            warnings.simplefilter("ignore", optimize.OptimizeWarning)
            p, cov = optimize.curve_fit(erf_profile, z, v, p0=[z0, w0], sigma=sigma,
                                        absolute_sigma=sigma is not None, maxfev=20000)
    except (RuntimeError, ValueError):
        return bad
    res = (v - erf_profile(z, *p)) / (sigma if sigma is not None else 1.0)
    dof = max(len(z) - 2, 1)
    chi2 = float(np.sum(res ** 2) / dof)
    err = np.sqrt(np.diag(cov))
    w = abs(p[1])
    # a fit is usable only when it is determined: finite errors smaller than the profile's span
    ok = bool(np.all(np.isfinite(err)) and zs[0] <= p[0] <= zs[-1] and w < 2 * span
              and err[0] < span and err[1] < span)
    return {"z_sb": float(p[0]), "z_sb_err": float(err[0]), "w_sb": float(w), "w_sb_err": float(err[1]),
            "chi2_red": chi2, "ok": ok}


def rotation_center(p0: np.ndarray, p1: np.ndarray, mask=None) -> tuple[float, float, float]:
    """Fit a rigid rotation about a vertical axis to the displacements of (masked) particles.

    Solves d_x = −Δθ y + a, d_y = Δθ x − b (small-angle) in the least-squares sense;
    returns (c_x, c_y, Δθ) with c = (b/Δθ, a/Δθ).
    """
    p0 = np.asarray(p0, float)
    p1 = np.asarray(p1, float)
    m = present(p0) & present(p1)
    if mask is not None:
        m &= mask
    x, y = p0[m, 0], p0[m, 1]
    d = p1[m] - p0[m]
    n = m.sum()
    A = np.zeros((2 * n, 3))
    A[:n, 0], A[:n, 1] = -y, 1.0
    A[n:, 0], A[n:, 2] = x, -1.0
    rhs = np.r_[d[:, 0], d[:, 1]]
    (dth, a, b), *_ = np.linalg.lstsq(A, rhs, rcond=None)
    if abs(dth) < 1e-15:
        raise ValueError("rotation_center: the selected particles did not rotate")
    return float(b / dth), float(a / dth), float(dth)


def angular_profiles(p0, p1, center, drive: float, radii, dr: float, z_edges, z_ref: float = 0.0,
                     min_count: int = 3) -> pd.DataFrame:
    """Mean normalised angular velocity Δθ_i / drive in (r̃, z) bins.

    p0, p1 : (N, 3) positions [m]; center (x, y) [m]; drive : driving rotation [rad] over the
    same interval; radii : ring centres r̃ [m]; dr : ring half-width [m]; z_edges [m] (relative
    to z_ref). Returns a DataFrame r_tilde, z, v, v_err (standard error of the mean), count.
    """
    p0 = np.asarray(p0, float)
    p1 = np.asarray(p1, float)
    m = present(p0) & present(p1)
    a0 = p0[m, :2] - center
    a1 = p1[m, :2] - center
    dth = np.arctan2(a0[:, 0] * a1[:, 1] - a0[:, 1] * a1[:, 0], np.einsum("ij,ij->i", a0, a1))
    v = dth / drive
    rr = np.hypot(a0[:, 0], a0[:, 1])
    zz = 0.5 * (p0[m, 2] + p1[m, 2]) - z_ref
    zc = 0.5 * (z_edges[1:] + z_edges[:-1])
    out = []
    for rt in np.atleast_1d(radii):
        ring = np.abs(rr - rt) <= dr
        b = np.digitize(zz[ring], z_edges) - 1
        good = (b >= 0) & (b < len(zc))
        b, vv = b[good], v[ring][good]
        cnt = np.bincount(b, minlength=len(zc))
        s1 = np.bincount(b, weights=vv, minlength=len(zc))
        s2 = np.bincount(b, weights=vv ** 2, minlength=len(zc))
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = s1 / cnt
            var = (s2 - cnt * mean ** 2) / (cnt - 1)
            sem = np.sqrt(np.clip(var, 0, None) / cnt)
        keep = cnt >= min_count
        out.append(pd.DataFrame({"r_tilde": rt, "z": zc[keep], "v": mean[keep], "v_err": sem[keep], "count": cnt[keep]}))
    return pd.concat(out, ignore_index=True)


def analyze_shearband(frames, radii=None, dr: float | None = None, n_radii: int = 4, center="fit",
                      z_ref: float = 0.0, z_range=None, bins_z: int = 30, pairs=None, interval=None,
                      stride: int = 1, control: str | None = None, drive="angle",
                      steady_from: float | None = None, top_fraction: float = 0.1,
                      stages: str = "loading") -> Result:
    """Shear band z_sb, w_sb over time and z_sb(r̃) at steady state (seed 000, eq. 2).

    Options (SI): ``radii`` r̃ [m] (default ``n_radii`` rings between 0.2 and 0.8 of the cell
    radius), ``dr`` ring half-width [m] (default half the ring spacing); ``center``: (x, y) [m],
    "axis" (bounding-box centre) or "fit" (rigid-rotation fit to the top ``top_fraction`` of
    particles by height, which co-rotate with the upper piston); ``z_ref`` (seed: vanes' top edge);
    ``z_range``, ``bins_z``; frame pairs as in D²min (``pairs``/``interval``/``stride``/``stages``:
    by default from the piston at rest before the rotation on);
    ``drive``: name of the control holding the driving rotation [rad] (default "angle"), a number
    [rad] per pair, or "max" (normalise by the largest bin mean); ``steady_from``: control value
    from which the state is steady (seed 000: 10° = 0.1745 rad).

    Tables: ``profiles`` (frame0, frame1, control, r_tilde, z, v, v_err, count), ``fits`` (per pair
    and r̃: z_sb, z_sb_err, w_sb, w_sb_err, chi2_red, ok), ``band`` (per pair: r̃-averaged z_sb,
    w_sb with errors), ``steady`` (r_tilde, z_sb, z_sb_err, w_sb, w_sb_err, n_fits).
    """
    cname, cvals = control_values(frames, control)
    pos = frames.position
    prs = frame_pairs(frames, pairs, interval, None, control, stride, stages)
    if isinstance(drive, str) and drive in frames.controls:
        # only pairs across which the cell turned (frames before shearing have no rotation)
        prs = [(a, b) for a, b in prs if frames.controls[drive][b] != frames.controls[drive][a]]
        if not prs:
            raise ValueError(f"shearband: the control {drive!r} does not change between any frame pair")
    first = pos[prs[0][0]]
    ok0 = present(first)
    lo, hi = np.nanmin(first[ok0], 0), np.nanmax(first[ok0], 0)
    axis_c = np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])])
    rcell = float(np.max(np.hypot(first[ok0, 0] - axis_c[0], first[ok0, 1] - axis_c[1])))
    if z_range is None:
        z_range = (float(lo[2] - z_ref), float(hi[2] - z_ref))
    z_edges = np.linspace(z_range[0], z_range[1], bins_z + 1)
    if radii is None:
        radii = np.linspace(0.2, 0.8, n_radii) * rcell
    radii = np.atleast_1d(np.asarray(radii, float))
    if dr is None:
        dr = 0.5 * (np.min(np.diff(radii)) if len(radii) > 1 else 0.2 * rcell)
    prof, fits, band = [], [], []
    for k0, k1 in prs:
        p0, p1 = pos[k0], pos[k1]
        if isinstance(drive, str) and drive not in ("max",):
            if drive not in frames.controls:
                raise KeyError(f"shearband: no control {drive!r} for the driving rotation; give drive=<rad> or 'max'")
            dth = float(frames.controls[drive][k1] - frames.controls[drive][k0])
        elif drive == "max":
            dth = 1.0
        else:
            dth = float(drive)
        if dth == 0:             # no driving rotation between these frames (before shearing)
            continue
        if isinstance(center, str) and center == "fit":
            zz = p0[:, 2]
            top = present(p0) & (zz >= np.nanquantile(zz, 1 - top_fraction))
            cx, cy, _ = rotation_center(p0, p1, top)
            c = np.array([cx, cy])
        elif isinstance(center, str) and center == "axis":
            c = axis_c
        else:
            c = np.asarray(center, float)[:2]
        pr = angular_profiles(p0, p1, c, dth, radii, dr, z_edges, z_ref)
        if drive == "max":
            vmax = pr.groupby("r_tilde")["v"].transform("max")
            pr["v"] /= vmax
            pr["v_err"] /= vmax
        pr.insert(0, "control", cvals[k1])
        pr.insert(0, "frame1", k1)
        pr.insert(0, "frame0", k0)
        prof.append(pr)
        rows = []
        for rt, g in pr.groupby("r_tilde"):
            f = fit_erf_profile(g["z"], g["v"], g["v_err"].where(g["v_err"] > 0))
            rows.append({"frame0": k0, "frame1": k1, "control": cvals[k1], "r_tilde": rt,
                         "center_x": c[0], "center_y": c[1], **f})
        fits.extend(rows)
        good = [r for r in rows if r["ok"]]
        if good:
            zs = np.array([r["z_sb"] for r in good]); ze = np.array([r["z_sb_err"] for r in good])
            ws = np.array([r["w_sb"] for r in good]); we = np.array([r["w_sb_err"] for r in good])
            wz, ww = 1 / ze ** 2, 1 / we ** 2
            band.append({"frame0": k0, "frame1": k1, "control": cvals[k1],
                         "z_sb": float(np.sum(wz * zs) / wz.sum()), "z_sb_err": float(1 / np.sqrt(wz.sum())),
                         "w_sb": float(np.sum(ww * ws) / ww.sum()), "w_sb_err": float(1 / np.sqrt(ww.sum())),
                         "n_radii": len(good)})
    ft = pd.DataFrame(fits)
    bt = pd.DataFrame(band)
    steady = []
    if len(ft):
        sel = ft[ft["ok"]]
        if steady_from is not None:
            sel = sel[sel["control"] >= steady_from]
        for rt, g in sel.groupby("r_tilde"):
            wz = 1 / g["z_sb_err"].to_numpy() ** 2
            ww = 1 / g["w_sb_err"].to_numpy() ** 2
            steady.append({"r_tilde": rt, "z_sb": float(np.sum(wz * g["z_sb"]) / wz.sum()),
                           "z_sb_err": float(1 / np.sqrt(wz.sum())), "z_sb_std": float(g["z_sb"].std(ddof=1)) if len(g) > 1 else np.nan,
                           "w_sb": float(np.sum(ww * g["w_sb"]) / ww.sum()), "w_sb_err": float(1 / np.sqrt(ww.sum())),
                           "n_fits": int(len(g))})
    st = pd.DataFrame(steady)
    scal = {"control": cname, "cell_radius": rcell}
    if len(bt):
        scal.update({"z_sb_last": float(bt["z_sb"].iloc[-1]), "w_sb_last": float(bt["w_sb"].iloc[-1])})
    return Result("shearband", tables={"profiles": pd.concat(prof, ignore_index=True) if prof else pd.DataFrame(),
                                       "fits": ft, "band": bt, "steady": st},
                  scalars=scal, options={"radii": radii.tolist(), "dr": dr, "z_ref": z_ref, "bins_z": bins_z,
                                         "drive": drive, "steady_from": steady_from}, plotter=plot_shearband)
