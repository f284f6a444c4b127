"""Whole-volume passes of the CT segmentation compiled with numba (one thread): the exact Euclidean
distance transform, label growing, per-label sums and bounding boxes, convex-hull candidates; and
the rays of the shape measurement (:func:`outermost_crossing`).

Distance transform: the separable algorithm of P. F. Felzenszwalb and D. P. Huttenlocher, "Distance transforms of sampled
functions", Theory of Computing 8 (2012) 415-428, sec. 2-3: the squared distance to the nearest zero
voxel is the lower envelope of parabolas, computed line by line along z (a plain 1-D distance), then
y, then x. Squared distances are integers below 2^24 for volumes under ~2900 voxels a side, hence
exact in float32; the result equals :func:`scipy.ndimage.distance_transform_edt` (the distance to
the nearest zero voxel inside the array; a volume with no zero voxel gives +inf).

On a 512^3 scan: ~6-10 s instead of ~55 s for scipy's feature transform + distances.
"""
from __future__ import annotations

import math

import numpy as np

from ..jit import numba   # numba with a writable kernel cache (orchestrator/jit.py)

__all__ = ["edt", "grow_kernel", "region_sums", "label_stats", "extreme_candidates", "basin_saddles",
           "label_sizes", "table_mask", "outermost_crossing"]


@numba.njit(cache=True, nogil=True)
def _envelope(f, n, out, v, zb):
    """1-D squared distance transform of the sampled function f[0:n] (inf: no source), into out."""
    inf = np.inf
    k = -1
    for q in range(n):
        fq = f[q]
        if fq == inf:
            continue
        s = 0.0
        while k >= 0:                            # pop the parabolas the new one hides
            p = v[k]
            s = ((fq + q * q) - (f[p] + p * p)) / (2.0 * (q - p))
            if s > zb[k]:
                break
            k -= 1
        if k < 0:                                # the first source, or it hides every earlier one
            k = 0
            v[0] = q
            zb[0] = -inf
            zb[1] = inf
            continue
        k += 1
        v[k] = q
        zb[k] = s
        zb[k + 1] = inf
    if k < 0:
        for q in range(n):
            out[q] = inf
        return
    k = 0
    for q in range(n):
        while zb[k + 1] < q:
            k += 1
        p = v[k]
        out[q] = (q - p) * (q - p) + f[p]


@numba.njit(cache=True, nogil=True)
def _edt_sq(binary, d):
    nz, ny, nx = binary.shape
    inf = np.inf
    # z: 1-D distance along each column (forward then backward scan), squared
    for y in range(ny):
        for x in range(nx):
            d[0, y, x] = 0.0 if binary[0, y, x] == 0 else inf
    for z in range(1, nz):
        for y in range(ny):
            for x in range(nx):
                d[z, y, x] = 0.0 if binary[z, y, x] == 0 else d[z - 1, y, x] + 1.0
    for z in range(nz - 2, -1, -1):
        for y in range(ny):
            for x in range(nx):
                a = d[z + 1, y, x] + 1.0
                if a < d[z, y, x]:
                    d[z, y, x] = a
    for z in range(nz):
        for y in range(ny):
            for x in range(nx):
                t = d[z, y, x]
                d[z, y, x] = t * t
    m = max(ny, nx)
    f = np.empty(m, np.float64)
    out = np.empty(m, np.float64)
    v = np.empty(m, np.int64)
    zb = np.empty(m + 1, np.float64)
    # y: lines d[z, :, x]
    for z in range(nz):
        for x in range(nx):
            for y in range(ny):
                f[y] = d[z, y, x]
            _envelope(f, ny, out, v, zb)
            for y in range(ny):
                d[z, y, x] = out[y]
    # x: lines d[z, y, :]
    for z in range(nz):
        for y in range(ny):
            for x in range(nx):
                f[x] = d[z, y, x]
            _envelope(f, nx, out, v, zb)
            for x in range(nx):
                d[z, y, x] = np.sqrt(out[x])


def edt(binary: np.ndarray) -> np.ndarray:
    """Euclidean distance [voxels] of every non-zero voxel of the 3-D ``binary`` to the nearest zero
    voxel (0 on zero voxels), float32."""
    b = np.ascontiguousarray(binary)
    if b.ndim != 3:
        raise ValueError(f"edt: a 3-D volume is expected, got shape {b.shape}")
    if b.dtype != np.bool_:
        b = b != 0
    d = np.empty(b.shape, np.float32)
    if b.size:
        _edt_sq(b.view(np.uint8), d)
    return d


# --- other whole-volume passes of the segmentation (orchestrator/ct/segment.py), one thread each ---

