"""Cell-list neighbour kernels compiled with numba (one thread): D²min with its affine tensor and
strains, and neighbour counts, at 10⁵ particles in a fraction of a second.

Present particles (no NaN coordinate) are sorted into cubic cells and copied in cell order
(neighbours then sit close in memory); each particle visits the (2 reach + 1)³ cells of edge
cutoff / reach around its own. A neighbour is another present particle whose centre is within the
cutoff (``|x_j - x_i| <= cutoff``, as :meth:`scipy.spatial.cKDTree.query_pairs`). Positions in m.

Why numba and not a pair list: the D²min sums need every pair twice (9 + 6 products, then the
residual); building the 1.8·10⁶ ordered pairs of 10⁵ particles with scipy's k-d tree and reducing
them with ``np.bincount`` and batched LAPACK calls took 1.5-5× OVITO's CPU time, most of it moving
pair and (N, 3, 3) arrays through memory. freud's queries need a periodic box; cKDTree's
``query_ball_point(return_length=True)`` was 3-4× slower for counts. benchmarks/bench_analysis.py
prints all of them side by side.
"""
from __future__ import annotations

import math

import numpy as np

# numba caches compiled kernels beside this file; where the package directory is read-only (a
# system install, another user's checkout) and no cache directory is set, cache them in a per-user
# temporary directory instead of failing ("no locator available")
from ..jit import numba   # numba with a writable kernel cache (orchestrator/jit.py)

__all__ = ["CellList", "d2min_kernel", "count_within", "strains"]


class CellList:
    """Present particles of ``position`` (N, 3) [m] sorted into cells of edge >= ``cutoff / reach``
    [m]; a particle's neighbours lie in the (2 reach + 1)³ cells around its own (reach 2: 42 % fewer
    distance checks than 27 cells of edge ``cutoff``).

    ``order``: row indices of the present particles in cell order; ``start[c]:start[c + 1]`` their
    range in cell c; ``sorted``: their positions in that order (contiguous); ``cell_of``: the cell of
    each sorted particle."""

    def __init__(self, position: np.ndarray, cutoff: float, reach: int = 2):
        p = np.asarray(position, dtype=np.float64)
        ok = ~np.isnan(p).any(axis=1)
        self.n = len(p)
        self.cutoff = float(cutoff)
        self.reach = int(reach)                 # cells of edge >= cutoff / reach; neighbours within reach cells
        rows = np.flatnonzero(ok)
        q = p[rows]
        lo = q.min(axis=0) if len(q) else np.zeros(3)
        span = q.max(axis=0) - lo if len(q) else np.zeros(3)
        ratio = span / (self.cutoff / self.reach)
        # at most ~8 cells per particle (a far outlier would otherwise ask for a huge empty grid):
        # larger cells only cost distance checks
        limit = 8.0 * max(len(q), 1) + 27
        grow = max(1.0, (np.prod(np.maximum(ratio, 1.0)) / limit) ** (1 / 3))
        self.dims = np.maximum((ratio / grow).astype(np.int64), 1)
        edge = np.maximum(span / self.dims, self.cutoff / self.reach)
        c = np.minimum(((q - lo) / edge).astype(np.int64), self.dims - 1) if len(q) else np.zeros((0, 3), np.int64)
        cell = (c[:, 0] * self.dims[1] + c[:, 1]) * self.dims[2] + c[:, 2]
        srt = np.argsort(cell, kind="stable")
        self.order = rows[srt].astype(np.int64)
        self.cell_of = cell[srt].astype(np.int64)
        self.start = np.searchsorted(self.cell_of, np.arange(int(np.prod(self.dims)) + 1)).astype(np.int64)
        self.sorted = np.ascontiguousarray(q[srt])

    def take(self, values: np.ndarray) -> np.ndarray:
        """Rows of ``values`` (N, ...) in cell order (contiguous)."""
        return np.ascontiguousarray(np.asarray(values)[self.order])


@numba.njit(cache=True, inline="always")
def _cell_xyz(c, dims):
    return c // (dims[2] * dims[1]), (c // dims[2]) % dims[1], c % dims[2]


@numba.njit(cache=True)
def _sym_eig_extremes(a00, a01, a02, a11, a12, a22):
    """Smallest and largest eigenvalue of a symmetric 3x3 matrix (trigonometric closed form)."""
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    q = (a00 + a11 + a22) / 3.0
    if p1 == 0.0:
        return min(a00, a11, a22), max(a00, a11, a22)
    p2 = (a00 - q) ** 2 + (a11 - q) ** 2 + (a22 - q) ** 2 + 2.0 * p1
    p = math.sqrt(p2 / 6.0)
    b00, b11, b22 = (a00 - q) / p, (a11 - q) / p, (a22 - q) / p
    b01, b02, b12 = a01 / p, a02 / p, a12 / p
    r = 0.5 * (b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02))
    r = min(1.0, max(-1.0, r))
    phi = math.acos(r) / 3.0
    big = q + 2.0 * p * math.cos(phi)
    small = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)
    return small, big


