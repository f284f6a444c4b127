"""Clumps from a shape library (issue 4): library validation, the union's mass properties against
closed forms, placement, the triaxial case option, LIGGGHTS' substitute ``inserted_clumps`` (refused
without it), and short YADE and LIGGGHTS triaxial runs with clumps whose bodies stay rigid and
whose engine mass and inertia match the union integrated here."""
from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from engines.lammps_dump import read_binary_dump
from engines.liggghts.segments import dump_segments
from orchestrator.case import load_case
from orchestrator.clumps import (LibraryError, bounding_radius, equivalent_scale, load_library,
                                 mass_properties, place, random_quaternions)

REPO = Path(__file__).resolve().parents[1]
SMOKE = REPO / "cases" / "triaxial_smoke.yaml"
LIB = REPO / "tests" / "data" / "clumps_smoke.yaml"
#: the smoke triaxial on 100 inserted clumps of LIB, 3 isotropic chunks at most, 1 % axial strain
SMOKE_CLUMPS = REPO / "tests" / "data" / "triaxial_smoke_clumps.yaml"


def test_library_formats_and_errors(tmp_path):
    shapes = load_library(LIB)
    assert [len(s) for s in shapes] == [2, 3, 4]
    # NPZ: the same shapes
    sp = np.vstack(shapes)
    idx = np.concatenate([np.full(len(s), k) for k, s in enumerate(shapes)])
    np.savez(tmp_path / "lib.npz", spheres=sp, shape=idx)
    again = load_library(tmp_path / "lib.npz")
    assert all(np.array_equal(a, b) for a, b in zip(shapes, again))
    bad = tmp_path / "bad.yaml"
    bad.write_text("shapes:\n  - spheres: [[0, 0, 0, 1], [5, 0, 0, 1]]\n")
    with pytest.raises(LibraryError, match="shape 0: 1 of 2 spheres do not touch"):
        load_library(bad)
    bad.write_text("shapes:\n  - spheres: [[0, 0, 0, -1]]\n")
    with pytest.raises(LibraryError, match="radius is not positive"):
        load_library(bad)
    with pytest.raises(LibraryError, match="not found"):
        load_library(tmp_path / "missing.yaml")


def test_mass_properties_against_closed_forms():
    # one sphere: V = 4/3 pi r^3, I = 2/5 m r^2
    mp = mass_properties(np.array([[0.3, -0.2, 0.1, 1.0]]), density=2.0, cells=80)
    V = 4 / 3 * math.pi
    assert mp["volume"] == pytest.approx(V, rel=3e-3)
    assert np.allclose(mp["center"], [0.3, -0.2, 0.1], atol=1e-3)
    assert np.allclose(mp["inertia"], 0.4 * 2.0 * V * np.eye(3), rtol=1e-2, atol=1e-2)
    # two equal overlapping spheres: union = 2 V - lens, lens = pi (4r + d)(2r - d)^2 / 12
    r, d = 1.0, 1.2
    mp2 = mass_properties(np.array([[0, 0, 0, r], [d, 0, 0, r]]), cells=80)
    lens = math.pi * (4 * r + d) * (2 * r - d) ** 2 / 12
    assert mp2["volume"] == pytest.approx(2 * V - lens, rel=3e-3)
    assert mp2["center"][0] == pytest.approx(d / 2, abs=2e-3)
    # elongated along x: smallest principal moment about x
    I = mp2["inertia"]
    assert I[0, 0] < I[1, 1] and I[1, 1] == pytest.approx(I[2, 2], rel=1e-2)


def test_mass_properties_disk_cache_returns_the_integration_exactly(tmp_path, monkeypatch):
    # a later process reads the stored integration: the same doubles, array for array
    import orchestrator.clumps as clumps
    monkeypatch.setenv("ORCHESTRATOR_CACHE", str(tmp_path))
    monkeypatch.setattr(clumps, "_MASS_CACHE", {})
    s = np.array([[0.0, 0.1, 0.0, 0.7], [0.9, 0.0, 0.2, 0.5]])
    fresh = mass_properties(s, density=2650.0, cells=40)
    assert len(list((tmp_path / "clump_mass").glob("*.json"))) == 1
    monkeypatch.setattr(clumps, "_MASS_CACHE", {})
    monkeypatch.setattr(clumps, "_mass_properties", lambda *a: pytest.fail("integrated again"))
    stored = mass_properties(s, density=2650.0, cells=40)
    assert stored.keys() == fresh.keys()
    for k in fresh:
        assert np.array_equal(np.asarray(stored[k]), np.asarray(fresh[k])), k


