"""Neighbour lists on particle centres (scipy.spatial.cKDTree), NaN rows ignored.

All functions take positions in metres and return row indices into the input arrays.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ._common import present

__all__ = ["pairs_within", "geometric_contacts", "contacts_to_rows"]


def pairs_within(position: np.ndarray, cutoff: float, ordered: bool = False):
    """Pairs of present particles whose centres are closer than ``cutoff`` [m].

    Returns ``(i, j)`` row indices with i < j, or both orientations if ``ordered``.
    """
    position = np.asarray(position, float)
    rows = np.flatnonzero(present(position))
    if rows.size < 2:
        e = np.zeros(0, np.int64)
        return e, e
    tree = cKDTree(position[rows])
    p = tree.query_pairs(float(cutoff), output_type="ndarray")
    i, j = rows[p[:, 0]], rows[p[:, 1]]
    if ordered:
        return np.concatenate([i, j]), np.concatenate([j, i])
    return i, j


def geometric_contacts(position: np.ndarray, radius: np.ndarray, tolerance: float = 0.0):
    """Contacts from geometry: ``|x_i - x_j| <= (R_i + R_j) (1 + tolerance)`` (polydisperse).

    ``tolerance`` is a relative gap (CT data: a few % of a diameter to absorb segmentation error).
    Returns ``(i, j)`` row indices with i < j.
    """
    position = np.asarray(position, float)
    radius = np.asarray(radius, float)
    ok = present(position)
    if not ok.any():
        e = np.zeros(0, np.int64)
        return e, e
    rmax = np.nanmax(radius[ok])
    i, j = pairs_within(position, 2.0 * rmax * (1.0 + tolerance))
    d = np.linalg.norm(position[j] - position[i], axis=1)
    keep = d <= (radius[i] + radius[j]) * (1.0 + tolerance)
    return i[keep], j[keep]


def contacts_to_rows(frames_or_ids, ci: np.ndarray, cj: np.ndarray):
    """Map contact ids to row indices. Ids that are not particles (walls) map to -1."""
    ids = frames_or_ids.ids if hasattr(frames_or_ids, "ids") else np.asarray(frames_or_ids)
    order = np.argsort(ids)
    sid = ids[order]

    def rows(c):
        c = np.asarray(c, np.int64)
        pos = np.clip(np.searchsorted(sid, c), 0, len(sid) - 1)
        hit = sid[pos] == c
        return np.where(hit, order[pos], -1)

    return rows(ci), rows(cj)
