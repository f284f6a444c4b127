"""Geometry of the YADE triaxial membrane (GridNode/PFacet sheet around a cylindrical sample):
mesh topology, the follow-the-surface pressure as nodal forces, and the volume and lateral area
enclosed by the sheet's inner surface. numpy only (no YADE): unit-tested without the engine.

Nodes are stored row by row: row ``k`` (z increasing) holds ``nt`` nodes, node ``i`` of row ``k``
has local index ``k * nt + i``; rows are staggered by half a cell."""
from __future__ import annotations

import math

import numpy as np


def node_positions(nt: int, nz: int, radius: float, z0: float, dz: float) -> np.ndarray:
    """(nt (nz + 1), 3) node centres [m]: ``nz + 1`` rows from ``z0`` in steps ``dz`` on a circle of
    ``radius``; odd rows turned by half a cell."""
    out = []
    for k in range(nz + 1):
        z = z0 + dz * k
        for i in range(nt):
            th = 2 * math.pi * (i + 0.5 * (k % 2)) / nt
            out.append((radius * math.cos(th), radius * math.sin(th), z))
    return np.array(out, dtype=float)


def triangles(nt: int, nz: int) -> np.ndarray:
    """(2 nt nz, 3) local node indices of the facets, two per cell, counter-clockwise seen from
    outside, so that (b - a) x (c - a) points outwards."""
    node = lambda i, k: k * nt + (i % nt)
    tris = []
    for k in range(nz):
        for i in range(nt):
            if k % 2 == 0:
                t1 = (node(i, k), node(i + 1, k), node(i, k + 1))
                t2 = (node(i + 1, k), node(i + 1, k + 1), node(i, k + 1))
            else:
                t1 = (node(i, k), node(i + 1, k), node(i + 1, k + 1))
                t2 = (node(i, k), node(i + 1, k + 1), node(i, k + 1))
            tris += [t1, t2]
    return np.array(tris, dtype=int)


def edges(tris) -> list:
    """Sorted unique node pairs (a < b) of the triangles' sides."""
    out = set()
    for t in np.asarray(tris).tolist():
        for a, b in ((t[0], t[1]), (t[1], t[2]), (t[0], t[2])):
            out.add((min(a, b), max(a, b)))
    return sorted(out)


def neighbour_mean_matrix(n: int, edge_list) -> np.ndarray:
    """(n, n) matrix whose row k averages over node k's neighbours (for the membrane's internal
    viscosity F_k = -c (v_k - <v_j>), which leaves a uniform motion of the sheet unresisted)."""
    nb = [set() for _ in range(n)]
    for a, b in edge_list:
        nb[a].add(b)
        nb[b].add(a)
    L = np.zeros((n, n))
    for a, bs in enumerate(nb):
        for b in bs:
            L[a, b] = 1.0 / len(bs)
    return L


def area_vectors(x: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """(n_tri, 3) outward area vectors [m^2] of the facets with node positions ``x``."""
    a, b, c = x[tri[:, 0]], x[tri[:, 1]], x[tri[:, 2]]
    return 0.5 * np.cross(b - a, c - a)


def mean_perimeter(x: np.ndarray, nt: int) -> float:
    """Mean over the rows of the node-centre polygon's perimeter [m]."""
    xr = x.reshape(-1, nt, 3)
    return float(np.mean(np.sum(np.hypot(np.roll(xr[:, :, 0], -1, axis=1) - xr[:, :, 0],
                                         np.roll(xr[:, :, 1], -1, axis=1) - xr[:, :, 1]), axis=1)))


def pressure_forces(x: np.ndarray, tri: np.ndarray, nt: int, rn: float, p: float, zb: float, zt: float) -> np.ndarray:
    """(n_nodes, 3) nodal forces [N] of a pressure ``p`` [Pa] on the sheet: ``p A_f / 3`` along each
    facet's inward normal to each of its nodes (follow-the-surface load). Only the membrane beside
    the sample is loaded: each facet by the fraction of its height between the platens ``zb``,
    ``zt``. The pressure acts on the node-centre surface; it is scaled by inner/centre perimeter
    (inner surface = centre surface shrunk by the node radius ``rn``) so that the force per unit
    area of the inner surface, which the grains feel, is ``p``."""
    av = area_vectors(x, tri)
    z = x[tri, 2]
    lo, hi = z.min(axis=1), z.max(axis=1)
    frac = np.clip((np.minimum(hi, zt) - np.maximum(lo, zb)) / np.maximum(hi - lo, 1e-300), 0.0, 1.0)
    per = mean_perimeter(x, nt)
    p_eff = p * (per - 2 * math.pi * rn) / per
    w = -p_eff * frac[:, None] * av / 3.0                     # each facet's force on each of its nodes
    idx = tri.ravel()
    return np.stack([np.bincount(idx, weights=np.repeat(w[:, d], 3), minlength=len(x)) for d in range(3)], axis=1)


def inner_geometry(x: np.ndarray, nt: int, rn: float, zb: float, zt: float) -> dict:
    """Volume [m^3] and lateral area [m^2] of the sheet's inner surface between ``zb`` and ``zt``:
    each node row is a closed polygon; its area and perimeter (node-centre polygon shrunk by the
    node radius ``rn``) are interpolated linearly in z between rows and integrated (401 points)."""
    xr = x.reshape(-1, nt, 3)
    xs, ys = xr[:, :, 0], xr[:, :, 1]
    area = 0.5 * np.abs(np.sum(xs * np.roll(ys, -1, axis=1) - np.roll(xs, -1, axis=1) * ys, axis=1))
    per = np.sum(np.hypot(np.roll(xs, -1, axis=1) - xs, np.roll(ys, -1, axis=1) - ys), axis=1)
    area_in = area - rn * per + math.pi * rn ** 2
    per_in = per - 2 * math.pi * rn
    zr = xr[:, :, 2].mean(axis=1)
    zq = np.linspace(zb, zt, 401)
    return {"volume": _trapezoid(np.interp(zq, zr, area_in), zq), "area": _trapezoid(np.interp(zq, zr, per_in), zq)}


def _trapezoid(y, x) -> float:
    """Trapezoidal rule, the same sum as numpy 1.24's ``np.trapz`` (renamed in numpy 2)."""
    return float((np.diff(x) * (y[1:] + y[:-1]) / 2.0).sum())
