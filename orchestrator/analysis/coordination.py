"""Coordination number Z per particle and its distribution P(Z) (seed 001, Fig. 6b).

Contacts come from the frame's contact list when the engine wrote one (``source="contacts"``),
otherwise from geometry: |x_i − x_j| <= (R_i + R_j)(1 + tolerance) (``source="geometry"``, the
only choice for CT frames). Contacts with walls (a contact id that is not a particle id) are not
counted unless ``include_walls``. Rattlers (Z < ``rattler_max`` + 1) are reported separately and
the mechanical coordination number Z_m excludes them.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from ._cells import CellList, count_within
from ._common import Result, control_values, d50, frame_indices, present
from .neighbors import contacts_to_rows, geometric_contacts, pairs_within
from .containers import make_container
from .plots import plot_coordination

__all__ = ["coordination_from_pairs", "neighbor_counts", "frame_contacts", "analyze_coordination"]


def coordination_from_pairs(n: int, i: np.ndarray, j: np.ndarray, mask: np.ndarray | None = None,
                            include_walls: bool = False) -> np.ndarray:
    """Z per row from contact row pairs (i, j); rows < 0 are walls. Absent rows (mask False) -> NaN.
    Z counts distinct neighbours: two grains that touch at several points (clumps, whose member
    spheres touch separately: orchestrator.grains) count each other once. Wall contacts are counted
    as listed."""
    i = np.asarray(i, np.int64)
    j = np.asarray(j, np.int64)
    z = np.zeros(n)
    pp = (i >= 0) & (j >= 0)
    pairs = np.unique(np.sort(np.column_stack([i[pp], j[pp]]), axis=1), axis=0)
    z += np.bincount(pairs[:, 0], minlength=n) + np.bincount(pairs[:, 1], minlength=n)
    if include_walls:
        z += np.bincount(i[(i >= 0) & (j < 0)], minlength=n) + np.bincount(j[(j >= 0) & (i < 0)], minlength=n)
    if mask is not None:
        z[~mask] = np.nan
    return z


def neighbor_counts(position: np.ndarray, cutoff: float) -> np.ndarray:
    """Number of other centres within ``cutoff`` [m] of each centre (OVITO's "Coordination");
    NaN for absent rows. Compiled cell-list count (:mod:`._cells`)."""
    c = count_within(CellList(position, cutoff, reach=1)).astype(float)
    c[c < 0] = np.nan
    return c


def frame_contacts(frames, k: int, source: str = "auto", tolerance: float = 0.0, cutoff: float | None = None):
    """(i_rows, j_rows, source_used, contact arrays or None) for frame k (walls as -1 rows when from
    the contact list). ``source="cutoff"``: every pair of centres within ``cutoff`` [m]."""
    if source == "auto":
        source = "contacts" if k in getattr(frames, "contact_frames", []) else "geometry"
    if source == "contacts":
        c = frames.contact_arrays(k)
        i, j = contacts_to_rows(frames, c["i"], c["j"])
        return i, j, "contacts", c
    if source == "geometry":
        i, j = geometric_contacts(frames.position[k], frames.radius, tolerance)
        return i, j, "geometry", None
    if source == "cutoff":
        if cutoff is None:
            raise ValueError("coordination source 'cutoff' needs a cutoff [m]")
        i, j = pairs_within(frames.position[k], cutoff)
        return i, j, "cutoff", None
    raise ValueError(f"coordination source must be 'auto', 'contacts', 'geometry' or 'cutoff', got {source!r}")


def analyze_coordination(frames, at=None, control: str | None = None, stride: int | None = None,
                         source: str = "auto", tolerance: float = 0.0, include_walls: bool = False,
                         rattler_max: int = 1, wall_distance: float | None = None, container=None,
                         cutoff: float | None = None, cutoff_d50: float | None = None) -> Result:
    """Coordination numbers of selected frames (default first and last).

    Options: ``source`` ("auto", "contacts", "geometry", "cutoff"), ``tolerance`` (relative gap for
    geometric contacts), ``cutoff`` [m] or ``cutoff_d50`` (× d50): a fixed-cutoff coordination, every
    centre within the cutoff counts (OVITO's coordination; giving either selects ``source="cutoff"``),
    ``include_walls``, ``rattler_max`` (Z <= this is a rattler),
    ``wall_distance`` [m]: only particles whose centre is at least this far from the container
    boundary enter the statistics (``container`` as in :mod:`.containers`, default inferred).

    Tables: ``particles`` (frame, id, z), ``distribution`` (frame, z, count, p), ``summary``
    (frame, control, mean_z, mean_z_mechanical, rattler_fraction, n_particles, source).
    """
    cname, cvals = control_values(frames, control)
    if cutoff is None and cutoff_d50 is not None:
        cutoff = float(cutoff_d50) * d50(frames.radius)
    if cutoff is not None:
        if source not in ("auto", "cutoff"):
            raise ValueError(f"coordination: a cutoff was given but source is {source!r}; use source 'cutoff'")
        source = "cutoff"
    if at is None and stride is None:
        ks = sorted({0, frames.n_frames - 1})
    else:
        ks = frame_indices(frames, at, control, stride or 1)
    parts, dists, summ = [], [], []
    for k in ks:
        pos = frames.position[k]
        ok = present(pos)
        i, j, used, _ = frame_contacts(frames, k, source, tolerance, cutoff)
        z = coordination_from_pairs(len(pos), i, j, ok, include_walls)
        sel = ok.copy()
        if wall_distance is not None:
            box = make_container(container, pos)
            sel &= box.distance_to_boundary(np.nan_to_num(pos)) >= wall_distance
        zs = z[sel]
        parts.append(pd.DataFrame({"frame": k, "id": frames.ids[sel], "z": zs}))
        vals, cnt = np.unique(zs.astype(int), return_counts=True)
        dists.append(pd.DataFrame({"frame": k, "control": cvals[k], "z": vals, "count": cnt,
                                   "p": cnt / max(cnt.sum(), 1)}))
        mech = zs[zs > rattler_max]
        summ.append({"frame": k, "control": cvals[k], "mean_z": float(np.mean(zs)) if zs.size else np.nan,
                     "mean_z_mechanical": float(np.mean(mech)) if mech.size else np.nan,
                     "rattler_fraction": float(np.mean(zs <= rattler_max)) if zs.size else np.nan,
                     "n_particles": int(zs.size), "source": used})
    s = pd.DataFrame(summ)
    return Result("coordination", tables={"particles": pd.concat(parts, ignore_index=True),
                                          "distribution": pd.concat(dists, ignore_index=True), "summary": s},
                  scalars={"mean_z_last": float(s["mean_z"].iloc[-1]), "source": str(s["source"].iloc[-1]),
                           "control": cname},
                  options={"source": source, "tolerance": tolerance, "include_walls": include_walls,
                           "cutoff": cutoff},
                  plotter=plot_coordination)
