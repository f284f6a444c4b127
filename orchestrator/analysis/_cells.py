"""Cell-list neighbour kernels compiled with numba (one thread): D²min with its affine tensor and
strains, and neighbour counts, at 10⁵ particles in a fraction of a second.

Present particles (no NaN coordinate) are sorted into cubic cells of edge >= the cutoff and copied
in cell order (neighbours then sit close in memory); each particle visits the 27 cells around its
own. A neighbour is another present particle whose centre is within the cutoff
(``|x_j - x_i| <= cutoff``, as :meth:`scipy.spatial.cKDTree.query_pairs`). Positions in m.

Why numba and not a pair list: the D²min sums need every pair twice (9 + 6 products, then the
residual); building the 1.8·10⁶ ordered pairs of 10⁵ particles with scipy's k-d tree and reducing
them with ``np.bincount`` and batched LAPACK calls took 1.5-5× OVITO's CPU time, most of it moving
pair and (N, 3, 3) arrays through memory. freud's queries need a periodic box; cKDTree's
``query_ball_point(return_length=True)`` was 3-4× slower for counts. benchmarks/bench_analysis.py
prints all of them side by side.
"""
from __future__ import annotations

import math
import os
import tempfile

import numpy as np

# numba caches compiled kernels beside this file; where the package directory is read-only (a
# system install, another user's checkout) and no cache directory is set, cache them in a per-user
# temporary directory instead of failing ("no locator available")
if "NUMBA_CACHE_DIR" not in os.environ and not os.access(os.path.dirname(os.path.abspath(__file__)), os.W_OK):
    os.environ["NUMBA_CACHE_DIR"] = os.path.join(tempfile.gettempdir(), f"orchestrator-numba-{os.getuid()}")

import numba  # noqa: E402  (after NUMBA_CACHE_DIR: numba reads it at import)

__all__ = ["CellList", "d2min_kernel", "count_within", "strains"]


