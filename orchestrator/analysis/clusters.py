"""Clusters of highly non-affine particles, P(s), radius of gyration and fractal dimension (seed 001, eq. 13).

The top ``top_fraction`` (seed: 10 %) of particles by D²min are joined when they are neighbours
(centres closer than ``cutoff``, default 1.5 d50 as for D²min, i.e. the first-shell
neighbours up to the first minimum of g(r)). For each cluster of s particles with volumes V_i:

    R̄ = Σ V_i r_i / Σ V_i,   R_g² = Σ V_i |r_i − R̄|² / Σ V_i        (eq. 13, volume weighted) [m]

The cluster-size distribution P(s) is fitted with a discrete power law P(s) ∝ s^(−τ) for
s >= s_min (maximum likelihood, Clauset et al. 2009, standard error from the curvature of the
log-likelihood), and R_g ∝ s^(1/d_f) gives the fractal dimension d_f (least squares on
log R_g vs log s for s >= s_min_rg, error propagated from the slope).
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ._fits import fractal_dimension, powerlaw_fit
from ._common import Result, d50, present, sphere_volume
from .neighbors import pairs_within
from .d2min import analyze_d2min
from .plots import plot_clusters

__all__ = ["find_clusters", "cluster_properties", "powerlaw_fit", "fractal_dimension", "analyze_clusters"]


def find_clusters(position: np.ndarray, selected: np.ndarray, cutoff: float) -> np.ndarray:
    """Label connected groups of selected particles whose centres are within ``cutoff`` [m].

    Returns (N,) int labels 0..n_clusters−1 for selected present particles and −1 elsewhere.
    """
    position = np.asarray(position, float)
    sel = np.asarray(selected, bool) & present(position)
    rows = np.flatnonzero(sel)
    labels = np.full(len(position), -1, np.int64)
    if rows.size == 0:
        return labels
    sub = np.where(sel[:, None], position, np.nan)
    i, j = pairs_within(sub, cutoff)
    # map rows to compact indices
    inv = np.full(len(position), -1, np.int64)
    inv[rows] = np.arange(rows.size)
    a = coo_matrix((np.ones(len(i)), (inv[i], inv[j])), shape=(rows.size, rows.size))
    _, lab = connected_components(a, directed=False)
    labels[rows] = lab
    return labels


def cluster_properties(position: np.ndarray, volume: np.ndarray, labels: np.ndarray) -> pd.DataFrame:
    """Per cluster: label, size s, volume [m³], centre x, y, z [m] and R_g [m] (eq. 13)."""
    position = np.asarray(position, float)
    volume = np.asarray(volume, float)
    m = labels >= 0
    lab = labels[m]
    if lab.size == 0:
        return pd.DataFrame(columns=["label", "size", "volume", "x", "y", "z", "rg"])
    n = lab.max() + 1
    p = position[m]
    v = volume[m]
    s = np.bincount(lab, minlength=n)
    vt = np.bincount(lab, weights=v, minlength=n)
    c = np.stack([np.bincount(lab, weights=v * p[:, a], minlength=n) for a in range(3)], 1) / vt[:, None]
    d2 = np.sum((p - c[lab]) ** 2, axis=1)
    rg = np.sqrt(np.bincount(lab, weights=v * d2, minlength=n) / vt)
    return pd.DataFrame({"label": np.arange(n), "size": s, "volume": vt, "x": c[:, 0], "y": c[:, 1],
                         "z": c[:, 2], "rg": rg})


def analyze_clusters(frames, top_fraction: float = 0.1, cutoff: float | None = None, cutoff_d50: float = 1.5,
                     s_min: int = 1, s_min_rg: int = 3, d2min_result=None, **d2min_options) -> Result:
    """Clusters of the top ``top_fraction`` D²min particles for each D²min frame pair.

    Options: ``top_fraction`` (seed 0.1), ``cutoff`` [m] / ``cutoff_d50`` (joining distance,
    default 1.5 d50), ``s_min`` (power-law fit), ``s_min_rg`` (fractal fit), and the D²min
    options (``pairs``, ``interval``, ``start``, ``control``, ``stride``, ``stages``, D²min
    ``d2min_cutoff``).
    A precomputed :func:`.d2min.analyze_d2min` result may be passed as ``d2min_result``.

    Tables: ``clusters`` (frame0, frame1, label, size, volume, x, y, z, rg), ``size_distribution``
    (s, count, p: pooled over all pairs, as the seed pools 8–18 % strain), ``particles`` (frame0,
    frame1, id, label). Scalars: ``tau``, ``tau_err``, ``d_f``, ``d_f_err`` of the pooled data.
    """
    dd = d50(frames.radius)
    cut = float(cutoff) if cutoff is not None else cutoff_d50 * dd
    if d2min_result is None:
        dopt = dict(d2min_options)
        if "d2min_cutoff" in dopt:
            dopt["cutoff"] = dopt.pop("d2min_cutoff")
        d2min_result = analyze_d2min(frames, **dopt)
    dp = d2min_result.tables["particles"]
    vol_all = sphere_volume(frames.radius)
    row_of = {int(i): r for r, i in enumerate(frames.ids)}
    clus, parts = [], []
    for (k0, k1), g in dp.groupby(["frame0", "frame1"], sort=True):
        v = g["d2min"].to_numpy()
        fin = np.isfinite(v)
        if fin.sum() == 0:
            continue
        thr = np.quantile(v[fin], 1.0 - top_fraction)
        sel = fin & (v >= thr)
        pos = g[["x", "y", "z"]].to_numpy()
        rows = np.array([row_of[int(i)] for i in g["id"].to_numpy()])
        lab = find_clusters(pos, sel, cut)
        cp = cluster_properties(pos, vol_all[rows], lab)
        cp.insert(0, "frame1", k1)
        cp.insert(0, "frame0", k0)
        clus.append(cp)
        parts.append(pd.DataFrame({"frame0": k0, "frame1": k1, "id": g["id"].to_numpy()[sel], "label": lab[sel]}))
    ct = pd.concat(clus, ignore_index=True) if clus else cluster_properties(np.zeros((0, 3)), np.zeros(0), np.zeros(0, int))
    sizes = ct["size"].to_numpy() if len(ct) else np.zeros(0)
    u, c = np.unique(sizes, return_counts=True)
    sd = pd.DataFrame({"s": u, "count": c, "p": c / max(c.sum(), 1)})
    pl = powerlaw_fit(sizes, s_min)
    fd = fractal_dimension(sizes, ct["rg"].to_numpy() if len(ct) else np.zeros(0), s_min_rg)
    scal = {"tau": pl["tau"], "tau_err": pl["tau_err"], "tau_n": pl["n"], "d_f": fd["d_f"], "d_f_err": fd["d_f_err"],
            "d_f_n": fd["n"], "cutoff_m": cut, "top_fraction": top_fraction,
            "n_clusters": int(len(ct)), "largest": int(sizes.max()) if sizes.size else 0}
    return Result("clusters", tables={"clusters": ct, "size_distribution": sd,
                                      "particles": pd.concat(parts, ignore_index=True) if parts else pd.DataFrame()},
                  scalars=scal, options={"top_fraction": top_fraction, "cutoff": cut, "s_min": s_min,
                                         "s_min_rg": s_min_rg}, plotter=plot_clusters)
