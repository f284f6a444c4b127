"""Force chains (seed 001, Fig. 15b-c), after Peters et al., Soft Matter 2005.

1. Particle stress σ_i (frames' ``stress`` field or Love–Weber from contacts, see :mod:`.stress`);
   its most compressive principal stress |σ_min| and direction p_i.
2. A particle is highly stressed when |σ_min| exceeds the mean over particles (× ``factor``).
3. A contact between two highly stressed particles is a chain link when the branch vector makes
   an angle of at most ``max_angle`` (default 45°) with both particles' directions p_i, p_j.
4. Chains are the connected groups of links with at least ``min_length`` particles.

Sign convention: tension positive, so the most compressive principal value is the smallest.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ._common import Result, control_values, frame_indices
from .fabric import contact_vectors
from .stress import particle_stress
from .plots import plot_forcechains

__all__ = ["force_chains", "analyze_forcechains"]


def force_chains(position, stress, i, j, max_angle_deg: float = 45.0, factor: float = 1.0, min_length: int = 3) -> dict:
    """Chain labels (N,) (−1 outside chains) and link mask (M,) from particle stresses (N, 3, 3)
    [Pa] and contact rows (i, j). Also returns ``compression`` |σ_min| (N,) [Pa]."""
    p = np.asarray(position, float)
    s = np.asarray(stress, float)
    n = len(p)
    finite = np.isfinite(s).all(axis=(1, 2))
    ev = np.full((n, 3), np.nan)
    evec = np.full((n, 3, 3), np.nan)
    ev[finite], evec[finite] = np.linalg.eigh(s[finite])
    comp = -ev[:, 0]                         # most compressive principal value (tension positive)
    d = evec[:, :, 0]
    loaded = comp > 0                        # NaN (non-finite stress) compares False
    mean = comp[loaded].mean() if loaded.any() else np.inf    # no loaded grain: no chain
    high = finite & (comp > factor * mean)
    b = p[j] - p[i]
    b /= np.linalg.norm(b, axis=1)[:, None]
    cosc = np.cos(np.radians(max_angle_deg))
    with np.errstate(invalid="ignore"):
        link = (high[i] & high[j] & (np.abs(np.einsum("ma,ma->m", b, d[i])) >= cosc)
                & (np.abs(np.einsum("ma,ma->m", b, d[j])) >= cosc))
    labels = np.full(n, -1, np.int64)
    if link.any():
        a = coo_matrix((np.ones(link.sum()), (i[link], j[link])), shape=(n, n))
        _, lab = connected_components(a, directed=False)
        size = np.bincount(lab, minlength=lab.max() + 1)
        inchain = np.zeros(n, bool)
        inchain[i[link]] = True
        inchain[j[link]] = True
        keep = inchain & (size[lab] >= min_length)
        _, compact = np.unique(lab[keep], return_inverse=True)
        labels[keep] = compact
        link &= labels[i] >= 0
    return {"labels": labels, "links": link, "compression": comp, "direction": d}


def analyze_forcechains(frames, at=None, control: str | None = None, stride: int | None = None,
                        max_angle: float = 45.0, factor: float = 1.0, min_length: int = 3, plane: str = "xz") -> Result:
    """Force chains of selected frames (default first and last); needs contacts (with forces) or
    a per-particle ``stress`` field plus geometric contacts.

    Tables: ``chains`` (frame, control, label, size, length [m] = extent along the chain's main
    axis, orientation_deg = angle of the main axis from z, mean_compression [Pa]), ``links``
    (frame, i, j ids, x_i..z_j [m], fn [N]), ``summary`` (frame, control, n_chains,
    fraction_in_chains, mean_size).
    """
    cname, cvals = control_values(frames, control)
    if at is None and stride is None:
        ks = sorted({0, frames.n_frames - 1})
    else:
        ks = frame_indices(frames, at, control, stride or 1)
    chains, links, summ = [], [], []
    for k in ks:
        pos = frames.position[k]
        cv = contact_vectors(frames, k)
        s = particle_stress(frames, k)
        fc = force_chains(pos, s, cv["i"], cv["j"], max_angle, factor, min_length)
        lab = fc["labels"]
        nch = int(lab.max() + 1) if (lab >= 0).any() else 0
        for c in range(nch):
            m = lab == c
            q = pos[m]
            q0 = q - q.mean(0)
            w, v = np.linalg.eigh(q0.T @ q0)
            ax = v[:, -1]
            proj = q0 @ ax
            chains.append({"frame": k, "control": cvals[k], "label": c, "size": int(m.sum()),
                           "length": float(np.ptp(proj)), "orientation_deg": float(np.degrees(np.arccos(abs(ax[2])))),
                           "mean_compression": float(np.mean(fc["compression"][m]))})
        L = fc["links"]
        ii, jj = cv["i"][L], cv["j"][L]
        links.append(pd.DataFrame({"frame": k, "i": frames.ids[ii], "j": frames.ids[jj],
                                   "x_i": pos[ii, 0], "y_i": pos[ii, 1], "z_i": pos[ii, 2],
                                   "x_j": pos[jj, 0], "y_j": pos[jj, 1], "z_j": pos[jj, 2], "fn": cv["fn"][L]}))
        npres = int(np.isfinite(pos).all(1).sum())
        summ.append({"frame": k, "control": cvals[k], "n_chains": nch,
                     "fraction_in_chains": float((lab >= 0).sum() / max(npres, 1)),
                     "mean_size": float(np.mean([c["size"] for c in chains if c["frame"] == k])) if nch else 0.0})
    ch = pd.DataFrame(chains, columns=["frame", "control", "label", "size", "length", "orientation_deg", "mean_compression"])
    return Result("forcechains", tables={"chains": ch, "links": pd.concat(links, ignore_index=True), "summary": pd.DataFrame(summ)},
                  scalars={"n_chains_last": int(summ[-1]["n_chains"]), "plane": plane},
                  options={"max_angle": max_angle, "factor": factor, "min_length": min_length, "plane": plane},
                  plotter=plot_forcechains)