class CellList:
    """Present particles of ``position`` (N, 3) [m] sorted into cells of edge >= ``cutoff`` [m].

    ``order``: row indices of the present particles in cell order; ``start[c]:start[c + 1]`` their
    range in cell c; ``sorted``: their positions in that order (contiguous); ``cell_of``: the cell of
    each sorted particle."""

    def __init__(self, position: np.ndarray, cutoff: float):
        p = np.asarray(position, dtype=np.float64)
        ok = ~np.isnan(p).any(axis=1)
        self.n = len(p)
        self.cutoff = float(cutoff)
        rows = np.flatnonzero(ok)
        q = p[rows]
        lo = q.min(axis=0) if len(q) else np.zeros(3)
        span = q.max(axis=0) - lo if len(q) else np.zeros(3)
        ratio = span / self.cutoff
        # at most ~8 cells per particle (a far outlier would otherwise ask for a huge empty grid):
        # larger cells only cost distance checks
        limit = 8.0 * max(len(q), 1) + 27
        grow = max(1.0, (np.prod(np.maximum(ratio, 1.0)) / limit) ** (1 / 3))
        self.dims = np.maximum((ratio / grow).astype(np.int64), 1)
        edge = np.maximum(span / self.dims, self.cutoff)
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
def _d2min(ref, cur, cell_of, start, dims, cut2, use, min_nb, rcond, F, d2, nn):
    n = ref.shape[0]
    X = np.empty((3, 3))
    Y = np.empty((3, 3))
    b0 = np.empty((64, 3))           # the neighbour vectors of one particle, for the residual pass
    b1 = np.empty((64, 3))
    for i in range(n):
        cx, cy, cz = _cell_xyz(cell_of[i], dims)
        X[:] = 0.0
        Y[:] = 0.0
        m = 0
        for ax in range(max(cx - 1, 0), min(cx + 2, dims[0])):
            for ay in range(max(cy - 1, 0), min(cy + 2, dims[1])):
                c0 = (ax * dims[1] + ay) * dims[2]
                for k in range(start[c0 + max(cz - 1, 0)], start[c0 + min(cz + 2, dims[2])]):
                    if k == i:
                        continue
                    m0x = ref[k, 0] - ref[i, 0]
                    m0y = ref[k, 1] - ref[i, 1]
                    m0z = ref[k, 2] - ref[i, 2]
                    if m0x * m0x + m0y * m0y + m0z * m0z > cut2:
                        continue
                    m1x = cur[k, 0] - cur[i, 0]
                    m1y = cur[k, 1] - cur[i, 1]
                    m1z = cur[k, 2] - cur[i, 2]
                    if m == b0.shape[0]:
                        g0 = np.empty((2 * m, 3))
                        g1 = np.empty((2 * m, 3))
                        g0[:m] = b0
                        g1[:m] = b1
                        b0, b1 = g0, g1
                    b0[m, 0], b0[m, 1], b0[m, 2] = m0x, m0y, m0z
                    b1[m, 0], b1[m, 1], b1[m, 2] = m1x, m1y, m1z
                    m += 1
                    X[0, 0] += m1x * m0x
                    X[0, 1] += m1x * m0y
                    X[0, 2] += m1x * m0z
                    X[1, 0] += m1y * m0x
                    X[1, 1] += m1y * m0y
                    X[1, 2] += m1y * m0z
                    X[2, 0] += m1z * m0x
                    X[2, 1] += m1z * m0y
                    X[2, 2] += m1z * m0z
                    Y[0, 0] += m0x * m0x
                    Y[0, 1] += m0x * m0y
                    Y[0, 2] += m0x * m0z
                    Y[1, 1] += m0y * m0y
                    Y[1, 2] += m0y * m0z
                    Y[2, 2] += m0z * m0z
        nn[i] = m
        if not use[i] or m < min_nb:
            continue
        lo, hi = _sym_eig_extremes(Y[0, 0], Y[0, 1], Y[0, 2], Y[1, 1], Y[1, 2], Y[2, 2])
        if not lo > rcond * max(hi, 1e-300):
            continue
        # Λ = X Y⁻¹ (Y symmetric: its inverse by cofactors)
        c00 = Y[1, 1] * Y[2, 2] - Y[1, 2] * Y[1, 2]
        c01 = Y[0, 2] * Y[1, 2] - Y[0, 1] * Y[2, 2]
        c02 = Y[0, 1] * Y[1, 2] - Y[0, 2] * Y[1, 1]
        c11 = Y[0, 0] * Y[2, 2] - Y[0, 2] * Y[0, 2]
        c12 = Y[0, 1] * Y[0, 2] - Y[0, 0] * Y[1, 2]
        c22 = Y[0, 0] * Y[1, 1] - Y[0, 1] * Y[0, 1]
        det = Y[0, 0] * c00 + Y[0, 1] * c01 + Y[0, 2] * c02
        for a in range(3):
            F[i, a, 0] = (X[a, 0] * c00 + X[a, 1] * c01 + X[a, 2] * c02) / det
            F[i, a, 1] = (X[a, 0] * c01 + X[a, 1] * c11 + X[a, 2] * c12) / det
            F[i, a, 2] = (X[a, 0] * c02 + X[a, 1] * c12 + X[a, 2] * c22) / det
        s = 0.0
        for q in range(m):
            m0x, m0y, m0z = b0[q, 0], b0[q, 1], b0[q, 2]
            rx = b1[q, 0] - (F[i, 0, 0] * m0x + F[i, 0, 1] * m0y + F[i, 0, 2] * m0z)
            ry = b1[q, 1] - (F[i, 1, 0] * m0x + F[i, 1, 1] * m0y + F[i, 1, 2] * m0z)
            rz = b1[q, 2] - (F[i, 2, 0] * m0x + F[i, 2, 1] * m0y + F[i, 2, 2] * m0z)
            s += rx * rx + ry * ry + rz * rz
        d2[i] = s / m


@numba.njit(cache=True)
def _count(pos, cell_of, start, dims, cut2, out):
    for i in range(pos.shape[0]):
        cx, cy, cz = _cell_xyz(cell_of[i], dims)
        m = 0
        for ax in range(max(cx - 1, 0), min(cx + 2, dims[0])):
            for ay in range(max(cy - 1, 0), min(cy + 2, dims[1])):
                c0 = (ax * dims[1] + ay) * dims[2]
                for k in range(start[c0 + max(cz - 1, 0)], start[c0 + min(cz + 2, dims[2])]):
                    dx = pos[k, 0] - pos[i, 0]
                    dy = pos[k, 1] - pos[i, 1]
                    dz = pos[k, 2] - pos[i, 2]
                    if k != i and dx * dx + dy * dy + dz * dz <= cut2:
                        m += 1
        out[i] = m


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
           cells.cutoff ** 2, cells.take(use), int(min_neighbors), float(rcond), F, d2, nn)
    outF = np.full((cells.n, 3, 3), np.nan)
    outd = np.full(cells.n, np.nan)
    outn = np.zeros(cells.n, np.int64)
    outF[cells.order], outd[cells.order], outn[cells.order] = F, d2, nn
    return outd, outF, outn


def count_within(cells: CellList) -> np.ndarray:
    """Number of other present centres within the cutoff of each present centre (int, -1 if absent)."""
    c = np.zeros(len(cells.order), np.int64)
    _count(cells.sorted, cells.cell_of, cells.start, cells.dims, cells.cutoff ** 2, c)
    out = np.full(cells.n, -1, np.int64)
    out[cells.order] = c
    return out