@numba.njit(cache=True, nogil=True)
def grow_kernel(labels, out, shell_start, dz, dy, dx):
    """Background voxels (0) of ``labels`` take the largest label among the offsets of the first
    shell (offsets shell_start[s]:shell_start[s+1], shells in increasing distance) that holds any
    labelled voxel; ``out`` starts as a copy of ``labels``."""
    nz, ny, nx = labels.shape
    ns = len(shell_start) - 1
    for z in range(nz):
        for y in range(ny):
            for x in range(nx):
                if labels[z, y, x] != 0:
                    continue
                for s in range(ns):
                    m = 0
                    for k in range(shell_start[s], shell_start[s + 1]):
                        zz, yy, xx = z + dz[k], y + dy[k], x + dx[k]
                        if 0 <= zz < nz and 0 <= yy < ny and 0 <= xx < nx:
                            v = labels[zz, yy, xx]
                            if v > m:
                                m = v
                    if m > 0:
                        out[z, y, x] = m
                        break


@numba.njit(cache=True, nogil=True)
def region_sums(regions, raw, pore, solid, n):
    """Per label 1..n of ``regions``: sum of the solid fraction w = clip((raw - pore)/(solid - pore), 0, 1)
    (float32, as Segmentation.raw_fraction) and of w z, w y, w x (float64, in C order: the same sums
    as scipy.ndimage.sum_labels / center_of_mass)."""
    nz, ny, nx = regions.shape
    s = np.zeros((n + 1, 4))
    p = np.float32(pore)
    den = np.float32(solid - pore)
    for z in range(nz):
        for y in range(ny):
            for x in range(nx):
                lab = regions[z, y, x]
                if lab == 0:
                    continue
                w = (np.float32(raw[z, y, x]) - p) / den
                if w < 0:
                    w = np.float32(0.0)
                elif w > 1:
                    w = np.float32(1.0)
                wd = np.float64(w)
                s[lab, 0] += wd
                s[lab, 1] += wd * z
                s[lab, 2] += wd * y
                s[lab, 3] += wd * x
    return s


@numba.njit(cache=True, nogil=True)
def label_stats(labels, dist, n):
    """Per label 1..n: voxel count, bounding box (z0 y0 x0 z1 y1 x1, stop exclusive; zeros when
    absent) and the largest ``dist`` value."""
    nz, ny, nx = labels.shape
    cnt = np.zeros(n + 1, np.int64)
    box = np.empty((n + 1, 6), np.int64)
    for k in range(n + 1):
        box[k, 0] = box[k, 1] = box[k, 2] = 1 << 62
        box[k, 3] = box[k, 4] = box[k, 5] = -1
    peak = np.zeros(n + 1, np.float32)
    for z in range(nz):
        for y in range(ny):
            for x in range(nx):
                lab = labels[z, y, x]
                if lab == 0:
                    continue
                cnt[lab] += 1
                if z < box[lab, 0]:
                    box[lab, 0] = z
                if y < box[lab, 1]:
                    box[lab, 1] = y
                if x < box[lab, 2]:
                    box[lab, 2] = x
                if z > box[lab, 3]:
                    box[lab, 3] = z
                if y > box[lab, 4]:
                    box[lab, 4] = y
                if x > box[lab, 5]:
                    box[lab, 5] = x
                d = dist[z, y, x]
                if d > peak[lab]:
                    peak[lab] = d
    for k in range(n + 1):
        if cnt[k] == 0:
            for a in range(6):
                box[k, a] = 0
        else:
            for a in range(3, 6):
                box[k, a] += 1
    return cnt, box, peak


@numba.njit(cache=True, nogil=True)
def extreme_candidates(labels):
    """Labelled voxels that are not the midpoint of two voxels of their own label along any of the
    13 lattice directions (face, edge, corner neighbours; the volume border counts as another label):
    a superset of the vertices of each label's convex hull (a midpoint is never a vertex)."""
    nz, ny, nx = labels.shape
    out = np.zeros(labels.shape, np.bool_)
    for z in range(nz):
        for y in range(ny):
            for x in range(nx):
                lab = labels[z, y, x]
                if lab == 0:
                    continue
                if z == 0 or z == nz - 1 or y == 0 or y == ny - 1 or x == 0 or x == nx - 1:
                    out[z, y, x] = True          # border voxels: kept (their outer neighbours are absent)
                    continue
                ok = True
                for dz in range(0, 2):
                    for dy in range(-1, 2):
                        for dx in range(-1, 2):
                            if dz == 0 and (dy < 0 or (dy == 0 and dx <= 0)):
                                continue          # one of each +- pair: 13 directions
                            if labels[z + dz, y + dy, x + dx] == lab and labels[z - dz, y - dy, x - dx] == lab:
                                ok = False
                                break
                        if not ok:
                            break
                    if not ok:
                        break
                out[z, y, x] = ok
    return out


