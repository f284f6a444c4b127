"""A scanned (or any frames.h5) packing as the initial particles of a simulation.

A case may say::

    initial_packing:
      frames: ct/frames.h5      # a frames.h5 or a run directory; relative to the case file
      frame: 0                  # frame index (default 0, the first scan)

The grains present in that frame (positions, radii; ids kept, shifted by +1 when a CT id is 0
because LIGGGHTS atom ids must be positive) are written as the run's ``particles.txt`` before the
scene prepares its files, so both engines start from exactly that packing and the particle count
follows the scan. Velocities start at zero. Shapes (SH invariants) are carried in the frames but
the engines' spheres use the equivalent radius.

Each scene keeps its protocol (the shear cell still relaxes, compresses and shears; its walls are
where the case puts them), so the packing must lie inside the scene's container; a grain outside
is an error naming the grain and the wall (an overlap with a wall up to 10 % of the grain's radius
is accepted: segmented radii and centroids carry sub-voxel errors, and loaded grains press into the
walls; the scene's relaxation stage resolves it). Shear cell: inside the sidewall, between the
plate faces or in the gap pockets beside the pistons. A scene whose ``prepare`` generates its own packing
regardless (it rewrote particles.txt) is reported as not supporting ``initial_packing``.
The run hash covers the frames file's content and the frame index.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from .case import CaseError
from .frames import Frames
from .particles_io import read_particle_table, write_particle_table

#: accepted overlap of a scanned grain with a wall, as a fraction of its radius. It must cover
#: the CT equivalent radius of grains in a dense packing, which runs large: +5.7 % on the compare
#: tests' synthetic scans (3 um voxels, 8-17 voxels across, PSF 0.7 voxel), where contact necks go
#: to the grains. It must also cover the grain's own load overlap with the wall and the centroid
#: error. At 0.10, a grain of the smoke shear cell touching the upper plate (3-5 % load overlap)
#: was refused; hence 0.15.
SLACK = 0.15

__all__ = ["load_packing", "packing_digest", "apply_initial_packing", "check_initial_packing"]


def _frames_path(ip) -> Path:
    p = Path(ip.frames)
    return p / "frames.h5" if p.is_dir() else p


def load_packing(ip) -> dict:
    """``{"id", "radius", "position"}`` of the grains present in frame ``ip.frame`` of ``ip.frames``."""
    fr = Frames(_frames_path(ip))
    k = range(fr.n_frames)[ip.frame]
    pos = fr.position[k]
    ok = np.isfinite(pos).all(1) & np.isfinite(fr.radius) & (fr.radius > 0)
    ids = fr.ids[ok].astype(np.int64)
    shift = 0
    if ids.min() <= 0:
        shift = int(1 - ids.min())
        ids = ids + shift
    return {"id": ids, "radius": fr.radius[ok], "position": pos[ok], "id_shift": shift, "frame": k,
            "source": str(fr.path), "n_absent": int((~ok).sum())}


def packing_digest(ip) -> str:
    """sha256 of the packing the run starts from (enters the run hash): the ids, radii and positions
    of the grains :func:`load_packing` takes from the frame, and the id shift. Not of the file's
    bytes: a frames file written again with the same grains (its ``meta.created`` differs) is the
    same initial packing, and the run made from it is reused."""
    return _digest(load_packing(ip))


def _digest(pk: dict) -> str:
    """sha256 of a loaded packing (:func:`packing_digest`)."""
    h = hashlib.sha256()
    for key in ("id", "radius", "position"):
        h.update(np.ascontiguousarray(pk[key], dtype="<i8" if key == "id" else "<f8").tobytes())
    h.update(str(pk["id_shift"]).encode())
    return h.hexdigest()


def check_initial_packing(case, params, pk) -> None:
    """Raise CaseError when a grain lies outside the scene's container."""
    sc = params["scene"]
    x, r = pk["position"], pk["radius"]
    # a scanned grain may press into a wall a little (equivalent radius, centroid error, load)
    r = (1 - SLACK) * r
    problems = []
    if case.scene.kind == "shear_cell":
        g = sc["geometry"]
        rho = np.hypot(x[:, 0], x[:, 1]) + r
        bad = np.nonzero(rho > g["R_cyl"] * (1 + 1e-9))[0]
        if len(bad):
            problems.append(f"initial_packing: {len(bad)} grain(s) reach beyond the sidewall (radius "
                            f"{g['R_cyl']:.4g} m), e.g. id {pk['id'][bad[0]]} at r + radius = {rho[bad[0]]:.4g} m; "
                            "the scan must be in the cell's frame (axis x = y = 0, lower plate face z = 0)")
        # between the plate faces, or in the gap pockets (piston edge - sidewall, closed by the flange
        # one plate thickness behind the face)
        pocket = np.hypot(x[:, 0], x[:, 1]) + r > g["R_piston"]
        depth = np.where(pocket, case.scene.plate_thickness, 0.0)
        lo = np.nonzero(x[:, 2] - r < g["z_lower_face"] - depth - 1e-12)[0]
        hi = np.nonzero(x[:, 2] + r > g["z_upper_face"] + depth + 1e-12)[0]
        if len(lo):
            problems.append(f"initial_packing: {len(lo)} grain(s) below the lower plate face z = 0, e.g. id "
                            f"{pk['id'][lo[0]]} at z - radius = {x[lo[0], 2] - r[lo[0]]:.4g} m")
        if len(hi):
            problems.append(f"initial_packing: {len(hi)} grain(s) above the upper plate face z = "
                            f"{g['z_upper_face']:.4g} m, e.g. id {pk['id'][hi[0]]} at r = "
                            f"{np.hypot(x[hi[0], 0], x[hi[0], 1]):.4g} m, z + radius = {x[hi[0], 2] + r[hi[0]]:.4g} m; "
                            "raise scene.fill_height or "
                            "lower scene.loose_fraction (they set the upper piston's start)")
    elif "box_lo" in sc and "box_hi" in sc:
        lo, hi = np.asarray(sc["box_lo"]), np.asarray(sc["box_hi"])
        bad = np.nonzero(((x - r[:, None]) < lo).any(1) | ((x + r[:, None]) > hi).any(1))[0]
        if len(bad):
            problems.append(f"initial_packing: {len(bad)} grain(s) outside the simulation box {lo.tolist()} .. "
                            f"{hi.tolist()} m, e.g. id {pk['id'][bad[0]]}")
    if problems:
        raise CaseError(case.source or case.name, problems)


