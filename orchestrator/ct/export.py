"""Tracked grains -> the common frame format (``frames.h5``, see orchestrator/frames.py).

Every grain gets one id for its whole life: the grains of the first scan are ids 0 ... N0-1; a grain
linked from scan k to scan k+1 keeps its id; a grain that appears (new) gets the next free id; a
lost grain is a NaN row from then on (a grain that is lost and found again in a later scan gets a
new id: the tracker links consecutive scans only). ``/particles/radius`` is the median equivalent
radius over the scans where the grain was seen, ``/particles/shape`` the median SH invariants
``||R_0|| ... ||R_L||`` [m] when the tables carry them (columns ``R0`` ...).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..frames import FrameWriter
from .track import Links

__all__ = ["assign_ids", "write_ct_frames"]


def assign_ids(n_per_scan, links: list[Links]) -> np.ndarray:
    """Stable ids: returns ``rows`` (T, N_ids) with the table row of id k in scan t, -1 where absent."""
    T = len(n_per_scan)
    if len(links) != T - 1:
        raise ValueError(f"{T} scans need {T - 1} link sets, got {len(links)}")
    ids_t = np.arange(n_per_scan[0])
    next_id = n_per_scan[0]
    per_scan = [ids_t]
    for t, L in enumerate(links):
        if len(L.a_to_b) != n_per_scan[t] or len(L.b_to_a) != n_per_scan[t + 1]:
            raise ValueError(f"links {t}->{t + 1} are for {len(L.a_to_b)}->{len(L.b_to_a)} grains, "
                             f"but the tables have {n_per_scan[t]}->{n_per_scan[t + 1]}")
        nb = n_per_scan[t + 1]
        ids_b = np.full(nb, -1, np.int64)
        linked = L.b_to_a >= 0
        ids_b[linked] = per_scan[t][L.b_to_a[linked]]
        new = np.nonzero(~linked)[0]
        ids_b[new] = next_id + np.arange(len(new))
        next_id += len(new)
        per_scan.append(ids_b)
    rows = np.full((T, next_id), -1, np.int64)
    for t, ids in enumerate(per_scan):
        rows[t, ids] = np.arange(len(ids))
    return rows


def write_ct_frames(path, tables: list[pd.DataFrame], links: list[Links], times=None, controls=None,
                    contacts: list[pd.DataFrame] | None = None, voxel_size: float | None = None,
                    meta: dict | None = None) -> Path:
    """Write tracked grains to ``path`` (frames.h5) with ``meta.source = "ct"``.

    tables : per scan, the grain table (``label``, ``x, y, z`` [m], ``radius`` [m], optional ``R0``..).
    links : per consecutive pair of scans, a :class:`~orchestrator.ct.track.Links`.
    times : (T,) scan times [s] (default 0, 1, 2 ...); controls : name -> (T,) values in SI.
    contacts : per scan, a contact table (``i``, ``j`` grain labels, ``px..``, ``nx..``), stored under
        ``/contacts/<scan>`` with grain ids.
    """
    T = len(tables)
    rows = assign_ids([len(t) for t in tables], links)
    N = rows.shape[1]
    ids = np.arange(N)
    pos = np.full((T, N, 3), np.nan)
    rad = np.full((T, N), np.nan)
    inv_cols = [c for c in tables[0].columns if c[:1] == "R" and c[1:].isdigit()]
    inv = np.full((T, N, len(inv_cols)), np.nan) if inv_cols else None
    for t, tab in enumerate(tables):
        present = rows[t] >= 0
        r = rows[t][present]
        pos[t, present] = tab[["x", "y", "z"]].to_numpy()[r]
        rad[t, present] = tab["radius"].to_numpy()[r]
        if inv is not None:
            inv[t, present] = tab[inv_cols].to_numpy()[r]
    with np.errstate(all="ignore"):
        import warnings
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            radius = np.nanmedian(rad, axis=0)
            shape = np.nanmedian(inv, axis=0) if inv is not None else None
    times = np.arange(T, dtype=float) if times is None else np.asarray(times, float)
    if np.any(~np.isfinite(times)):
        times = np.arange(T, dtype=float)
    controls = {k: np.asarray(v, float) for k, v in (controls or {}).items()}
    m = {"source": "ct", "engine": "ct", "tracking": [L.summary() for L in links],
         "grains_per_scan": [len(t) for t in tables], "shape_columns": inv_cols}
    if voxel_size is not None:
        m["voxel_size"] = float(voxel_size)
    m.update(meta or {})
    with FrameWriter(path, ids, radius, controls=controls.keys(), shape=shape, meta=m) as w:
        for t in range(T):
            k = w.append(float(times[t]), t, controls={c: v[t] for c, v in controls.items()}, position=pos[t])
            if contacts is not None and contacts[t] is not None and len(contacts[t]):
                c = contacts[t]
                lab2id = np.full(int(tables[t]["label"].max()) + 1, -1, np.int64)
                present = rows[t] >= 0
                lab2id[tables[t]["label"].to_numpy()[rows[t][present]]] = ids[present]
                i, j = lab2id[c["i"].to_numpy()], lab2id[c["j"].to_numpy()]
                ok = (i >= 0) & (j >= 0)
                w.write_contacts(k, {"i": i[ok], "j": j[ok], "point": c[["px", "py", "pz"]].to_numpy()[ok],
                                     "normal": c[["nx", "ny", "nz"]].to_numpy()[ok]})
    return Path(path)
