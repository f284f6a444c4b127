"""A clump sample's grains from its member spheres: the one place where the frames of a clump run
become frames of grains, so that every analysis counts grains, not the spheres they are built of.

An engine integrates each clump as a rigid body but writes its member spheres (``frames.h5`` holds
one row per member; ``clumps.txt`` in the run directory maps each member id to its clump). An
analysis that took those rows for grains would measure the clump's own geometry: g(r) would peak
at the members' spacing, D²min would read a clump's rotation as non-affine motion of its members,
a grain touching a neighbour through two members would count two contacts, and Love–Weber's stress
would leave out the forces that hold the members together. :func:`clump_frames` turns the members
into one particle per clump, the way freud's ``NeighborQuery.from_system`` adapts other formats:

- **position**: the centre of mass of the union of the members (seed 001 tracks CT grains by their
  centroids, §2.2). The union's centre is integrated once, in the reference frame (the first frame
  that holds every member; :func:`orchestrator.clumps.union_properties`, 40³ grid per clump), and
  carried by each clump's rigid motion, fitted to its members frame by frame (Kabsch 1976; exact
  for a rigid body, whatever the shape: two collinear members leave the turn about their axis
  undetermined, which does not move a centre on that axis).
- **orientation**: the turn since the reference frame, a unit quaternion (w, x, y, z).
- **radius**: the volume-equivalent radius (3V/4π)^(1/3) of the union, so that a grain's sphere
  volume is its solid volume (the equivalent radius of a CT grain, seed 001 §2.2).
- **velocity**, **angular_velocity**: the rigid-body fit of the member velocities v_i = v + ω × (x_i − x),
  least squares: (Σ |d|² I − d dᵀ) ω = Σ d × (v_i − v̄), d = x_i − x̄ (exact for a rigid body; the
  spin about the axis of a row of members, which the members' centres do not show, reads 0, as does
  a one-sphere clump's). When the frames hold the members' ``angular_velocity``, ω is their mean
  (exact: every member of a rigid body spins with it).
- **mass**: the members' density times the union's volume [kg].
- **contacts**: every member contact between two clumps, with i and j the clumps' grain ids (wall
  ids stay negative), its point, normal and forces as the engine wrote them, and the two member
  spheres' radii as ``radius_i`` and ``radius_j`` (a contact's Hertz energy depends on the members
  that touch, :mod:`orchestrator.analysis.energy`). Several contacts may join the same two grains;
  :func:`orchestrator.analysis.coordination.coordination_from_pairs` counts a neighbour once.
- **stress**: Love–Weber's grain stress σ = (1/V) Σ_c (x_c − x) ⊗ f_c over the grain's contact
  points (:func:`orchestrator.analysis.stress.love_weber_stress`, V the union's volume), in every
  frame with contacts (NaN rows in a frame without): the members' own ``stress`` field (their
  per-atom virials) leaves out the forces that hold a clump together. ``force`` and ``torque``
  are dropped.
- time, steps, controls, walls and meta are the members' frames'.

Grain ids are 1 + the clump index of ``clumps.txt`` (0 ... n − 1). Units SI.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from .analysis.neighbors import contacts_to_rows
from .analysis.stress import love_weber_stress
from .clumps import union_properties
from .frames import Frames

__all__ = ["read_clump_map", "clump_frames", "frames_for_analysis", "rigid_fits"]

#: grid cells per union edge for the centre of mass and volume (orchestrator.clumps.mass_properties)
UNION_CELLS = 40


def read_clump_map(run_dir) -> np.ndarray | None:
    """``clumps.txt`` of a run directory as (M, 2) int64 rows (member id, clump index); None when
    the run has no clumps."""
    f = Path(run_dir) / "clumps.txt"
    if not f.exists():
        return None
    try:
        rows = np.loadtxt(f, ndmin=2, comments="#", dtype=np.int64)
    except ValueError as exc:
        raise ValueError(f"{f}: not a clump map ({exc}); it lists one member sphere a line: "
                         "member id, clump index (integers), as the run wrote it") from None
    if rows.shape[1] != 2:
        raise ValueError(f"{f}: expected two columns (member id, clump index), got {rows.shape[1]}")
    return rows


def frames_for_analysis(run_dir) -> Frames:
    """The frames the analyses read for a run directory (or its ``frames.h5``): its frames, or, for
    a clump sample (a ``clumps.txt`` beside them), the grains built from them (:func:`clump_frames`)."""
    path = Path(run_dir)
    fr = Frames(path)
    rows = read_clump_map(path.parent if path.is_file() else path)
    return fr if rows is None else clump_frames(fr, rows[:, 0], rows[:, 1])


def _segment_sums(values: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Sums over consecutive segments of axis 0 that begin at ``starts``."""
    return np.add.reduceat(values, starts, axis=0)


