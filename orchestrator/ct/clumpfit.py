"""Clump shape libraries from CT: approximate each segmented grain by a few overlapping spheres.

A grain (a boolean voxel mask ``[z, y, x]``) is covered by spheres inscribed in it, taken one at a
time from its Euclidean distance transform (EDT), after the "Euclidean map" method of Angelidakis,
Nadimi, Otsubo & Utili (2021, CLUMP: a code library to generate universal multi-sphere particles,
SoftwareX 15: 100735): every voxel's EDT value is the radius of the largest sphere centred there
that stays inside the grain. Where CLUMP takes the EDT maximum of the not yet covered part, the next
sphere here is, among the maximal inscribed spheres (the voxels of the EDT's discrete medial axis),
the one that covers most not yet covered grain voxels and touches the spheres taken so far (a
greedy set cover, Johnson 1974 / Chvátal 1979: within a factor 1 + ln n of the fewest spheres).
The first sphere is the EDT maximum in both. It stops at ``n_spheres`` spheres, when the covered
fraction of the grain reaches ``coverage``, or when no sphere of at least ``min_radius`` adds
anything. With ``refine`` (our addition, not in CLUMP), after each new sphere every centre and
radius is moved by +-1/2, then 1/4, then 1/8 voxel while the number of voxels where the union and
the grain differ falls: inscribed spheres leave the grain's surface between them uncovered, the
refined ones may cross it a little, so the union's volume and shape come closer to the grain's
(moving all spheres, rather than only the new one, gave ~1 % more coverage on irregular grains).
``refine=False`` keeps the inscribed spheres.

The package ``clump-python`` (CLUMP's Python port, 0.3.3) is not used: it reads STL surfaces only
(its voxel-image branch stops on undefined names), recomputes the full EDT per sphere, and is GPL-3.0.

Library files are those of :func:`orchestrator.clumps.load_library` (YAML ``shapes: [{name, spheres:
[[x, y, z, r], ...]}]``), written atomically by :func:`write_shape_library`. All lengths in metres;
see docs/ct.md, "Clump shape libraries from CT".
"""
from __future__ import annotations

import numpy as np
import pandas as pd
import yaml
from scipy.spatial import cKDTree
from skimage.measure import marching_cubes, mesh_surface_area

from ..atomic import write_text
from ..clumps import LibraryError, check_shape
from .segment import _hull_ratio, distance_map

__all__ = ["fit_clump", "clump_quality", "shape_figures", "rasterize_spheres", "library_grains",
           "shape_library_from_labels", "shape_library_from_segmentation", "write_shape_library"]

_PAD = 4                      # voxels around a grain's crop: room for refined spheres to cross its surface
_STEPS = (0.5, 0.25, 0.125)   # refinement steps [voxels]
_SWEEPS = 4                   # passes over the spheres per step (at most)
# a voxel centre is inside a sphere when its squared distance is below r^2 (1 - 1e-9): the voxels
# at exactly the EDT radius (outside the grain) stay out after a round trip through metres
_INSIDE = 1 - 1e-9


