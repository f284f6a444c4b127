"""The engine-free integration of seed 000 eq. 1 (orchestrator.seed_law): without damping and
adhesion it is the elastic Hertz impact (Johnson 1985 §11.4, orchestrator.derive.hertz_*); with
damping alone e_n falls with speed like a √ξ ξ̇ law must; adhesion lowers e_n further."""
from __future__ import annotations

from dataclasses import replace

import pytest

from orchestrator.derive import hertz_contact_time, hertz_max_overlap
from orchestrator.seed_law import head_on, seed_pair

GLASS = dict(E=63e9, nu=0.2, rho=2230.0, f_adh_median=50e-9, d50=30e-6, mu=0.58)


def test_elastic_limit_is_hertz():
    p = replace(seed_pair(r1=15e-6, r2=15e-6, **GLASS), gamma_n=0.0, f_adh=0.0)
    c = head_on(p, 0.1)
    assert c.restitution == pytest.approx(1.0, abs=1e-7)
    # derive's 2.868 prefactor is rounded to 4 digits: 1e-4
    assert c.contact_time == pytest.approx(hertz_contact_time(p.m_eff, p.r_eff, p.E_eff, 0.1), rel=2e-4, abs=0)
    assert c.max_overlap == pytest.approx(hertz_max_overlap(p.m_eff, p.r_eff, p.E_eff, 0.1), rel=1e-7, abs=0)
    # no damping: the sliding integrals are equal (F_adh = 0, the damping integral vanishes)
    assert c.seed_tangential_impulse == pytest.approx(c.hertz_plus_adhesion_impulse, rel=1e-6, abs=0)


def test_damping_and_adhesion_lower_the_restitution():
    p = seed_pair(r1=15e-6, r2=15e-6, **GLASS)
    damped = head_on(replace(p, f_adh=0.0), 0.1)
    slow = head_on(replace(p, f_adh=0.0), 0.01)
    assert 0 < damped.restitution < slow.restitution < 1       # damping/elastic grows like v^(1/5)
    with_adhesion = head_on(p, 0.01)
    assert with_adhesion.restitution < slow.restitution
    # the pull-off is in the LAMMPS-form integral, not in the seed's: it is the larger one
    assert with_adhesion.hertz_plus_adhesion_impulse > with_adhesion.seed_tangential_impulse


def test_pull_off_scales_with_reduced_radius():
    small, median = seed_pair(r1=12.5e-6, r2=12.5e-6, **GLASS), seed_pair(r1=15e-6, r2=15e-6, **GLASS)
    assert median.f_adh == pytest.approx(50e-9, rel=1e-12, abs=0)
    assert small.f_adh / median.f_adh == pytest.approx(12.5 / 15, rel=1e-12, abs=0)
