"""A clump sample's grains from its member spheres (orchestrator.grains): rigid motions recovered
exactly, an affine deformation of turning clumps reads as affine (D²min zero) on grains and not on
members, a neighbour touched at two points counts once, contacts keep the members' radii, and the
analyses read grains whenever a run holds clumps."""
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from orchestrator.analysis import run_analyses
from orchestrator.analysis.coordination import analyze_coordination
from orchestrator.analysis.d2min import d2min
from orchestrator.analysis.energy import hertz_normal_energy
from orchestrator.analysis.stress import particle_stress
from orchestrator.frames import Frames, write_frames
from orchestrator.grains import clump_frames, frames_for_analysis, rigid_fits

R0 = 1e-4          # member radius scale [m]
# shapes in their own frame (x, y, z, r) [m] whose union's centre of mass is the origin by symmetry:
# one sphere, a dumbbell, a regular tetrahedron of four spheres, a row of three with a larger middle
SHAPES = [
    np.array([[0, 0, 0, 1.0]]) * R0,
    np.array([[-0.8, 0, 0, 1.0], [0.8, 0, 0, 1.0]]) * R0,
    np.array([[1, 1, 1, 0.9], [1, -1, -1, 0.9], [-1, 1, -1, 0.9], [-1, -1, 1, 0.9]]) * (0.6 * R0, 0.6 * R0, 0.6 * R0, R0),
    np.array([[-1.2, 0, 0, 0.7], [0, 0, 0, 1.1], [1.2, 0, 0, 0.7]]) * R0,
]


def _sample(n_side=3, spacing=8 * R0, seed=0):
    """Clumps on a lattice (centres of mass ``c`` (n, 3)), each one of SHAPES turned by ``rot``;
    the members' (ids, clump index, local offsets (M, 3), radii (M,))."""
    rng = np.random.default_rng(seed)
    g = np.arange(n_side) * spacing
    c = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3) + rng.normal(0, 0.3 * R0, (n_side ** 3, 3))
    kind = np.arange(len(c)) % len(SHAPES)
    rot = Rotation.random(len(c), random_state=seed)
    local = [SHAPES[k][:, :3] for k in kind]
    clump = np.concatenate([np.full(len(l), i) for i, l in enumerate(local)])
    radius = np.concatenate([SHAPES[k][:, 3] for k in kind])
    ids = np.arange(1, len(clump) + 1) * 3 + 7          # member ids need not be 1..M
    return c, rot, local, clump, radius, ids


def _members(c, rot, local):
    return np.concatenate([r.apply(l) + ci for ci, r, l in zip(c, rot, local)])


def _deformed_run(T=3, seed=0):
    """Member frames of the lattice under a growing affine deformation of the centres of mass while
    every clump turns by a large random rotation; member velocities of a rigid motion per clump.
    Returns (member Frames, clump map, true centres (T, n, 3), true velocities, true spins)."""
    c, rot, local, clump, radius, ids = _sample(seed=seed)
    rng = np.random.default_rng(seed + 1)
    pos, vel, centres, vc, wc = [], [], [], [], []
    for t in range(T):
        F = np.eye(3) + t * np.array([[0.02, 0.0, 0.05], [0.0, -0.01, 0.0], [0.0, 0.0, -0.04]])
        ct = c @ F.T
        rt = Rotation.random(len(c), random_state=seed + 10 + t) * rot
        v = rng.normal(0, 0.1, (len(c), 3))
        w = rng.normal(0, 500.0, (len(c), 3))
        x = _members(ct, rt, local)
        pos.append(x)
        vel.append(v[clump] + np.cross(w[clump], x - ct[clump]))
        centres.append(ct), vc.append(v), wc.append(w)
    mass = 2500.0 * 4 / 3 * np.pi * radius ** 3
    fr = Frames.from_arrays(np.array(pos), radius, time=np.arange(T) * 1e-3, ids=ids, mass=mass,
                            velocity=np.array(vel))
    return fr, (ids, clump), np.array(centres), np.array(vc), np.array(wc)


def test_rigid_fits_recover_known_rotations():
    rng = np.random.default_rng(3)
    ref = rng.normal(size=(12, 3))
    starts = np.array([0, 4, 9])
    Rs = Rotation.random(3, random_state=4).as_matrix()
    cur = np.concatenate([ref[a:b] @ R.T + rng.normal(size=3) for (a, b), R in zip([(0, 4), (4, 9), (9, 12)], Rs)])
    assert np.allclose(rigid_fits(ref, cur, starts), Rs, atol=1e-12)
    # proper rotations only: a mirrored segment is fitted by a rotation, not the reflection
    R = rigid_fits(ref, cur * [1, 1, -1], starts)
    assert np.allclose(np.linalg.det(R), 1.0)


