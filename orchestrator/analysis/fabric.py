"""Contact fabric: rose diagrams of branch vectors, contact normals and mean normal force, and the
fabric tensor (seed 001, Figs. 6c-d, 14, 15a).

Fabric tensor φ = <n ⊗ n> over contacts (trace 1). With the second-order expansion
E(n) = (1 + a_ij n_i n_j)/4π, the anisotropy tensor is a = (15/2) φ' (φ' its deviator) and the
scalar anisotropy a_c = sqrt(3/2 a:a). The force-weighted tensor H = <f_n n ⊗ n>/<f_n> gives the
normal-force anisotropy a_n = sqrt(3/2 b:b) with b = (15/2) H' − a (Ouadfel & Rothenburg 2001).

Rose diagrams: each contact contributes both n and −n (the fabric is centrosymmetric); its
direction is projected onto a plane (default "xz", a vertical plane containing the loading axis)
and binned by the in-plane angle ψ.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from ._common import Result, control_values, frame_indices, present
from .coordination import frame_contacts
from .plots import plot_fabric

__all__ = ["fabric_tensor", "anisotropy", "rose", "contact_vectors", "analyze_fabric"]

_PLANES = {"xy": (0, 1), "xz": (0, 2), "yz": (1, 2)}


def fabric_tensor(vectors: np.ndarray, weights=None) -> np.ndarray:
    """<n ⊗ n> of unit vectors (M, 3), optionally weighted (e.g. by f_n): Σ w n n / Σ w."""
    v = np.asarray(vectors, float)
    n = v / np.linalg.norm(v, axis=1)[:, None]
    w = np.ones(len(n)) if weights is None else np.asarray(weights, float)
    return np.einsum("m,ma,mb->ab", w, n, n) / np.sum(w)


def anisotropy(phi: np.ndarray) -> tuple[np.ndarray, float]:
    """(a_ij, a) with a_ij = 15/2 dev(φ) and a = sqrt(3/2 a_ij a_ij)."""
    dev = phi - np.trace(phi) / 3.0 * np.eye(3)
    a = 7.5 * dev
    return a, float(np.sqrt(1.5 * np.sum(a * a)))


def rose(vectors: np.ndarray, plane: str = "xz", bins: int = 36, values=None) -> pd.DataFrame:
    """Angular distribution in a plane: angle ψ (bin centre, rad, from the plane's first axis),
    ``fraction`` of (±)vectors per bin, ``density`` (fraction / bin width, 1/rad) and, if
    ``values`` (e.g. |f_n|) are given, their ``mean`` per bin."""
    a, b = _PLANES[plane]
    v = np.asarray(vectors, float)
    v = np.concatenate([v, -v])
    psi = np.mod(np.arctan2(v[:, b], v[:, a]), 2 * np.pi)
    edges = np.linspace(0, 2 * np.pi, bins + 1)
    idx = np.clip(np.digitize(psi, edges) - 1, 0, bins - 1)
    cnt = np.bincount(idx, minlength=bins).astype(float)
    df = pd.DataFrame({"psi": 0.5 * (edges[1:] + edges[:-1]), "fraction": cnt / max(cnt.sum(), 1)})
    df["density"] = df["fraction"] / (2 * np.pi / bins)
    if values is not None:
        val = np.concatenate([np.asarray(values, float)] * 2)
        s = np.bincount(idx, weights=val, minlength=bins)
        with np.errstate(invalid="ignore", divide="ignore"):
            df["mean"] = s / cnt
    return df


def contact_vectors(frames, k: int, source: str = "auto", tolerance: float = 0.0) -> dict:
    """Particle–particle contacts of frame k: ``branch`` (x_j − x_i) [m], ``normal`` (unit), ``fn``
    (|normal force| [N], NaN from geometry) and ``source``. Wall contacts are dropped."""
    i, j, used, c = frame_contacts(frames, k, source, tolerance)
    pos = frames.position[k]
    pp = (i >= 0) & (j >= 0)
    i2, j2 = i[pp], j[pp]
    branch = pos[j2] - pos[i2]
    if c is not None and "normal" in c:
        normal = np.asarray(c["normal"], float)[pp]
    else:
        normal = branch / np.linalg.norm(branch, axis=1)[:, None]
    fn = np.linalg.norm(np.asarray(c["fn"], float)[pp], axis=1) if c is not None and "fn" in c else np.full(len(i2), np.nan)
    ok = present(pos[i2]) & present(pos[j2])
    return {"i": i2[ok], "j": j2[ok], "branch": branch[ok], "normal": normal[ok], "fn": fn[ok], "source": used}


def analyze_fabric(frames, at=None, control: str | None = None, stride: int | None = None, plane: str = "xz",
                   bins: int = 36, source: str = "auto", tolerance: float = 0.0) -> Result:
    """Rose diagrams and fabric tensors of selected frames (default first and last).

    Options: ``plane`` ("xz", "yz", "xy"), ``bins``, ``source``/``tolerance`` as in coordination.

    Tables: ``rose`` (frame, control, quantity ∈ {branch, normal, force}, psi, fraction, density,
    mean [N] for force), ``tensor`` (frame, control, phi_xx … phi_zz, eigenvalues, a_c, a_n, n_contacts).
    """
    if plane not in _PLANES:
        raise ValueError(f"plane must be one of {sorted(_PLANES)}, got {plane!r}")
    cname, cvals = control_values(frames, control)
    if at is None and stride is None:
        ks = sorted({0, frames.n_frames - 1})
    else:
        ks = frame_indices(frames, at, control, stride or 1)
    roses, tens = [], []
    for k in ks:
        cv = contact_vectors(frames, k, source, tolerance)
        if len(cv["normal"]) == 0:
            continue
        for q, vec, val in (("branch", cv["branch"], None), ("normal", cv["normal"], None),
                            ("force", cv["normal"], cv["fn"] if np.isfinite(cv["fn"]).all() else None)):
            if q == "force" and val is None:
                continue
            r = rose(vec, plane, bins, val)
            r.insert(0, "quantity", q)
            r.insert(0, "control", cvals[k])
            r.insert(0, "frame", k)
            roses.append(r)
        phi = fabric_tensor(cv["normal"])
        a_ij, a_c = anisotropy(phi)
        row = {"frame": k, "control": cvals[k], "n_contacts": len(cv["normal"]), "source": cv["source"]}
        for x in range(3):
            for y in range(3):
                row[f"phi_{'xyz'[x]}{'xyz'[y]}"] = phi[x, y]
        ev = np.linalg.eigvalsh(phi)
        row.update({"phi_1": ev[2], "phi_2": ev[1], "phi_3": ev[0], "a_c": a_c})
        phib = fabric_tensor(cv["branch"])
        row["a_branch"] = anisotropy(phib)[1]
        if np.isfinite(cv["fn"]).all() and cv["fn"].sum() > 0:
            H = fabric_tensor(cv["normal"], cv["fn"])
            b = 7.5 * (H - np.trace(H) / 3 * np.eye(3)) - a_ij
            row["a_n"] = float(np.sqrt(1.5 * np.sum(b * b)))
            row["mean_fn"] = float(cv["fn"].mean())
        tens.append(row)
    if not tens:
        raise ValueError(f"{frames.path}: no contacts in the selected frames {ks}")
    t = pd.DataFrame(tens)
    return Result("fabric", tables={"rose": pd.concat(roses, ignore_index=True), "tensor": t},
                  scalars={"a_c_last": float(t["a_c"].iloc[-1]), "plane": plane},
                  options={"plane": plane, "bins": bins, "source": source}, plotter=plot_fabric)