@numba.njit(cache=True)
def _d2min(ref, cur, cell_of, start, dims, reach, cut2, use, min_nb, rcond, F, d2, nn):
    # pass 1: every pair once (k > i in cell order), its products added to both particles
    # (mu_ik = -mu_ki, so mu1 ⊗ mu0 and mu0 ⊗ mu0 are the same for both)
    n = ref.shape[0]
    X = np.zeros((n, 9))
    Y = np.zeros((n, 6))
    pi = np.empty(16 * n + 16, np.int64)
    pk = np.empty(16 * n + 16, np.int64)
    npair = 0
    for i in range(n):
        cx, cy, cz = _cell_xyz(cell_of[i], dims)
        for ax in range(max(cx - reach, 0), min(cx + reach + 1, dims[0])):
            for ay in range(max(cy - reach, 0), min(cy + reach + 1, dims[1])):
                c0 = (ax * dims[1] + ay) * dims[2]
                for k in range(max(start[c0 + max(cz - reach, 0)], i + 1), start[c0 + min(cz + reach + 1, dims[2])]):
                    m0x = ref[k, 0] - ref[i, 0]
                    m0y = ref[k, 1] - ref[i, 1]
                    m0z = ref[k, 2] - ref[i, 2]
                    if m0x * m0x + m0y * m0y + m0z * m0z > cut2:
                        continue
                    m1x = cur[k, 0] - cur[i, 0]
                    m1y = cur[k, 1] - cur[i, 1]
                    m1z = cur[k, 2] - cur[i, 2]
                    if npair == pi.shape[0]:
                        gi = np.empty(2 * npair, np.int64)
                        gk = np.empty(2 * npair, np.int64)
                        gi[:npair] = pi
                        gk[:npair] = pk
                        pi, pk = gi, gk
                    pi[npair] = i
                    pk[npair] = k
                    npair += 1
                    nn[i] += 1
                    nn[k] += 1
                    for j, v in enumerate((m1x * m0x, m1x * m0y, m1x * m0z, m1y * m0x, m1y * m0y, m1y * m0z,
                                           m1z * m0x, m1z * m0y, m1z * m0z)):
                        X[i, j] += v
                        X[k, j] += v
                    for j, v in enumerate((m0x * m0x, m0x * m0y, m0x * m0z, m0y * m0y, m0y * m0z, m0z * m0z)):
                        Y[i, j] += v
                        Y[k, j] += v
    # Λ = X Y⁻¹ per particle (Y symmetric: its inverse by cofactors)
    ok = np.zeros(n, np.bool_)
    for i in range(n):
        if not use[i] or nn[i] < min_nb:
            continue
        y00, y01, y02, y11, y12, y22 = Y[i, 0], Y[i, 1], Y[i, 2], Y[i, 3], Y[i, 4], Y[i, 5]
        lo, hi = _sym_eig_extremes(y00, y01, y02, y11, y12, y22)
        if not lo > rcond * max(hi, 1e-300):
            continue
        ok[i] = True
        c00 = y11 * y22 - y12 * y12
        c01 = y02 * y12 - y01 * y22
        c02 = y01 * y12 - y02 * y11
        c11 = y00 * y22 - y02 * y02
        c12 = y01 * y02 - y00 * y12
        c22 = y00 * y11 - y01 * y01
        det = y00 * c00 + y01 * c01 + y02 * c02
        for a in range(3):
            xa0, xa1, xa2 = X[i, 3 * a], X[i, 3 * a + 1], X[i, 3 * a + 2]
            F[i, a, 0] = (xa0 * c00 + xa1 * c01 + xa2 * c02) / det
            F[i, a, 1] = (xa0 * c01 + xa1 * c11 + xa2 * c12) / det
            F[i, a, 2] = (xa0 * c02 + xa1 * c12 + xa2 * c22) / det
    # pass 2: residuals |mu1 - Λ mu0|² of both particles of every pair
    s = np.zeros(n)
    for q in range(npair):
        i = pi[q]
        k = pk[q]
        m0x = ref[k, 0] - ref[i, 0]
        m0y = ref[k, 1] - ref[i, 1]
        m0z = ref[k, 2] - ref[i, 2]
        m1x = cur[k, 0] - cur[i, 0]
        m1y = cur[k, 1] - cur[i, 1]
        m1z = cur[k, 2] - cur[i, 2]
        if ok[i]:
            rx = m1x - (F[i, 0, 0] * m0x + F[i, 0, 1] * m0y + F[i, 0, 2] * m0z)
            ry = m1y - (F[i, 1, 0] * m0x + F[i, 1, 1] * m0y + F[i, 1, 2] * m0z)
            rz = m1z - (F[i, 2, 0] * m0x + F[i, 2, 1] * m0y + F[i, 2, 2] * m0z)
            s[i] += rx * rx + ry * ry + rz * rz
        if ok[k]:
            rx = m1x - (F[k, 0, 0] * m0x + F[k, 0, 1] * m0y + F[k, 0, 2] * m0z)
            ry = m1y - (F[k, 1, 0] * m0x + F[k, 1, 1] * m0y + F[k, 1, 2] * m0z)
            rz = m1z - (F[k, 2, 0] * m0x + F[k, 2, 1] * m0y + F[k, 2, 2] * m0z)
            s[k] += rx * rx + ry * ry + rz * rz
    for i in range(n):
        if ok[i]:
            d2[i] = s[i] / nn[i]


