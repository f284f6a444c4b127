"""Rigid clumps of spheres from a shape library (issue 4: "an option builds clumps from given particle
shapes, so that a shape library measured from CT can be used").

A library is a list of shapes; each shape is a list of member spheres (x, y, z, r) in its own frame,
in any length unit (shapes are rescaled to the sampled grain size). Two file formats:

- YAML: ``shapes: [{name: a, spheres: [[x, y, z, r], ...]}, ...]``
- NPZ: ``spheres`` (M, 4) and ``shape`` (M,) integer shape index of each row (0 ... S-1).

Mass properties of a clump are those of the *union* of its spheres (members overlap), integrated on a
regular grid (:func:`mass_properties`), as YADE's ``clump()`` does with its own grid
(``O.bodies.appendClumped(..., discretization=N)``) and LIGGGHTS' ``particletemplate/multisphere``
does by Monte Carlo. A shape is placed (:func:`place`) with its centre of mass at the grain position,
rotated by a unit quaternion, and scaled so that its union volume equals the volume of the sampled
sphere diameter (volume-equivalent diameter, as a CT grain's equivalent radius in seed 001 §2.2).
All SI in the results.
"""
from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np
import yaml

from .atomic import cache_dir, write_json
from .psd import portable


class LibraryError(ValueError):
    """A shape library that cannot be used: the file, the shape and what is wrong."""


def library_digest(path) -> str:
    """sha256 of a clump library's shapes as :func:`load_library` reads them (their order, member
    spheres and radii as little-endian doubles): what a run depends on, not where the file lies nor
    its comments, so a run hash (orchestrator.case.Case.hash_input) survives moving the checkout."""
    h = hashlib.sha256()
    for sp in load_library(path):
        h.update(np.int64(len(sp)).tobytes())
        h.update(np.ascontiguousarray(sp, dtype="<f8").tobytes())
    return h.hexdigest()


