"""Spherical-harmonic description of grain shape (seed 001, eqs. 1-4).

The surface of a star-shaped grain, seen from its centroid, is the polar radius r(theta, phi)
[m] (theta in [0, pi] from +z, phi in [0, 2 pi) from +x). It is expanded to degree L (15 by default)

    r(theta, phi) = sum_{n=0}^{L} sum_{m=-n}^{n} c_n^m Y_n^m(theta, phi)

with orthonormal complex harmonics Y_n^m from :func:`scipy.special.sph_harm_y`, the coefficients
found by least squares. Coefficients are stored as complex arrays ``c[n, m + L]`` [m]; since r is
real, ``c[n, -m] = (-1)^m conj(c[n, m])``. The rotation invariants are

    ||R_n|| = sqrt( sum_m |c_n^m|^2 )   [m],  n = 0 ... L   (eq. 4)

They are unchanged by rotating or translating the grain; ``||R_0|| = sqrt(4 pi) * mean radius``.

The surface radius of a segmented grain is measured by casting rays from the centroid through a
sub-voxel "solid fraction" image restricted to the grain (see :func:`grain_shapes`).

Reproducibility (docs/ct.md): turning a grain ~14 voxels across changes ``||R||`` by ~0.016 voxel
(median, noise-free scans); between two scans with noise of 8 % of the contrast it changes by
~0.07 voxel whether or not the grain turned, the noise of each coefficient (~0.02 voxel) being near
the information bound sigma_noise * sqrt(2 sqrt(pi) sigma_psf) / r of the data.
"""
from __future__ import annotations

import functools

import numpy as np
import pandas as pd
from scipy import ndimage
from scipy.special import sph_harm_y

from ._kernels import outermost_crossing

__all__ = ["sh_basis", "sh_fit", "sh_evaluate", "invariants", "reconstruct", "fibonacci_directions",
           "grain_shapes", "radial_profile", "DEGREE"]

DEGREE = 15


def _nm(degree):
    n = np.concatenate([np.full(2 * l + 1, l) for l in range(degree + 1)])
    m = np.concatenate([np.arange(-l, l + 1) for l in range(degree + 1)])
    return n, m


def sh_basis(theta, phi, degree=DEGREE) -> np.ndarray:
    """Complex orthonormal harmonics Y_n^m at (theta, phi) (M,): array (M, (degree+1)^2), columns
    ordered n = 0..L, m = -n..n."""
    n, m = _nm(degree)
    theta = np.asarray(theta, float).ravel()
    phi = np.asarray(phi, float).ravel()
    return sph_harm_y(n[None, :], m[None, :], theta[:, None], phi[:, None])


def _real_design(theta, phi, degree):
    """Real least-squares design: columns Y_n^0, Re Y_n^m, Im Y_n^m (m > 0)."""
    n = np.concatenate([np.full(l + 1, l) for l in range(degree + 1)])
    m = np.concatenate([np.arange(0, l + 1) for l in range(degree + 1)])
    Y = sph_harm_y(n[None, :], m[None, :], np.ravel(theta)[:, None], np.ravel(phi)[:, None])
    pos = m > 0
    A = np.concatenate([Y.real, Y.imag[:, pos]], axis=1)
    return A, n, m, pos


def _real_to_complex(x, n, m, pos, degree):
    """Map real least-squares unknowns to complex c[n, m + L] (see module docstring)."""
    k = len(n)
    a = x[:k]
    b = np.zeros(k)
    b[pos] = x[k:]
    c = np.zeros(x.shape[1:] + (degree + 1, 2 * degree + 1), dtype=complex) if x.ndim > 1 else \
        np.zeros((degree + 1, 2 * degree + 1), dtype=complex)
    # r = sum a_n0 Y_n0 + sum_{m>0} (a Re Y - (-b) Im Y);  a = 2 Re c, b = -2 Im c  for m > 0
    cm = np.where(m[:, None] > 0, (a - 1j * b) / 2, a) if x.ndim > 1 else np.where(m > 0, (a - 1j * b) / 2, a)
    if x.ndim > 1:
        cm = cm.T                                     # (G, k)
        c[:, n, m + degree] = cm
        c[:, n[pos], -m[pos] + degree] = ((-1.0) ** m[pos]) * np.conj(cm[:, pos])
    else:
        c[n, m + degree] = cm
        c[n[pos], -m[pos] + degree] = ((-1.0) ** m[pos]) * np.conj(cm[pos])
    return c