def fit_clump(mask, voxel_size, n_spheres=6, coverage=0.97, min_radius=None, refine=True) -> np.ndarray:
    """Overlapping spheres that approximate one grain.

    Parameters
    ----------
    mask : (nz, ny, nx) bool array
        The grain's voxels (one connected grain, indexed ``[z, y, x]``).
    voxel_size : float
        Voxel edge [m].
    n_spheres : int
        Most spheres to use.
    coverage : float
        Stop adding spheres once this fraction of the grain's voxels lies inside them.
    min_radius : float, optional
        Smallest sphere [m] to add; default 0.25 x the first (largest) sphere, at least 1 voxel. Small
        members set a clump's DEM time step.
    refine : bool
        Move centres and radii (steps of 1/2, 1/4, 1/8 voxel) while the union differs from the grain
        in fewer voxels (it may then cross the grain's surface a little); the union stays one
        connected body.

    Returns
    -------
    spheres : (M, 4) float array
        ``[x, y, z, r]`` [m], centres relative to the grain's centroid (the mean of its voxel
        centres), largest first, M <= n_spheres. Every member touches or overlaps the others
        (:func:`orchestrator.clumps.check_shape` passes).

    Notes
    -----
    The EDT value of a voxel (distance to the nearest voxel outside the grain) is taken as the radius
    of the inscribed sphere centred there. A voxel sits inside a sphere when its centre is closer to
    the sphere's centre than the radius (:func:`rasterize_spheres`). See the module docstring for
    the method and its sources.
    """
    m = _crop(mask)
    if not m.any():
        raise ValueError("fit_clump: the mask holds no voxel")
    centroid = np.argwhere(m).mean(axis=0)                                   # (z, y, x) in the crop
    # squared lattice distances are integers: exact float64 radii (float32 rounds sqrt(65) up, which
    # would put the voxels at exactly that distance, outside the grain, inside the sphere)
    d = np.sqrt(np.rint(distance_map(m).astype(np.float64) ** 2))
    dmax = float(d.max())
    floor = max(1.0, 0.25 * dmax) if min_radius is None else max(min_radius / voxel_size, 0.5)
    cand = _medial(d, min(floor, dmax))
    pc, rc = np.argwhere(cand).astype(float), d[cand].astype(float)
    n = int(m.sum())
    balls = np.empty((0, 4))
    count = np.zeros(m.shape, np.int16)          # spheres covering each voxel
    while len(balls) < n_spheres:
        b = _next_ball(m, count, pc, rc, balls)
        if b is None:
            break
        balls = np.vstack([balls, b])
        sl, ball = _ball(b, m.shape)
        count[sl] += ball
        if refine:
            balls = _refine(m, balls, count)
        if np.count_nonzero(m & (count > 0)) >= coverage * n:
            break
    out = np.empty((len(balls), 4))
    out[:, :3] = (balls[:, 2::-1] - centroid[::-1]) * voxel_size
    out[:, 3] = balls[:, 3] * voxel_size
    return out[np.argsort(-out[:, 3], kind="stable")]


def rasterize_spheres(spheres_zyxr, shape) -> np.ndarray:
    """Voxels of a ``shape`` grid whose centre lies strictly inside any of the spheres
    ``spheres_zyxr`` (M, 4): centre (z, y, x) and radius, all in voxels (squared distance below
    r^2 (1 - 1e-9)). Bool array."""
    out = np.zeros(shape, bool)
    for b in np.asarray(spheres_zyxr, float):
        sl, ball = _ball(b, shape)
        out[sl] |= ball
    return out


def clump_quality(mask, voxel_size, spheres) -> dict:
    """How well the spheres ``spheres`` ((M, 4) ``[x, y, z, r]`` [m] about the grain's centroid, as
    :func:`fit_clump` returns them) reproduce the grain ``mask`` (bool ``[z, y, x]``, voxel edge
    ``voxel_size`` [m]).

    The union is rasterised on the grain's voxel grid (:func:`rasterize_spheres`), so grain and clump
    are compared voxel for voxel. Returns a dict:

    * ``volume_ratio``: union volume / grain volume;
    * ``coverage``: fraction of the grain's voxels inside the union;
    * ``outside``: fraction of the union's voxels outside the grain;
    * ``<figure>_grain`` and ``<figure>_clump`` for the figures of :func:`shape_figures`
      (sphericity, elongation, flatness, hull_ratio), both measured on voxel masks;
    * ``n_spheres`` and ``radius_ratio`` (smallest / largest member radius).
    """
    s = np.asarray(spheres, float).reshape(-1, 4)
    m = _crop(mask)
    c = np.argwhere(m).mean(axis=0)
    zyxr = np.column_stack([c + s[:, 2::-1] / voxel_size, s[:, 3] / voxel_size])
    # grow the grid so that the union fits, keeping the grain's voxels where they are
    below = np.maximum(0, np.ceil(-(zyxr[:, :3] - zyxr[:, 3:]).min(axis=0)).astype(int) + 1)
    above = np.maximum(0, np.ceil((zyxr[:, :3] + zyxr[:, 3:]).max(axis=0) - (np.array(m.shape) - 1)).astype(int) + 1)
    m = np.pad(m, list(zip(below, above)))
    zyxr[:, :3] += below
    u = rasterize_spheres(zyxr, m.shape)
    ng, nu, both = int(m.sum()), int(u.sum()), int((m & u).sum())
    q = {"volume_ratio": nu / ng, "coverage": both / ng, "outside": (nu - both) / nu if nu else float("nan")}
    fg, fc = shape_figures(m), shape_figures(u)
    for k in fg:
        q[f"{k}_grain"], q[f"{k}_clump"] = fg[k], fc[k]
    q["n_spheres"] = int(len(s))
    q["radius_ratio"] = float(s[:, 3].min() / s[:, 3].max())
    return q


