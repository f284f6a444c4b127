"""Non-affine displacement D²min, local affine tensor and local deviatoric strain (seed 001, eqs. 9-12).

For particle i with neighbours k (centres within ``cutoff`` in the reference configuration),
with mu_ki = x_k - x_i the vector from i to k in the reference (ε) and current (ε+δε) frames:

    X = Σ_k mu_ki(ε+δε) ⊗ mu_ki(ε)                      (eq. 11)
    Y = Σ_k mu_ki(ε) ⊗ mu_ki(ε)                         (eq. 12)
    Λ_i = X Y⁻¹                                         (eq. 10)
    D²min = (1/N_i) Σ_k |mu_ki(ε+δε) − Λ_i mu_ki(ε)|²   (eq. 9)   [m²]

Local strain: the seed writes ε^L = −(Λ + Λᵀ)/2 (soil-mechanics sign, compression positive, and
the identity left in; the identity has no deviatoric part). We return the small strain
ε = (Λ + Λᵀ)/2 − I with tension positive, its volumetric part ε_v = tr ε and the local deviatoric
strain ε_q = sqrt(2/3 ε_dev : ε_dev), which is the same under either sign convention. The
Green–Lagrange strain E = (ΛᵀΛ − I)/2 and its von Mises shear invariant (what OVITO's
AtomicStrainModifier calls shear strain) are returned too.

Everything is vectorised over pairs (np.bincount) and particles (batched 3×3 solves); there is
no Python loop over particles.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from ._common import Result, control_values, d50, frame_pairs, present
from .neighbors import pairs_within

__all__ = ["d2min", "local_strain", "analyze_d2min"]

_COMP = [(a, b) for a in range(3) for b in range(3)]


def _sum_outer(idx, u, v, n):
    """Σ over pairs with the same idx of u ⊗ v -> (n, 3, 3)."""
    out = np.empty((n, 3, 3))
    for a, b in _COMP:
        out[:, a, b] = np.bincount(idx, weights=u[:, a] * v[:, b], minlength=n)
    return out


def d2min(reference: np.ndarray, current: np.ndarray, cutoff: float, min_neighbors: int = 3,
          rcond: float = 1e-6) -> dict:
    """D²min and the best-fit affine tensor Λ for every particle (seed 001, eqs. 9-12).

    Parameters
    ----------
    reference, current : (N, 3) centre positions [m] at strain ε and ε + δε; NaN rows (absent
        particles) are skipped and neither count as neighbours nor get a value.
    cutoff : neighbour cutoff [m] in the reference configuration (seed: 1.5 d50).
    min_neighbors : particles with fewer neighbours (or a neighbourhood that does not span 3-D,
        smallest/largest eigenvalue of Y below ``rcond``) get NaN.

    Returns
    -------
    dict of arrays: ``d2min`` (N,) [m²], ``F`` (N, 3, 3) affine tensor Λ [-], ``n_neighbors`` (N,),
    plus the strain measures of :func:`local_strain`.
    """
    ref = np.asarray(reference, float)
    cur = np.asarray(current, float)
    if ref.shape != cur.shape or ref.ndim != 2 or ref.shape[1] != 3:
        raise ValueError(f"reference and current must both be (N, 3), got {ref.shape} and {cur.shape}")
    n = len(ref)
    both = present(ref) & present(cur)
    ref_m = np.where(both[:, None], ref, np.nan)
    i, k = pairs_within(ref_m, cutoff, ordered=True)
    mu0 = ref[k] - ref[i]
    mu1 = cur[k] - cur[i]
    nn = np.bincount(i, minlength=n)
    X = _sum_outer(i, mu1, mu0, n)
    Y = _sum_outer(i, mu0, mu0, n)
    ev = np.linalg.eigvalsh(Y)
    ok = both & (nn >= max(min_neighbors, 3)) & (ev[:, 0] > rcond * np.maximum(ev[:, 2], 1e-300))
    Ys = np.where(ok[:, None, None], Y, np.eye(3))
    # Λ = X Y⁻¹  <=>  Y Λᵀ = Xᵀ (Y symmetric)
    F = np.swapaxes(np.linalg.solve(Ys, np.swapaxes(X, 1, 2)), 1, 2)
    F[~ok] = np.nan
    res = mu1 - np.einsum("pab,pb->pa", F[i], mu0)
    d2 = np.bincount(i, weights=np.einsum("pa,pa->p", res, res), minlength=n)
    with np.errstate(invalid="ignore", divide="ignore"):
        d2 = d2 / nn
    d2[~ok] = np.nan
    out = {"d2min": d2, "F": F, "n_neighbors": np.where(both, nn, 0)}
    out.update(local_strain(F))
    return out


def local_strain(F: np.ndarray) -> dict:
    """Strain measures from affine tensors Λ (N, 3, 3).

    Returns ``strain`` ε = sym(Λ) − I (tension positive), ``eps_v`` = tr ε, ``eps_q`` =
    sqrt(2/3 ε_dev:ε_dev) (seed 001 after eq. 12), ``green`` E = (ΛᵀΛ − I)/2 and ``shear_vm``
    = sqrt(E_xy² + E_xz² + E_yz² + ((E_xx−E_yy)² + (E_yy−E_zz)² + (E_xx−E_zz)²)/6).
    """
    F = np.asarray(F, float)
    eye = np.eye(3)
    eps = 0.5 * (F + np.swapaxes(F, -1, -2)) - eye
    tr = np.trace(eps, axis1=-2, axis2=-1)
    dev = eps - tr[..., None, None] / 3.0 * eye
    eq = np.sqrt(2.0 / 3.0 * np.einsum("...ab,...ab->...", dev, dev))
    E = 0.5 * (np.einsum("...ba,...bc->...ac", F, F) - eye)
    vm = np.sqrt(E[..., 0, 1] ** 2 + E[..., 0, 2] ** 2 + E[..., 1, 2] ** 2
                 + ((E[..., 0, 0] - E[..., 1, 1]) ** 2 + (E[..., 1, 1] - E[..., 2, 2]) ** 2
                    + (E[..., 0, 0] - E[..., 2, 2]) ** 2) / 6.0)
    return {"strain": eps, "eps_v": tr, "eps_q": eq, "green": E, "shear_vm": vm}


def analyze_d2min(frames, cutoff: float | None = None, cutoff_d50: float = 1.5, pairs=None,
                  interval: float | None = None, start=None, control: str | None = None,
                  stride: int = 1, min_neighbors: int = 3) -> Result:
    """D²min, Λ and ε_q for frame pairs of a run (seed 001, eqs. 9-12).

    Options
    -------
    cutoff : neighbour cutoff [m]; default ``cutoff_d50`` × d50 (seed: 1.5 d50, the first
        minimum of g(r)).
    pairs / interval / start / control / stride : which (reference, current) frames, see
        :func:`orchestrator.analysis._common.frame_pairs` (seed: interval 0.01 axial strain).

    Tables
    ------
    ``particles``: frame0, frame1, control0, control1, id, radius, x, y, z (reference), d2min [m²],
    d2min_d50 (D²min / d50², dimensionless), eps_q, eps_v, shear_vm, n_neighbors, F_xx … F_zz.
    ``summary``: per pair the mean/median/90th percentile of D²min and ε_q and the number of valid
    particles.
    """
    from .plots import plot_d2min
    dd = d50(frames.radius)
    cut = float(cutoff) if cutoff is not None else cutoff_d50 * dd
    cname, cvals = control_values(frames, control)
    pos = frames.position
    rows, summ = [], []
    for k0, k1 in frame_pairs(frames, pairs, interval, start, control, stride):
        r = d2min(pos[k0], pos[k1], cut, min_neighbors=min_neighbors)
        df = pd.DataFrame({
            "frame0": k0, "frame1": k1, "control0": cvals[k0], "control1": cvals[k1],
            "id": frames.ids, "radius": frames.radius,
            "x": pos[k0][:, 0], "y": pos[k0][:, 1], "z": pos[k0][:, 2],
            "d2min": r["d2min"], "d2min_d50": r["d2min"] / dd ** 2, "eps_q": r["eps_q"],
            "eps_v": r["eps_v"], "shear_vm": r["shear_vm"], "n_neighbors": r["n_neighbors"]})
        for a, b in _COMP:
            df[f"F_{'xyz'[a]}{'xyz'[b]}"] = r["F"][:, a, b]
        df = df[present(pos[k0]) & present(pos[k1])]
        rows.append(df)
        v = df["d2min"].to_numpy()
        q = df["eps_q"].to_numpy()
        summ.append({"frame0": k0, "frame1": k1, "control0": cvals[k0], "control1": cvals[k1],
                     "n_valid": int(np.isfinite(v).sum()), "d2min_mean": np.nanmean(v),
                     "d2min_median": np.nanmedian(v), "d2min_p90": np.nanpercentile(v, 90),
                     "eps_q_mean": np.nanmean(q), "eps_q_median": np.nanmedian(q)})
    return Result("d2min", tables={"particles": pd.concat(rows, ignore_index=True),
                                   "summary": pd.DataFrame(summ)},
                  scalars={"cutoff_m": cut, "d50_m": dd, "control": cname},
                  options={"cutoff": cut, "pairs": pairs, "interval": interval, "control": cname},
                  plotter=plot_d2min)
