"""Incremental particle displacements per strain increment and their distributions (seed 001, Figs. 9-10).

u_i = x_i(k1) − x_i(k0) [m] for every frame pair; |u| is also given in units of d50. Particles
absent from either frame are dropped.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from ._common import Result, control_values, d50, frame_pairs, present
from .plots import plot_displacements

__all__ = ["incremental_displacements", "analyze_displacements"]


def incremental_displacements(p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
    """(N, 3) displacement [m]; NaN rows where a particle is absent in either frame."""
    return np.asarray(p1, float) - np.asarray(p0, float)


def analyze_displacements(frames, pairs=None, interval=None, start=None, control: str | None = None,
                          stride: int = 1, bins: int = 50, log_bins: bool = True,
                          stages: str = "loading") -> Result:
    """Per-particle incremental displacements, their PDF and box-chart statistics per increment.

    Options: frame pairs as in D²min (``pairs``, ``interval`` e.g. 0.01 axial strain, ``start``,
    ``control``, ``stride``, ``stages``: the loading stage by default); ``bins`` and ``log_bins`` for the PDF of |u|/d50.

    Tables: ``particles`` (frame0, frame1, id, x, y, z, ux, uy, uz [m], u [m], u_d50),
    ``pdf`` (frame0, frame1, u_d50 bin centre, pdf), ``stats`` (per pair: mean, std, quartiles,
    5/95 % of |u| [m]).
    """
    dd = d50(frames.radius)
    cname, cvals = control_values(frames, control)
    pos = frames.position
    parts, pdfs, stats = [], [], []
    for k0, k1 in frame_pairs(frames, pairs, interval, start, control, stride, stages):
        u = incremental_displacements(pos[k0], pos[k1])
        m = present(pos[k0]) & present(pos[k1])
        un = np.linalg.norm(u[m], axis=1)
        parts.append(pd.DataFrame({"frame0": k0, "frame1": k1, "control0": cvals[k0], "control1": cvals[k1],
                                   "id": frames.ids[m], "x": pos[k0][m, 0], "y": pos[k0][m, 1], "z": pos[k0][m, 2],
                                   "ux": u[m, 0], "uy": u[m, 1], "uz": u[m, 2], "u": un, "u_d50": un / dd}))
        x = un / dd
        pos_x = x[x > 0]
        if pos_x.size:
            edges = (np.geomspace(pos_x.min(), pos_x.max() * 1.0001, bins + 1) if log_bins and pos_x.max() > pos_x.min()
                     else np.linspace(0, x.max() * 1.0001 + 1e-300, bins + 1))
            h, _ = np.histogram(x, edges, density=True)
            pdfs.append(pd.DataFrame({"frame0": k0, "frame1": k1, "control1": cvals[k1],
                                      "u_d50": np.sqrt(edges[1:] * edges[:-1]) if log_bins else 0.5 * (edges[1:] + edges[:-1]),
                                      "pdf": h}))
        q = np.percentile(un, [5, 25, 50, 75, 95]) if un.size else [np.nan] * 5
        stats.append({"frame0": k0, "frame1": k1, "control0": cvals[k0], "control1": cvals[k1], "n": int(un.size),
                      "mean": float(un.mean()) if un.size else np.nan, "std": float(un.std()) if un.size else np.nan,
                      "p05": q[0], "p25": q[1], "median": q[2], "p75": q[3], "p95": q[4]})
    return Result("displacements", tables={"particles": pd.concat(parts, ignore_index=True),
                                           "pdf": pd.concat(pdfs, ignore_index=True) if pdfs else pd.DataFrame(),
                                           "stats": pd.DataFrame(stats)},
                  scalars={"d50_m": dd, "control": cname}, options={"pairs": pairs, "interval": interval, "stages": stages},
                  plotter=plot_displacements)