def sh_fit(theta, phi, r, degree=DEGREE) -> np.ndarray:
    """Least-squares SH coefficients c[n, m + L] [m] of radii r (M,) [m] at directions (theta, phi).

    ``r`` may be (M, G) to fit G grains sampled along the same directions at once (returns (G, L+1,
    2L+1)); rows with NaN are not allowed there (fit grains with missing rays one by one).
    Needs at least (degree+1)^2 well-spread directions.
    """
    r = np.asarray(r, float)
    A, n, m, pos = _real_design(theta, phi, degree)
    if A.shape[0] < A.shape[1]:
        raise ValueError(f"degree {degree} needs at least {A.shape[1]} surface samples, got {A.shape[0]}")
    x, *_ = np.linalg.lstsq(A, r, rcond=None)
    return _real_to_complex(x, n, m, pos, degree)


def sh_evaluate(c, theta, phi) -> np.ndarray:
    """r(theta, phi) [m] from coefficients c[n, m + L]; theta, phi any matching shape."""
    c = np.asarray(c)
    degree = c.shape[0] - 1
    theta = np.asarray(theta, float)
    Y = sh_basis(theta, phi, degree)
    n, m = _nm(degree)
    return (Y @ c[n, m + degree]).real.reshape(theta.shape)


def invariants(c) -> np.ndarray:
    """Rotation invariants ||R_n|| (eq. 4) [m] of coefficients c[..., n, m + L]: shape (..., L+1)."""
    return np.sqrt(np.sum(np.abs(np.asarray(c)) ** 2, axis=-1))


def reconstruct(c, centre=(0, 0, 0), n_theta=32, n_phi=64):
    """Surface mesh of the SH shape: vertices (V, 3) world (x, y, z) [m] and triangles (F, 3).

    A (theta, phi) grid with poles as single vertices; suitable for meshio/pyvista."""
    th = np.linspace(0, np.pi, n_theta + 1)[1:-1]
    ph = np.linspace(0, 2 * np.pi, n_phi, endpoint=False)
    T, P = np.meshgrid(th, ph, indexing="ij")
    r = sh_evaluate(c, T, P)
    v = np.stack([r * np.sin(T) * np.cos(P), r * np.sin(T) * np.sin(P), r * np.cos(T)], -1).reshape(-1, 3)
    rn = sh_evaluate(c, np.array([0.0, np.pi]), np.array([0.0, 0.0]))
    v = np.vstack([[0, 0, rn[0]], v, [0, 0, -rn[1]]]) + np.asarray(centre, float)
    faces = []
    idx = lambda i, j: 1 + i * n_phi + (j % n_phi)
    for j in range(n_phi):
        faces.append((0, idx(0, j), idx(0, j + 1)))
        last = len(v) - 1
        faces.append((last, idx(n_theta - 2, j + 1), idx(n_theta - 2, j)))
        for i in range(n_theta - 2):
            faces.append((idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)))
            faces.append((idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)))
    return v, np.asarray(faces, dtype=np.int64)


def fibonacci_directions(k: int):
    """k nearly uniform unit vectors (x, y, z) and their (theta, phi)."""
    i = np.arange(k) + 0.5
    z = 1 - 2 * i / k
    phi = np.mod(np.pi * (1 + 5 ** 0.5) * i, 2 * np.pi)
    theta = np.arccos(z)
    u = np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), z])
    return u, theta, phi


def radial_profile(field, centre_zyx, u, rmax, step=0.25, level=0.5):
    """Outermost radius [voxels] where ``field`` (a crop, [z, y, x]) crosses ``level`` along rays
    from ``centre_zyx`` (voxel coordinates in the crop) in directions u (K, 3) world (x, y, z).
    Linear interpolation between samples; NaN where the ray never reaches ``level``. A float32
    field takes the compiled path (:func:`._kernels.outermost_crossing`, the same numbers)."""
    s = np.arange(0, rmax + step, step)
    if field.dtype == np.float32 and field.ndim == 3:
        return outermost_crossing(np.ascontiguousarray(field), np.ascontiguousarray(centre_zyx, dtype=float),
                                  np.ascontiguousarray(u, dtype=float), s, float(step), float(level))
    return _radial_profile_sampled(field, centre_zyx, u, s, step, level)


