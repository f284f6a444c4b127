"""The particle table the orchestrator samples once and hands identically to both engines.

Plain text, one particle per line: ``id radius density x y z vx vy vz`` in SI, written
atomically. YADE reads it with ``numpy.loadtxt``; the LIGGGHTS adapter turns it into a
``read_data`` file.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

HEADER = "id radius[m] density[kg/m^3] x[m] y[m] z[m] vx[m/s] vy[m/s] vz[m/s]"


def write_particle_table(path, ids, radius, density, position, velocity=None) -> Path:
    """Write the table atomically; scalars broadcast over particles."""
    ids = np.asarray(ids, dtype=np.int64)
    n = len(ids)
    radius = np.broadcast_to(np.asarray(radius, dtype=float), (n,))
    density = np.broadcast_to(np.asarray(density, dtype=float), (n,))
    position = np.asarray(position, dtype=float).reshape(n, 3)
    velocity = np.zeros((n, 3)) if velocity is None else np.asarray(velocity, dtype=float).reshape(n, 3)
    table = np.column_stack([ids, radius, density, position, velocity])
    path = Path(path)
    tmp = path.with_name(path.name + ".partial")
    np.savetxt(tmp, table, fmt=["%d"] + ["%.17g"] * 8, header=HEADER)
    os.replace(tmp, path)
    return path


def read_particle_table(path) -> dict:
    """``particles.txt`` as arrays: id, radius [m], density [kg/m³], position [m], velocity [m/s],
    and each sphere's mass ρ 4/3 π r³ [kg] (what every adapter writes into frames.h5)."""
    a = np.loadtxt(path, ndmin=2)
    return {"id": a[:, 0].astype(np.int64), "radius": a[:, 1], "density": a[:, 2],
            "position": a[:, 3:6], "velocity": a[:, 6:9], "mass": a[:, 2] * 4 / 3 * np.pi * a[:, 1] ** 3}


def ensure_particle_table(run_dir, case, sample) -> Path:
    """``run_dir/particles.txt``, written from ``sample()`` (a dict with id, radius, position) unless
    it exists already (a resumed run, or a packing given by the case); engine adapters derive
    their own input from it (LIGGGHTS' read_data file is written by its adapter)."""
    table = Path(run_dir) / "particles.txt"
    if not table.exists():
        parts = sample()
        write_particle_table(table, parts["id"], parts["radius"], case.material.density, parts["position"],
                             parts.get("velocity"))
    return table