def test_place_is_a_rigid_scaled_motion():
    rng = np.random.default_rng(3)
    for sh in load_library(LIB):
        mp = mass_properties(sh)
        d = 0.5e-3
        s = equivalent_scale(sh, d, mp["volume"])
        q = random_quaternions(1, rng)[0]
        assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-12)
        w = place(sh, [1e-3, 2e-3, 3e-3], s, q, mp["center"])
        # distances between members scale by s exactly; radii too
        D0 = np.linalg.norm(sh[:, None, :3] - sh[None, :, :3], axis=2)
        D1 = np.linalg.norm(w[:, None, :3] - w[None, :, :3], axis=2)
        assert np.allclose(D1, s * D0, rtol=1e-12, atol=1e-15)
        mw = mass_properties(w)
        assert mw["volume"] == pytest.approx(math.pi / 6 * d ** 3, rel=1e-2)   # volume-equivalent diameter
        assert np.allclose(mw["center"], [1e-3, 2e-3, 3e-3], atol=1e-2 * d)
        # principal moments scale by s^5 (rotation leaves them unchanged)
        assert np.allclose(mw["principal"], mp["principal"] * s ** 5, rtol=3e-2)
        assert bounding_radius(w, mw["center"]) >= d / 2


def _clump_case(**extra):
    scene = {"particles": {"shape": "clumps", "library": str(LIB)}}
    scene.update(extra)
    return load_case(SMOKE, overrides={"scene": scene})


def test_case_option_is_validated(tmp_path):
    with pytest.raises(Exception, match="needs particles.library"):
        load_case(SMOKE, overrides={"scene": {"particles": {"shape": "clumps"}}})
    with pytest.raises(Exception, match="not found"):
        load_case(SMOKE, overrides={"scene": {"particles": {"shape": "clumps", "library": str(tmp_path / "x.yaml")}}})
    with pytest.raises(Exception, match="only used with particles.shape: clumps"):
        load_case(SMOKE, overrides={"scene": {"particles": {"library": str(LIB)}}})
    case = _clump_case()
    from orchestrator.scenes.triaxial import required_features, size_range
    assert "placed_clumps" in required_features(case)
    # the time step follows the smallest member sphere, smaller than the smallest grain
    assert size_range(case)[0] < case.scene.psd.bounds()[0] / 2


def test_library_path_is_relative_to_the_case_file(tmp_path):
    """scene.particles.library names a file beside the case that sets it (as extends: does), not
    one relative to the working directory."""
    (tmp_path / "shapes").mkdir()
    (tmp_path / "shapes" / "lib.yaml").write_text(LIB.read_text())
    (tmp_path / "sub").mkdir()
    parent = tmp_path / "parent.yaml"
    parent.write_text(f"extends: {SMOKE}\nscene: {{particles: {{shape: clumps, library: shapes/lib.yaml}}}}\n")
    child = tmp_path / "sub" / "child.yaml"
    child.write_text("extends: ../parent.yaml\nname: child\n")
    case = load_case(child)
    assert Path(case.scene.particles.library) == (tmp_path / "shapes" / "lib.yaml").resolve()


def test_dry_run_sizes_the_member_spheres():
    """A clump case is sized (particles, memory, frames.h5, engine time) on the member spheres the
    engines integrate, which build_clumps places, not on the grain count."""
    from orchestrator.derive import derive
    from orchestrator.scenes.triaxial import build_clumps
    from orchestrator.sizing import estimate
    case = _clump_case()
    params = derive(case)
    sc = params["scene"]
    d = np.asarray(sc["diameters"])
    members, owner, _, _ = build_clumps(case, d, sc["diameter"] / 2, sc["height"])
    assert len(np.unique(owner)) == sc["n"] and sc["n_spheres"] == len(members) > sc["n"]
    size = estimate(case, params, "yade")
    assert size["particles"] == len(members)
    spheres = estimate(load_case(SMOKE), derive(load_case(SMOKE)), "yade")
    assert spheres["particles"] == sc["n"]
    assert size["engine_time_s"] > spheres["engine_time_s"] * len(members) / sc["n"] * 0.5


