"""The vaned micro shear-tester (seed 000, issue 3): meshes, particles, decks, and the smoke case
on both real engines (LIGGGHTS ~20 s, YADE ~1 min on one core)."""
from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from orchestrator.case import load_case
from orchestrator.derive import derive
from orchestrator.geometry import Mesh, MeshError, box, check_manifold, cylinder_shell, read_stl, vaned_piston
from orchestrator.psd import lognormal_diameters, max_overlap, pack_cylinder
from orchestrator.contact_law import SERVO_DASHPOT_GAIN
from orchestrator.scenes.shear_cell import geometry_numbers, servo_dashpot_gain
from orchestrator.scenes import shear_cell
from shear_cell_protocol import check_smoke_protocol

CASES = Path(__file__).resolve().parents[1] / "cases"
SMOKE = CASES / "shear_cell_smoke.yaml"
SCHEDULE_MINUTES = 4
ENGINES = [e for e in ("liggghts", "yade") if shutil.which(e)]


# ------------------------------------------------------------------------------------------------
# meshes
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("case_file", ["shear_cell_smoke.yaml", "shear_cell_small.yaml", "shear_cell_seed.yaml"])
def test_meshes_are_closed_and_manifold(case_file):
    case = load_case(CASES / case_file)
    params = derive(case)
    meshes = shear_cell.build_meshes(case, params)
    for name, m in meshes.items():
        rep = check_manifold(m, name)
        assert rep["closed"] and rep["manifold"] and not rep["faults"]
        assert all(s["euler"] == 2 and s["volume"] > 0 for s in rep["shells"])
    # a piston = plate + flange + six vanes, each its own shell (no shared edges with the plate)
    assert len(check_manifold(meshes["lower"])["shells"]) == 8
    # vanes start off the axis: no vertex of a piston lies within the vane inner radius but the plate's
    g = params["scene"]["geometry"]
    v = meshes["lower"].vertices
    r = np.hypot(v[:, 0], v[:, 1])
    above = v[:, 2] > 1e-12
    assert r[above].min() >= g["vane_inner_radius"] * (1 - 1e-9)


@pytest.mark.filterwarnings("error::RuntimeWarning")   # read_stl reads our ASCII STL without meshio's overflow warning
def test_stl_round_trip_stays_manifold(tmp_path):
    from orchestrator.geometry import write_stl
    m = vaned_piston(0.2e-3, 0.05e-3, 48, 0.05e-3, 0.02e-3, 0.04e-3, flange_radius=0.25e-3)
    write_stl(m, tmp_path / "p.stl")
    back = read_stl(tmp_path / "p.stl")
    assert check_manifold(back)["closed"]
    assert len(back.triangles) == len(m.triangles)


def test_manifold_check_catches_bad_meshes():
    good = box(0, 1, 0, 1, 0, 1)
    check_manifold(good)
    with pytest.raises(MeshError, match="open"):                      # a missing triangle
        check_manifold(Mesh(good.vertices, good.triangles[:-1]))
    with pytest.raises(MeshError, match="orientation"):               # one flipped triangle
        t = good.triangles.copy()
        t[0] = t[0][::-1]
        check_manifold(Mesh(good.vertices, t))
    # two boxes sharing an edge (vanes meeting on the axis / on the plate): non-manifold
    a = box(0, 1, 0, 1, 0, 1)
    b = box(1, 2, 1, 2, 0, 1)
    verts = np.vstack([a.vertices, b.vertices])
    _, inv = np.unique(np.round(verts, 12), axis=0, return_inverse=True)
    uniq = np.unique(np.round(verts, 12), axis=0)
    tris = inv.ravel()[np.vstack([a.triangles, b.triangles + 8])]
    with pytest.raises(MeshError, match="non-manifold|Euler"):
        check_manifold(Mesh(uniq, tris))


