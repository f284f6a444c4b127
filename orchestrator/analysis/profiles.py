"""Number-density and volume-fraction profiles n(z), n(r), n(r, z) in a cylindrical cell (seed 000, Fig. 1).

Heights are measured from ``z_ref`` (seed 000: the vanes' top edge) and radii from the cell axis
through ``center`` (x, y). Number density n = (centres in bin) / (bin volume) [1/m³], bin volume
π (r₂² − r₁²) Δz. Volume fraction φ = (particle volume inside the bin) / (bin volume) [-]: each
sphere's volume is spread over a fixed, uniform set of sample points inside it (``samples``
points per sphere, low-discrepancy), so spheres cut by bin boundaries are shared correctly for
any bin shape; polydisperse radii are exact in the weights.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from ._common import Result, control_values, frame_indices, present, sphere_volume
from .plots import plot_profiles

__all__ = ["density_profile", "analyze_profiles"]


def _ball_points(n: int) -> np.ndarray:
    """n quasi-uniform points in the unit ball (Halton sequence, radial cube-root map)."""
    def halton(i, b):
        f, r = 1.0, np.zeros_like(i, dtype=float)
        i = i.copy()
        while np.any(i > 0):
            f /= b
            r += f * (i % b)
            i //= b
        return r
    k = np.arange(1, n + 1)
    u, v, w = halton(k, 2), halton(k, 3), halton(k, 5)
    rr = u ** (1.0 / 3.0)
    ct = 2 * v - 1
    st = np.sqrt(1 - ct ** 2)
    ph = 2 * np.pi * w
    return np.c_[rr * st * np.cos(ph), rr * st * np.sin(ph), rr * ct]


def density_profile(position, radius, r_edges, z_edges, center=(0.0, 0.0), z_ref: float = 0.0,
                    samples: int = 64) -> dict:
    """n(r, z) [1/m³] and φ(r, z) [-] on the given bin edges [m] (r from the axis, z − z_ref).

    Returns dict with ``n``, ``phi``, ``count`` (len(r_edges)−1, len(z_edges)−1) and ``volume``
    (bin volumes [m³]).
    """
    p = np.asarray(position, float)
    R = np.asarray(radius, float)
    ok = present(p)
    p, R = p[ok], R[ok]
    r_edges = np.asarray(r_edges, float)
    z_edges = np.asarray(z_edges, float)
    rc = np.hypot(p[:, 0] - center[0], p[:, 1] - center[1])
    zc = p[:, 2] - z_ref
    count, _, _ = np.histogram2d(rc, zc, [r_edges, z_edges])
    vol = np.pi * np.diff(r_edges ** 2)[:, None] * np.diff(z_edges)[None, :]
    phi = np.zeros_like(count)
    if samples > 0 and len(p):
        b = _ball_points(samples)
        w = sphere_volume(R) / samples
        # process in chunks to bound memory
        step = max(1, 2_000_000 // samples)
        for s in range(0, len(p), step):
            q = p[s:s + step, None, :] + R[s:s + step, None, None] * b[None]
            rq = np.hypot(q[..., 0] - center[0], q[..., 1] - center[1]).ravel()
            zq = q[..., 2].ravel() - z_ref
            h, _, _ = np.histogram2d(rq, zq, [r_edges, z_edges], weights=np.repeat(w[s:s + step], samples))
            phi += h
    return {"n": count / vol, "phi": phi / vol, "count": count, "volume": vol}


def _filled_height(position, radius, z_ref: float) -> tuple[float, float]:
    """(lowest grain bottom, highest grain top) − z_ref [m] of one frame's present grains."""
    ok = present(position)
    z = position[ok, 2] - z_ref
    return float(np.min(z - radius[ok])), float(np.max(z + radius[ok]))


