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

The neighbour sums run in compiled cell-list kernels (:mod:`._cells`, numba), the 3×3 solves
are batched in numpy; there is no Python loop over particles.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from ._cells import CellList, d2min_kernel, strains
from ._common import Result, control_values, d50, frame_pairs, present
from .containers import make_container
from .plots import plot_d2min

__all__ = ["d2min", "local_strain", "analyze_d2min"]

_COMP = [(a, b) for a in range(3) for b in range(3)]


def d2min(reference: np.ndarray, current: np.ndarray, cutoff: float, min_neighbors: int = 3,
          rcond: float = 1e-6, wall_distance: float | None = None, container=None) -> dict:
    """D²min and the best-fit affine tensor Λ for every particle (seed 001, eqs. 9-12).

    Parameters
    ----------
    reference, current : (N, 3) centre positions [m] at strain ε and ε + δε; NaN rows (absent
        particles) are skipped and neither count as neighbours nor get a value.
    cutoff : neighbour cutoff [m] in the reference configuration (seed: 1.5 d50).
    min_neighbors : particles with fewer neighbours (or a neighbourhood that does not span 3-D,
        smallest/largest eigenvalue of Y below ``rcond``) get NaN.
    wall_distance : [m] only particles whose reference centre is at least this far from the
        container boundary get a value (the interior; near walls the neighbourhood is one-sided); all
        particles still serve as neighbours. ``container`` as in :mod:`.containers` (default
        inferred from the reference positions).

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
    if wall_distance is not None:
        interior = np.zeros(n, bool)
        box = make_container(container, np.where(both[:, None], ref, np.nan))
        interior[both] = box.distance_to_boundary(ref[both]) >= float(wall_distance)
    else:
        interior = both
    cells = CellList(np.where(both[:, None], ref, np.nan), cutoff)
    d2, F, nn = d2min_kernel(cells, np.where(both[:, None], cur, 0.0), interior, max(min_neighbors, 3), rcond)
    out = {"d2min": d2, "F": F, "n_neighbors": np.where(both, nn, 0)}
    out.update(local_strain(F))
    return out


def local_strain(F: np.ndarray) -> dict:
    """Strain measures from affine tensors Λ (N, 3, 3).

    Returns ``strain`` ε = sym(Λ) − I (tension positive), ``eps_v`` = tr ε, ``eps_q`` =
    sqrt(2/3 ε_dev:ε_dev) (seed 001 after eq. 12), ``green`` E = (ΛᵀΛ − I)/2 and ``shear_vm``
    = sqrt(E_xy² + E_xz² + E_yz² + ((E_xx−E_yy)² + (E_yy−E_zz)² + (E_xx−E_zz)²)/6).
    """
    return strains(F)


def analyze_d2min(frames, cutoff: float | None = None, cutoff_d50: float = 1.5, pairs=None,
                  interval: float | None = None, start=None, control: str | None = None,
                  stride: int = 1, min_neighbors: int = 3, wall_distance: float | None = None,
                  container=None, stages: str = "loading") -> Result:
    """D²min, Λ and ε_q for frame pairs of a run (seed 001, eqs. 9-12).

    Options
    -------
    cutoff : neighbour cutoff [m]; default ``cutoff_d50`` × d50 (seed: 1.5 d50, the first
        minimum of g(r)).
    pairs / interval / start / control / stride / stages : which (reference, current) frames, see
        :func:`orchestrator.analysis._common.frame_pairs` (seed: interval 0.01 axial strain; by
        default only the loading stage, ``stages="all"`` adds the preparation).
    wall_distance / container : only particles at least ``wall_distance`` [m] from the container
        boundary get a value (see :func:`d2min`).

    Tables
    ------
    ``particles``: frame0, frame1, control0, control1, id, radius, x, y, z (reference), d2min [m²],
    d2min_d50 (D²min / d50², dimensionless), eps_q, eps_v, shear_vm, n_neighbors, F_xx … F_zz.
    ``summary``: per pair the mean/median/90th percentile of D²min and ε_q and the number of valid
    particles.
    """
    dd = d50(frames.radius)
    cut = float(cutoff) if cutoff is not None else cutoff_d50 * dd
    cname, cvals = control_values(frames, control)
    pos = frames.position
    rows, summ = [], []
    for k0, k1 in frame_pairs(frames, pairs, interval, start, control, stride, stages):
        r = d2min(pos[k0], pos[k1], cut, min_neighbors=min_neighbors, wall_distance=wall_distance,
                  container=container)
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
                  options={"cutoff": cut, "pairs": pairs, "interval": interval, "control": cname,
                           "wall_distance": wall_distance, "stages": stages},
                  plotter=plot_d2min)