SUBS = {"liggghts.membrane": "shell_pressure", "liggghts.placed_clumps": "inserted_clumps"}


def _liggghts_clump_case(**extra):
    scene = {"particles": {"shape": "clumps", "library": str(LIB)}}
    scene.update(extra)
    return load_case(SMOKE, overrides={"scene": scene, "contact": {"substitutes": SUBS},
                                       "output": {"angular_velocity": True}})


def test_liggghts_clumps_need_the_inserted_clumps_substitute(tmp_path):
    """Without the substitute a LIGGGHTS clump case stops before it starts, naming the feature and the
    substitute; with it the deck inserts the library shapes as multisphere bodies (and no nve/sphere
    integrates their members) and summary.json lists the substitution."""
    from engines.base import UnsupportedFeature
    from orchestrator.runner import run_case
    with pytest.raises(UnsupportedFeature, match="placed_clumps.*inserted_clumps"):
        run_case(_clump_case(), "liggghts", runs_root=tmp_path, dry_run=True, progress=False)
    case = _liggghts_clump_case()
    out = run_case(case, "liggghts", runs_root=tmp_path, dry_run=True, progress=False)
    assert {"feature": "placed_clumps", "mechanism": "inserted_clumps"}.items() <= out.summary["substitutions"][1].items()
    deck = (out.run_dir / "deck.in").read_text()
    C = json.loads((out.run_dir / "params.json").read_text())["scene"]["clumps"]["inserted"]
    assert deck.count("particletemplate/multisphere") == len(C["templates"]) == 9     # 3 shapes x 3 classes
    assert "fix integrate all multisphere" in deck and "all nve/sphere" not in deck and "read_data" not in deck
    assert f"particles_in_region {case.scene.grains}" in deck
    # the classes keep the count of every shape and the total solid volume of the sampled PSD
    assert sum(t["count"] for t in C["templates"]) == case.scene.grains
    assert abs(C["volume_error_classes"]) < 1e-12
    assert not (out.run_dir / "particles.data").exists()


def test_liggghts_templates_keep_the_shape_mix_and_the_solid_volume():
    """The size classes of inserted_clumps: equal counts, volume-mean diameters inside the class
    bounds, the count of every library shape as YADE's draw, the total solid volume; each template's
    mass is that of its volume-equivalent sphere and its members are centred on the centre of mass."""
    from orchestrator.scenes.triaxial import _clump_draw, _sample_size, inserted_clumps
    case = _liggghts_clump_case()
    d = _sample_size(case)[3]
    rho = case.material.density
    k = _clump_draw(case, d)[0]
    for K in (1, 3):
        case.scene.particles.size_classes = K
        C = inserted_clumps(case, d)
        assert len(C["classes"]) == K and sum(c["count"] for c in C["classes"]) == len(d)
        assert max(c["count"] for c in C["classes"]) - min(c["count"] for c in C["classes"]) <= 1
        for c in C["classes"]:
            assert c["d_min"] <= c["diameter"] <= c["d_max"]
        assert abs(C["volume_error_classes"]) < 1e-12
        per_shape = np.bincount([t["shape"] for t in C["templates"] for _ in range(t["count"])], minlength=3)
        assert per_shape.tolist() == np.bincount(k, minlength=3).tolist()
        for t in C["templates"]:
            assert t["mass"] == pytest.approx(rho * math.pi / 6 * t["diameter"] ** 3, rel=5e-3)
            sp = np.array(t["spheres"])
            assert np.allclose(mass_properties(sp, cells=40)["center"], 0, atol=3e-3 * t["diameter"])
        if K == 1:
            assert C["classes"][0]["diameter"] == pytest.approx(np.mean(d ** 3) ** (1 / 3), rel=1e-12)