def shape_figures(mask) -> dict:
    """Shape figures of a voxel mask (bool ``[z, y, x]``), dimensionless:

    * ``sphericity``: Wadell's pi^(1/3) (6 V)^(2/3) / A, V the voxel count, A the area of the
      marching-cubes surface (:func:`skimage.measure.marching_cubes` at 0.5 of the mask). The voxel
      steps add area: a voxelised sphere of radius 7-14 voxels reads 0.92-0.93 and a 2:1:1 spheroid
      0.86 (exact 0.929): compare masks on the same grid, not with continuous values;
    * ``elongation`` b/a and ``flatness`` c/b: a >= b >= c the square roots of the principal
      second moments of the voxel centres (the semi-axes of the ellipsoid of the same moments, up
      to a common factor);
    * ``hull_ratio``: convex-hull volume of the voxel centres per voxel, as the segmentation's grain
      table (``orchestrator.ct.segment``): larger for concave grains.
    """
    m = np.asarray(mask, bool)
    p = np.argwhere(m).astype(float)
    if len(p) < 20:
        return {"sphericity": np.nan, "elongation": np.nan, "flatness": np.nan, "hull_ratio": np.nan}
    q = p - p.mean(axis=0)
    ev = np.sort(np.linalg.eigvalsh(q.T @ q / len(q)))[::-1]
    a, b, c = np.sqrt(np.maximum(ev, 0))
    v, f, *_ = marching_cubes(np.pad(m, 1).astype(np.float32), 0.5)
    area = mesh_surface_area(v, f)
    hull = _hull_ratio(np.ascontiguousarray(m, dtype=np.int32), 1, np.array([len(p)]))[0]
    return {"sphericity": float(np.pi ** (1 / 3) * (6 * len(p)) ** (2 / 3) / area),
            "elongation": float(b / a), "flatness": float(c / b), "hull_ratio": float(hull)}


def shape_library_from_labels(labels, voxel_size, table, n_spheres=6, **fit_kw):
    """Fit every grain of a label volume listed in ``table``.

    labels : int array ``[z, y, x]`` (0 = pore); voxel_size : voxel edge [m]; table : DataFrame with
    ``label`` and the bounding box ``z0, y0, x0, z1, y1, x1`` [voxels, end exclusive] of each grain to
    fit (the segmentation's grain table, filtered). ``fit_kw`` goes to :func:`fit_clump`.

    Returns ``(shapes, quality)``: a list of (M, 4) arrays ``[x, y, z, r]`` [m] about each grain's
    centroid, and a DataFrame with one row per shape: ``name``, ``label``, ``n_voxels``,
    ``radius`` (volume-equivalent radius of the voxels [m]) and the figures of :func:`clump_quality`.
    """
    shapes, rows = [], []
    for t in table.itertuples(index=False):
        lab = int(t.label)
        sl = tuple(slice(int(a), int(b)) for a, b in ((t.z0, t.z1), (t.y0, t.y1), (t.x0, t.x1)))
        m = labels[sl] == lab
        s = fit_clump(m, voxel_size, n_spheres=n_spheres, **fit_kw)
        n = int(m.sum())
        shapes.append(s)
        rows.append({"name": f"ct_{lab:05d}", "label": lab, "n_voxels": n,
                     "radius": float(np.cbrt(3 * n / (4 * np.pi)) * voxel_size),
                     **clump_quality(m, voxel_size, s)})
    return shapes, pd.DataFrame(rows)


def library_grains(grains, min_voxels=1000, skip_flagged=True) -> np.ndarray:
    """Rows of a segmentation grain table (``at_border``, ``n_voxels``, ``flag``) that make library
    shapes: not at the scan border (cut by the field of view), at least ``min_voxels`` voxels (a
    coarser grain gives a coarse shape), and, with ``skip_flagged``, not flagged "over"/"under" (a
    fragment, or several grains in one label). Bool array, one per row."""
    keep = ~grains["at_border"].to_numpy(bool) & (grains["n_voxels"].to_numpy() >= min_voxels)
    if skip_flagged:
        flag = grains["flag"]
        keep &= (flag.isna() | (flag.astype(str) == "")).to_numpy()      # read from CSV: "" is NaN
    return keep