def test_vanes_refuse_to_meet_on_the_axis():
    with pytest.raises(ValueError, match="meet"):
        vaned_piston(0.2e-3, 0.05e-3, 48, 0.05e-3, 0.02e-3, 0.015e-3)


def test_cylinder_volume_close_to_exact():
    c = cylinder_shell(1.0, 0.0, 2.0, 192)
    assert c.volume() == pytest.approx(2 * math.pi, rel=1e-3)


# ------------------------------------------------------------------------------------------------
# particles
# ------------------------------------------------------------------------------------------------
def test_lognormal_truncated_and_seeded():
    d = lognormal_diameters(20000, 30e-6, 25e-6, 50e-6, 0.12, 7)
    assert d.min() >= 25e-6 and d.max() <= 50e-6
    assert np.median(d) == pytest.approx(30.6e-6, rel=0.03)      # truncation below shifts it up a little
    assert np.array_equal(d, lognormal_diameters(20000, 30e-6, 25e-6, 50e-6, 0.12, 7))


def test_loose_packing_has_no_overlap_and_requested_fraction():
    case = load_case(SMOKE)
    params = derive(case)
    parts = shear_cell.sample_particles(case, params)
    g = params["scene"]["geometry"]
    assert max_overlap(parts["position"], parts["radius"]) == 0.0
    r = np.hypot(parts["position"][:, 0], parts["position"][:, 1])
    assert np.all(r + parts["radius"] <= g["R_cyl"])
    vol = np.sum(4 / 3 * np.pi * parts["radius"] ** 3)
    box_vol = np.pi * g["R_cyl"] ** 2 * (g["z_pack"][1] - g["z_pack"][0])
    assert vol / box_vol == pytest.approx(case.scene.loose_fraction, rel=0.05)
    with pytest.raises(ValueError, match="too small"):
        pack_cylinder(np.full(500, 1.0), 5.0, 0.0, 5.0, 1)


def test_servo_speed_keeps_the_dashpot_loop_stable():
    """The piston servo's loop gain against its contacts' dashpots, G = v_max kp γ_w/F_c, stays at
    or below SERVO_DASHPOT_GAIN: on the tall medium cell the compression inertial number alone asks
    for 0.47 m/s (G = 2.7, where the servo alternated every step and held 1.22 x the target), so its
    speed is capped; the thinner cells' speeds are what I_c gives."""
    for name in ("shear_cell_smoke", "shear_cell_small", "shear_cell_default", "shear_cell_medium"):
        case = load_case(CASES / f"{name}.yaml")
        sv = derive(case).scene.servo
        s = case.scene
        v_ic = (s.compression_inertial_number / (s.psd.median * math.sqrt(case.material.density / s.normal_stress))
                * geometry_numbers(case)["h_dense_estimate"])
        G = servo_dashpot_gain(case, sv["v_max"], sv["kp"])
        assert G <= SERVO_DASHPOT_GAIN * (1 + 1e-12), (name, G)
        if name == "shear_cell_medium":
            assert servo_dashpot_gain(case, v_ic, sv["kp"]) > 2 and sv["v_max"] < 0.3 * v_ic
        else:
            assert sv["v_max"] == v_ic, name


def test_plane_shear_servo_speed_keeps_the_dashpot_loop_stable():
    """The plane shear's top-wall servo obeys the same cap: the seed case's I_c speed (0.63 m/s)
    would give G = 7.6 against the grain-grain dashpots under the wall; the smoke case is uncapped."""
    from orchestrator.scenes import plane_shear as ps
    for name, capped in (("plane_shear_smoke", False), ("plane_shear_seed", True)):
        case = load_case(CASES / f"{name}.yaml")
        sv = derive(case).scene.servo
        s = case.scene
        v_ic = s.compression_inertial_number * ps.geometry(case)["H_dense"] / ps._time_scale(case)
        assert ps.servo_dashpot_gain(case, sv["v_max"], sv["kp"]) <= SERVO_DASHPOT_GAIN * (1 + 1e-12), name
        assert (sv["v_max"] < 0.2 * v_ic) if capped else (sv["v_max"] == v_ic), name


