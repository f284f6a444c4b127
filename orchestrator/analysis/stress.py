"""Particle stress q, its volatility V and the correlation of V with D²min (seed 001, eqs. 14-15).

Particle stress σ_i [Pa] is read from the frames' ``stress`` field, or, when absent, computed from
the contact list with the Love–Weber formula σ_i = (1/V_i) Σ_c (x_c − x_i) ⊗ f_c (f_c: total
contact force on i, x_c: contact point; tension positive). Following the seed,

    q = sqrt(½ s_ij s_ij),  s = σ − (tr σ / 3) I                 [Pa]
    R_i = ln(q_i / q_{i−1})                                       (eq. 14)
    V = sqrt( 1/(N−1) Σ_i (R_i − R̄)² )                           (eq. 15)

over the states of a strain window (seed: Δε_a = 2.5e-3 over ε_a = 10 %..20 %).
"""
from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
from scipy import stats as sps

from ._common import Result, control_values, d50, frame_indices, present, stage_frames, sphere_volume
from .neighbors import contacts_to_rows
from .d2min import d2min

from .plots import plot_stress

__all__ = ["deviatoric_q", "love_weber_stress", "volatility", "particle_stress", "analyze_stress"]


def deviatoric_q(stress: np.ndarray) -> np.ndarray:
    """q = sqrt(½ s:s) of (..., 3, 3) stress tensors [Pa] (seed 001, §5)."""
    s = np.asarray(stress, float)
    tr = np.trace(s, axis1=-2, axis2=-1)
    dev = s - tr[..., None, None] / 3.0 * np.eye(3)
    return np.sqrt(0.5 * np.einsum("...ab,...ab->...", dev, dev))


def love_weber_stress(position, radius, rows_i, rows_j, point, force) -> np.ndarray:
    """Particle stress (N, 3, 3) [Pa] from contacts: σ_i = (1/V_i) Σ_c (x_c − x_i) ⊗ f_c.

    ``force`` (M, 3) is the force on particle ``rows_i``; particle ``rows_j`` receives −force.
    Rows < 0 are walls (their side is skipped). Volumes are the spheres' 4/3 π R³.
    """
    p = np.asarray(position, float)
    n = len(p)
    out = np.zeros((n, 3, 3))
    point = np.asarray(point, float)
    force = np.asarray(force, float)
    for rows, f in ((np.asarray(rows_i), force), (np.asarray(rows_j), -force)):
        m = rows >= 0
        r = rows[m]
        l = point[m] - p[r]
        for a in range(3):
            for b in range(3):
                out[:, a, b] += np.bincount(r, weights=l[:, a] * f[m, b], minlength=n)
    return out / sphere_volume(radius)[:, None, None]


def particle_stress(frames, k: int) -> np.ndarray:
    """σ of every particle at frame k [Pa]: the ``stress`` field if present, else Love–Weber."""
    if "stress" in frames.fields:
        return frames.stress[k]
    if k not in frames.contact_frames:
        raise KeyError(f"{frames.path}: frame {k} has neither a 'stress' field nor contacts; "
                       "particle stress needs one of them (dump per-particle stress or contacts)")
    c = frames.contact_arrays(k)
    i, j = contacts_to_rows(frames, c["i"], c["j"])
    f = c["fn"] + (c["ft"] if "ft" in c else 0.0)
    if "point" in c:
        point = c["point"]
    else:  # midpoint between centres, or the centre of i shifted by its radius for walls
        p = frames.position[k]
        point = np.where((j >= 0)[:, None], 0.5 * (p[i] + p[np.maximum(j, 0)]), p[i] + frames.radius[i][:, None] * c["normal"])
    s = love_weber_stress(frames.position[k], frames.radius, i, j, point, f)
    s[~present(frames.position[k])] = np.nan
    return s


