"""Particle size distributions and packings (loose: :func:`rsa_pack`; dense: :func:`relax_overlaps`), sampled once by the orchestrator and handed
identically to every engine (same ids, diameters and positions).

Units: SI (m). Every function takes an explicit ``numpy.random.Generator`` or seed, so a case's
``seed`` reproduces its particles exactly.
"""
from __future__ import annotations

import math

import numpy as np

from .contact_law import remembered


#: mantissa bits kept by :func:`portable` (relative step 2^-32 ≈ 2e-10)
PORTABLE_BITS = 32


def portable(x: np.ndarray) -> np.ndarray:
    """``x`` with its mantissas rounded to :data:`PORTABLE_BITS` bits (exact power-of-two arithmetic).
    NumPy's vectorised ``exp`` takes a different SIMD path on CPUs with AVX-512 (SVML) than on the
    others and differs from it by an ulp in ~5 % of the values; rounded, the same seed draws the same
    diameters, hence the same packing, on every x86 CPU (a 1-ulp change crosses a rounding step with
    probability ~2^-20, once in ~2e7 diameters)."""
    m, e = np.frexp(np.asarray(x, dtype=float))
    return np.ldexp(np.round(m * 2.0 ** PORTABLE_BITS) / 2.0 ** PORTABLE_BITS, e)


def portable_cube(x: np.ndarray) -> np.ndarray:
    """``x ** 3`` as the C library's ``pow`` computes it, element by element [same units cubed]. NumPy's
    vectorised ``power`` takes the SVML path on CPUs with AVX-512 and differs from ``pow`` by an ulp
    in some values; the dense packer's weights (:func:`relax_overlaps`) carried that into packings
    1e-12 apart after its sweeps, and the trajectories of a triaxial run apart after that (session
    37's AMD EPYC of family 26 against the AVX2 machines before it). ``math.pow`` is the same on every
    CPU, and is what NumPy computes without AVX-512, so the packings stay those of before."""
    return np.array([math.pow(v, 3.0) for v in np.asarray(x, dtype=float).ravel().tolist()]).reshape(np.shape(x))


def truncated_lognormal(n: int, mu_ln: float | None, sigma_ln: float, d_min: float, d_max: float,
                        rng, median: float | None = None) -> np.ndarray:
    """``n`` diameters [m] with ln d ~ N(``mu_ln``, ``sigma_ln``²) truncated to [``d_min``, ``d_max``]
    (rejection sampling: the truncated density is the log-normal one renormalised, seed 000 §3.2).
    The one sampler of the project: :func:`lognormal_diameters` (by median) and the triaxial
    scene's PSD (by truncated mean, :func:`lognormal_mu_for_mean`) both draw through it. Give
    ``median`` = exp(mu_ln) [m] instead of ``mu_ln`` (None) to keep a median exact to the last bit."""
    if not (0 < d_min <= d_max):
        raise ValueError(f"need 0 < d_min <= d_max, got {d_min}, {d_max}")
    rng = np.random.default_rng(rng)
    if sigma_ln == 0:
        d = math.exp(mu_ln) if median is None else median
        if not d_min <= d <= d_max:
            raise ValueError(f"sigma_ln = 0 and the diameter {d} lies outside [{d_min}, {d_max}]")
        return np.full(n, d)
    out = np.empty(0)
    while out.size < n:
        z = rng.standard_normal(max(2 * (n - out.size), 64))
        # the same law either way; the two forms differ by an ulp and keep each caller's draws
        # bit-identical to what it drew before the samplers were folded into one (golden decks)
        d = np.exp(mu_ln + sigma_ln * z) if median is None else median * np.exp(sigma_ln * z)
        d = portable(d)
        out = np.concatenate([out, d[(d >= d_min) & (d <= d_max)]])
    return out[:n]


def lognormal_diameters(n: int, median: float, d_min: float, d_max: float, sigma_ln: float,
                        rng) -> np.ndarray:
    """``n`` diameters [m] from a log-normal distribution with median ``median`` [m] and log
    standard deviation ``sigma_ln`` [-], accepted only within [d_min, d_max]
    (:func:`truncated_lognormal` with mu_ln = ln median)."""
    if not (0 < d_min <= median <= d_max):
        raise ValueError(f"need 0 < d_min <= median <= d_max, got {d_min}, {median}, {d_max}")
    return truncated_lognormal(n, None, sigma_ln, d_min, d_max, rng, median=median)