def test_quasi_static_omega_and_frame_schedule():
    case = load_case(CASES / "shear_cell_seed.yaml")
    sc = derive(case)["scene"]
    s = case.scene
    assert sc["omega"] * math.sqrt(case.material.density * s.psd.median ** 2 / s.normal_stress) == pytest.approx(1e-4)
    deg = np.degrees(sc["frame_angles"][3:])
    assert np.allclose(deg, list(np.arange(0.5, 9.51, 0.5)) + [14.5, 19.5, 24.5, 29.5, 34.5, 39.5])
    assert sc["frame_steps"][-1] == sc["stages"]["shear"][1]


# ------------------------------------------------------------------------------------------------
# decks: a block appears only when its case asks for it
# ------------------------------------------------------------------------------------------------
def _render(tmp_path, engine, overrides):
    from engines import get_engine
    from orchestrator.runner import prepare
    case = load_case(SMOKE, overrides)
    run_dir = tmp_path / engine
    params, subs = prepare(case, engine, run_dir)
    deck = get_engine(engine).render(case, params, run_dir)
    return deck.read_text(), subs


FULL = {"contact": {"adhesion": {"force": "0.05 uN"}, "rolling": {"model": "seed000"},
                    "torsion": {"coefficient": 0.58},
                    "substitutes": {"seed000_damping": "tsuji_restitution",
                                    "liggghts.adhesion": "sjkr_matched_overlap",
                                    "liggghts.rolling_friction_load": "epsd2_constant",
                                    "liggghts.torsion_friction": "epsd2_torsion_torque",
                                    "yade.rolling_friction_load": "mindlin_moment",
                                    "yade.torsion_friction": "mindlin_ktwist_elastic"}}}
ZERO = {"contact": {"adhesion": {"force": 0}, "rolling": {"model": "constant", "coefficient": 0.0},
                    "torsion": {"coefficient": 0.0}}}


@pytest.mark.parametrize("engine", ["liggghts", "yade"])
def test_contact_blocks_only_when_asked(tmp_path, engine):
    markers = {"liggghts": {"adhesion": "cohesion sjkr", "rolling": "rolling_friction epsd2",
                            "torsion": "torsionTorque on"},
               "yade": {"adhesion": "includeAdhesion = True", "rolling": "ip2.krot", "torsion": "ip2.ktwist"}}[engine]
    plain, subs = _render(tmp_path / "plain", engine, {})
    zero, _ = _render(tmp_path / "zero", engine, ZERO)
    full, subs_full = _render(tmp_path / "full", engine, FULL)
    for term, m in markers.items():
        assert m not in plain, f"{term} block in a deck that did not ask for it"
        assert m not in zero, f"{term} block emitted for a zero-strength term"
        assert m in full, f"{term} block missing"
    only_adh, _ = _render(tmp_path / "adh", engine, {"contact": dict(FULL["contact"], rolling=None, torsion=None)})
    assert markers["adhesion"] in only_adh and markers["rolling"] not in only_adh and markers["torsion"] not in only_adh
    names = {s.feature: s.mechanism for s in subs_full}
    assert names["seed000_damping"] == "tsuji_restitution"
    if engine == "liggghts":
        assert names["adhesion"] == "sjkr_matched_overlap"
    else:
        assert names["torsion_friction"] == "mindlin_ktwist_elastic"


def test_substitute_needs_naming():
    from engines import get_engine
    from engines.base import UnsupportedFeature
    case = load_case(SMOKE, {"contact": {"adhesion": {"force": "0.05 uN"}}})
    feats = derive(case)["features"]
    with pytest.raises(UnsupportedFeature, match="adhesion"):
        get_engine("liggghts").check(feats, {"seed000_damping": "tsuji_restitution"})