def volatility(q: np.ndarray) -> np.ndarray:
    """Eq. 15 for series q (T, N) [Pa] -> V (N,) [-]; needs >= 3 positive finite values per particle."""
    q = np.asarray(q, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        R = np.log(q[1:] / q[:-1])          # eq. 14
    R[~np.isfinite(R)] = np.nan
    cnt = np.sum(np.isfinite(R), axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            V = np.nanstd(R, axis=0, ddof=1)
    V[cnt < 2] = np.nan
    return V


def analyze_stress(frames, window=None, interval: float | None = None, at=None, control: str | None = None,
                   d2min_cutoff_d50: float = 1.5, d2min_cutoff: float | None = None,
                   stages: str = "loading") -> Result:
    """q per particle and state, volatility V over a window, and corr(V, D²min) (seed 001, eqs. 14-15, Fig. 16).

    Options: ``window`` (control range (lo, hi), seed: (0.10, 0.20) axial strain; default all
    frames of the loading stage, ``stages="all"`` adds the preparation: :func:`._common.stage_frames`),
    ``interval`` (control step between states, seed 2.5e-3; default every frame in the window), or
    explicit ``at`` (frame indices or control values); ``control``. D²min is taken
    over the whole window (first to last state) with ``d2min_cutoff`` [m] (default 1.5 d50).

    Tables: ``q`` (frame, control, id, q [Pa]), ``volatility`` (id, V, d2min [m²]),
    ``summary`` (per state: mean and median q). Scalars: pearson_r, pearson_p, spearman_r,
    spearman_p, n.
    """
    cname, cvals = control_values(frames, control)
    if at is not None:
        ks = frame_indices(frames, at, control)
    else:
        ks = np.asarray(stage_frames(frames, stages), int)
        if window is not None:
            lo, hi = window
            ks = ks[(cvals[ks] >= lo - 1e-12) & (cvals[ks] <= hi + 1e-12)]
        if interval is not None and len(ks):
            targets = np.arange(cvals[ks[0]], cvals[ks[-1]] + 0.5 * interval, interval)
            ks = np.unique([ks[np.argmin(np.abs(cvals[ks] - t))] for t in targets])
        ks = list(ks)
    # states without stresses (a frame without contacts, e.g. a clump sample's insertion frame,
    # orchestrator.grains) are left out
    ks = [k for k in ks if "stress" not in frames.fields or np.isfinite(frames.stress[k]).any()]
    if len(ks) < 3:
        raise ValueError(f"stress volatility needs at least 3 states in the window, got {len(ks)}")
    Q = np.stack([deviatoric_q(particle_stress(frames, k)) for k in ks])
    V = volatility(Q)
    pos = frames.position
    cut = d2min_cutoff if d2min_cutoff is not None else d2min_cutoff_d50 * d50(frames.radius)
    D = d2min(pos[ks[0]], pos[ks[-1]], cut)["d2min"]
    m = np.isfinite(V) & np.isfinite(D)
    scal = {"n": int(m.sum()), "frame_first": int(ks[0]), "frame_last": int(ks[-1]), "n_states": len(ks)}
    if m.sum() > 2:
        pr = sps.pearsonr(V[m], D[m])
        sr = sps.spearmanr(V[m], D[m])
        scal.update({"pearson_r": float(pr[0]), "pearson_p": float(pr[1]),
                     "spearman_r": float(sr[0]), "spearman_p": float(sr[1])})
    qt = pd.DataFrame({"frame": np.repeat(ks, len(frames.ids)), "control": np.repeat(cvals[ks], len(frames.ids)),
                       "id": np.tile(frames.ids, len(ks)), "q": Q.ravel()}).dropna()
    vt = pd.DataFrame({"id": frames.ids, "V": V, "d2min": D})
    vt = vt[np.isfinite(vt["V"])]
    su = qt.groupby(["frame", "control"])["q"].agg(["mean", "median"]).reset_index()
    return Result("stress", tables={"q": qt, "volatility": vt, "summary": su}, scalars=scal,
                  options={"window": window, "interval": interval, "control": cname, "stages": stages},
                  plotter=plot_stress)