def shape_library_from_segmentation(seg, n_spheres=6, min_voxels=1000, skip_flagged=True, **fit_kw):
    """Clump shapes of the grains of a :class:`~orchestrator.ct.segment.Segmentation` chosen by
    :func:`library_grains`. ``n_spheres`` and ``fit_kw`` go to :func:`fit_clump`. Returns ``(shapes,
    quality)`` as :func:`shape_library_from_labels`."""
    g = seg.grains
    keep = library_grains(g, min_voxels, skip_flagged)
    return shape_library_from_labels(seg.labels, seg.scan.voxel_size, g[keep], n_spheres=n_spheres, **fit_kw)


def write_shape_library(path, shapes, names=None, meta=None, quality=None, comment: str = ""):
    """Write a clump library that :func:`orchestrator.clumps.load_library` reads (YAML).

    path : .yaml/.yml file, written atomically (``<path>.partial``, then renamed);
    shapes : list of (M, 4) arrays ``[x, y, z, r]`` [m]; every one is checked with
    :func:`orchestrator.clumps.check_shape` first (a :class:`~orchestrator.clumps.LibraryError`
    names the shape) and written to 6 significant digits (all digits when rounding would part two
    members that just touch);
    names : one name per shape (default ``shape_000`` ...);
    meta : mapping stored under ``meta:`` (provenance: scan, parameters, units), which the loader
    ignores; ``unit: m`` and the number of shapes are added;
    quality : optional DataFrame or list of mappings, one per shape, stored as each shape's
    ``quality:`` (numbers rounded to 4 significant digits);
    comment : text written as ``#`` lines at the top of the file.
    """
    names = [f"shape_{k:03d}" for k in range(len(shapes))] if names is None else list(names)
    if len(names) != len(shapes):
        raise ValueError(f"write_shape_library: {len(names)} names for {len(shapes)} shapes")
    rows = quality.to_dict("records") if isinstance(quality, pd.DataFrame) else quality
    doc_shapes = []
    for k, (name, s) in enumerate(zip(names, shapes)):
        s = np.asarray(s, float).reshape(-1, 4)
        try:
            check_shape(s)
        except LibraryError as e:
            raise LibraryError(f"shape {k} ({name}): {e}") from None
        rounded = [[_num(v, 6) for v in row] for row in s]
        try:
            check_shape(np.asarray(rounded))
        except LibraryError:            # members that just touch: keep every digit
            rounded = s.tolist()
        entry = {"name": str(name), "spheres": rounded}
        if rows is not None:
            entry["quality"] = {str(a): _num(b, 4) for a, b in rows[k].items() if a != "name"}
        doc_shapes.append(entry)
    head = {"unit": "m", "n_shapes": len(shapes), **dict(meta or {})}
    text = "".join(f"# {line}\n".replace("# \n", "#\n") for line in comment.splitlines())
    text += yaml.safe_dump({"meta": _plain(head)}, sort_keys=False, width=120)
    text += yaml.safe_dump({"shapes": doc_shapes}, sort_keys=False, width=120, default_flow_style=None)
    return write_text(path, text)


# ------------------------------------------------------------------------------------------ helpers

def _num(v, digits):
    """A YAML-friendly number: Python int/float rounded to ``digits`` significant digits."""
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(f"{float(v):.{digits}g}")
    return v


def _plain(o):
    """Numpy scalars/arrays and tuples in ``o`` as plain Python for :func:`yaml.safe_dump`."""
    if isinstance(o, dict):
        return {str(k): _plain(v) for k, v in o.items()}
    if isinstance(o, (list, tuple, np.ndarray)):
        return [_plain(v) for v in (o.tolist() if isinstance(o, np.ndarray) else o)]
    return _num(o, 6)


def _crop(mask):
    """The mask cut to its bounding box plus ``_PAD`` empty voxels on every side."""
    mask = np.asarray(mask, bool)
    if mask.ndim != 3:
        raise ValueError(f"a grain mask must be 3-D [z, y, x], got shape {mask.shape}")
    idx = np.argwhere(mask)
    if len(idx) == 0:
        return np.zeros((1, 1, 1), bool)
    a, b = idx.min(axis=0), idx.max(axis=0) + 1
    m = mask[a[0]:b[0], a[1]:b[1], a[2]:b[2]]
    return np.pad(m, _PAD)


def _ball(b, shape):
    """Slices of the grid ``shape`` holding sphere ``b`` (z, y, x, r) [voxels], and the voxels of that
    window whose centre lies strictly inside it."""
    lo = np.maximum(np.floor(b[:3] - b[3]).astype(int), 0)
    hi = np.minimum(np.ceil(b[:3] + b[3]).astype(int) + 1, shape)
    sl = tuple(slice(int(a), int(c)) for a, c in zip(lo, np.maximum(hi, lo)))
    z, y, x = np.ogrid[sl]
    return sl, (z - b[0]) ** 2 + (y - b[1]) ** 2 + (x - b[2]) ** 2 < b[3] ** 2 * _INSIDE