def test_grains_follow_the_clumps_rigid_motion():
    fr, (ids, clump), centres, vc, wc = _deformed_run()
    g = clump_frames(fr, ids, clump)
    assert g.n_particles == len(centres[0]) and list(g.ids) == list(range(1, len(centres[0]) + 1))
    # centres of mass: the union's, integrated on a 40³ grid once, then carried by the fitted motion
    assert np.abs(g.position - centres).max() < 2e-3 * R0
    # velocity of the centre and spin: the rigid-body fit is exact (the centre's grid error enters v only)
    # (the members' positions and velocities fix a clump's spin but for the turn about the axis of a
    # row of members: zero there, the least-squares fit's smallest answer; a single sphere's spin: 0)
    kind = np.arange(len(wc[0])) % len(SHAPES)
    axis = np.array([1.0, 0, 0])
    for t in range(len(wc)):
        turn = Rotation.random(len(wc[0]), random_state=10 + t) * _sample()[1]
        for n, k in enumerate(kind):
            w = wc[t, n]
            if k in (1, 3):
                a = turn[n].apply(axis)
                w = w - a * (w @ a)
            elif k == 0:
                w = np.zeros(3)
            assert np.allclose(g.angular_velocity[t, n], w, rtol=1e-9, atol=1e-9 * np.abs(wc).max())
    assert np.abs(g.velocity - vc).max() < 1e-2 * R0 * np.abs(wc).max()
    # the volume-equivalent radius: the union's volume (one sphere: its own radius)
    assert g.radius[0] == pytest.approx(R0, rel=2e-3)
    assert g.radius[1] > R0 and g.radius[1] < 2 ** (1 / 3) * R0          # two overlapping spheres
    assert g.mass[0] == pytest.approx(2500.0 * 4 / 3 * np.pi * R0 ** 3, rel=5e-3)
    # orientation: the turn since frame 0, unit quaternions, identity at frame 0
    assert np.allclose(np.linalg.norm(g.orientation, axis=2), 1.0)
    assert np.allclose(np.abs(g.orientation[0, :, 0]), 1.0)


def test_affine_deformation_of_turning_clumps_is_affine_on_grains_only():
    """D²min (seed 001 eq. 9) of an affine deformation whose clumps also turn: zero on the grains'
    centres, not on the members (whose turning reads as non-affine motion)."""
    fr, (ids, clump), centres, _, _ = _deformed_run()
    g = clump_frames(fr, ids, clump)
    on_grains = d2min(g.position[0], g.position[2], cutoff=9 * R0)["d2min"]
    on_members = d2min(fr.position[0], fr.position[2], cutoff=9 * R0)["d2min"]
    ok = np.isfinite(on_grains)
    assert ok.sum() >= 20
    assert np.nanmax(on_grains) < (2e-3 * R0) ** 2 * 10
    assert np.nanmedian(on_members) > 1e3 * np.nanmax(on_grains)


def _two_dumbbells():
    """Two dumbbells side by side whose members touch pairwise (two contact points between the two
    grains), the first also touching the bottom wall (id -1) through one member."""
    r = R0
    x = np.array([[0, 0, 0], [1.6 * r, 0, 0], [0, 0, 2 * r], [1.6 * r, 0, 2 * r]], float)
    radius = np.array([r, r, 0.9 * r, 0.9 * r])
    ids = np.array([1, 2, 3, 4])
    clump = np.array([0, 0, 1, 1])
    f = np.array([0, 0, -1.0])                        # force on i (lower member) from j (above)
    c = {"i": np.array([1, 2, 1]), "j": np.array([3, 4, -1]),
         "point": np.array([[0, 0, r], [1.6 * r, 0, r], [0, 0, -r]]),
         "normal": np.array([[0, 0, 1.0], [0, 0, 1.0], [0, 0, -1.0]]),
         "fn": np.array([f, f, [0, 0, 2.0]]), "ft": np.zeros((3, 3))}
    fr = Frames.from_arrays(x[None], radius, ids=ids, mass=2500.0 * 4 / 3 * np.pi * radius ** 3,
                            contacts={0: c})
    return fr, ids, clump


def test_contacts_between_grains_count_a_neighbour_once_and_keep_member_radii():
    fr, ids, clump = _two_dumbbells()
    g = clump_frames(fr, ids, clump)
    c = g.contact_arrays(0)
    assert list(c["i"]) == [1, 1, 1] and list(c["j"]) == [2, 2, -1]
    assert np.allclose(c["radius_i"], R0) and np.allclose(c["radius_j"][:2], 0.9 * R0) and np.isnan(c["radius_j"][2])
    z = analyze_coordination(g, source="contacts").tables["particles"]
    assert list(z["z"]) == [1, 1]                      # two contact points, one neighbour
    zw = analyze_coordination(g, source="contacts", include_walls=True).tables["particles"]
    assert list(zw["z"]) == [2, 1]
    # the Hertz energy of a member contact uses the members' radii, not the grains' equivalent ones
    e = hertz_normal_energy(np.ones(2), c["radius_i"][:2], c["radius_j"][:2], 1e9)
    assert np.allclose(e, hertz_normal_energy(np.ones(2), [R0, R0], [0.9 * R0, 0.9 * R0], 1e9))
    assert not np.allclose(e, hertz_normal_energy(np.ones(2), g.radius[[0, 0]], g.radius[[1, 1]], 1e9))


