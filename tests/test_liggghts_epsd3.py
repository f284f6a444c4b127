"""LIGGGHTS' ``epsd3_matched`` rolling stand-in (engines/liggghts/numbers.py ``rolling_numbers``):
the rolling spring C k_n(ξ) μ_r² r_eff² and the dashpot η 2√(I_r k_r) must give the seed's
k_t r_eff² and 2√(k_r m_eff r_eff²) for a median pair at the matched overlap, and the torque must
stop at μ_r r_eff |F_n|.

A real LIGGGHTS run of two median spheres held at the matched overlap (``fix setforce``), spun in
opposite senses about an axis normal to the line of centres: pure rolling, no slip at the contact
point, so the tangential spring carries nothing and the torque on each sphere is the rolling
model's alone. Below the limit the torque is -(k_r θ + c θ̇) in the relative rolling angle θ: a
least-squares fit over the run recovers k_r and c. A fast spin drives it to the limit.
"""
from __future__ import annotations

import math
import subprocess
from pathlib import Path

import numpy as np
import pytest

from engines.liggghts.numbers import EPSD3_INERTIA_RATIO, liggghts_numbers, matched_overlap
from orchestrator.case import CaseError, load_case
from orchestrator.derive import derive

REPO = Path(__file__).resolve().parents[1]
EPSD3 = {"contact": {"match_overlap": 0.56, "substitutes": {
    "liggghts.rolling_friction_load": "epsd3_matched", "liggghts.torsion_friction": "epsd3_torsion_torque"}}}

DECK = """atom_style granular
atom_modify map array
boundary f f f
newton off
communicate single vel yes
units si
read_data pair.data
fix m_E all property/global youngsModulus peratomtype {E}
fix m_nu all property/global poissonsRatio peratomtype {nu}
fix m_e all property/global coefficientRestitution peratomtypepair 1 0.9
fix m_mu all property/global coefficientFriction peratomtypepair 1 0.5
fix m_rf all property/global coefficientRollingFriction peratomtypepair 1 {mu_r}
fix m_rs all property/global rollingStiffness scalar {C}
fix m_rv all property/global coefficientRollingViscousDamping peratomtypepair 1 {eta}
pair_style gran model hertz tangential history rolling_friction epsd3 limitForce on
pair_coeff * *
timestep {dt}
fix integr all nve/sphere
fix hold all setforce 0.0 0.0 0.0
dump d all custom 1 spin.txt id omegax tqx
dump_modify d sort id
run {steps}
"""
#: atom_style granular: id type diameter density x y z; velocities: id vx vy vz wx wy wz
DATA = """two median spheres at the matched overlap, spun in opposite senses about x

2 atoms
1 atom types
-{L} {L} xlo xhi
-{L} {L} ylo yhi
-{L} {L} zlo zhi

Atoms

1 1 {d} {rho} 0.0 0.0 0.0
2 1 {d} {rho} 0.0 0.0 {z2}

Velocities

1 0.0 0.0 0.0 {w0} 0.0 0.0
2 0.0 0.0 0.0 {mw0} 0.0 0.0
"""


def _numbers():
    case = load_case(REPO / "cases" / "shear_cell_small.yaml", overrides=EPSD3)
    params = derive(case)
    c = params.scene.contact
    num = liggghts_numbers(case, params)
    return case, params, c, num


def test_epsd3_numbers_match_the_seed_at_the_matched_overlap():
    case, params, c, num = _numbers()
    assert num.rolling_model == "epsd3"
    xi = matched_overlap(case, c)
    assert xi == pytest.approx(0.56 * c.expected_overlap)
    kn = 4 / 3 * params.E_eff_pp * math.sqrt(c.r_eff_mean * xi)            # LIGGGHTS' model hertz k_n
    assert num.rolling_stiffness_coefficient * kn * c.rolling_coefficient ** 2 * c.r_eff_mean ** 2 == \
        pytest.approx(c.rolling_stiffness, rel=1e-12)
    assert num.rolling_viscous_damping ** 2 * EPSD3_INERTIA_RATIO == pytest.approx(1.0)
    # sjkr's k matched at the same overlap: k A(ξ_m) = F_adh, A = 2π r_eff ξ
    assert num.cohesion_energy_density * 2 * math.pi * c.r_eff_mean * xi == pytest.approx(c.adhesion_force)