# ------------------------------------------------------------------------------------------------
# single contact: how far each substitute is from the seed's formula
# ------------------------------------------------------------------------------------------------
def test_single_contact_substitutes_vs_seed():
    """One median pair (r_eff = x50/4) of the seed case, overlaps 0.1 to 10 times the expected one.
    Seed: F_adh constant; rolling limit sqrt(2 r_eff xi)|F|; torsion limit mu r_eff |F|.
    LIGGGHTS sjkr: F = k A(xi) with A the exact sphere-intersection area; epsd2: mu_r r_eff |F| with
    mu_r frozen at xi_sigma. YADE DMT: 4 pi gamma r_eff (exact); Mindlin moment: eta R_mean |F|."""
    case = load_case(CASES / "shear_cell_seed.yaml")
    params = derive(case)
    c = params["scene"]["contact"]
    x50 = case.scene.psd.median
    R = x50 / 2
    r_eff = R / 2
    xs = c["expected_overlap"] * np.array([0.1, 0.5, 1.0, 2.0, 10.0])
    dist = 2 * R - xs
    A = np.pi / 4 * ((dist - 2 * R) * dist * dist * (dist + 2 * R)) / dist ** 2
    A = np.abs(A)
    from engines.liggghts.numbers import liggghts_numbers
    from engines.yade.numbers import yade_numbers
    lig, yad = liggghts_numbers(case, params), yade_numbers(case, params)
    f_sjkr = lig.cohesion_energy_density * A
    f_seed = c["adhesion_force"]
    ratio = f_sjkr / f_seed
    assert ratio[2] == pytest.approx(1.0, rel=1e-3)                 # matched at the expected overlap
    assert ratio[0] == pytest.approx(0.1, rel=1e-2) and ratio[-1] == pytest.approx(10, rel=2e-2)
    assert 4 * np.pi * yad.gamma * r_eff == pytest.approx(f_seed, rel=1e-12)   # YADE DMT exact
    lever_seed = np.sqrt(2 * r_eff * xs)
    lever_epsd2 = c["rolling_coefficient"] * r_eff
    lever_yade = yad.eta * R
    assert lever_epsd2 / lever_seed[2] == pytest.approx(1.0, rel=1e-9)
    assert lever_yade == pytest.approx(lever_epsd2, rel=1e-12)
    assert lever_epsd2 / lever_seed[0] == pytest.approx(np.sqrt(10), rel=1e-9)     # frozen: off by sqrt(xi_s/xi)
    # torsion: seed limit mu r_eff |F|; LIGGGHTS epsd2 torsionTorque shares the rolling limit;
    # YADE's twisting spring has no limit at all
    assert c["torsion_coefficient"] * r_eff / lever_epsd2 > 10
    assert yad.ktwist == c["twisting_stiffness"]


# ------------------------------------------------------------------------------------------------
# the smoke case on the real engines
# ------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def smoke_runs(runs_root):
    """The smoke case on LIGGGHTS and YADE in the session's runs directory: the compare tests'
    crossval (tests/compare/conftest.py) reuses these runs when xdist puts both files on one worker."""
    from orchestrator.runner import run_case
    if not ENGINES:
        pytest.fail("neither liggghts nor yade is installed; run `bash .ci/setup`")
    case = load_case(SMOKE)
    return case, {e: run_case(case, e, runs_root=runs_root, progress=False) for e in ENGINES}


@pytest.mark.engine
@pytest.mark.parametrize("engine", ["liggghts", "yade"])
def test_smoke_protocol(smoke_runs, engine):
    case, runs = smoke_runs
    if engine not in runs:
        pytest.fail(f"{engine} not installed; run `bash .ci/setup`")
    out = runs[engine]
    r = check_smoke_protocol(case, out)
    pos, angle, lp, sc = r["pos"], r["angle"], r["lp"], r["params"]["scene"]
    # the cell: above the lower flange from the start
    assert pos[..., 2].min() > -case.scene.plate_thickness / 2
    # nobody below the lower plate face at the end (the flange closes the gap)
    z_face_end = lp["position"][-1, 2]
    assert (pos[-1, :, 2] > z_face_end - 2 * case.scene.plate_thickness).all()
    assert np.allclose(angle[3:], sc["frame_angles"][3:], rtol=0, atol=1e-12)


