"""Pre-run stability checks (no engine): every limit, the refusal with numbers, the override."""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from orchestrator.case import CaseError, load_case
from orchestrator.derive import derive, hertz_contact_time, rayleigh_time_step
from orchestrator.stability.checks import critical_steps

CASES = Path(__file__).resolve().parents[2] / "cases"


def test_limits_match_formulas():
    case = load_case(CASES / "stability" / "mu1.yaml")
    p = derive(case)
    cs = critical_steps(case, p)
    fd = cs["damping_factor"]
    zeta = cs["damping_ratio"]
    assert fd == pytest.approx(math.sqrt(1 + zeta ** 2) - zeta)
    m = case.material
    assert cs["limits"]["rayleigh"] == pytest.approx(rayleigh_time_step(p["r_min"], m.density, m.youngs_modulus,
                                                                        m.poisson_ratio) * fd)
    # the largest speed includes the walls: twice the servo speed limit
    assert cs["speed"] >= 2 * p["scene"]["servo"]["v_max"] * (1 - 1e-12)
    m_min = m.density * 4 / 3 * math.pi * p["r_min"] ** 3
    tc = hertz_contact_time(m_min / 2, p["r_min"] / 2, p["E_eff_pp"], cs["speed"])
    assert cs["limits"]["contact_time"] <= tc / 10 * fd * (1 + 1e-9)
    # central-difference stability of the stiffest contact: 2/omega below the contact time
    assert cs["limits"]["hertz"] < tc
    assert cs["limits"]["skin"] == pytest.approx(0.5 * p["scene"]["skin"] / cs["speed"])


def test_rolling_and_twisting_limits_from_the_springs():
    case = load_case(CASES / "shear_cell_seed.yaml")
    lim = derive(case)["stability"]["limits"]
    assert "rolling" in lim and "twisting" in lim
    assert 0 < lim["rolling"] < math.inf


def test_confinement_raises_the_contact_stiffness():
    lo = derive(load_case(CASES / "stability" / "confinement_low.yaml"))["stability"]["contacts"]["particle-particle"]
    hi = derive(load_case(CASES / "stability" / "confinement_high.yaml"))["stability"]["contacts"]["particle-particle"]
    assert hi["overlap_static"] > lo["overlap_static"]
    assert hi["overlap"] == hi["overlap_static"]      # at 1 MPa the static overlap dominates the impact one


def test_unsafe_dt_refused_with_numbers_unless_forced():
    path = CASES / "stability" / "quartz_stiff.yaml"
    p = derive(load_case(path))
    # below derive's critical step (so its own check passes) but above half the Rayleigh step
    assert p["stability"]["dt_max_safe"] < 0.9 * p["dt_critical"]
    dt = 0.9 * p["dt_critical"]
    with pytest.raises(CaseError) as exc:
        load_case(path, overrides={"timestep": {"dt": f"{dt!r} s"}})
    msg = str(exc.value)
    assert "rayleigh: dt/limit" in msg and "largest safe dt" in msg and "m/s" in msg and "allow_unsafe" in msg
    forced = load_case(path, overrides={"timestep": {"dt": f"{dt!r} s", "allow_unsafe": True}})
    rep = derive(forced)["stability"]
    assert rep["forced"] and not rep["ok"]


def test_safe_fraction_tightens_the_check():
    case = load_case(CASES / "stability" / "quartz_stiff.yaml")
    p = derive(case)
    assert p["stability"]["binding"] == "rayleigh"
    with pytest.raises(CaseError, match="rayleigh"):
        load_case(CASES / "stability" / "quartz_stiff.yaml", overrides={"stability": {"safe_fraction": 0.1}})


def test_coordination_limit_from_the_rotational_row():
    """A grain turning against Z contacts: ω_rot² = Z k_t r²/I = (2.5 Z/7) ω_t², its damping ratio
    ζ_t (Z/2.8)(ω_t/ω_rot); it binds the strongly damped member, where YADE heats up below the
    pair limits (docs/stability.md)."""
    from orchestrator.stability.checks import COORDINATION
    case = load_case(CASES / "stability" / "restitution_overdamped.yaml")
    p = derive(case)
    cs = critical_steps(case, p)
    t, c = cs["contacts"]["tangential"], cs["contacts"]["coordination"]
    Z = COORDINATION
    assert c["omega"] ** 2 == pytest.approx(2.5 * Z / 7 * t["omega"] ** 2)
    assert c["damping_ratio"] == pytest.approx(t["damping_ratio"] * Z / 2.8 * t["omega"] / c["omega"])
    zr = c["damping_ratio"]
    assert cs["limits"]["coordination"] == pytest.approx(2 / c["omega"] * (math.sqrt(1 + zr ** 2) - zr))
    assert cs["limits"]["coordination"] < cs["limits"]["tangential"]
    assert p["stability"]["binding"] == "coordination"
    # measured on YADE: the settled packing heats from f = 0.6; the check must accept less
    assert p["stability"]["dt_max_safe"] / p["dt_critical"] < 0.5
    # frictionless grains have no tangential spring, hence no such limit
    assert "coordination" not in derive(load_case(CASES / "stability" / "mu0.yaml"))["stability"]["limits"]
