"""Synthetic tomograms with ground truth: render grains into grey-value volumes.

Everything here works in SI units (positions and radii in metres) and renders into a voxel grid
with the conventions of :mod:`orchestrator.ct.io` (volume ``[z, y, x]``, voxel centres at
``origin + voxel_size * (i, j, k)``).

Rendering is in two steps:

1. :func:`render_phase` gives the solid fraction of every voxel in [0, 1] with partial-volume
   accuracy: voxels cut by a grain surface are supersampled (``supersample**3`` points each),
   voxels inside or outside are set exactly.
2. :func:`acquire` turns solid fraction into grey values like a CT scanner: grey levels of pore and
   solid, a Gaussian point-spread function, a linear intensity drift along z, Gaussian noise and
   quantisation to uint16.

Grains are spheres (``radius``) or star-shaped irregular grains described by spherical-harmonic
coefficients (see :mod:`orchestrator.ct.shape`), optionally hollow.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from ..psd import Box, Cylinder, relax_overlaps
from ._render import NO_TABLE, coverage_into
from .io import Scan
from .shape import _nm, sh_basis

__all__ = ["pack_spheres", "render_phase", "acquire", "render_scan", "render_sequence",
           "random_sh_grains", "twist", "separate_contacts", "contact_packing", "score_contacts", "scans_from_frames", "Grain"]


# ------------------------------------------------------------------------------------- packings

def pack_spheres(radii, box=None, cylinder=None, seed=0, iterations=3000, tol=1e-3, initial=None):
    """Place spheres without overlap inside a box or a cylinder (the project's dense packer,
    :func:`orchestrator.psd.relax_overlaps`, from a jittered lattice in a box or random centres in
    a cylinder).

    radii : (N,) radii [m].
    box : ((x0, y0, z0), (x1, y1, z1)) [m]; or
    cylinder : (cx, cy, R, z0, z1) [m], axis along z.
    initial : (N, 3) starting positions [m] (e.g. displaced grains whose overlaps must be removed);
    default random.
    Returns centres (N, 3) [m]. The largest remaining overlap is below ``tol`` times the mean radius
    (a :class:`RuntimeError` otherwise: the packing is too dense for this relaxation).
    """
    rng = np.random.default_rng(seed)
    r = np.asarray(radii, dtype=float)
    n = len(r)
    if box is not None:
        lo, hi = np.asarray(box[0], float), np.asarray(box[1], float)
        container = Box(lo, hi)
    elif cylinder is not None:
        cx, cy, R, z0, z1 = cylinder
        container = Cylinder(R, z0, z1, center=(cx, cy))
    else:
        raise ValueError("give box or cylinder")
    if initial is not None:
        x = np.array(initial, dtype=float)
    elif box is not None:
        # start from a jittered lattice with at least n sites: far fewer overlaps than random
        # positions, so the relaxation converges in a few dozen sweeps
        span = hi - lo - 2 * r.mean()
        cell = (np.prod(span) / n) ** (1 / 3)
        m = np.maximum(np.floor(span / cell).astype(int), 1)
        while np.prod(m) < n:
            m[np.argmax(span / m)] += 1
        g = np.stack(np.meshgrid(*[(np.arange(k) + 0.5) / k for k in m], indexing="ij"), -1).reshape(-1, 3)
        g = g[rng.permutation(len(g))[:n]]
        x = lo + r.mean() + g * span + (rng.random((n, 3)) - 0.5) * 0.2 * span / m
    else:
        rho = (R - r) * np.sqrt(rng.random(n))
        phi = rng.random(n) * 2 * np.pi
        x = np.column_stack([cx + rho * np.cos(phi), cy + rho * np.sin(phi),
                             z0 + r + rng.random(n) * (z1 - z0 - 2 * r)])
    container.project(x, r)
    x, _, worst = relax_overlaps(x, r, container, tol, r.mean(), iterations, separation=1.02, weights="equal")
    if worst >= tol:
        raise RuntimeError(f"pack_spheres: largest overlap still {worst:.3g} mean radii after "
                           f"{iterations} iterations; use fewer or smaller grains")
    return x


def separate_contacts(centres, radii, min_gap, overlap=0.005, iterations=2000, box=None):
    """Make every near pair of a packing either a contact or clearly apart, as a DEM packing with its
    contact list: pairs whose surfaces are closer than ``min_gap / 2`` [m] when first seen become
    contacts, kept touching with an overlap of at most ``2 overlap`` times the sum of their radii
    (a DEM contact: Hertz overlaps are ~0.1-1 % of a diameter); the other pairs are kept at least
    ``min_gap`` apart (a gap that the scan should resolve). Each violated bound moves both spheres by
    half the violation along the branch vector; sweeps repeat until every bound holds.

    box : ((x0, y0, z0), (x1, y1, z1)) [m] keeps the spheres inside.
    Returns (centres (N, 3) [m], contacts (M, 2) index pairs i < j).
    """
    x = np.array(centres, dtype=float)
    r = np.asarray(radii, dtype=float)
    n = len(x)
    rmax = r.max()
    contact = set()            # decided once, when a pair is first seen near (no flip-flopping)
    apart = set()
    for _ in range(iterations):
        p = cKDTree(x).query_pairs(2 * rmax + min_gap, output_type="ndarray")
        i, j = p[:, 0], p[:, 1]
        d = x[j] - x[i]
        dist = np.linalg.norm(d, axis=1)
        h = dist - r[i] - r[j]
        key = (i * n + j).tolist()
        for k in np.flatnonzero(h < min_gap).tolist():
            if key[k] not in contact and key[k] not in apart:
                (contact if h[k] < 0.5 * min_gap else apart).add(key[k])
        is_c = np.fromiter((k in contact for k in key), bool, len(key))
        s = r[i] + r[j]
        # contacts: overlap between overlap/4 and 2 overlap (a Hertz overlap range); others: the gap
        target = np.where(is_c, np.clip(h, -2 * overlap * s, 0.0), np.maximum(h, min_gap))
        bad = np.abs(target - h) > 0.02 * min_gap
        if not bad.any():
            return x, p[is_c]
        i, j, d, dist, corr = i[bad], j[bad], d[bad], dist[bad], (target - h)[bad]
        corr += np.sign(corr) * 0.01 * min_gap              # aim inside the bound
        push = d / dist[:, None] * (0.5 * corr)[:, None]
        for k in range(3):
            x[:, k] += np.bincount(j, push[:, k], n) - np.bincount(i, push[:, k], n)
        if box is not None:
            x = np.clip(x, np.asarray(box[0]) + r[:, None], np.asarray(box[1]) - r[:, None])
    raise RuntimeError(f"separate_contacts: pairs still between contact and {min_gap:g} m after {iterations} sweeps")


def twist(position, centre_xy, angle):
    """Rotate positions (N, 3) [m] about the vertical axis through ``centre_xy`` by ``angle`` (N,) [rad]."""
    p = np.asarray(position, dtype=float).copy()
    a = np.broadcast_to(np.asarray(angle, dtype=float), (len(p),))
    v = p[:, :2] - centre_xy
    c, s = np.cos(a), np.sin(a)
    p[:, 0] = centre_xy[0] + c * v[:, 0] - s * v[:, 1]
    p[:, 1] = centre_xy[1] + s * v[:, 0] + c * v[:, 1]
    return p


# ----------------------------------------------------------------------------------- grain shapes

@dataclass
class Grain:
    """A star-shaped grain for rendering: centre [m], bounding radius [m], and ``radial(u)`` giving the
    surface radius [m] along unit vectors u (M, 3) in the grain's own frame; ``rotation`` (3, 3) maps
    grain frame to world. ``hollow`` is the inner/outer radius ratio of a concentric void (0 = solid)."""
    centre: np.ndarray
    rmax: float
    radial: object = None       # callable(u (M,3)) -> (M,) radii [m]; None = sphere of radius rmax
    rotation: np.ndarray | None = None
    hollow: float = 0.0


class _GridRadial:
    """r(theta, phi) tabulated on a regular grid, bilinear interpolation (periodic in phi)."""

    _basis_cache: dict = {}

    def __init__(self, coeffs, degree, ntheta=91, nphi=180):
        self.th = np.linspace(0, np.pi, ntheta)
        self.ph = np.linspace(0, 2 * np.pi, nphi + 1)
        r = _grid_eval(coeffs, ntheta, nphi, self._basis_cache)
        self.table = np.concatenate([r, r[:, :1]], axis=1)
        self.rmax = float(r.max())

    def __call__(self, u):
        th = np.arccos(np.clip(u[:, 2], -1, 1))
        ph = np.mod(np.arctan2(u[:, 1], u[:, 0]), 2 * np.pi)
        fi = th / self.th[1]
        fj = ph / self.ph[1]
        return ndimage.map_coordinates(self.table, [fi, fj], order=1, mode="nearest")


def _grid_eval(c, ntheta, nphi, cache):
    """r on a (ntheta x nphi) grid (theta incl. poles, phi without 2 pi); the basis is cached.

    Separable: Y_n^m(theta, phi) = Y_n^m(theta, 0) exp(i m phi), so the coefficients are first summed
    over n for every theta and m (ntheta x (2L+1)), then over m for every phi: ~(L+1)^2 / (2L+1)
    times fewer operations than the full (ntheta nphi) x (L+1)^2 basis (equal to it to rounding).
    No BLAS call: these small products cost ~30x more in a multi-threaded BLAS on a busy machine."""
    degree = c.shape[0] - 1
    key = (ntheta, nphi, degree)
    if key not in cache:
        cache[key] = _separable_basis(ntheta, nphi, degree)
    y0, n, m, starts, phase = cache[key]
    a = np.add.reduceat(y0 * c[n, m + degree], starts, axis=1)            # (ntheta, 2L+1): sum over n
    return np.einsum("im,mj->ij", a.real, phase.real) - np.einsum("im,mj->ij", a.imag, phase.imag)


def _separable_basis(ntheta, nphi, degree):
    """The factors of :func:`_grid_eval`: Y_n^m(theta, 0) on ntheta polar angles in [0, pi] (poles
    included), columns ordered by m then n (ntheta, (L+1)^2); those columns' n and m; the first
    column of each m = -L..L; exp(i m phi) on nphi azimuths in [0, 2 pi) ((2L+1, nphi))."""
    n, m = _nm(degree)
    order = np.lexsort((n, m))
    n, m = n[order], m[order]
    th = np.linspace(0, np.pi, ntheta)
    ph = np.linspace(0, 2 * np.pi, nphi, endpoint=False)
    y0 = sh_basis(th, np.zeros(ntheta), degree)[:, order]
    starts = np.searchsorted(m, np.arange(-degree, degree + 1))
    phase = np.exp(1j * np.arange(-degree, degree + 1)[:, None] * ph[None, :])
    return y0, n, m, starts, phase


def random_sh_grains(n, r0, degree=15, roughness=0.12, decay=1.6, seed=0, r0_spread=0.1):
    """Random star-shaped grain shapes as complex SH coefficients c[n, m + degree].

    r0 : mean grain radius [m]; each grain's radius is drawn with relative spread ``r0_spread``.
    roughness : relative standard deviation of the surface radius contributed by degree 2;
    higher degrees fall off as ``n**-decay``. Returns a list of (degree+1, 2*degree+1) arrays.
    The surface radius is kept above 0.4 r0 (star-shaped, no holes).
    """
    rng = np.random.default_rng(seed)
    out = []
    cache: dict = {}
    while len(out) < n:
        rad = r0 * (1 + r0_spread * rng.standard_normal())
        c = np.zeros((degree + 1, 2 * degree + 1), dtype=complex)
        c[0, degree] = rad * np.sqrt(4 * np.pi)
        for l in range(2, degree + 1):
            amp = rad * roughness * np.sqrt(4 * np.pi / (2 * l + 1)) * (l / 2.0) ** (-decay)
            c[l, degree] = amp * rng.standard_normal()
            for m in range(1, l + 1):
                v = amp * (rng.standard_normal() + 1j * rng.standard_normal()) / np.sqrt(2)
                c[l, degree + m] = v
                c[l, degree - m] = (-1) ** m * np.conj(v)
        r = _grid_eval(c, 46, 90, cache)
        if r.min() > 0.4 * rad:
            out.append(c)
    return out


def _random_rotation(rng):
    q = rng.standard_normal(4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


# -------------------------------------------------------------------------------------- rendering

_IDENTITY = np.eye(3)


def _offsets(s):
    g = (np.arange(s) + 0.5) / s - 0.5
    return np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)


def render_phase(shape, voxel_size, grains, origin=(0, 0, 0), supersample=5, out=None):
    """Solid fraction [0, 1] of each voxel for a list of :class:`Grain` (float32 volume [z, y, x]).

    Voxels whose centre lies within ``band`` voxels of a surface (0.9 for spheres, 1.3 for irregular
    grains, measured along the radius) are supersampled with ``supersample**3`` points; overlapping
    grains are combined by taking the larger fraction.
    """
    shape = tuple(int(s) for s in shape)
    vol = np.zeros(shape, np.float32) if out is None else out
    origin = np.asarray(origin, float)
    offs = _offsets(supersample)                       # (S, 3) in voxel units, (z, y, x)
    for g in grains:
        c = (np.asarray(g.centre, float) - origin)[::-1] / voxel_size     # (z, y, x) voxel coords
        rv = g.rmax / voxel_size
        lo = np.maximum(np.floor(c - rv - 2).astype(int), 0)
        hi = np.minimum(np.ceil(c + rv + 2).astype(int) + 1, shape)
        if np.any(hi <= lo):
            continue
        sub = vol[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
        if g.radial is None or isinstance(g.radial, _GridRadial):
            _coverage_compiled(sub, lo, c, g, voxel_size, offs)
            continue
        zz, yy, xx = np.meshgrid(*[np.arange(a, b) for a, b in zip(lo, hi)], indexing="ij")
        p = np.stack([zz, yy, xx], -1).reshape(-1, 3).astype(float) - c
        frac = _coverage(p, g, voxel_size, offs)
        np.maximum(sub, frac.reshape(sub.shape).astype(np.float32), out=sub)
    return vol


def _coverage_compiled(sub, lo, c, g, voxel_size, offs):
    """:func:`_coverage` of a sphere or a :class:`_GridRadial` grain, compiled
    (:func:`._render.coverage_into`), combined into the volume view ``sub`` (float32) by the maximum.
    lo : first voxel (z, y, x) of ``sub``; c : grain centre (z, y, x) [voxels]."""
    rot = _IDENTITY if g.rotation is None else np.ascontiguousarray(g.rotation, dtype=float)
    if g.radial is None:
        table, dth, dph = NO_TABLE, 1.0, 1.0
    else:
        table, dth, dph = g.radial.table, float(g.radial.th[1]), float(g.radial.ph[1])
    coverage_into(sub, lo.astype(np.int64), np.ascontiguousarray(c), float(g.rmax / voxel_size), float(g.hollow),
                  _band(g), offs, table, dth, dph, rot, float(voxel_size))


def _surface(p, g, voxel_size):
    """Signed radial distance (voxels) of points p (M,3 zyx, relative to the centre) to the surface,
    positive inside; and the same for the hollow core (positive inside the void)."""
    d = np.linalg.norm(p, axis=1)
    if g.radial is None:
        rs = np.full(len(p), g.rmax / voxel_size)
    else:
        u = p[:, ::-1] / np.maximum(d, 1e-12)[:, None]          # world xyz unit vectors
        if g.rotation is not None:
            u = u @ np.asarray(g.rotation)                       # world -> grain frame (R^T u)
        rs = g.radial(u) / voxel_size
    s = rs - d
    core = g.hollow * rs - d if g.hollow > 0 else None
    return s, core


def _band(g):
    """Half-width [voxels] of the supersampled shell around the surface of grain g."""
    return 0.9 if g.radial is None else 1.3


def _coverage(p, g, voxel_size, offs):
    band = _band(g)
    s, core = _surface(p, g, voxel_size)
    frac = (s > 0).astype(float)
    edge = np.abs(s) < band
    if core is not None:
        frac[core > 0] = 0.0
        edge |= np.abs(core) < band
    idx = np.nonzero(edge)[0]
    if len(idx):
        q = (p[idx, None, :] + offs[None]).reshape(-1, 3)
        sq, cq = _surface(q, g, voxel_size)
        inside = sq > 0
        if cq is not None:
            inside &= ~(cq > 0)
        frac[idx] = inside.reshape(len(idx), -1).mean(axis=1)
    return frac


def acquire(phase, psf_sigma=0.8, noise=0.05, drift=0.0, pore=0.2, solid=0.8, seed=0,
            dtype=np.uint16, offset=0.0):
    """Grey values from a solid-fraction volume, like a CT reconstruction.

    psf_sigma : standard deviation of the Gaussian point-spread function [voxels].
    noise : standard deviation of additive Gaussian noise, as a fraction of the solid-pore contrast.
    drift : relative change of the grey-level contrast from the bottom to the top slice (linear in z).
    pore, solid : grey levels of pore space and solid as fractions of the dtype's range.
    offset : additive grey-level offset for the whole scan (scan-to-scan drift), fraction of range.
    """
    rng = np.random.default_rng(seed)
    img = phase.astype(np.float32)
    if psf_sigma > 0:
        img = ndimage.gaussian_filter(img, psf_sigma)
    contrast = solid - pore
    if drift:
        nz = img.shape[0]
        gain = 1.0 + drift * (np.arange(nz, dtype=np.float32) / max(nz - 1, 1) - 0.5)
        img = img * gain[:, None, None]
    img = pore + offset + contrast * img
    if noise > 0:
        img += rng.standard_normal(img.shape, dtype=np.float32) * np.float32(noise * contrast)
    if np.issubdtype(np.dtype(dtype), np.integer):
        top = np.iinfo(dtype).max
        return np.clip(np.rint(img * top), 0, top).astype(dtype)
    return img.astype(dtype)


def render_scan(shape, voxel_size, centres, radii=None, grains=None, origin=(0, 0, 0), hollow=None,
                supersample=5, time=float("nan"), controls=None, _phase=None, _keep=None, **acquire_kw) -> Scan:
    """Render spheres (``centres`` (N,3) [m], ``radii`` (N,) [m]) or a list of :class:`Grain` into a
    :class:`Scan`. ``hollow`` (N,) gives the void/grain radius ratio per sphere (0 = solid)."""
    if grains is None:
        centres = np.asarray(centres, float)
        radii = np.broadcast_to(np.asarray(radii, float), (len(centres),))
        hol = np.zeros(len(centres)) if hollow is None else np.broadcast_to(hollow, (len(centres),))
        ok = np.all(np.isfinite(centres), axis=1)
        grains = [Grain(c, r, hollow=float(h)) for c, r, h, k in zip(centres, radii, hol, ok) if k]
    phase = render_phase(shape, voxel_size, grains, origin, supersample) if _phase is None else _phase
    if _keep is not None:
        _keep.append(phase)
    return Scan(acquire(phase, **acquire_kw), voxel_size, origin, time, dict(controls or {}), "<synthetic>")


def render_sequence(shape, voxel_size, positions, radii=None, grain_shapes=None, rotations=None,
                    origin=(0, 0, 0), times=None, controls=None, seed=0, progress=False, **kw) -> list[Scan]:
    """A scan per frame: ``positions`` (T, N, 3) [m] (NaN rows = absent), spheres of ``radii`` (N,) [m]
    or irregular grains given by SH coefficient arrays ``grain_shapes`` (N) with per-frame rotation
    matrices ``rotations`` (T, N, 3, 3). Grain k of every frame is the same grain (known identity).
    Each scan gets its own noise realisation (seed + frame index)."""
    positions = np.asarray(positions, float)
    T = len(positions)
    radials = None
    if grain_shapes is not None:
        radials = [_GridRadial(c, c.shape[0] - 1) for c in grain_shapes]
    scans = []
    phases = {}                # a frame that repeats an earlier one's grains reuses its solid fraction
    it = range(T)
    if progress:
        from rich.progress import track
        it = track(it, description="rendering scans")
    for t in it:
        key = positions[t].tobytes() + (b"" if rotations is None else np.asarray(rotations[t], float).tobytes())
        keep = [] if key not in phases else None
        kw["_phase"], kw["_keep"] = phases.get(key), keep
        if radials is None:
            sc = render_scan(shape, voxel_size, positions[t], radii, origin=origin, seed=seed + t,
                             time=float(times[t]) if times is not None else float(t),
                             controls={k: float(v[t]) for k, v in (controls or {}).items()}, **kw)
        else:
            grains = [Grain(positions[t, k], rad.rmax, rad, None if rotations is None else rotations[t, k])
                      for k, rad in enumerate(radials) if np.all(np.isfinite(positions[t, k]))]
            sc = render_scan(shape, voxel_size, None, grains=grains, origin=origin, seed=seed + t,
                             time=float(times[t]) if times is not None else float(t),
                             controls={k: float(v[t]) for k, v in (controls or {}).items()}, **kw)
        if keep:
            phases[key] = keep[0]
        sc.source = f"<synthetic frame {t}>"
        scans.append(sc)
    return scans


def scans_from_frames(frames, voxel_size, margin=None, frame_indices=None, progress=True, **kw):
    """Render frames of a ``frames.h5`` (path or :class:`orchestrator.frames.Frames`) as scans.

    The grid covers all positions of the selected frames plus ``margin`` [m] (default: 2 radii).
    Returns (scans, ids): ``ids`` are the particle ids of the rows rendered, the ground truth."""
    from ..frames import Frames
    fr = frames if isinstance(frames, Frames) else Frames(frames)
    idx = list(range(fr.n_frames)) if frame_indices is None else list(frame_indices)
    pos = fr.position[idx]
    rmax = float(np.nanmax(fr.radius))
    margin = 2 * rmax if margin is None else margin
    lo = np.nanmin(pos.reshape(-1, 3), axis=0) - margin
    hi = np.nanmax(pos.reshape(-1, 3), axis=0) + margin
    shape = tuple(int(n) + 1 for n in np.ceil((hi - lo) / voxel_size)[::-1])
    if math.prod(shape) > 1024 ** 3:
        raise ValueError(f"{fr.path}: at voxel size {voxel_size:.3g} m the scan would have shape {shape} "
                         "(over 1024^3 voxels); choose a larger voxel size (ct synth --voxel-size)")
    controls = {k: v[idx] for k, v in fr.controls.items()}
    scans = render_sequence(shape, voxel_size, pos, fr.radius, origin=lo, times=fr.time[idx],
                            controls=controls, progress=progress, **kw)
    return scans, fr.ids


def contact_packing(shape, voxel_size, radius_range, min_gap=0.5, fill=0.45, seed=0, margin=2):
    """A packing with its contact list, for testing contact detection: spheres with radii uniform in
    ``radius_range`` [voxels] packed in a box of ``shape`` voxels (``margin`` voxels from the faces) at
    volume fraction ``fill``, then :func:`separate_contacts` with ``min_gap`` [voxels].
    Returns (centres (N, 3) [m], radii (N,) [m], contacts (M, 2) index pairs)."""
    rng = np.random.default_rng(seed)
    inner = np.asarray(shape, float) - 2 * margin
    n = int(fill * np.prod(inner) / (4 / 3 * np.pi * np.mean(radius_range) ** 3))
    r = rng.uniform(*radius_range, n) * voxel_size
    box = ((margin * voxel_size,) * 3, tuple((np.asarray(shape[::-1], float) - margin) * voxel_size))
    c = pack_spheres(r, box=box, seed=seed + 1)
    c, con = separate_contacts(c, r, min_gap * voxel_size, box=box)
    return c, r, con


def score_contacts(seg, centres, radii, contacts, refined=None) -> dict:
    """Precision and recall of detected contacts against a known contact list.

    seg : :class:`~.segment.Segmentation` of a scan of the spheres ``centres`` (N, 3) [m], ``radii``
    (N,) [m]; contacts : (M, 2) true contact index pairs. Each label is matched to the nearest true
    centre (within half its radius, otherwise the label's contacts count as false).
    Returns precision, recall, mean coordination number (over grains found) of the truth, of the
    candidates (face-adjacent labels) and of the refined contacts, and the median / 90th percentile
    normal error [deg] of the refined true contacts (PCA normal against the true branch vector)."""
    g = seg.grains
    d, k = cKDTree(centres).query(g[["x", "y", "z"]].to_numpy())
    ok = d < 0.5 * radii[k]
    lab2 = dict(zip(g["label"].to_numpy()[ok], k[ok]))
    cand = seg.contacts(refine=False) if refined is None else refined
    ti = np.array([lab2.get(a, -1) for a in cand["i"]], np.int64)
    tj = np.array([lab2.get(b, -2) for b in cand["j"]], np.int64)
    n = len(centres)
    truth = set((np.minimum(contacts[:, 0], contacts[:, 1]) * n + np.maximum(contacts[:, 0], contacts[:, 1])).tolist())
    key = np.minimum(ti, tj) * n + np.maximum(ti, tj)
    hit = np.array([(a >= 0 and b >= 0 and kk in truth) for a, b, kk in zip(ti, tj, key.tolist())], bool)
    det = cand["touching"].to_numpy(bool)
    tp = int((hit & det).sum())
    br = centres[tj[hit & det]] - centres[ti[hit & det]]
    br /= np.linalg.norm(br, axis=1)[:, None]
    nrm = cand.loc[hit & det, ["nx", "ny", "nz"]].to_numpy()
    err = np.degrees(np.arccos(np.clip(np.abs(np.einsum("ij,ij->i", br, nrm)), 0, 1)))
    found = np.unique(k[ok])
    inside = np.isin(contacts, found).all(axis=1)
    n_found = max(len(found), 1)
    return {"true": len(truth), "candidates": len(cand), "detected": int(det.sum()),
            "precision": tp / max(int(det.sum()), 1), "recall": tp / max(len(truth), 1),
            "recall_candidates": int(hit.sum()) / max(len(truth), 1),
            "z_true": 2 * int(inside.sum()) / n_found, "z_candidates": 2 * len(cand) / n_found,
            "z_refined": 2 * int(det.sum()) / n_found,
            "normal_err_median_deg": float(np.median(err)) if err.size else float("nan"),
            "normal_err_p90_deg": float(np.percentile(err, 90)) if err.size else float("nan")}