def test_torsion_must_ride_on_the_chosen_rolling_model():
    bad = {"contact": {"substitutes": {"liggghts.rolling_friction_load": "epsd3_matched",
                                       "liggghts.torsion_friction": "epsd2_torsion_torque"}}}
    with pytest.raises(CaseError, match="epsd3_torsion_torque"):
        load_case(REPO / "cases" / "shear_cell_small.yaml", overrides=bad)


def _spin(tmp_path, w0: float, steps: int):
    case, params, c, num = _numbers()
    R = case.scene.psd.median / 2
    xi = matched_overlap(case, c)
    rho = params.material.rho
    m = rho * 4 / 3 * math.pi * R ** 3
    inertia = 0.4 * m * R ** 2
    k_seed = c.rolling_stiffness
    dt = 2 * math.pi * math.sqrt(inertia / (2 * k_seed)) / 2000           # 2000 steps per rolling period
    deck = DECK.format(E=params.material.E, nu=params.material.nu, mu_r=c.rolling_coefficient,
                       C=num.rolling_stiffness_coefficient, eta=num.rolling_viscous_damping, dt=dt, steps=steps)
    (tmp_path / "deck.in").write_text(deck)
    (tmp_path / "pair.data").write_text(DATA.format(L=4 * R, z2=2 * R - xi, d=2 * R, rho=rho, w0=w0, mw0=-w0))
    proc = subprocess.run(["liggghts", "-in", "deck.in", "-log", "none", "-screen", "none"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    rows = []
    with open(tmp_path / "spin.txt") as fh:
        lines = fh.read().splitlines()
    for i, ln in enumerate(lines):
        if ln.startswith("ITEM: ATOMS"):
            a = [float(v) for v in lines[i + 1].split()]
            b = [float(v) for v in lines[i + 2].split()]
            rows.append((a[1], b[1], a[2]))          # omegax of 1, of 2, torque x on 1
    w1, w2, tq1 = (np.array(col) for col in zip(*rows))
    w_rel = w1 - w2
    theta = np.concatenate([[0.0], np.cumsum(w_rel[:-1]) * dt])       # the deck's explicit increments
    fn = 4 / 3 * params.E_eff_pp * math.sqrt(c.r_eff_mean * xi) * xi                  # Hertz F_n at rest
    return dict(theta=theta, w_rel=w_rel, tq1=tq1, k_seed=k_seed, m=m, R=R, fn=fn, c=c)


@pytest.mark.engine
@pytest.mark.usefixtures("engines_installed")
def test_epsd3_rolling_spring_and_dashpot_are_the_seeds(tmp_path):
    # slow spin: the torque stays far below the limit μ_r r_eff F_n
    r = _spin(tmp_path, w0=1.0, steps=3000)
    c = r["c"]
    assert np.abs(r["tq1"]).max() < 0.5 * c.rolling_coefficient * c.r_eff_mean * r["fn"]
    A = np.column_stack([r["theta"], r["w_rel"]])
    (k, damp), *_ = np.linalg.lstsq(A[1:], -r["tq1"][1:], rcond=None)
    m_eff, r_eff = r["m"] / 2, c.r_eff_mean
    c_seed = 2 * math.sqrt(r["k_seed"] * m_eff * r_eff ** 2)
    print(f"epsd3 matched: k_r {k / r['k_seed']:.3f}, dashpot {damp / c_seed:.3f} of the seed's")   # docs/crossval.md
    assert k == pytest.approx(r["k_seed"], rel=0.02)
    assert damp == pytest.approx(2 * math.sqrt(r["k_seed"] * m_eff * r_eff ** 2), rel=0.02)


@pytest.mark.engine
@pytest.mark.usefixtures("engines_installed")
def test_epsd3_rolling_torque_stops_at_the_limit(tmp_path):
    r = _spin(tmp_path, w0=1e5, steps=600)
    c = r["c"]
    limit = c.rolling_coefficient * c.r_eff_mean * r["fn"]
    assert np.abs(r["tq1"]).max() == pytest.approx(limit, rel=0.01)