def truncated_lognormal_mean(mu_ln: float, sigma_ln: float, d_min: float, d_max: float,
                             m: int = 4000) -> float:
    """Number mean [m] of the truncated log-normal (quadrature on m points in ln d)."""
    x = np.linspace(math.log(d_min), math.log(d_max), m)
    w = np.exp(-0.5 * ((x - mu_ln) / sigma_ln) ** 2)
    return float(np.sum(w * np.exp(x)) / np.sum(w))


@remembered          # a root search (and scipy.optimize's import) per call: kept across processes
def lognormal_mu_for_mean(mean: float, sigma_ln: float, d_min: float, d_max: float) -> float:
    """mu_ln such that the log-normal truncated to [d_min, d_max] has number mean ``mean`` [m]."""
    from scipy.optimize import brentq      # here: scipy.optimize costs ~0.3 s to import (validate, #16)
    return brentq(lambda mu: truncated_lognormal_mean(mu, sigma_ln, d_min, d_max) - mean,
                  math.log(d_min) - 5 * sigma_ln, math.log(d_max) + 5 * sigma_ln)


def mean_sphere_volume(median: float, d_min: float, d_max: float, sigma_ln: float,
                       samples: int = 200_000, seed: int = 0) -> float:
    """⟨π d³/6⟩ [m³] of the truncated log-normal (Monte Carlo, fixed seed: deterministic)."""
    d = lognormal_diameters(samples, median, d_min, d_max, sigma_ln, seed)
    return float(np.mean(np.pi / 6 * d ** 3))


class Cylinder:
    """Container of the packers: r <= ``radius`` about the vertical axis through ``center`` (x, y),
    z in [``z_lo``, ``z_hi``]; centres at least ``wall_clearance`` [m] more than a radius from every
    wall. :meth:`draw` (one random centre, :func:`rsa_pack`) is about the z axis."""

    periodic = False

    def __init__(self, radius: float, z_lo: float, z_hi: float, wall_clearance: float = 0.0,
                 center: tuple[float, float] = (0.0, 0.0)):
        self.radius, self.z_lo, self.z_hi, self.clearance = radius, z_lo, z_hi, wall_clearance
        self.center = np.asarray(center, dtype=float)

    def project(self, pos: np.ndarray, r: np.ndarray) -> None:
        """Move the centres ``pos`` (n, 3) [m] of spheres of radii ``r`` radially and vertically
        back inside, in place (the closest point inside, :func:`relax_overlaps`)."""
        v = pos[:, :2] - self.center
        rr = np.hypot(v[:, 0], v[:, 1])
        lim = self.radius - r
        out = rr > lim
        pos[out, :2] = self.center + v[out] * (lim[out] / rr[out])[:, None]
        pos[:, 2] = np.clip(pos[:, 2], self.z_lo + r, self.z_hi - r)

    def draw(self, r: float, rng) -> np.ndarray:
        R = self.radius - r - self.clearance
        lo, hi = self.z_lo + r + self.clearance, self.z_hi - r - self.clearance
        if R <= 0 or hi <= lo:
            raise ValueError("the packing region is smaller than a particle")
        rr = R * math.sqrt(rng.random())
        th = 2 * math.pi * rng.random()
        return np.array([rr * math.cos(th), rr * math.sin(th), lo + (hi - lo) * rng.random()])


class Box:
    """Container of :func:`relax_overlaps`: the box ``lo`` <= x <= ``hi`` (each (3,) [m]), walls on
    all faces."""

    periodic = False

    def __init__(self, lo, hi):
        self.lo, self.hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)

    def project(self, pos: np.ndarray, r: np.ndarray) -> None:
        """Clip the centres ``pos`` (n, 3) [m] into the box less each radius ``r``, in place."""
        pos[:] = np.clip(pos, self.lo + r[:, None], self.hi - r[:, None])