def _radial_profile_sampled(field, centre_zyx, u, s, step, level):
    """:func:`radial_profile` by sampling every ray at every radius of ``s`` (S,) [voxels] with
    :func:`scipy.ndimage.map_coordinates`: any field dtype; the reference of the compiled path."""
    pts = centre_zyx[None, None, :] + s[None, :, None] * u[:, None, ::-1]          # (K, S, 3) zyx
    f = ndimage.map_coordinates(field, pts.reshape(-1, 3).T, order=1, mode="constant", cval=0.0)
    f = f.reshape(len(u), len(s))
    above = f >= level
    has = above.any(axis=1)
    last = len(s) - 1 - np.argmax(above[:, ::-1], axis=1)                        # outermost sample >= level
    nxt = np.minimum(last + 1, len(s) - 1)
    k = np.arange(len(u))
    f0, f1 = f[k, last], f[k, nxt]
    frac = np.where(f0 > f1, (f0 - level) / np.where(f0 > f1, f0 - f1, 1), 0.0)
    r = s[last] + step * np.clip(frac, 0, 1)
    r[~has] = np.nan
    return r


@functools.lru_cache(maxsize=8)
def _ray_design(degree, n_rays):
    """Ray directions, real design matrix and its pseudo-inverse for (degree, n_rays): the same for
    every grain of every scan, built once per process (the pseudo-inverse of the 1024 x 256 design
    at degree 15 costs ~3 s CPU). Arrays are read-only."""
    u, theta, phi = fibonacci_directions(n_rays)
    A, n, m, pos = _real_design(theta, phi, degree)
    out = (u, A, n, m, pos, np.linalg.pinv(A))
    for a in out:
        a.setflags(write=False)
    return out


def grain_shapes(seg, degree=DEGREE, n_rays=None, labels=None, progress=False):
    """SH coefficients and invariants of every grain of a :class:`~orchestrator.ct.segment.Segmentation`.

    Rays are cast from each grain's centroid through the grain's solid-fraction field (normalised
    grey values, restricted to the grain and the pore voxels nearest to it) and the outermost 0.5
    crossing is the surface radius. Returns (table, coeffs): ``table`` has ``label`` and ``R0`` ...
    ``R<degree>`` [m] plus ``sh_residual`` (rms fit residual [m]); ``coeffs`` is (G, L+1, 2L+1).
    """
    n_rays = n_rays or max(4 * (degree + 1) ** 2, 400)
    u, A, n, m, pos, pinv = _ray_design(degree, n_rays)
    frac = seg.solid_fraction()
    own = seg.grain_regions()
    vs = seg.scan.voxel_size
    table = seg.grains if labels is None else seg.grains.set_index("label").loc[labels].reset_index()
    objs = ndimage.find_objects(own)
    G = len(table)
    coeffs = np.zeros((G, degree + 1, 2 * degree + 1), dtype=complex)
    resid = np.full(G, np.nan)
    it = range(G)
    if progress:
        from rich.progress import track
        it = track(it, description="SH shapes")
    cz = seg.scan.to_voxel(table[["x", "y", "z"]].to_numpy())
    for g in it:
        lab = int(table["label"].iloc[g])
        sl = objs[lab - 1]
        if sl is None:
            continue
        lo = np.array([s.start for s in sl])
        crop = np.where(own[sl] == lab, frac[sl], 0.0).astype(np.float32)
        c0 = cz[g] - lo
        # farthest crop corner + 1 voxel: beyond it the field is 0 (cval), no crossing can lie there
        rmax = float(np.linalg.norm(np.maximum(np.abs(c0), np.abs(np.array(crop.shape) - 1 - c0)))) + 1
        r = radial_profile(crop, c0, u, rmax)
        ok = np.isfinite(r)
        if ok.sum() < A.shape[1]:
            continue
        if ok.all():
            x, A_ok, r_ok = pinv @ r, A, r               # A[ok] would copy the 2 MB design per grain
        else:
            A_ok, r_ok = A[ok], r[ok]
            x, *_ = np.linalg.lstsq(A_ok, r_ok, rcond=None)
        resid[g] = np.sqrt(np.mean((A_ok @ x - r_ok) ** 2)) * vs
        coeffs[g] = _real_to_complex(x * vs, n, m, pos, degree)
    inv = invariants(coeffs)
    out = pd.DataFrame({"label": table["label"].to_numpy()})
    for k in range(degree + 1):
        out[f"R{k}"] = inv[:, k]
    out["sh_residual"] = resid
    return out, coeffs