@pytest.mark.engine
def test_liggghts_triaxial_with_clumps(tmp_path):
    """A short LIGGGHTS triaxial run on inserted clumps (100 grains, 3 isotropic chunks at most, 1 %
    axial strain): every clump inserted with its template's members, the members of every clump keep
    their distances in every frame, LIGGGHTS' body masses match the union integrated here on the
    members as they lie in the first frame, its rotational kinetic energy of the bodies
    (compute erotate/multisphere) matches 1/2 w.I.w with the inertia integrated here, the bodies' state
    crosses the deck's segment boundaries (restart files) unchanged, and no member crosses a platen."""
    from orchestrator.runner import run_case
    if shutil.which("liggghts") is None:
        pytest.fail("liggghts is not installed; run `bash .ci/setup`")
    case = load_case(SMOKE_CLUMPS)          # the resume test's case (tests/test_triaxial_resume.py)
    out = run_case(case, "liggghts", runs_root=tmp_path, progress=False)
    assert out.status == "complete", out.status
    assert any(s["mechanism"] == "inserted_clumps" for s in out.summary["substitutions"])
    rd = out.run_dir
    C = json.loads((rd / "params.json").read_text())["scene"]["clumps"]["inserted"]   # the inserted-clumps table (engine-neutral name)
    rho = case.material.density
    owner = np.loadtxt(rd / "clumps.txt", ndmin=2).astype(int)
    with h5py.File(rd / "frames.h5") as f:
        pos = f["frames/position"][:]
        omega = f["frames/angular_velocity"][:]
        steps = f["frames/step"][:]
        r = f["particles/radius"][:]
        pid = f["particles/id"][:]
        zb = f["walls/platen_bottom/position"][:, 2]
        zt = f["walls/platen_top/position"][:, 2]
        wstep = np.rint(f["walls/platen_top/time"][:] / json.loads((rd / "params.json").read_text())["dt"])
    assert pos.shape[0] >= 4 and not np.isnan(pos).any()
    # the void ratio when loading begins is measured inside the sample too (the members' union:
    # test_triaxial_summary checks it on a lattice of overlapping pairs), as seed 001 measures it by CT
    e = json.loads((rd / "scene_summary.json").read_text())["isotropic_end"]["void_ratio"]
    assert e["interior"] is not None and 0.2 < e["interior_solid_fraction"] < 0.74, e
    # number of clumps and members as asked, per template (shape x size class)
    assert len(np.unique(owner[:, 1])) == case.scene.grains == C["count"]
    assert len(owner) == len(pid) == C["members"]
    start = _report(rd / "dump" / "clumps_start.txt")
    end = _report(rd / "dump" / "clumps_end.txt")
    row = {int(p): k for k, p in enumerate(pid)}
    keys = [(t["nspheres"], np.sort([sp[3] for sp in t["spheres"]])) for t in C["templates"]]
    counts = np.zeros(len(keys), int)
    for mass, _, mem in start.values():
        rr = np.sort(r[[row[m] for m in mem]])
        hit = [k for k, (m, tr) in enumerate(keys) if m == len(rr) and np.allclose(rr, tr, rtol=1e-9, atol=0)]
        assert len(hit) == 1
        counts[hit[0]] += 1
    assert counts.tolist() == [t["count"] for t in C["templates"]]
    for c in start:                                   # LIGGGHTS keeps each body's mass
        assert end[c][0] == start[c][0]
    # rigid bodies: member distances unchanged in every frame
    worst = 0.0
    for c in np.unique(owner[:, 1]):
        rows = [row[int(m)] for m in owner[owner[:, 1] == c, 0]]
        D = np.linalg.norm(pos[:, rows, None, :] - pos[:, None, rows, :], axis=3)
        worst = max(worst, float(np.max(np.abs(D - D[0]))) / float(np.max(r[rows])))
    assert worst < 1e-9, f"member distances changed by {worst:.3g} member radii"
    # mass: LIGGGHTS' (given from the template's grid integration) vs the union of the members as placed
    # in the first frame, integrated here on a world-axes grid
    errs = []
    for mass, _, mem in start.values():
        rows = [row[m] for m in mem]
        errs.append(mass / mass_properties(np.column_stack([pos[0][rows], r[rows]]), density=rho)["mass"] - 1)
    assert np.max(np.abs(errs)) < 0.01, np.max(np.abs(errs))
    # inertia: LIGGGHTS' rotational kinetic energy of the bodies in a loaded frame vs 1/2 w.I.w with I
    # of the members' union in its world orientation (grid integration here; w from the dump)
    E = np.loadtxt(rd / "dump" / "clump_energy.txt", ndmin=2)
    k = len(steps) // 2
    j = int(np.flatnonzero(E[:, 0] == steps[k])[0])
    e_rot = 0.0
    for _, _, mem in start.values():
        rows = [row[m] for m in mem]
        I = mass_properties(np.column_stack([pos[k][rows], r[rows]]), density=rho, cells=40)["inertia"]
        w = omega[k][rows[0]]
        e_rot += 0.5 * w @ I @ w
    assert E[j, 2] > 0 and E[j, 2] == pytest.approx(e_rot, rel=0.01)
    # the deck runs in segments (clear + read_restart, the templates and fix multisphere defined again):
    # the frame of a segment's first step is written twice, at the end of the segment before and by the
    # new one's set-up; the bodies' state came back from the restart file, so the members' positions,
    # velocities and angular velocities (the body's, fix multisphere sets them) are the same doubles
    cols = json.loads((rd / "dump" / "columns.json").read_text())
    kin = [cols.index(c) for c in ("x", "y", "z", "vx", "vy", "vz", "omegax", "omegay", "omegaz")]
    seen, twice = {}, 0
    for seg in dump_segments(rd):
        for st, a in read_binary_dump([seg], len(cols)):
            a = a[np.argsort(a[:, cols.index("id")])][:, kin]
            if st in seen:
                np.testing.assert_array_equal(a, seen[st], err_msg=f"step {st}: {seg.name} differs")
                twice += 1
            seen[st] = a
    assert twice >= 2, "fewer than two segment boundaries on frame steps"
    # no member crosses a platen (beyond a contact overlap) in any frame
    smallest = float(r.min())
    for kk, st in enumerate(steps):
        w = int(np.argmin(np.abs(wstep - st)))
        assert np.min(pos[kk][:, 2] - r) > zb[w] - 0.05 * smallest
        assert np.max(pos[kk][:, 2] + r) < zt[w] + 0.05 * smallest