class PeriodicBox:
    """Container of :func:`rsa_pack`: [0, ``L``)² periodic in x and y, z in [``z_lo``, ``z_hi``]
    (centres at least a radius from both z faces)."""

    periodic = True

    def __init__(self, L: float, z_lo: float, z_hi: float):
        self.L, self.z_lo, self.z_hi = L, z_lo, z_hi

    def draw(self, r: float, rng) -> np.ndarray:
        if self.z_hi - r <= self.z_lo + r:
            raise ValueError("the packing region is smaller than a particle")
        return np.array([rng.uniform(0, self.L), rng.uniform(0, self.L), rng.uniform(self.z_lo + r, self.z_hi - r)])


def rsa_pack(radii: np.ndarray, container, rng, max_tries: int = 200) -> np.ndarray:
    """Random loose packing by random sequential addition: spheres of ``radii`` [m], largest
    first, each at the first of up to ``max_tries`` uniform random positions in ``container``
    (:class:`Cylinder` or :class:`PeriodicBox`) that overlaps no sphere placed before (minimum
    image across periodic faces). Returns (n, 3) positions in the order of ``radii``. Raises
    ValueError when a sphere finds no place (RSA jams near φ ≈ 0.38). The one loose packer of
    the shear-cell and plane-shear scenes."""
    rng = np.random.default_rng(rng)
    radii = np.asarray(radii, dtype=float)
    n = len(radii)
    order = np.argsort(-radii)
    pos = np.full((n, 3), np.nan)
    cell = 2 * radii.max()
    if container.periodic:
        nc = max(1, int(container.L // cell))          # cells of L / nc >= 2 r_max, wrapped in x, y
        cxy, L = container.L / nc, container.L
    else:
        nc, cxy = None, cell
    grid: dict[tuple, list] = {}
    for count, idx in enumerate(order):
        r = radii[idx]
        for _ in range(max_tries):
            p = container.draw(r, rng)
            ix, iy, iz = int(math.floor(p[0] / cxy)), int(math.floor(p[1] / cxy)), int(math.floor(p[2] / cell))
            keys = {((ix + dx) % nc, (iy + dy) % nc, iz + dz) if nc else (ix + dx, iy + dy, iz + dz)
                    for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1)}    # a set: nc < 3 wraps
            clash = any(_overlaps(p, pos[j], r + radii[j], L if nc else None) for k in keys for j in grid.get(k, ()))
            if not clash:
                break
        else:
            raise ValueError(f"could not place particle {count + 1} of {n} without overlap after {max_tries} tries: "
                             "the packing volume is too small for this volume fraction")
        pos[idx] = p
        key = (ix % nc, iy % nc, iz) if nc else (ix, iy, iz)
        grid.setdefault(key, []).append(idx)
    return pos


def _overlaps(p: np.ndarray, q: np.ndarray, contact: float, L: float | None) -> bool:
    """Spheres at ``p`` and ``q`` closer than ``contact`` [m] (minimum image in x, y over period ``L``)."""
    d = p - q
    if L is not None:
        d[:2] -= L * np.round(d[:2] / L)
    return d @ d < contact ** 2


def pack_cylinder(radii: np.ndarray, radius: float, z_lo: float, z_hi: float, rng,
                  wall_clearance: float = 0.0, max_tries: int = 200) -> np.ndarray:
    """:func:`rsa_pack` in a :class:`Cylinder` (shear cell)."""
    return rsa_pack(radii, Cylinder(radius, z_lo, z_hi, wall_clearance), rng, max_tries)


def pack_box(radii: np.ndarray, L: float, z_lo: float, z_hi: float, rng, max_tries: int = 2000) -> np.ndarray:
    """:func:`rsa_pack` in a :class:`PeriodicBox` (plane shear)."""
    return rsa_pack(radii, PeriodicBox(L, z_lo, z_hi), rng, max_tries)


def relax_overlaps(pos: np.ndarray, r: np.ndarray, container, tol: float, scale: float,
                   max_iter: int, separation: float = 0.55, weights: str = "volume") -> tuple[np.ndarray, int, float]:
    """Dense packing by collective rearrangement: from the centres ``pos`` (n, 3) [m] of spheres
    of radii ``r`` [m], repeatedly push every overlapping pair apart along its centre line, each
    sphere by the share its partner's volume carries (w_i = r_j³/(r_i³ + r_j³); ``weights="equal"``:
    w_i = 1/2) of ``separation`` × the overlap (0.55, the triaxial packer; the synthetic CT packings
    use 1.02 with equal weights, which leaves their touching grains a sliver apart, as their
    segmentation and tracking tests were tuned on), and project the centres back into
    ``container`` (:class:`Cylinder`, :class:`Box`), until the largest overlap is below ``tol`` ×
    ``scale`` [m] (checked before each push) or ``max_iter`` sweeps have run. The dense packer of
    the triaxial scene and of the synthetic CT packings (the loose one is :func:`rsa_pack`).

    The overlapping pairs come from a Verlet list (:func:`_verlet_pairs`: the pairs closer than
    r_i + r_j + skin, rebuilt once a centre has moved more than skin/2), so each sweep finds
    exactly the pairs a fresh neighbour search would, in index order whatever the list's age.
    Returns (positions, sweeps run, largest overlap / ``scale`` at the last check); converged when
    the last is below ``tol``."""
    pos = np.array(pos, dtype=float)
    r = np.asarray(r, dtype=float)
    n = len(r)
    vol = portable_cube(r)
    skin = _VERLET_SKIN * float(np.median(r))
    worst = np.inf
    it = 0
    ref = None
    for it in range(max_iter):
        if ref is None or np.max(np.sum((pos - ref) ** 2, axis=1)) > (0.5 * skin) ** 2:
            ci, cj = _verlet_pairs(pos, r, skin)
            ref = pos.copy()
        dv = pos[cj] - pos[ci]
        dist = np.sqrt(np.einsum("ij,ij->i", dv, dv))
        ov = r[ci] + r[cj] - dist
        m = ov > 0
        worst = ov[m].max() / scale if m.any() else 0.0
        if worst < tol:
            break
        i, j, dv, dist, ov = ci[m], cj[m], dv[m], dist[m], ov[m]
        nvec = dv / np.maximum(dist, 1e-300)[:, None]
        wi = vol[j] / (vol[i] + vol[j]) if weights == "volume" else np.full(len(i), 0.5)
        step = separation * ov
        a, b = (step * wi)[:, None] * nvec, (step * (1 - wi))[:, None] * nvec
        for c in range(3):
            pos[:, c] += np.bincount(j, b[:, c], minlength=n) - np.bincount(i, a[:, c], minlength=n)
        container.project(pos, r)
    return pos, it, float(worst)


#: Verlet skin of :func:`relax_overlaps`, in median radii (0.3: the list is rebuilt every few
#: sweeps once the packing has settled; seed 001's 16 000 grains pack in ~5x less CPU than with a
#: neighbour search every sweep, 15 s against 78 s: benchmarks/bench_packing.py)
_VERLET_SKIN = 0.3


def _verlet_pairs(pos: np.ndarray, r: np.ndarray, skin: float) -> tuple[np.ndarray, np.ndarray]:
    """Index arrays (i, j), i < j, of the sphere pairs whose gap |x_i - x_j| - r_i - r_j is below
    ``skin`` [m], sorted by (i, j)."""
    from scipy.spatial import cKDTree      # here: scipy.spatial costs ~0.3 s to import (validate, #16)
    pairs = cKDTree(pos).query_pairs(2 * r.max() + skin, output_type="ndarray")
    i, j = pairs[:, 0], pairs[:, 1]
    d = np.linalg.norm(pos[j] - pos[i], axis=1)
    keep = d < r[i] + r[j] + skin
    i, j = i[keep], j[keep]
    order = np.lexsort((j, i))
    return i[order], j[order]


def max_overlap(position: np.ndarray, radii: np.ndarray) -> float:
    """Largest pairwise overlap r_i + r_j - |x_i - x_j| [m] (0 when nothing overlaps)."""
    pos = np.asarray(position, dtype=float)
    ok = np.all(np.isfinite(pos), axis=1)
    pos, radii = pos[ok], np.asarray(radii)[ok]
    from scipy.spatial import cKDTree      # here: scipy.spatial costs ~0.3 s to import (validate, #16)
    tree = cKDTree(pos)
    pairs = tree.query_pairs(2 * radii.max(), output_type="ndarray")
    if len(pairs) == 0:
        return 0.0
    d = np.linalg.norm(pos[pairs[:, 0]] - pos[pairs[:, 1]], axis=1)
    return float(max(0.0, np.max(radii[pairs[:, 0]] + radii[pairs[:, 1]] - d)))