def _measured_rotation(a0, a1):
    d = math.atan2(a1[1], a1[0]) - math.atan2(a0[1], a0[0])
    return (d + math.pi) % (2 * math.pi) - math.pi


@pytest.mark.engine
@pytest.mark.parametrize("engine", ["liggghts", "yade"])
def test_smoke_rotating_parts_turned_by_requested_angle(smoke_runs, engine):
    case, runs = smoke_runs
    if engine not in runs:
        pytest.fail(f"{engine} not installed; run `bash .ci/setup`")
    d = runs[engine].run_dir
    want = case.scene.final_angle
    params = json.loads((d / "params.json").read_text())
    tol = 2 * params["scene"]["omega"] * params["dt"]
    if engine == "liggghts":
        # a frictionless sidewall is LIGGGHTS' analytic cylinder, which stands still (templates/liggghts/shear_cell.in.j2)
        assert params["scene"]["wall_mu"] == 0 and not list(d.glob("cylinder_final.*.stl"))
        for start, end in (("upper.stl", "upper_final"),):
            a, b = read_stl(d / start), read_stl(next(d.glob(f"{end}.*.stl")))
            # the same vertex set rotated by the requested angle
            rot = np.array([[math.cos(want), -math.sin(want), 0], [math.sin(want), math.cos(want), 0], [0, 0, 1]])
            expect = a.vertices @ rot.T
            # every turned vertex has a counterpart in the final mesh
            from scipy.spatial import cKDTree
            dist, _ = cKDTree(b.vertices).query(expect)
            assert dist.max() < 1e-3 * np.ptp(a.vertices), (start, dist.max())
    else:
        j = json.loads((d / "rotation_final.json").read_text())
        for part in ("upper", "cylinder"):
            got = _measured_rotation(j["start"][part], j["end"][part])
            assert got == pytest.approx(want, abs=tol + 1e-9), part


@pytest.mark.engine
def test_yade_never_pairs_two_wall_facets(smoke_runs):
    """YADE's collider pairs every two bodies whose boxes overlap, the fixed wall facets too (~34 000
    facet pairs at 4 108 grains: no force, but the collider and the InteractionLoop handled them every
    step: 2.7x the CPU time of the smoke case, benchmarks/bench_yade_facet_pairs.py). The deck keeps
    them apart by group mask (templates/yade/shear_cell.py.j2): at the end no facet pair exists, while
    grains still touch the walls and each other."""
    case, runs = smoke_runs
    if "yade" not in runs:
        pytest.fail("yade not installed; run `bash .ci/setup`")
    census = json.loads((runs["yade"].run_dir / "interactions.json").read_text())
    assert "Facet-Facet" not in census, census
    assert census["Facet-Sphere"]["real"] > 0 and census["Sphere-Sphere"]["real"] > 0, census


@pytest.mark.engine
def test_smoke_both_engines_start_identical(smoke_runs):
    case, runs = smoke_runs
    if len(runs) < 2:
        pytest.fail("needs both engines; run `bash .ci/setup`")
    tabs = [np.loadtxt(runs[e].run_dir / "particles.txt") for e in ("liggghts", "yade")]
    assert np.array_equal(tabs[0], tabs[1])
    with h5py.File(runs["liggghts"].run_dir / "frames.h5") as a, h5py.File(runs["yade"].run_dir / "frames.h5") as b:
        assert np.array_equal(a["particles/radius"][:], b["particles/radius"][:])
        assert np.allclose(a["frames/position"][0], b["frames/position"][0], rtol=0, atol=1e-15)
        assert list(a["frames/step"][:]) == list(b["frames/step"][:])