@pytest.mark.engine
def test_liggghts_incomplete_insertion_stops_with_a_clear_error(tmp_path):
    """One insertion attempt per clump leaves most of them out: the deck stops right after the
    insertion and the error names the fix, the counts and the case fields to change."""
    from engines.base import EngineError
    from orchestrator.runner import run_case
    if shutil.which("liggghts") is None:
        pytest.fail("liggghts is not installed; run `bash .ci/setup`")
    case = _liggghts_clump_case(grains=100, particles={"shape": "clumps", "library": str(LIB),
                                                       "insertion_attempts": 1})
    with pytest.raises(EngineError, match=r"fix ms_ins \(insert/pack\) inserted \d+ of 311 member spheres "
                                          r"\(100 clumps asked\): raise scene.particles.insertion_attempts"):
        run_case(case, "liggghts", runs_root=tmp_path, progress=False)


def _report(path):
    """YADE's clump report format: body id, mass [kg], 3 principal moments [kg m^2], member ids."""
    rows = [ln.split() for ln in Path(path).read_text().splitlines()]
    return {int(x[0]): (float(x[1]), np.array([float(v) for v in x[2:5]]), [int(v) for v in x[5:]]) for x in rows}


@pytest.mark.engine
@pytest.mark.slow(reason="~50 s of YADE: the default suite sat at 15:08 on 27 Nov 2026; LIGGGHTS' clump run stays in it")
def test_yade_triaxial_with_clumps(tmp_path):
    """A short triaxial run (2 isotropic chunks at most, 1 % axial strain) on clumps: every clump
    keeps its mass and inertia, its members keep their distances in every frame, and YADE's mass
    and inertia of each clump match the union's integrated here."""
    from orchestrator.runner import run_case
    if shutil.which("yade") is None:
        pytest.fail("yade is not installed; run `bash .ci/setup`")
    case = _clump_case(axial_strain=0.01, frames=4, isotropic={"max_chunks": 2, "inertial_number": 5e-3})
    out = run_case(case, "yade", runs_root=tmp_path, progress=False)
    assert out.status == "complete", out.status
    rd = out.run_dir
    owner = np.loadtxt(rd / "clumps.txt", ndmin=2).astype(int)
    rho = case.material.density

    def report(name):
        rows = [ln.split() for ln in (rd / "dump" / name).read_text().splitlines()]
        return {int(r[0]): (float(r[1]), np.array([float(x) for x in r[2:5]]), [int(x) for x in r[5:]]) for r in rows}
    start, end = report("clumps_start.txt"), report("clumps_end.txt")
    assert len(start) == case.scene.grains
    for c in start:                                   # mass and inertia conserved, exactly
        assert end[c][0] == start[c][0] and np.array_equal(end[c][1], start[c][1])
    with h5py.File(rd / "frames.h5") as f:
        pos = f["frames/position"][:]
        r = f["particles/radius"][:]
        pid = f["particles/id"][:]
    assert pos.shape[0] >= 4 and not np.isnan(pos).any()
    row = {int(p): k for k, p in enumerate(pid)}
    worst = 0.0
    checked = 0
    for c in np.unique(owner[:, 1]):
        rows = [row[int(m)] for m in owner[owner[:, 1] == c, 0]]
        if len(rows) < 2:
            continue
        D = np.linalg.norm(pos[:, rows, None, :] - pos[:, None, rows, :], axis=3)
        worst = max(worst, float(np.max(np.abs(D - D[0]))) / float(np.max(r[rows])))
        checked += 1
    assert checked == case.scene.grains
    assert worst < 1e-9, f"member distances changed by {worst:.3g} member radii"
    # YADE's clump mass and principal inertia vs the union integrated here (grid error ~1 %)
    members = np.column_stack([pos[0], r])
    for mass, inertia, mem in list(start.values())[:30]:
        mp = mass_properties(members[[row[m] for m in mem]], density=rho, cells=60)
        assert mass == pytest.approx(mp["mass"], rel=0.03)
        assert np.sort(inertia) == pytest.approx(mp["principal"], rel=0.06)