def rigid_fits(ref: np.ndarray, cur: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Rotations R (n, 3, 3) taking each segment of ``ref`` (M, 3) [m] onto the same segment of
    ``cur`` about the segments' means, in the least-squares sense (Kabsch 1976, with the sign fix
    that keeps R a proper rotation): cur_i − c̄ ≈ R (ref_i − r̄). Segments begin at ``starts``. A
    segment whose points lie on a line fixes no turn about it: R is the smallest rotation that takes
    its line onto the new one (the identity for one point, or for a line that has not moved)."""
    counts = np.diff(np.r_[starts, len(ref)])
    a = ref - np.repeat(_segment_sums(ref, starts) / counts[:, None], counts, axis=0)
    b = cur - np.repeat(_segment_sums(cur, starts) / counts[:, None], counts, axis=0)
    H = _segment_sums(a[:, :, None] * b[:, None, :], starts)          # Σ a bᵀ per segment
    U, S, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.einsum("nji,nkj->nik", Vt, U)))
    d[d == 0] = 1.0
    D = np.zeros_like(H)
    D[:, 0, 0] = D[:, 1, 1] = 1.0
    D[:, 2, 2] = d
    R = np.einsum("nji,njk,nlk->nil", Vt, D, U)                        # V D Uᵀ
    line = S[:, 1] <= 1e-9 * S[:, 0]
    R[line] = _align(U[line, :, 0], Vt[line, 0, :])
    R[S[:, 0] == 0] = np.eye(3)
    return R


def _align(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Smallest rotations (n, 3, 3) taking unit vectors ``u`` (n, 3) onto ``v`` (Rodrigues:
    R = I + [w]ₓ + [w]ₓ² / (1 + u·v), w = u × v; half a turn about a perpendicular when v = −u)."""
    w = np.cross(u, v)
    c = np.einsum("ni,ni->n", u, v)
    K = np.zeros((len(u), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = w[:, 2], -w[:, 1], w[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        R = np.eye(3) + K + np.einsum("nij,njk->nik", K, K) / (1.0 + c)[:, None, None]
    back = c < -1 + 1e-12
    if back.any():
        p = np.cross(u[back], np.where(np.abs(u[back, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
        p /= np.linalg.norm(p, axis=1)[:, None]
        R[back] = 2 * p[:, :, None] * p[:, None, :] - np.eye(3)
    return R


def _rigid_velocity(x: np.ndarray, v: np.ndarray, starts: np.ndarray, centre: np.ndarray, spin=None):
    """(velocity of ``centre`` (n, 3) [m/s], angular velocity (n, 3) [rad/s]) of each segment's
    rigid motion fitted to member positions ``x`` and velocities ``v`` (M, 3); ``spin`` (M, 3), the
    members' angular velocities when known, gives ω as their mean."""
    counts = np.diff(np.r_[starts, len(x)])
    xm = _segment_sums(x, starts) / counts[:, None]
    vm = _segment_sums(v, starts) / counts[:, None]
    if spin is not None:
        w = _segment_sums(spin, starts) / counts[:, None]
    else:
        d = x - np.repeat(xm, counts, axis=0)
        A = _segment_sums(np.einsum("mk,mk->m", d, d)[:, None, None] * np.eye(3) - d[:, :, None] * d[:, None, :], starts)
        b = _segment_sums(np.cross(d, v - np.repeat(vm, counts, axis=0)), starts)
        w = np.einsum("nij,nj->ni", np.linalg.pinv(A, hermitian=True), b)
    return vm + np.cross(w, centre - xm), w


def clump_frames(frames: Frames, member_ids, clump) -> Frames:
    """Frames of grains, one per clump, from the frames of their member spheres (module docstring).

    ``member_ids`` (M,) and ``clump`` (M,): the clump index (0 ... n − 1) of each member id, as
    ``clumps.txt`` lists them; every particle of ``frames`` must be a member.
    """
    member_ids = np.asarray(member_ids, np.int64)
    clump = np.asarray(clump, np.int64)
    owner = dict(zip(member_ids.tolist(), clump.tolist()))
    missing = [int(i) for i in frames.ids if int(i) not in owner]
    if missing:
        raise ValueError(f"{frames.path}: {len(missing)} particles are in no clump of the clump map "
                         f"(first ids {missing[:5]}); the map (clumps.txt) must list every member sphere")
    g_of_row = np.array([owner[int(i)] for i in frames.ids], np.int64)
    labels, g_of_row = np.unique(g_of_row, return_inverse=True)
    order = np.argsort(g_of_row, kind="stable")                       # member rows grouped by clump
    gsorted = g_of_row[order]
    starts = np.flatnonzero(np.r_[True, np.diff(gsorted) != 0])
    n = len(labels)
    pos = frames.position[:, order]                                     # (T, M, 3)
    r = frames.radius[order]
    whole = ~np.isnan(pos).any(axis=2)
    full = np.flatnonzero(whole.all(axis=1))
    if not len(full):
        raise ValueError(f"{frames.path}: no frame holds every member sphere; a clump's centre needs them all")
    k0 = int(full[0])
    spheres = np.column_stack([pos[k0], r])
    props = [union_properties(spheres[a:b], UNION_CELLS) for a, b in zip(starts, np.r_[starts[1:], len(r)])]
    volume = np.array([p["volume"] for p in props])
    centre0 = np.array([p["center"] for p in props])
    counts = np.diff(np.r_[starts, len(r)])
    mean0 = _segment_sums(pos[k0], starts) / counts[:, None]
    T = frames.n_frames
    position = np.full((T, n, 3), np.nan)
    orientation = np.full((T, n, 4), np.nan)
    fields = {}
    vel = frames.velocity[:, order] if "velocity" in frames.fields else None
    spin = frames.angular_velocity[:, order] if "angular_velocity" in frames.fields else None
    if vel is not None:
        fields["velocity"] = np.full((T, n, 3), np.nan)
        fields["angular_velocity"] = np.full((T, n, 3), np.nan)
    for k in range(T):
        ok = _segment_sums(whole[k].astype(np.int64), starts) == counts   # clumps with every member here
        R = rigid_fits(pos[k0], np.nan_to_num(pos[k]), starts)
        mean = _segment_sums(np.nan_to_num(pos[k]), starts) / counts[:, None]
        c = mean + np.einsum("nij,nj->ni", R, centre0 - mean0)
        position[k, ok] = c[ok]
        if ok.any():
            orientation[k, ok] = Rotation.from_matrix(R[ok]).as_quat()[:, [3, 0, 1, 2]]   # (w, x, y, z)
        if vel is not None:
            v, w = _rigid_velocity(np.nan_to_num(pos[k]), np.nan_to_num(vel[k]), starts, c,
                                   None if spin is None else np.nan_to_num(spin[k]))
            fields["velocity"][k, ok] = v[ok]
            fields["angular_velocity"][k, ok] = w[ok]
    mass = None
    if frames.mass is not None:
        density = float(np.median(frames.mass / (4.0 / 3.0 * np.pi * frames.radius ** 3)))
        mass = density * volume
    grain_ids = labels + 1
    grain_of_row = labels[g_of_row] + 1                                 # grain id of each member row
    contacts = {k: _grain_contacts(frames, frames.contact_arrays(k), grain_of_row) for k in frames.contact_frames}
    radius = (3.0 * volume / (4.0 * np.pi)) ** (1.0 / 3.0)
    if contacts:
        fields["stress"] = np.full((T, n, 3, 3), np.nan)
        for k, c in contacts.items():
            if "point" not in c:            # a grain's stress needs where its contacts are, not its centre's
                continue
            i, j = contacts_to_rows(grain_ids, c["i"], c["j"])
            f = np.asarray(c["fn"], float) + (np.asarray(c["ft"], float) if "ft" in c else 0.0)
            fields["stress"][k] = love_weber_stress(position[k], radius, i, j, c["point"], f)
    meta = dict(frames.meta)
    meta["grains"] = (f"{n} clumps of {len(r)} member spheres (orchestrator.grains.clump_frames): centre of "
                      f"mass, volume-equivalent radius, rigid-body velocities, contacts between clumps")
    return Frames.from_arrays(position, radius, time=frames.time,
                              ids=grain_ids, controls=frames.controls, meta=meta, mass=mass, step=frames.step,
                              contacts=contacts, walls={w: frames.wall(w) for w in frames.wall_names},
                              orientation=orientation, **fields)


def _grain_contacts(frames: Frames, c: dict, grain_of_row: np.ndarray) -> dict:
    """One frame's member contacts ``c`` with i, j replaced by grain ids (walls, negative ids, kept),
    the members' radii [m] as ``radius_i`` / ``radius_j`` (NaN for a wall), contacts inside a clump
    dropped. ``grain_of_row``: the grain id of each particle row of ``frames``."""
    ci, cj = np.asarray(c["i"], np.int64), np.asarray(c["j"], np.int64)
    ri, rj = contacts_to_rows(frames, ci, cj)
    if ((ri < 0) & (ci >= 0)).any() or ((rj < 0) & (cj >= 0)).any():
        raise ValueError("a contact names a particle id that is neither a member sphere nor a wall (negative id)")
    gi = np.where(ri >= 0, grain_of_row[ri], ci)
    gj = np.where(rj >= 0, grain_of_row[rj], cj)
    keep = gi != gj
    out = {key: np.asarray(a)[keep] for key, a in c.items()}
    out["i"], out["j"] = gi[keep], gj[keep]
    out["radius_i"] = np.where(ri >= 0, frames.radius[ri], np.nan)[keep]
    out["radius_j"] = np.where(rj >= 0, frames.radius[rj], np.nan)[keep]
    return out
