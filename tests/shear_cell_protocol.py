"""The shear-cell smoke run's protocol checks that every engine must pass (tests/test_shear_cell.py
for LIGGGHTS and YADE, tests/test_lammps_shear_cell.py for LAMMPS): one set of assertions, so an
engine cannot pass a weaker copy of them."""
from __future__ import annotations

import json

import h5py
import numpy as np

from orchestrator.psd import max_overlap


def check_smoke_protocol(case, out) -> dict:
    """Assert the smoke run ``out`` of ``case`` kept every grain inside the cell, wrote the frames
    at the requested steps and angles starting from the packing handed over, relaxed without
    overlaps above 1 % of r_min, reached the normal load within 2 % at the end of compression,
    moved the piston into the sample and turned the rotating parts under torque. Returns what it
    read (params, table, frames and wall series) for an engine's own further checks."""
    assert out.status == "complete"
    params = json.loads((out.run_dir / "params.json").read_text())
    sc = params["scene"]
    g = sc["geometry"]
    table = np.loadtxt(out.run_dir / "particles.txt", ndmin=2)
    with h5py.File(out.run_dir / "frames.h5") as h:
        pos = h["frames/position"][:]
        steps = h["frames/step"][:]
        angle = h["frames/angle"][:]
        ids = h["particles/id"][:]
        radius = h["particles/radius"][:]
        lp = {k: h[f"walls/lower_piston/{k}"][:] for k in ("time", "position", "force")}
        rot = {k: h[f"walls/rotating/{k}"][:] for k in ("angle", "torque")}
    # particle count conserved, nobody lost, nobody outside the cell
    order = np.argsort(table[:, 0])
    assert pos.shape[1] == len(table) == sc["n"]
    assert np.array_equal(ids, table[order, 0].astype(int))
    assert np.array_equal(radius, table[order, 1])
    assert np.isfinite(pos).all()
    assert np.hypot(pos[..., 0], pos[..., 1]).max() < g["R_cyl"]
    # between the flanges (the gap pockets reach half a plate thickness behind each face)
    t = case.scene.plate_thickness
    assert pos[..., 2].min() > lp["position"][:, 2].min() - t / 2
    assert pos[..., 2].max() < g["z_upper_face"] + t / 2
    # frames at the requested steps and angles, the first the packing handed over
    assert list(steps) == sc["frame_steps"]
    assert np.allclose(np.degrees(angle[3:]), [1, 2, 3, 4], atol=sc["omega"] * params["dt"] * 180 / np.pi)
    assert np.allclose(pos[0], table[order, 3:6], rtol=0, atol=1e-15)
    # relaxation leaves no overlap above 1 % of r_min
    assert max_overlap(pos[1], table[order, 1]) < 0.01 * case.scene.psd.d_min / 2
    # normal load within 2 % of the target, time-averaged over the end of compression
    chk = json.loads((out.run_dir / "shear_cell_checks.json").read_text())["compression"]
    assert abs(chk["relative_error"]) < 0.02, chk
    # the piston moved up into the sample and the rotating parts carried a torque while shearing
    assert lp["position"][-1, 2] > 0.5 * g["travel_estimate"]
    shear = rot["angle"] > 0
    assert np.abs(rot["torque"][shear, 2]).max() > 0
    return {"params": params, "table": table, "pos": pos, "angle": angle, "lp": lp, "rot": rot, "shear": shear}
