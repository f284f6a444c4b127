"""Stress–strain–volume curves of a triaxial test (seed 001, §4.1, Fig. 8) from the ``triaxial``
wall series of the frames (every time-series row, not only the frames).

Conventions (docs/triaxial.md): compression positive; ε_a = (H0 − H)/H0 and ε_v = (V0 − V)/V0
referenced to the end of isotropic compression; σ1 the axial, σ3 the lateral stress [Pa].

Derived figures (standard soil-mechanics definitions):

- the mobilised friction angle φ = asin((R − 1)/(R + 1)) with R = σ1/σ3 (Mohr–Coulomb, cohesionless);
- the dilatancy angle ψ = asin(−ε̇_v / (2 ε̇_a − ε̇_v)) (Vermeer & de Borst 1984, triaxial form,
  compression positive), with dε_v/dε_a fitted over a 1 % window of axial strain;
- a running mean over ``smoothing_rows`` rows damps the row-to-row noise of instantaneous contact
  forces (the same window as the scene summary's ``sigma3_error_max_abs_smoothed``).
"""
from __future__ import annotations

import numpy as np

from ..numerics import running_mean
import pandas as pd

from ._common import Result
from .plots import plot_triaxial
from ..frames import Frames

__all__ = ["running_mean", "local_slope", "friction_angle", "dilatancy_angle", "triaxial_curves", "analyze_triaxial",
           "plot_triaxial_runs"]


def friction_angle(stress_ratio) -> np.ndarray:
    """Mobilised friction angle [rad] from R = σ1/σ3: asin((R − 1)/(R + 1))."""
    r = np.asarray(stress_ratio, float)
    return np.arcsin(np.clip((r - 1.0) / (r + 1.0), -1.0, 1.0))


