"""Tracking grains between consecutive scans: the three methods of the seeds.

(a) :func:`link` — links that minimise the total squared displacement, with displacements above a
    threshold ``max_disp`` [m] impossible (seed 000 §2.2, after Murphy et al.). Solved exactly as
    a sparse assignment problem: candidates from a k-d tree, one minimum-weight full bipartite
    matching (:func:`scipy.sparse.csgraph.min_weight_full_bipartite_matching`) on a graph augmented
    with "lost" and "new" dummies, so that leaving a grain unlinked costs ``max_disp**2 / 2``.
(b) :func:`estimate_rotation` — an image-based local rotation about the cell axis, per height slab
    and per ring of equal area, maximising the correlation of each ring with the next scan (seed 000
    §2.2, after Weis & Schröter); :meth:`RotationField.predict` feeds it to (a) as the prediction.
(c) :func:`match_invariants` — matching by spherical-harmonic invariants within ``3 d50`` and a
    10 % volume tolerance, with the conflict resolution of seed 001's Algorithm 1.

All return a :class:`Links`: for every grain of scan A the index of its partner in scan B (-1 =
lost) and vice versa (-1 = new).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage, sparse
from scipy.sparse.csgraph import min_weight_full_bipartite_matching
from scipy.spatial import cKDTree
from .io import check_series
from .synth import twist

__all__ = ["Links", "link", "estimate_rotation", "RotationField", "match_invariants", "track_sequence"]


@dataclass
class Links:
    """Correspondence between the grains of two scans.

    a_to_b : (Na,) index into scan B of each grain of scan A, -1 if lost.
    b_to_a : (Nb,) index into scan A of each grain of scan B, -1 if new.
    cost : (Na,) displacement [m] (methods a, b) or invariant distance [m] (method c) of each link,
        NaN if lost.
    """
    a_to_b: np.ndarray
    b_to_a: np.ndarray
    cost: np.ndarray
    method: str = ""
    info: dict = field(default_factory=dict)

    @property
    def lost(self) -> np.ndarray:
        """Indices of scan-A grains with no partner in scan B."""
        return np.nonzero(self.a_to_b < 0)[0]

    @property
    def new(self) -> np.ndarray:
        """Indices of scan-B grains with no partner in scan A."""
        return np.nonzero(self.b_to_a < 0)[0]

    @property
    def n_linked(self) -> int:
        return int((self.a_to_b >= 0).sum())

    def summary(self) -> dict:
        return {"method": self.method, "grains_a": len(self.a_to_b), "grains_b": len(self.b_to_a),
                "linked": self.n_linked, "lost": len(self.lost), "new": len(self.new), **self.info}


def _links_from_pairs(na, nb, ia, ib, cost, method, info=None):
    a_to_b = np.full(na, -1, np.int64)
    b_to_a = np.full(nb, -1, np.int64)
    c = np.full(na, np.nan)
    a_to_b[ia] = ib
    b_to_a[ib] = ia
    c[ia] = cost
    return Links(a_to_b, b_to_a, c, method, info or {})


# ------------------------------------------------------------------------------- (a) linking

def link(pos_a, pos_b, max_disp: float, predicted=None) -> Links:
    """Link grains of scan A (``pos_a`` (Na, 3) [m]) to scan B (``pos_b`` (Nb, 3) [m]) minimising the
    sum of squared displacements, each at most ``max_disp`` [m].

    ``predicted`` (Na, 3) [m] are expected positions of A's grains in scan B (e.g. from
    :meth:`RotationField.predict`); displacements are then measured from the prediction.
    A grain is left unlinked (lost / new) rather than linked beyond ``max_disp``; the optimum is
    exact (not greedy). NaN rows are ignored (never linked).
    """
    pa = np.asarray(pos_a if predicted is None else predicted, dtype=float)
    pb = np.asarray(pos_b, dtype=float)
    na, nb = len(pa), len(pb)
    if max_disp <= 0:
        raise ValueError(f"max_disp must be positive [m], got {max_disp}")
    oka = np.all(np.isfinite(pa), axis=1)
    okb = np.all(np.isfinite(pb), axis=1)
    ia_ok, ib_ok = np.nonzero(oka)[0], np.nonzero(okb)[0]
    if len(ia_ok) == 0 or len(ib_ok) == 0:
        return _links_from_pairs(na, nb, [], [], [], "displacement", {"max_disp": max_disp})
    i, j, d = _candidates(pa[ia_ok], pb[ib_ok], max_disp)
    n1, n2 = len(ia_ok), len(ib_ok)
    if len(i) == 0:
        return _links_from_pairs(na, nb, [], [], [], "displacement", {"max_disp": max_disp})
    # A pair that is each other's only candidate is linked outright: linking costs d^2 <= max_disp^2,
    # leaving both unlinked 2 * max_disp^2 / 2. Only the other components need the matching.
    deg_a = np.bincount(i, minlength=n1)
    deg_b = np.bincount(j, minlength=n2)
    alone = (deg_a[i] == 1) & (deg_b[j] == 1)
    la, lb = [i[alone]], [j[alone]]
    i, j, d = i[~alone], j[~alone], d[~alone]
    if len(i):
        ua, i = np.unique(i, return_inverse=True)
        ub, j = np.unique(j, return_inverse=True)
        m1, m2 = len(ua), len(ub)
        # augmented graph: rows = A (m1) + dummies of B (m2); cols = B (m2) + dummies of A (m1).
        # every edge gets +1 so that no weight is zero (sparse zeros are missing edges); a full
        # matching always has m1 + m2 edges, so the offset does not change the optimum.
        w = 1.0 + (d * d) / max_disp ** 2
        half = 1.5
        rows = np.concatenate([i, np.arange(m1), m1 + np.arange(m2), m1 + j])
        cols = np.concatenate([j, m2 + np.arange(m1), np.arange(m2), m2 + i])
        wts = np.concatenate([w, np.full(m1, half), np.full(m2, half), np.ones(len(i))])
        G = sparse.csr_matrix((wts, (rows, cols)), shape=(m1 + m2, m1 + m2))
        rr, cc = min_weight_full_bipartite_matching(G)
        real = (rr < m1) & (cc < m2)
        la.append(ua[rr[real]])
        lb.append(ub[cc[real]])
    ia, ib = np.concatenate(la), np.concatenate(lb)
    disp = np.linalg.norm(pa[ia_ok[ia]] - pb[ib_ok[ib]], axis=1)
    return _links_from_pairs(na, nb, ia_ok[ia], ib_ok[ib], disp, "displacement",
                             {"max_disp": max_disp, "candidates": int(len(i) + alone.sum())})


def _candidates(pa, pb, max_disp, k=2):
    """Every pair (i, j, distance) with ``|pa[i] - pb[j]| <= max_disp``: the k nearest points of B for
    each point of A from one k-d tree query, k doubled for the rows whose k-th neighbour is still
    within reach (few: at the usual steps most grains have one candidate)."""
    tree = cKDTree(pb)
    rows = np.arange(len(pa))
    out_i, out_j, out_d = [], [], []
    while len(rows):
        k = min(k, len(pb))
        dist, idx = tree.query(pa[rows], k=k, distance_upper_bound=max_disp)
        dist, idx = dist.reshape(len(rows), k), idx.reshape(len(rows), k)
        full = np.isfinite(dist[:, -1]) & (k < len(pb))
        keep = np.isfinite(dist) & ~full[:, None]
        out_i.append(np.broadcast_to(rows[:, None], dist.shape)[keep])
        out_j.append(idx[keep])
        out_d.append(dist[keep])
        rows = rows[full]
        k *= 2
    return np.concatenate(out_i), np.concatenate(out_j), np.concatenate(out_d)


# -------------------------------------------------------------------- (b) image-based rotation

@dataclass
class RotationField:
    """Local rotation angle about the vertical cell axis between two scans.

    z : (Z,) heights of the slab centres [m]; ring_edges : (K+1,) ring radii [m] (rings of equal
    area); angle : (Z, K) rotation from scan A to scan B [rad] (counter-clockwise seen from +z);
    quality : (Z, K) peak correlation coefficient; centre : (x, y) of the axis [m].
    """
    z: np.ndarray
    ring_edges: np.ndarray
    angle: np.ndarray
    quality: np.ndarray
    centre: np.ndarray

    @property
    def ring_centres(self) -> np.ndarray:
        e = self.ring_edges
        return np.sqrt(0.5 * (e[:-1] ** 2 + e[1:] ** 2))        # radius halving each ring's area

    def angle_at(self, position) -> np.ndarray:
        """Rotation angle [rad] at positions (N, 3) [m], bilinear in (height, ring), clamped at the ends."""
        p = np.asarray(position, float)
        rho = np.hypot(p[:, 0] - self.centre[0], p[:, 1] - self.centre[1])
        fz = np.interp(p[:, 2], self.z, np.arange(len(self.z)))
        fr = np.interp(rho, self.ring_centres, np.arange(len(self.ring_centres)))
        return ndimage.map_coordinates(self.angle, [fz, fr], order=1, mode="nearest")

    def predict(self, position) -> np.ndarray:
        """Positions (N, 3) [m] rotated about the axis by the local angle: the prediction for :func:`link`."""
        p = np.asarray(position, float)
        return twist(p, self.centre, self.angle_at(p))


def estimate_rotation(scan_a, scan_b, centre=None, radius=None, n_rings: int = 4, slab=None,
                      max_angle: float = np.deg2rad(15), n_phi: int | None = None, smooth: int = 1) -> RotationField:
    """Local rotation about the vertical axis between two scans, per height slab and ring of equal area.

    Each slice is resampled on a polar grid about ``centre`` (x, y) [m] (default: the volume centre)
    out to ``radius`` [m] (default: the largest circle inside the volume), split into ``n_rings``
    rings of equal area. For every slab of ``slab`` [m] height (default 4 voxels) and ring, the
    circular cross-correlation in angle between scan A and scan B is computed by FFT and its peak,
    refined by a parabola, within ``max_angle`` [rad], gives the local rotation. ``smooth`` slabs
    are median-filtered along the height to reject outliers (1 = no smoothing).
    """
    check_series([scan_a, scan_b])
    vs = scan_a.voxel_size
    nz, ny, nx = scan_a.shape
    if centre is None:
        centre = scan_a.to_world(np.array([0, (ny - 1) / 2, (nx - 1) / 2]))[:2]
    centre = np.asarray(centre, float)
    c_vox = ((centre - scan_a.origin[:2]) / vs)[::-1]                  # (y, x)
    rmax_vox = min(c_vox[0], c_vox[1], ny - 1 - c_vox[0], nx - 1 - c_vox[1])
    R = rmax_vox if radius is None else min(radius / vs, rmax_vox)
    if R < 4:
        raise ValueError(f"{scan_a.source}: the axis at {centre} m leaves a radius of only {R:.1f} voxels")
    edges = R * np.sqrt(np.arange(n_rings + 1) / n_rings)
    n_phi = n_phi or int(2 ** np.ceil(np.log2(2 * np.pi * R)))
    phi = np.arange(n_phi) * (2 * np.pi / n_phi)
    rho = np.arange(0.5, R, 0.5)
    ring_of = np.searchsorted(edges, rho, side="right") - 1
    ring_of = np.clip(ring_of, 0, n_rings - 1)
    yy = c_vox[0] + rho[:, None] * np.sin(phi)[None, :]
    xx = c_vox[1] + rho[:, None] * np.cos(phi)[None, :]
    slab_vox = 4 if slab is None else max(1, int(round(slab / vs)))
    starts = np.arange(0, nz - slab_vox + 1, slab_vox)
    max_shift = int(np.ceil(max_angle / (2 * np.pi) * n_phi))
    angle = np.zeros((len(starts), n_rings))
    quality = np.zeros((len(starts), n_rings))
    va = scan_a.volume.astype(np.float32)
    vb = scan_b.volume.astype(np.float32)
    for s, z0 in enumerate(starts):
        acc = np.zeros((n_rings, n_phi))
        na2 = np.zeros(n_rings)
        nb2 = np.zeros(n_rings)
        for zi in range(z0, z0 + slab_vox):
            A = ndimage.map_coordinates(va[zi], [yy, xx], order=1)
            B = ndimage.map_coordinates(vb[zi], [yy, xx], order=1)
            # weight each radius by rho so that every ring element counts by its area
            for k in range(n_rings):
                sel = ring_of == k
                a = A[sel] - A[sel].mean()
                b = B[sel] - B[sel].mean()
                wgt = rho[sel][:, None]
                fa = np.fft.rfft(a * wgt, axis=1)
                fb = np.fft.rfft(b, axis=1)
                acc[k] += np.fft.irfft((np.conj(fa) * fb).sum(axis=0), n=n_phi)
                na2[k] += (a * a * wgt).sum()
                nb2[k] += (b * b * wgt).sum()
        for k in range(n_rings):
            cc = acc[k] / np.sqrt(max(na2[k] * nb2[k], 1e-30))
            shifts = np.arange(-max_shift, max_shift + 1)
            vals = cc[shifts % n_phi]
            p = int(np.argmax(vals))
            frac = 0.0
            if 0 < p < len(vals) - 1:
                y0, y1, y2 = vals[p - 1], vals[p], vals[p + 1]
                den = y0 - 2 * y1 + y2
                frac = 0.5 * (y0 - y2) / den if den < 0 else 0.0
            angle[s, k] = (shifts[p] + frac) * 2 * np.pi / n_phi
            quality[s, k] = vals[p]
    if smooth > 1:
        angle = ndimage.median_filter(angle, size=(smooth, 1), mode="nearest")
    zc = scan_a.origin[2] + vs * (starts + (slab_vox - 1) / 2)
    return RotationField(zc, edges * vs, angle, quality, centre)


# ------------------------------------------------------------------------ (c) SH invariants

def match_invariants(pos_a, vol_a, inv_a, pos_b, vol_b, inv_b, d50: float, search: float = 3.0,
                     vol_tol: float = 0.1, predicted=None) -> Links:
    """Match grains by their SH rotation invariants (seed 001, Algorithm 1).

    For grain i of scan A the candidates are the grains of scan B within ``search * d50`` [m] of
    its position (or of ``predicted[i]``), whose volume differs by at most ``vol_tol`` of v_i; the
    best is the one with the smallest L2 distance between invariant vectors (eq. 5). When two grains
    of A want the same grain j of B, the closer one in invariant distance keeps j and the other
    re-matches among its remaining candidates, repeated until no conflict is left. Grains of A
    without candidates are lost, grains of B never chosen are new.

    pos_* (N, 3) [m]; vol_* (N,) [m^3]; inv_* (N, L+1) [m].
    """
    pa = np.asarray(pos_a if predicted is None else predicted, float)
    pb = np.asarray(pos_b, float)
    va, vb = np.asarray(vol_a, float), np.asarray(vol_b, float)
    Ra, Rb = np.asarray(inv_a, float), np.asarray(inv_b, float)
    na, nb = len(pa), len(pb)
    oka = np.all(np.isfinite(pa), axis=1) & np.all(np.isfinite(Ra), axis=1)
    okb = np.all(np.isfinite(pb), axis=1) & np.all(np.isfinite(Rb), axis=1)
    ia_ok, ib_ok = np.nonzero(oka)[0], np.nonzero(okb)[0]
    D = cKDTree(pa[ia_ok]).sparse_distance_matrix(cKDTree(pb[ib_ok]), search * d50, output_type="coo_matrix")
    i, j = ia_ok[D.row], ib_ok[D.col]
    keep = np.abs(vb[j] - va[i]) <= vol_tol * va[i]                       # set 2C
    i, j = i[keep], j[keep]
    rp = np.linalg.norm(Ra[i] - Rb[j], axis=1)                            # R_p, eq. 5
    order = np.lexsort((rp, i))                                           # by i, then by R_p
    i, j, rp = i[order], j[order], rp[order]
    start = np.searchsorted(i, np.arange(na + 1))
    ptr = start[:-1].copy()
    owner = np.full(nb, -1, np.int64)
    owner_cost = np.full(nb, np.inf)
    # deferred acceptance: each grain of A proposes to its candidates in order of R_p; a grain of B
    # keeps the proposer with the smaller R_p (Algorithm 1, lines 17-34)
    queue = list(np.nonzero(start[1:] > start[:-1])[0][::-1])
    while queue:
        l = queue.pop()
        while ptr[l] < start[l + 1]:
            k = ptr[l]
            ptr[l] += 1
            jj = j[k]
            if owner[jj] < 0:
                owner[jj], owner_cost[jj] = l, rp[k]
                break
            if rp[k] < owner_cost[jj]:
                p = owner[jj]
                owner[jj], owner_cost[jj] = l, rp[k]
                queue.append(p)
                break
    ib = np.nonzero(owner >= 0)[0]
    ia = owner[ib]
    return _links_from_pairs(na, nb, ia, ib, owner_cost[ib], "sh-invariants",
                             {"search": search * d50, "vol_tol": vol_tol, "candidates": int(len(i))})


def track_sequence(tables, method: str = "displacement", max_disp: float | None = None, scans=None,
                   invariants=None, d50: float | None = None, rotation_kw: dict | None = None,
                   progress: bool = False) -> list[Links]:
    """Link each scan to the next. ``tables`` are grain tables (x, y, z [m], volume [m^3]).

    method : "displacement" (a), "rotation" ((b) as prediction for (a); needs ``scans``) or
        "invariants" ((c); needs ``invariants`` per table, (N, L+1) each, or R0.. columns).
    max_disp : threshold of (a) [m] (default: half the median grain diameter).
    d50 : median grain diameter [m] for (c) (default: from the first table).
    """
    out = []
    d50 = d50 or 2 * float(np.median(tables[0]["radius"]))
    max_disp = max_disp or 0.5 * d50
    it = range(len(tables) - 1)
    if progress:
        from rich.progress import track as _track
        it = _track(it, description=f"tracking ({method})")
    for k in it:
        A, B = tables[k], tables[k + 1]
        pa, pb = A[["x", "y", "z"]].to_numpy(), B[["x", "y", "z"]].to_numpy()
        if method == "displacement":
            out.append(link(pa, pb, max_disp))
        elif method == "rotation":
            if scans is None:
                raise ValueError("method 'rotation' needs the scans (image-based rotation estimate)")
            field = estimate_rotation(scans[k], scans[k + 1], **(rotation_kw or {}))
            L = link(pa, pb, max_disp, predicted=field.predict(pa))
            L.method = "rotation+displacement"
            L.info["rotation_deg_max"] = float(np.rad2deg(np.abs(field.angle).max()))
            out.append(L)
        elif method == "invariants":
            if invariants is not None:
                ia, ib = invariants[k], invariants[k + 1]
            else:
                cols = [c for c in A.columns if c[:1] == "R" and c[1:].isdigit()]
                if not cols:
                    raise ValueError("method 'invariants' needs SH invariants (columns R0, R1, ...)")
                ia, ib = A[cols].to_numpy(), B[cols].to_numpy()
            out.append(match_invariants(pa, A["volume"].to_numpy(), ia, pb, B["volume"].to_numpy(), ib, d50))
        else:
            raise ValueError(f"unknown tracking method {method!r}; use displacement, rotation or invariants")
    return out