def apply_initial_packing(case, params, run_dir) -> dict | None:
    """Write ``particles.txt`` from the case's ``initial_packing`` (no-op without one). Returns the
    packing's summary for params (its ``grains`` the scene's particle count ``n`` from now on)."""
    ip = getattr(case, "initial_packing", None)
    if ip is None:
        return None
    pk = load_packing(ip)
    check_initial_packing(case, params, pk)
    write_particle_table(Path(run_dir) / "particles.txt", pk["id"], pk["radius"], case.material.density,
                         pk["position"])
    return {"source": pk["source"], "frame": pk["frame"], "grains": int(len(pk["id"])), "id_shift": pk["id_shift"],
            "absent_in_frame": pk["n_absent"], "digest": _digest(pk), "_radii": np.sort(pk["radius"])}


def verify_written(case, run_dir, info) -> None:
    """After the scene's prepare: particles.txt must still be the packing (else the scene ignored it)."""
    t = read_particle_table(Path(run_dir) / "particles.txt")
    pk = info.pop("_radii", None)
    if len(t["id"]) != info["grains"] or (pk is not None and not np.allclose(np.sort(t["radius"]), pk)):
        raise CaseError(case.source or case.name, [
            f"initial_packing: scene '{case.scene.kind}' generates its own packing and does not accept a scanned "
            "one yet; remove initial_packing or use the shear_cell scene"])