def local_slope(x, y, window: float) -> np.ndarray:
    """dy/dx at every sample from a least-squares line through the samples with |x − x_k| ≤ window/2."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    order = np.argsort(x, kind="stable")
    xs, ys = x[order], y[order]
    c = [np.concatenate([[0.0], np.cumsum(v)]) for v in (np.ones_like(xs), xs, ys, xs * xs, xs * ys)]
    lo = np.searchsorted(xs, xs - 0.5 * window, "left")
    hi = np.searchsorted(xs, xs + 0.5 * window, "right")
    n, sx, sy, sxx, sxy = ((ci[hi] - ci[lo]) for ci in c)
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = (n * sxy - sx * sy) / (n * sxx - sx * sx)
    out = np.empty_like(slope)
    out[order] = slope
    return out


def dilatancy_angle(axial_strain, volumetric_strain, window: float = 0.01) -> np.ndarray:
    """Dilatancy angle [rad] along a curve: asin(−dε_v / (2 dε_a − dε_v)), compression positive
    (Vermeer & de Borst 1984); > 0 while the sample dilates. dε_v/dε_a is the slope of a straight
    line fitted over ``window`` of axial strain around each point (1 %: seed 001's increment)."""
    d = local_slope(axial_strain, volumetric_strain, window)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = -d / (2.0 - d)
    return np.arcsin(np.clip(s, -1.0, 1.0))


def triaxial_curves(axial_strain, sigma1, sigma3, volumetric_strain, smoothing_rows: int = 10,
                    dilatancy_window: float = 0.01) -> pd.DataFrame:
    """One row per time-series row of the loading stage: raw and smoothed σ1, σ3 [Pa], R = σ1/σ3,
    φ [deg] (smoothed R), ε_v and ψ [deg] (ε_v slope over ``dilatancy_window`` of ε_a)."""
    ea = np.asarray(axial_strain, float)
    s1 = np.asarray(sigma1, float)
    s3 = np.asarray(sigma3, float)
    ev = np.asarray(volumetric_strain, float)
    m1, m3, mv = (running_mean(x, smoothing_rows) for x in (s1, s3, ev))
    with np.errstate(divide="ignore", invalid="ignore"):
        r = s1 / s3
        rm = m1 / m3
    return pd.DataFrame({"axial_strain": ea, "sigma1": s1, "sigma3": s3, "stress_ratio": r,
                         "sigma1_smoothed": m1, "sigma3_smoothed": m3, "stress_ratio_smoothed": rm,
                         "friction_angle_deg": np.degrees(friction_angle(rm)),
                         "volumetric_strain": ev, "volumetric_strain_smoothed": mv,
                         "dilatancy_angle_deg": np.degrees(dilatancy_angle(ea, ev, dilatancy_window))})


def analyze_triaxial(frames, smoothing_rows: int = 10, residual_from: float = 0.8, dilatancy_window: float = 0.01,
                     wall: str = "triaxial") -> Result:
    """Stress–strain–volume curves of the loading stage and their characteristic figures.

    Options: ``smoothing_rows`` (running-mean window, rows), ``residual_from`` (the last part of the
    loading, as a fraction of the final axial strain, averaged for the residual state),
    ``dilatancy_window`` (axial-strain window of the ε_v slope), ``wall`` (the frames' wall series holding the test's time series).

    Tables: ``curves`` (see :func:`triaxial_curves`). Scalars: ``peak_stress_ratio`` (smoothed) and
    the axial strain at it, ``peak_friction_angle_deg``, ``residual_stress_ratio`` and
    ``residual_friction_angle_deg``, ``max_dilatancy_angle_deg``, ``final_axial_strain``,
    ``final_volumetric_strain``, ``max_contraction`` (largest ε_v).
    """
    if wall not in frames.wall_names:
        raise ValueError(f"{frames.path}: no '{wall}' wall series (walls: {frames.wall_names}); the triaxial "
                         "analysis needs the test's time series (scene kind triaxial)")
    w = frames.wall(wall)
    load = w[w["stage"] >= 2] if "stage" in w else w
    if len(load) < 3:
        raise ValueError(f"{frames.path}: the '{wall}' series has {len(load)} loading rows; the run did not load")
    c = triaxial_curves(load["axial_strain"], load["sigma1"], load["sigma3"], load["volumetric_strain"],
                        smoothing_rows, dilatancy_window)
    k = int(np.nanargmax(c["stress_ratio_smoothed"].to_numpy()))
    ea = c["axial_strain"].to_numpy()
    tail = ea >= residual_from * ea[-1]
    r_res = float(np.nanmean(c["stress_ratio_smoothed"].to_numpy()[tail]))
    psi = c["dilatancy_angle_deg"].to_numpy()
    scal = {"peak_stress_ratio": float(c["stress_ratio_smoothed"].iloc[k]),
            "axial_strain_at_peak": float(ea[k]),
            "peak_friction_angle_deg": float(c["friction_angle_deg"].iloc[k]),
            "residual_stress_ratio": r_res,
            "residual_friction_angle_deg": float(np.degrees(friction_angle(r_res))),
            "max_dilatancy_angle_deg": float(np.nanmax(psi)) if np.isfinite(psi).any() else float("nan"),
            "final_axial_strain": float(ea[-1]),
            "final_volumetric_strain": float(c["volumetric_strain"].iloc[-1]),
            "max_contraction": float(c["volumetric_strain_smoothed"].max()),
            "smoothing_rows": int(smoothing_rows)}
    return Result("triaxial", tables={"curves": c}, scalars=scal,
                  options={"smoothing_rows": smoothing_rows, "residual_from": residual_from,
                           "dilatancy_window": dilatancy_window, "wall": wall},
                  plotter=plot_triaxial)


def plot_triaxial_runs(runs, labels=None, smoothing_rows: int = 10):
    """Overlay the curves of several runs (run directories, frames files or Frames): σ1/σ3 and ε_v
    against ε_a. Returns a matplotlib Figure (e.g. LIGGGHTS against YADE)."""
    results = [analyze_triaxial(r if isinstance(r, Frames) else Frames(r), smoothing_rows) for r in runs]
    labels = labels or [str(getattr(r, "path", r)) for r in runs]
    return plot_triaxial(results[0], others=list(zip(labels[1:], results[1:])), label=labels[0])
