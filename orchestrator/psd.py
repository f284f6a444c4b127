"""Particle size distributions and loose packings, sampled once by the orchestrator and handed
identically to every engine (same ids, diameters and positions).

Units: SI (m). Every function takes an explicit ``numpy.random.Generator`` or seed, so a case's
``seed`` reproduces its particles exactly.
"""
from __future__ import annotations

import math

import numpy as np


def lognormal_diameters(n: int, median: float, d_min: float, d_max: float, sigma_ln: float,
                        rng) -> np.ndarray:
    """``n`` diameters [m] from a log-normal distribution with median ``median`` [m] and log
    standard deviation ``sigma_ln`` [-], accepted only within [d_min, d_max] (rejection
    sampling: the truncated density is the log-normal one renormalised, as in seed 000 §3.2)."""
    if not (0 < d_min <= median <= d_max):
        raise ValueError(f"need 0 < d_min <= median <= d_max, got {d_min}, {median}, {d_max}")
    rng = np.random.default_rng(rng)
    if sigma_ln == 0:
        return np.full(n, median)
    out = np.empty(0)
    while out.size < n:
        d = median * np.exp(sigma_ln * rng.standard_normal(max(2 * (n - out.size), 64)))
        out = np.concatenate([out, d[(d >= d_min) & (d <= d_max)]])
    return out[:n]


def mean_sphere_volume(median: float, d_min: float, d_max: float, sigma_ln: float,
                       samples: int = 200_000, seed: int = 0) -> float:
    """⟨π d³/6⟩ [m³] of the truncated log-normal (Monte Carlo, fixed seed: deterministic)."""
    d = lognormal_diameters(samples, median, d_min, d_max, sigma_ln, seed)
    return float(np.mean(np.pi / 6 * d ** 3))


def pack_cylinder(radii: np.ndarray, radius: float, z_lo: float, z_hi: float, rng,
                  wall_clearance: float = 0.0, max_tries: int = 200) -> np.ndarray:
    """Random loose packing: place spheres of ``radii`` [m] (largest first) at random positions
    in the cylinder r <= ``radius``, z in [``z_lo``, ``z_hi``] without any overlap with each other
    or the walls (random sequential addition). Returns (n, 3) positions in the order of
    ``radii``. Raises ValueError when the volume cannot hold them (RSA jams near φ ≈ 0.38)."""
    rng = np.random.default_rng(rng)
    radii = np.asarray(radii, dtype=float)
    n = len(radii)
    order = np.argsort(-radii)
    pos = np.full((n, 3), np.nan)
    r_max = radii.max()
    cell = 2 * r_max
    # spatial hash: dict cell -> list of placed indices
    grid: dict[tuple, list] = {}
    placed_pos = np.empty((n, 3))
    placed_r = np.empty(n)

    def key(p):
        return (int(math.floor(p[0] / cell)), int(math.floor(p[1] / cell)), int(math.floor(p[2] / cell)))

    count = 0
    for idx in order:
        r = radii[idx]
        R = radius - r - wall_clearance
        lo, hi = z_lo + r + wall_clearance, z_hi - r - wall_clearance
        if R <= 0 or hi <= lo:
            raise ValueError("the packing region is smaller than a particle")
        ok = False
        for _ in range(max_tries):
            rr = R * math.sqrt(rng.random())
            th = 2 * math.pi * rng.random()
            p = np.array([rr * math.cos(th), rr * math.sin(th), lo + (hi - lo) * rng.random()])
            kx, ky, kz = key(p)
            clash = False
            for dx in (-1, 0, 1):
                for dy in (-1, 0, 1):
                    for dz in (-1, 0, 1):
                        for j in grid.get((kx + dx, ky + dy, kz + dz), ()):
                            if np.sum((placed_pos[j] - p) ** 2) < (placed_r[j] + r) ** 2:
                                clash = True
                                break
                        if clash:
                            break
                    if clash:
                        break
                if clash:
                    break
            if not clash:
                ok = True
                break
        if not ok:
            raise ValueError(f"could not place particle {count + 1} of {n} without overlap after {max_tries} tries: "
                             "the packing volume is too small for this volume fraction")
        placed_pos[count] = p
        placed_r[count] = r
        grid.setdefault((kx, ky, kz), []).append(count)
        pos[idx] = p
        count += 1
    return pos


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