def test_love_weber_stress_of_a_grain_uses_its_centre_and_every_contact_point():
    fr, ids, clump = _two_dumbbells()
    g = clump_frames(fr, ids, clump)
    s = particle_stress(g, 0)
    # grain 1 (lower dumbbell, centre (0.8 r, 0, 0)): forces (0, 0, -1) N at (0, 0, r) and (1.6 r, 0, r)
    # from grain 2, (0, 0, 2) N at (0, 0, -r) from the wall: σ = Σ (x_c − x) ⊗ f / V
    x = g.position[0, 0]
    pts = np.array([[0, 0, R0], [1.6 * R0, 0, R0], [0, 0, -R0]])
    fs = np.array([[0, 0, -1.0], [0, 0, -1.0], [0, 0, 2.0]])
    want = sum(np.outer(p - x, f) for p, f in zip(pts, fs)) / (4 / 3 * np.pi * g.radius[0] ** 3)
    assert np.allclose(s[0], want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
    assert s[0, 2, 2] < 0                               # compressed along z


def test_frames_for_analysis_reads_grains_when_the_run_has_clumps(tmp_path):
    fr, (ids, clump), centres, _, _ = _deformed_run()
    write_frames(tmp_path / "frames.h5", fr.ids, fr.radius, fr.time, fr.position, mass=fr.mass,
                 velocity=fr.velocity, controls={"axial_strain": np.array([0.0, 0.01, 0.02])})
    plain = frames_for_analysis(tmp_path)
    assert plain.n_particles == len(ids)               # no clumps.txt: the spheres themselves
    (tmp_path / "clumps.txt").write_text("# member_id clump\n" + "".join(f"{i} {c}\n" for i, c in zip(ids, clump)))
    g = frames_for_analysis(tmp_path)
    assert g.n_particles == len(centres[0]) and "grains" in g.meta
    assert np.allclose(g.axial_strain, [0.0, 0.01, 0.02])
    out = run_analyses(g, ["rdf", {"d2min": {"cutoff": 9 * R0}}], tmp_path / "analysis", plots=False)
    assert all(e["status"] == "ok" for e in out.values()), json.dumps(out, default=str)[:2000]
    with pytest.raises(ValueError, match="in no clump"):
        clump_frames(fr, ids[1:], clump[1:])
    (tmp_path / "clumps.txt").write_text("member clump\n1 x\n")
    with pytest.raises(ValueError, match="clumps.txt: not a clump map"):
        frames_for_analysis(tmp_path)


def test_analyze_redoes_a_complete_clump_run_on_grains_and_keeps_its_record(tmp_path, capsys):
    """`orchestrator analyze RUN_DIR` on a complete run: its analyses on grains, and the run's summary
    and integrity record follow them (the next `orchestrator run` reuses them instead of reading the
    changed files as damage)."""
    from orchestrator.cli import main
    from orchestrator.integrity import run_record, verify_run
    fr, (ids, clump), centres, _, _ = _deformed_run()
    write_frames(tmp_path / "frames.h5", fr.ids, fr.radius, fr.time, fr.position, mass=fr.mass, velocity=fr.velocity)
    (tmp_path / "clumps.txt").write_text("# member_id clump\n" + "".join(f"{i} {c}\n" for i, c in zip(ids, clump)))
    (tmp_path / "case.yaml").write_text("analysis: [rdf]\n")
    (tmp_path / "summary.json").write_text(json.dumps({"status": "complete", "integrity": run_record(tmp_path)}))
    assert main(["analyze", str(tmp_path)]) == 0
    capsys.readouterr()
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["analysis_specs"] == ["rdf"] and summary["analysis"]["rdf"]["status"] == "ok"
    assert verify_run(tmp_path, summary) == []
    assert "analysis/rdf_rdf.csv" in summary["integrity"]
    # g(r) of the grains: no pair closer than two grains' equivalent radii at contact would allow
    # (on the members it would peak inside one clump, at the member spacing)
    import pandas as pd
    g = pd.read_csv(tmp_path / "analysis" / "rdf_rdf.csv")
    first = g.loc[g["g"] > 0, "r"].min()
    assert first > 4 * R0