def analyze_profiles(frames, center=None, z_ref: float = 0.0, r_max: float | None = None,
                     z_range=None, radial_z_range=None, axial_r_range=None, bins_r: int = 20, bins_z: int = 40,
                     at=None, control: str | None = None, stride: int | None = None, samples: int = 64) -> Result:
    """Axial n(z), φ(z), radial n(r), φ(r) and the 2-D n(r, z) of selected frames (default first and last).

    Options (SI): ``center`` (x, y) of the cell axis (default: centre of the centres' bounding
    box), ``z_ref`` (height origin, seed 000: vanes' top edge), ``r_max`` (cell radius, default
    largest centre distance + its radius), ``z_range`` (z − z_ref range of the axial profile,
    default all), ``radial_z_range`` (z − z_ref slab for the radial profile; seed 000:
    (0, 0.7e-3); default: each frame's own filled height, from its lowest grain bottom to its
    highest grain top, so that a compacted frame's φ(r) is not diluted by the empty height a
    looser frame filled), ``axial_r_range`` (radial range for the axial profile, default (0, r_max)),
    ``bins_r``, ``bins_z``, ``samples`` (points per sphere for φ).

    Tables: ``axial`` (frame, control, z, n, phi), ``radial`` (frame, control, r, n, phi),
    ``map`` (frame, control, r, z, n, phi).
    """
    cname, cvals = control_values(frames, control)
    pos_all = frames.position
    if at is None and stride is None:
        ks = sorted({0, frames.n_frames - 1})
    else:
        ks = frame_indices(frames, at, control, stride or 1)
    # default extents cover every selected frame (a compacted sample may have left the first
    # frame's height range entirely: the shear cell's lower piston lifts it by ~0.5 mm)
    sel = pos_all[ks].reshape(-1, 3)
    rad = np.tile(frames.radius, len(ks))
    okf = present(sel)
    if center is None:
        first = pos_all[ks[0]]
        lo, hi = np.nanmin(first[present(first)], 0), np.nanmax(first[present(first)], 0)
        center = (0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]))
    center = tuple(float(c) for c in center)
    if r_max is None:
        rc = np.hypot(sel[okf, 0] - center[0], sel[okf, 1] - center[1])
        r_max = float(np.max(rc + rad[okf]))
    if z_range is None:
        zz = sel[okf, 2] - z_ref
        z_range = (float(np.min(zz - rad[okf])), float(np.max(zz + rad[okf])))
    axial_r_range = axial_r_range or (0.0, r_max)
    z_edges = np.linspace(z_range[0], z_range[1], bins_z + 1)
    r_edges = np.linspace(0.0, r_max, bins_r + 1)
    ax, rad, mp = [], [], []
    for k in ks:
        p = pos_all[k]
        a = density_profile(p, frames.radius, np.array(axial_r_range, float), z_edges, center, z_ref, samples)
        ax.append(pd.DataFrame({"frame": k, "control": cvals[k], "z": 0.5 * (z_edges[1:] + z_edges[:-1]),
                                "n": a["n"][0], "phi": a["phi"][0], "count": a["count"][0]}))
        r = density_profile(p, frames.radius, r_edges, np.array(radial_z_range or _filled_height(p, frames.radius, z_ref),
                                                                  float), center, z_ref, samples)
        rad.append(pd.DataFrame({"frame": k, "control": cvals[k], "r": 0.5 * (r_edges[1:] + r_edges[:-1]),
                                 "n": r["n"][:, 0], "phi": r["phi"][:, 0], "count": r["count"][:, 0]}))
        m = density_profile(p, frames.radius, r_edges, z_edges, center, z_ref, samples)
        R, Z = np.meshgrid(0.5 * (r_edges[1:] + r_edges[:-1]), 0.5 * (z_edges[1:] + z_edges[:-1]), indexing="ij")
        mp.append(pd.DataFrame({"frame": k, "control": cvals[k], "r": R.ravel(), "z": Z.ravel(),
                                "n": m["n"].ravel(), "phi": m["phi"].ravel()}))
    return Result("profiles", tables={"axial": pd.concat(ax, ignore_index=True), "radial": pd.concat(rad, ignore_index=True),
                                      "map": pd.concat(mp, ignore_index=True)},
                  scalars={"center_x": center[0], "center_y": center[1], "z_ref": z_ref, "r_max": r_max, "control": cname},
                  options={"center": center, "z_ref": z_ref, "r_max": r_max, "z_range": list(z_range),
                           "radial_z_range": list(radial_z_range) if radial_z_range else None,   # None: each frame's filled height
                           "bins_r": bins_r, "bins_z": bins_z},
                  plotter=plot_profiles)
