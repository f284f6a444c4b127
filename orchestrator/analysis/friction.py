"""Macroscopic friction coefficient μ_macro from wall torque and normal force (seed 000, §3.2).

For a cylindrical shear cell of radius R sheared over its whole cross-section with a uniform
shear stress τ and normal stress σ = F_N/(πR²), the torque is T = ∫₀ᴿ τ r 2πr dr = (2/3)πR³τ, so

    μ_macro = τ/σ = 3 T / (2 R F_N)       [-]

(``geometry="disc"``); for a thin annulus of mean radius R it is T/(R F_N) (``geometry="ring"``).
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from ..numerics import block_drift, block_sem
from ._common import Result
from .plots import plot_friction

__all__ = ["mu_macro", "analyze_friction"]


def mu_macro(torque, normal_force, radius: float, geometry: str = "disc") -> np.ndarray:
    """μ_macro from the torque about the cell axis T [N m], the normal force F_N [N] and the cell
    radius R [m]. Signs are ignored (magnitudes)."""
    T = np.abs(np.asarray(torque, float))
    F = np.abs(np.asarray(normal_force, float))
    k = {"disc": 1.5, "ring": 1.0}.get(geometry)
    if k is None:
        raise ValueError(f"geometry must be 'disc' or 'ring', got {geometry!r}")
    with np.errstate(invalid="ignore", divide="ignore"):
        return k * T / (float(radius) * F)


def _pick(frames, want: str, given):
    if given is not None:
        if given not in frames.wall_names:
            raise KeyError(f"{frames.path}: no wall {given!r}; walls: {frames.wall_names}")
        return given
    cands = []
    for n in frames.wall_names:
        cols = frames.wall(n).columns
        if f"{want}_z" in cols:
            s = np.nanmax(np.abs(frames.wall(n)[f"{want}_z"].to_numpy())) if len(frames.wall(n)) else 0
            cands.append((s, n))
    if not cands:
        raise KeyError(f"{frames.path}: no wall carries {want}_z; walls: {frames.wall_names} (give {want}_wall=...)")
    return max(cands)[1]


def analyze_friction(frames, radius: float | None = None, torque_wall: str | None = None,
                     force_wall: str | None = None, geometry: str = "disc", steady_from: float | None = None,
                     steady_control: str = "time") -> Result:
    """μ_macro(t) from wall time series, and its steady-state mean ± standard deviation.

    Options: ``radius`` [m] (default: largest particle-centre distance from the axis plus radius
    in frame 0), ``torque_wall`` / ``force_wall`` (wall names; default the wall with the largest
    |torque_z| / |force_z|), ``geometry`` ("disc" or "ring"), ``steady_from`` (value of
    ``steady_control``: "time" [s] or "angle" [rad] of the torque wall, from which to average).

    Tables: ``friction`` (time, angle if known, torque [N m], normal_force [N], mu).
    Scalars: ``mu_mean``, ``mu_std`` (of the samples), ``mu_sem`` (standard error of the mean from 8
    block means: the samples are correlated, :func:`orchestrator.numerics.block_sem`), ``n``, and the
    steadiness of the window: ``mu_drift`` ± ``mu_drift_se``, the change of μ across it from a line
    through the 8 block means (:func:`orchestrator.numerics.block_drift`), and ``mu_steady``,
    |drift| ≤ 2 standard errors (no trend the window's own fluctuations do not explain).
    """
    tw = _pick(frames, "torque", torque_wall)
    fw = _pick(frames, "force", force_wall)
    wt, wf = frames.wall(tw), frames.wall(fw)
    if radius is None:
        p = frames.position[0]
        ok = ~np.isnan(p).any(1)
        c = 0.5 * (np.nanmin(p[ok, :2], 0) + np.nanmax(p[ok, :2], 0))
        radius = float(np.max(np.hypot(p[ok, 0] - c[0], p[ok, 1] - c[1]) + frames.radius[ok]))
    t = wt["time"].to_numpy()
    T = wt["torque_z"].to_numpy()
    F = np.interp(t, wf["time"].to_numpy(), wf["force_z"].to_numpy()) if len(wf) else np.full_like(t, np.nan)
    df = pd.DataFrame({"time": t, "torque": T, "normal_force": F, "mu": mu_macro(T, F, radius, geometry)})
    if "angle" in wt.columns:
        df.insert(1, "angle", wt["angle"].to_numpy())
    sel = df
    if steady_from is not None:
        if steady_control not in df.columns:
            raise KeyError(f"friction: steady_control {steady_control!r} not available; use one of {list(df.columns[:2])}")
        sel = df[df[steady_control] >= steady_from]
    mu = sel["mu"].to_numpy()
    mu = mu[np.isfinite(mu)]
    scal = {"mu_mean": float(mu.mean()) if mu.size else np.nan, "mu_std": float(mu.std(ddof=1)) if mu.size > 1 else np.nan,
            "mu_sem": block_sem(mu),
            "n": int(mu.size), "radius_m": radius, "torque_wall": tw, "force_wall": fw, "geometry": geometry}
    drift, drift_se = block_drift(mu)
    scal.update({"mu_drift": drift, "mu_drift_se": drift_se,
                 "mu_steady": bool(abs(drift) <= 2 * drift_se) if np.isfinite(drift_se) else None})
    return Result("friction", tables={"friction": df}, scalars=scal,
                  options={"radius": radius, "torque_wall": tw, "force_wall": fw, "geometry": geometry,
                           "steady_from": steady_from, "steady_control": steady_control}, plotter=plot_friction)