def _medial(d, r_min):
    """Voxels whose inscribed sphere (radius ``d``) lies in no neighbour's: d(q) < d(p) + |q - p|
    for all 26 neighbours q (the EDT is 1-Lipschitz, so equality means containment), and d >= r_min."""
    keep = d >= r_min
    dp = np.pad(d, 1)
    n = d.shape
    for off in np.ndindex(3, 3, 3):
        o = np.array(off) - 1
        if not o.any():
            continue
        q = dp[off[0]:off[0] + n[0], off[1]:off[1] + n[1], off[2]:off[2] + n[2]]
        keep &= q < d + np.linalg.norm(o) - 1e-6
    return keep


def _next_ball(m, count, pc, rc, balls):
    """The candidate sphere (centres ``pc`` (K, 3) [z, y, x], radii ``rc`` [voxels]) that covers most
    voxels of ``m`` not yet covered (``count == 0``) and touches one of ``balls`` (any, if none yet);
    None when none adds a voxel. Returns ``[z, y, x, r]``."""
    free = np.argwhere(m & (count == 0)).astype(float)
    if len(free) == 0 or len(pc) == 0:
        return None
    gain = cKDTree(free).query_ball_point(pc, rc * (1 - 1e-9), return_length=True).astype(float)
    if len(balls):
        dist = np.linalg.norm(pc[:, None, :] - balls[None, :, :3], axis=2)
        gain[~(dist <= rc[:, None] + balls[None, :, 3]).any(axis=1)] = 0
    k = int(np.argmax(gain))
    return None if gain[k] <= 0 else np.array([*pc[k], rc[k]])


def _refine(m, balls, count):
    """Move the centre and radius of every sphere by +-step along each axis (each of ``_STEPS``
    [voxels] in turn) while the number of voxels where the union and the grain ``m`` differ falls and
    the spheres stay one connected body (:func:`orchestrator.clumps.check_shape`). Only the moved
    sphere's old and new bounding boxes are counted again. ``count`` (spheres covering each voxel)
    is updated in place."""
    balls = balls.copy()
    shape = np.array(m.shape)
    moves = np.vstack([np.eye(4), -np.eye(4)])
    for step in _STEPS:
        for _ in range(_SWEEPS):
            moved = False
            for k in range(len(balls)):
                old = balls[k].copy()
                best, best_b = 0, None
                for mv in moves * step:
                    b = old + mv
                    if b[3] < 0.5 or (b[:3] - b[3] < 0).any() or (b[:3] + b[3] > shape - 1).any():
                        continue
                    delta = _delta(m, count, old, b)
                    if delta < best and _connected(balls, k, b):
                        best, best_b = delta, b
                if best_b is not None:
                    sl, ball = _ball(old, m.shape)
                    count[sl] -= ball
                    sl, ball = _ball(best_b, m.shape)
                    count[sl] += ball
                    balls[k] = best_b
                    moved = True
            if not moved:
                break
    return balls


def _connected(balls, k, b):
    """Whether the spheres stay one body when sphere k becomes ``b``."""
    if len(balls) == 1:
        return True
    trial = balls.copy()
    trial[k] = b
    try:
        check_shape(trial)
    except LibraryError:
        return False
    return True


def _delta(m, count, old, new):
    """Change of the number of voxels where the union differs from ``m`` when sphere ``old`` becomes
    ``new`` (``count``: spheres covering each voxel, ``old`` included)."""
    lo = np.maximum(np.floor(np.minimum(old[:3] - old[3], new[:3] - new[3])).astype(int), 0)
    hi = np.minimum(np.ceil(np.maximum(old[:3] + old[3], new[:3] + new[3])).astype(int) + 1, m.shape)
    sl = tuple(slice(int(a), int(b)) for a, b in zip(lo, hi))
    z, y, x = np.ogrid[sl]
    r2 = lambda b: (z - b[0]) ** 2 + (y - b[1]) ** 2 + (x - b[2]) ** 2 < b[3] ** 2 * _INSIDE
    ins_old = r2(old)
    others = (count[sl] - ins_old) > 0
    mm = m[sl]
    return int(np.count_nonzero((others | r2(new)) != mm)) - int(np.count_nonzero((others | ins_old) != mm))