@numba.njit(cache=True)
def _count(pos, cell_of, start, dims, reach, cut2, out):
    # every pair once (k > i in cell order), counted for both
    for i in range(pos.shape[0]):
        cx, cy, cz = _cell_xyz(cell_of[i], dims)
        for ax in range(max(cx - reach, 0), min(cx + reach + 1, dims[0])):
            for ay in range(max(cy - reach, 0), min(cy + reach + 1, dims[1])):
                c0 = (ax * dims[1] + ay) * dims[2]
                for k in range(max(start[c0 + max(cz - reach, 0)], i + 1), start[c0 + min(cz + reach + 1, dims[2])]):
                    dx = pos[k, 0] - pos[i, 0]
                    dy = pos[k, 1] - pos[i, 1]
                    dz = pos[k, 2] - pos[i, 2]
                    if dx * dx + dy * dy + dz * dz <= cut2:
                        out[i] += 1
                        out[k] += 1


@numba.njit(cache=True)
def _strains(F, eps, ev, eq, E, vm):
    for i in range(F.shape[0]):
        for a in range(3):
            for b in range(3):
                eps[i, a, b] = 0.5 * (F[i, a, b] + F[i, b, a]) - (1.0 if a == b else 0.0)
                t = 0.0
                for c in range(3):
                    t += F[i, c, a] * F[i, c, b]
                E[i, a, b] = 0.5 * (t - (1.0 if a == b else 0.0))
        tr = eps[i, 0, 0] + eps[i, 1, 1] + eps[i, 2, 2]
        ev[i] = tr
        dd = 0.0
        for a in range(3):
            for b in range(3):
                x = eps[i, a, b] - (tr / 3.0 if a == b else 0.0)
                dd += x * x
        eq[i] = math.sqrt(2.0 / 3.0 * dd)
        vm[i] = math.sqrt(E[i, 0, 1] ** 2 + E[i, 0, 2] ** 2 + E[i, 1, 2] ** 2
                          + ((E[i, 0, 0] - E[i, 1, 1]) ** 2 + (E[i, 1, 1] - E[i, 2, 2]) ** 2
                             + (E[i, 0, 0] - E[i, 2, 2]) ** 2) / 6.0)


def strains(F: np.ndarray) -> dict:
    """The strain measures of :func:`orchestrator.analysis.d2min.local_strain` for affine tensors
    F (..., 3, 3), one compiled pass (NaN tensors give NaN)."""
    F = np.asarray(F, dtype=np.float64)
    shape = F.shape[:-2]
    f = np.ascontiguousarray(F.reshape(-1, 3, 3))
    m = len(f)
    eps, E = np.empty((m, 3, 3)), np.empty((m, 3, 3))
    ev, eq, vm = np.empty(m), np.empty(m), np.empty(m)
    _strains(f, eps, ev, eq, E, vm)
    return {"strain": eps.reshape(shape + (3, 3)), "eps_v": ev.reshape(shape), "eps_q": eq.reshape(shape),
            "green": E.reshape(shape + (3, 3)), "shear_vm": vm.reshape(shape)}


def d2min_kernel(cells: CellList, current: np.ndarray, use: np.ndarray, min_neighbors: int, rcond: float):
    """D²min [m²], affine tensor Λ and neighbour count of every particle (seed 001, eqs. 9-12);
    neighbours within the cutoff in the reference positions of ``cells``. Only rows with ``use``
    (bool (N,)) and at least ``min_neighbors`` neighbours whose Y is well conditioned (smallest /
    largest eigenvalue > ``rcond``) get values; the others NaN. Returns (d2 (N,), F (N,3,3), nn (N,))."""
    m = len(cells.order)
    F = np.full((m, 3, 3), np.nan)
    d2 = np.full(m, np.nan)
    nn = np.zeros(m, np.int64)
    _d2min(cells.sorted, cells.take(np.asarray(current, np.float64)), cells.cell_of, cells.start, cells.dims,
           cells.reach, cells.cutoff ** 2, cells.take(use), int(min_neighbors), float(rcond), F, d2, nn)
    outF = np.full((cells.n, 3, 3), np.nan)
    outd = np.full(cells.n, np.nan)
    outn = np.zeros(cells.n, np.int64)
    outF[cells.order], outd[cells.order], outn[cells.order] = F, d2, nn
    return outd, outF, outn


def count_within(cells: CellList) -> np.ndarray:
    """Number of other present centres within the cutoff of each present centre (int, -1 if absent)."""
    c = np.zeros(len(cells.order), np.int64)
    _count(cells.sorted, cells.cell_of, cells.start, cells.dims, cells.reach, cells.cutoff ** 2, c)
    out = np.full(cells.n, -1, np.int64)
    out[cells.order] = c
    return out