def test_run_hash_follows_the_library_shapes_not_its_path(tmp_path):
    """The run hash holds the clump library by its shapes: the same case and library in two places
    (a moved or second checkout) hash alike, so a run there is found and resumed; a comment in the
    library changes nothing; a changed member radius makes a new run."""
    from orchestrator.runner import run_hash
    text = LIB.read_text()
    hashes = {}
    for name, lib in (("a", text), ("b", text), ("comment", "# a comment\n" + text),
                      ("radius", text.replace("[0, 0, 0, 1.0], [1.2, 0, 0, 1.0]", "[0, 0, 0, 1.0], [1.2, 0, 0, 0.9]"))):
        d = tmp_path / name
        d.mkdir()
        (d / "shapes.yaml").write_text(lib)
        (d / "case.yaml").write_text(f"extends: {SMOKE}\nscene:\n  particles:\n    shape: clumps\n"
                                     "    library: shapes.yaml\n")
        hashes[name] = run_hash(load_case(d / "case.yaml"), "yade", "2023.02")
    assert "[1.2, 0, 0, 1.0]" in text                        # the radius edit below takes
    assert hashes["a"] == hashes["b"] == hashes["comment"]
    assert hashes["radius"] != hashes["a"]


def test_liggghts_clumps_on_several_ranks_are_refused():
    """LIGGGHTS-PUBLIC's multisphere bodies run on one process (on 2 ranks fix insert/pack put 310 of
    311 member spheres in): a clump case asking for 2 ranks is refused when loaded, naming the field
    and the fix, before anything runs."""
    from orchestrator.case import CaseError
    with pytest.raises(CaseError, match=r"engine_options.mpi_ranks: 2 ranks.*one process.*set engine_options.mpi_ranks: 1"):
        load_case(SMOKE, overrides={"scene": {"particles": {"shape": "clumps", "library": str(LIB)}},
                                    "contact": {"substitutes": SUBS}, "engine_options": {"mpi_ranks": 2}})
    load_case(SMOKE, overrides={"scene": {"particles": {"shape": "clumps", "library": str(LIB)}},
                                "contact": {"substitutes": SUBS}, "engine_options": {"mpi_ranks": 1}})
