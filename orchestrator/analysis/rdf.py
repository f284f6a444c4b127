"""Pair correlation g(r) of a finite, walled sample with edge correction (seed 001, Fig. 6a).

The seed defines g(r) = n(r) / (ρ 4π r² dr) with ρ = N/V. In a finite container a particle near a
wall has part of its shell outside the sample, so that naive estimator falls below 1 at large r.
We use the isotropised translation (Ohser–Stoyan) estimator:

    g(r) = V² / (N (N−1)) · C(r, r+dr) / ∫_r^{r+dr} 4π s² γ̄(s) ds

with C the number of ordered pairs with separation in the shell and γ̄(s) the isotropised set
covariance of the container (volume shared by the window and its translate by s, averaged over
directions, exact for boxes and cylinders; see :mod:`.containers`). For a uniform random
(binomial) sample the expectation of this estimator is exactly 1 at every r.

Pair counting: z-sorted slabs, one ``cKDTree.query_pairs`` each, bounded memory.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from ._common import Result, control_values, d50, frame_indices, present
from .containers import make_container
from .plots import plot_rdf

__all__ = ["pair_counts", "rdf", "analyze_rdf"]


def pair_counts(position: np.ndarray, edges: np.ndarray, max_pairs: int = 4_000_000) -> np.ndarray:
    """Number of ordered pairs (i ≠ j) with separation in each [edges[k], edges[k+1]) [m].

    Centres are sorted by z and processed in slabs (slab plus a halo of thickness edges[-1] above
    it), each with one ``cKDTree.query_pairs``; ``max_pairs`` bounds the pairs held in memory.
    """
    p = np.asarray(position, float)
    p = p[present(p)]
    edges = np.asarray(edges, float)
    out = np.zeros(len(edges) - 1)
    if len(p) < 2:
        return out
    rmax = float(edges[-1])
    p = p[np.argsort(p[:, 2], kind="stable")]
    z = p[:, 2]
    n = len(p)
    span = np.ptp(p, axis=0)
    vol = float(np.prod(np.maximum(span, rmax)))
    per = n * 4.0 / 3.0 * np.pi * rmax ** 3 / vol                 # rough neighbours per particle
    core = int(min(n, max(1000, max_pairs / max(per, 1e-9))))
    d0, dr = edges[0], np.diff(edges)
    uniform = np.allclose(dr, dr[0], rtol=1e-12, atol=0)
    s = 0
    while s < n:
        e = min(s + core, n)
        h = int(np.searchsorted(z, z[e - 1] + rmax, side="right"))
        q = p[s:h]
        pr = cKDTree(q).query_pairs(rmax, output_type="ndarray")
        pr = pr[pr[:, 0] < e - s]                                  # i < j: keep pairs with a core member
        d = np.sqrt(np.sum((q[pr[:, 0]] - q[pr[:, 1]]) ** 2, axis=1))
        if uniform:
            k = np.floor((d - d0) / dr[0]).astype(np.int64)
            k = k[(k >= 0) & (k < len(out))]
            out += np.bincount(k, minlength=len(out))
        else:
            out += np.histogram(d, edges)[0]
        s = e
    return 2.0 * out


def rdf(position: np.ndarray, r_max: float, bins: int = 100, container=None,
        edge_correction: bool = True, r_min: float = 0.0) -> pd.DataFrame:
    """Pair-correlation function of one configuration.

    Parameters
    ----------
    position : (N, 3) centres [m]; NaN rows ignored.
    r_max : largest distance [m]; bins : number of equal bins on [r_min, r_max].
    container : where centres may lie (see :func:`.containers.make_container`); default: inferred
        from the centres (box or upright cylinder).
    edge_correction : if False, the naive estimator n(r)/(ρ 4π r² dr) of the seed (what OVITO's
        CoordinationAnalysisModifier computes in a non-periodic cell).

    Returns
    -------
    DataFrame: r [m] (bin centre), r_lo, r_hi, pairs (ordered pair count), g, g_err (Poisson
    standard error of g from the pair count); g and g_err are NaN in a bin where no pair can be
    expected (r beyond the container's extent).
    """
    p = np.asarray(position, float)
    p = p[present(p)]
    n = len(p)
    box = make_container(container, p)
    V = box.volume
    edges = np.linspace(r_min, r_max, int(bins) + 1)
    counts = pair_counts(p, edges)
    # ∫ 4π s² w(s) ds over each bin with 4-point Gauss–Legendre nodes
    x, w = np.polynomial.legendre.leggauss(4)
    lo, hi = edges[:-1], edges[1:]
    s = 0.5 * (hi - lo)[:, None] * (x[None, :] + 1.0) + lo[:, None]
    ws = 0.5 * (hi - lo)[:, None] * w[None, :]
    if edge_correction:
        gam = box.set_covariance(s.ravel()).reshape(s.shape)
    else:
        gam = np.full(s.shape, V)
    expected = (n * (n - 1) / V ** 2) * np.sum(ws * 4.0 * np.pi * s ** 2 * gam, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        g = counts / expected
        # ordered counts come in pairs: Poisson error of the unordered count, doubled
        err = 2.0 * np.sqrt(counts / 2.0) / expected
    # a bin where no pair is expected (beyond the container's extent, where its set covariance is
    # 0) has no g: NaN, not the inf of a count over zero
    none_expected = ~(expected > 0)
    g[none_expected] = np.nan
    err[none_expected] = np.nan
    return pd.DataFrame({"r": 0.5 * (lo + hi), "r_lo": lo, "r_hi": hi, "pairs": counts, "g": g, "g_err": err})


def analyze_rdf(frames, r_max: float | None = None, r_max_d50: float = 5.0, bins: int = 100,
                container=None, edge_correction: bool = True, at=None, control: str | None = None,
                stride: int | None = None) -> Result:
    """g(r) of selected frames (default: first and last) with edge correction.

    Options: ``r_max`` [m] (default ``r_max_d50`` × d50), ``bins``, ``container`` (dict, see
    :func:`.containers.make_container`; default inferred per frame), ``edge_correction``, ``at``
    (frame indices or control values), ``stride``.

    Tables: ``rdf`` with frame, control, r [m], r_d50 (r/d50), g, g_err, pairs. Scalars: position
    of the first peak and of the first minimum after it (in d50) for the last frame analysed.
    """
    dd = d50(frames.radius)
    rmax = float(r_max) if r_max is not None else r_max_d50 * dd
    if at is None and stride is None:
        ks = sorted({0, frames.n_frames - 1})
    else:
        ks = frame_indices(frames, at, control, stride or 1)
    cname, cvals = control_values(frames, control)
    tabs = []
    for k in ks:
        p = frames.position[k]
        df = rdf(p, rmax, bins, container, edge_correction)
        df.insert(0, "control", cvals[k])
        df.insert(0, "frame", k)
        df["r_d50"] = df["r"] / dd
        tabs.append(df)
    t = pd.concat(tabs, ignore_index=True)
    last = tabs[-1]
    g = last["g"].to_numpy()
    scal = {"d50_m": dd, "r_max_m": rmax, "edge_correction": bool(edge_correction)}
    if np.isfinite(g).any():
        ip = int(np.nanargmax(g))
        scal["first_peak_d50"] = float(last["r_d50"].iloc[ip])
        after = g[ip:]
        # first local minimum after the peak (smoothed by 3 bins)
        sm = np.convolve(np.nan_to_num(after, nan=np.inf), np.ones(3) / 3, mode="same")
        loc = [m for m in range(1, len(sm) - 1) if sm[m] <= sm[m - 1] and sm[m] < sm[m + 1]]
        if loc:
            scal["first_min_d50"] = float(last["r_d50"].iloc[ip + loc[0]])
    scal["control"] = cname                 # what the frames' "control" column holds (their legends)
    return Result("rdf", tables={"rdf": t}, scalars=scal,
                  options={"r_max": rmax, "bins": bins, "edge_correction": edge_correction}, plotter=plot_rdf)