@numba.njit(cache=True, nogil=True)
def basin_saddles(basins, height):
    """Pairs of different non-zero labels among 26-connected neighbours: (key i*(n+1)+j with i < j,
    saddle = min of ``height`` at the two voxels); consecutive repeats of a key keep their largest
    saddle only (the caller reduces the rest with a maximum per key)."""
    nz, ny, nx = basins.shape
    n1 = np.int64(0)
    for z in range(nz):
        for y in range(ny):
            for x in range(nx):
                if basins[z, y, x] > n1:
                    n1 = np.int64(basins[z, y, x])
    n1 += 1
    cap = 1 << 20
    keys = np.empty(cap, np.int64)
    sad = np.empty(cap, np.float64)
    m = 0
    last = np.int64(-1)
    for z in range(nz):
        for y in range(ny):
            for x in range(nx):
                a = basins[z, y, x]
                if a == 0:
                    continue
                ha = height[z, y, x]
                for dz in range(0, 2):
                    zz = z + dz
                    if zz >= nz:
                        continue
                    for dy in range(-1, 2):
                        yy = y + dy
                        if yy < 0 or yy >= ny:
                            continue
                        for dx in range(-1, 2):
                            if dz == 0 and (dy < 0 or (dy == 0 and dx <= 0)):
                                continue
                            xx = x + dx
                            if xx < 0 or xx >= nx:
                                continue
                            b = basins[zz, yy, xx]
                            if b == 0 or b == a:
                                continue
                            hb = height[zz, yy, xx]
                            s = ha if ha < hb else hb
                            k = (np.int64(a) * n1 + b) if a < b else (np.int64(b) * n1 + a)
                            if k == last and m > 0:
                                if s > sad[m - 1]:
                                    sad[m - 1] = s
                                continue
                            if m == cap:
                                cap *= 2
                                k2 = np.empty(cap, np.int64)
                                s2 = np.empty(cap, np.float64)
                                k2[:m] = keys[:m]
                                s2[:m] = sad[:m]
                                keys, sad = k2, s2
                            keys[m] = k
                            sad[m] = s
                            m += 1
                            last = k
    return keys[:m], sad[:m], n1


@numba.njit(cache=True, nogil=True)
def label_sizes(lab, n):
    """Voxel count of each label 0..n (np.bincount without its int64 copy of the volume)."""
    out = np.zeros(n + 1, np.int64)
    flat = lab.ravel()
    for i in range(flat.size):
        out[flat[i]] += 1
    return out


@numba.njit(cache=True, nogil=True)
def table_mask(lab, table, base):
    """Boolean volume ``table[lab]``, or-ed with ``base`` when ``base`` has the volume's size."""
    out = np.empty(lab.shape, np.bool_)
    fo = out.ravel()
    fl = lab.ravel()
    if base.size == lab.size:
        fb = base.ravel()
        for i in range(fl.size):
            fo[i] = fb[i] or table[fl[i]]
    else:
        for i in range(fl.size):
            fo[i] = table[fl[i]]
    return out


# --- rays of the shape measurement (orchestrator/ct/shape.py radial_profile) ---

@numba.njit(cache=True, nogil=True, inline="always")
def _trilinear(f, z, y, x):
    """``f`` (z, y, x) at a fractional voxel position, trilinear; 0 outside [0, n - 1] along any axis.
    The arithmetic of :func:`scipy.ndimage.map_coordinates` with ``order=1, mode="constant",
    cval=0`` (bit-identical results, tests/ct/test_kernels.py)."""
    nz, ny, nx = f.shape
    if not (0.0 <= z <= nz - 1 and 0.0 <= y <= ny - 1 and 0.0 <= x <= nx - 1):
        return 0.0
    z0, y0, x0 = int(math.floor(z)), int(math.floor(y)), int(math.floor(x))
    wz = (1.0 - (z - z0), z - z0)
    wy = (1.0 - (y - y0), y - y0)
    wx = (1.0 - (x - x0), x - x0)
    t = 0.0
    for a in range(2):
        za = min(z0 + a, nz - 1)
        for b in range(2):
            yb = min(y0 + b, ny - 1)
            for c in range(2):
                t += f[za, yb, min(x0 + c, nx - 1)] * wz[a] * wy[b] * wx[c]
    return t


@numba.njit(cache=True, nogil=True)
def outermost_crossing(field, centre, u, s, step, level):
    """Outermost radius [voxels] where ``field`` (float32, [z, y, x]) crosses ``level`` along the rays
    from ``centre`` (z, y, x) [voxels] in the directions u (K, 3) (x, y, z), sampled at the radii
    ``s`` (S,) (increasing by ``step`` [voxels]): the last sample at or above ``level`` plus ``step``
    times the linear interpolation (in float32, as the field) towards the next one; NaN where no
    sample reaches ``level``. Each ray is walked inwards from its end and stops at its first such
    sample."""
    k_rays, n_s = u.shape[0], s.shape[0]
    lev = np.float32(level)
    r = np.full(k_rays, np.nan)
    for k in range(k_rays):
        f_next = np.float32(0.0)
        for q in range(n_s - 1, -1, -1):
            f0 = np.float32(_trilinear(field, centre[0] + s[q] * u[k, 2], centre[1] + s[q] * u[k, 1],
                                       centre[2] + s[q] * u[k, 0]))
            if f0 >= lev:
                f1 = f0 if q == n_s - 1 else f_next
                frac = (f0 - lev) / (f0 - f1) if f0 > f1 else np.float32(0.0)
                frac = min(max(frac, np.float32(0.0)), np.float32(1.0))
                r[k] = s[q] + np.float32(step) * frac
                break
            f_next = f0
    return r