def load_library(path) -> list[np.ndarray]:
    """Shapes as a list of (m, 4) arrays [x, y, z, r]; validated (see :func:`check_shape`)."""
    path = Path(path)
    if not path.exists():
        raise LibraryError(f"{path}: clump library not found (scene.particles.library is read relative to the case "
                           "file that names it; write a path from there, or an absolute one)")
    if path.suffix.lower() == ".npz":
        d = np.load(path)
        if "spheres" not in d or "shape" not in d:
            raise LibraryError(f"{path}: an NPZ library needs arrays 'spheres' (M, 4) and 'shape' (M,)")
        sp, idx = np.asarray(d["spheres"], float), np.asarray(d["shape"], int)
        if sp.ndim != 2 or sp.shape[1] != 4 or idx.shape != (len(sp),):
            raise LibraryError(f"{path}: 'spheres' must be (M, 4) and 'shape' (M,), got {sp.shape} and {idx.shape}")
        shapes = [sp[idx == k] for k in range(int(idx.max()) + 1)] if len(sp) else []
    elif path.suffix.lower() in (".yaml", ".yml"):
        # libCYAML's loader where PyYAML has it (the same documents, ~10x faster than the pure-Python one)
        doc = yaml.load(path.read_text(), Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
        if not isinstance(doc, dict) or not isinstance(doc.get("shapes"), list):
            raise LibraryError(f"{path}: a YAML library needs 'shapes: [{{name: ..., spheres: [[x, y, z, r], ...]}}]'")
        shapes = []
        for k, s in enumerate(doc["shapes"]):
            try:
                shapes.append(np.asarray(s["spheres"], dtype=float).reshape(-1, 4))
            except (KeyError, TypeError, ValueError) as e:
                raise LibraryError(f"{path}: shape {k}: 'spheres' must be a list of [x, y, z, r] ({e})") from None
    else:
        raise LibraryError(f"{path}: clump library must be .yaml/.yml or .npz")
    if not shapes:
        raise LibraryError(f"{path}: the library holds no shape")
    for k, s in enumerate(shapes):
        try:
            check_shape(s)
        except LibraryError as e:
            raise LibraryError(f"{path}: shape {k}: {e}") from None
    return shapes


def check_shape(s: np.ndarray) -> None:
    """One rigid body: at least one sphere, finite values, positive radii, and every member
    overlapping or touching the rest (a connected union)."""
    if len(s) == 0:
        raise LibraryError("no sphere")
    if not np.isfinite(s).all():
        raise LibraryError("non-finite value")
    if (s[:, 3] <= 0).any():
        raise LibraryError("a radius is not positive")
    n = len(s)
    d = np.linalg.norm(s[:, None, :3] - s[None, :, :3], axis=2)
    touch = d <= (s[:, None, 3] + s[None, :, 3]) * (1 + 1e-9)
    seen, todo = {0}, [0]
    while todo:
        i = todo.pop()
        for j in np.flatnonzero(touch[i]):
            if j not in seen:
                seen.add(int(j))
                todo.append(int(j))
    if len(seen) != n:
        raise LibraryError(f"{n - len(seen)} of {n} spheres do not touch the others (not one rigid grain)")


_MASS_CACHE: dict = {}


def mass_properties(s: np.ndarray, density: float = 1.0, cells: int = 60) -> dict:
    """Volume, centre of mass and inertia tensor (about the centre of mass) of the union of the
    spheres ``s`` (m, 4), by midpoint integration on a ``cells``³ grid over the bounding box
    (relative volume error ~1e-3 at 60). Units: those of ``s``; mass = density × volume.
    Pure: results are remembered by the spheres' values, in this process (a case derives its templates
    more than once) and on disk (``cache_dir("clump_mass")``: a dry run of a 100-shape library then
    skips ~1 s of integration, #15's 2 s)."""
    s = np.asarray(s, dtype=float)
    key = (s.tobytes(), s.shape, float(density), int(cells))
    if key not in _MASS_CACHE:
        _MASS_CACHE[key] = _stored_mass_properties(s, density, cells)
    out = _MASS_CACHE[key]
    return {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in out.items()}


def union_properties(s: np.ndarray, cells: int = 40) -> dict:
    """:func:`mass_properties` at unit density, integrated afresh (neither remembered nor written
    to the disk cache): for the many one-off unions of a sample's clumps as its frames hold them
    (:mod:`orchestrator.grains`). ``volume`` [units³] and ``center`` [units] of the union."""
    return _mass_properties(np.asarray(s, dtype=float), 1.0, int(cells))


def _stored_mass_properties(s: np.ndarray, density: float, cells: int) -> dict:
    """:func:`_mass_properties`, read from or written to the disk cache (exact doubles in JSON; a
    cache that cannot be read or written is no error: the grid is integrated again)."""
    h = hashlib.sha256(s.tobytes() + repr((s.shape, float(density), int(cells), 1)).encode()).hexdigest()[:24]
    f = cache_dir("clump_mass") / f"{h}.json"
    try:
        d = json.loads(f.read_text())
        return {k: (np.array(v) if isinstance(v, list) else v) for k, v in d.items()}
    except (OSError, ValueError):
        pass
    out = _mass_properties(s, density, cells)
    try:
        f.parent.mkdir(parents=True, exist_ok=True)
        write_json(f, out)
    except OSError:
        pass
    return out


def _mass_properties(s: np.ndarray, density: float, cells: int) -> dict:
    lo = (s[:, :3] - s[:, 3:]).min(axis=0)
    hi = (s[:, :3] + s[:, 3:]).max(axis=0)
    h = (hi - lo) / cells
    ax = [lo[k] + h[k] * (np.arange(cells) + 0.5) for k in range(3)]
    # the grid point (i, j, k) is (ax[0][i], ax[1][j], ax[2][k]); squared distances by broadcasting
    # the three axes (the same sums, in the same order, as over the (cells³, 3) point list)
    inside = np.zeros((cells,) * 3, bool)
    for x, y, z, r in s:
        d2 = ((ax[0] - x) ** 2)[:, None, None] + ((ax[1] - y) ** 2)[None, :, None]
        d2 = d2 + ((ax[2] - z) ** 2)[None, None, :]
        inside |= d2 <= r * r
    i, j, k = np.nonzero(inside)                # C order = the meshgrid('ij') ravel order
    P = np.column_stack([ax[0][i], ax[1][j], ax[2][k]])
    dv = float(np.prod(h))
    V = len(P) * dv
    c = P.mean(axis=0)
    q = P - c
    I = density * dv * (np.sum(q * q) * np.eye(3) - q.T @ q)
    return {"volume": V, "mass": density * V, "center": c, "inertia": I,
            "principal": np.sort(np.linalg.eigvalsh(I))}


def equivalent_scale(s: np.ndarray, diameter: float, volume: float | None = None) -> float:
    """Factor that scales shape ``s`` so that its union volume is that of a sphere of ``diameter``."""
    V = mass_properties(s)["volume"] if volume is None else volume
    return (math.pi / 6 * diameter ** 3 / V) ** (1 / 3)


def random_quaternions(n: int, rng: np.random.Generator) -> np.ndarray:
    """n uniformly distributed unit quaternions (w, x, y, z) (Shoemake 1992)."""
    u1, u2, u3 = rng.random((3, n))
    a, b = np.sqrt(1 - u1), np.sqrt(u1)
    # rounded (psd.portable: vectorised sin and cos differ by an ulp on AVX-512 CPUs), then normalised
    # (sqrt and division are exact IEEE operations): the same orientations on every x86 CPU
    q = portable(np.column_stack([b * np.cos(2 * np.pi * u3), a * np.sin(2 * np.pi * u2),
                                  a * np.cos(2 * np.pi * u2), b * np.sin(2 * np.pi * u3)]))
    return q / np.sqrt(np.sum(q * q, axis=1))[:, None]


def rotation_matrix(q) -> np.ndarray:
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def place(s: np.ndarray, center_of_mass, scale: float, q, com_local=None) -> np.ndarray:
    """World spheres (m, 4) of shape ``s`` scaled by ``scale``, rotated by ``q`` and translated so
    that its centre of mass lies at ``center_of_mass``."""
    c = mass_properties(s)["center"] if com_local is None else np.asarray(com_local)
    local = (s[:, :3] - c) * scale
    out = np.empty_like(s, dtype=float)
    out[:, :3] = local @ rotation_matrix(q).T + np.asarray(center_of_mass)
    out[:, 3] = s[:, 3] * scale
    return out


def bounding_radius(s: np.ndarray, com_local=None) -> float:
    """Radius of the smallest sphere about the centre of mass that holds the shape (same units)."""
    c = mass_properties(s)["center"] if com_local is None else np.asarray(com_local)
    return float(np.max(np.linalg.norm(s[:, :3] - c, axis=1) + s[:, 3]))
