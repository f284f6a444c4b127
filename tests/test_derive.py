"""Derived parameters against independent calculations."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from orchestrator import derive as d


def _integrate_hertz(m, R, E, v):
    """Independent check: integrate m x'' = -4/3 E sqrt(R) x^1.5 for an elastic impact."""
    k = 4 / 3 * E * math.sqrt(R)
    ev = lambda t, y: y[0]
    ev.terminal, ev.direction = True, -1
    s = solve_ivp(lambda t, y: [y[1], -k / m * max(y[0], 0) ** 1.5], (0, 1), [1e-15, v], events=ev,
                  rtol=1e-11, atol=1e-16, max_step=1e-7, dense_output=True)
    t = s.t[-1]
    tt = np.linspace(0, t, 20001)
    return t, s.sol(tt)[0].max()


def test_hertz_formulas_match_direct_integration():
    m, R, E, v = 1e-3, 2e-3, 1e10, 0.5
    tc, dmax = _integrate_hertz(m, R, E, v)
    assert d.hertz_contact_time(m, R, E, v) == pytest.approx(tc, rel=2e-4)
    assert d.hertz_max_overlap(m, R, E, v) == pytest.approx(dmax, rel=1e-5)
    assert d.hertz_peak_force(m, R, E, v) == pytest.approx(4 / 3 * E * math.sqrt(R) * dmax ** 1.5, rel=2e-5)


def test_effective_moduli():
    assert d.effective_modulus(1e9, 0.0, 1e9, 0.0) == pytest.approx(0.5e9)
    assert d.effective_modulus(70e9, 0.3, 1e30, 0.0) == pytest.approx(70e9 / (1 - 0.09))


def test_restitution_input_inverts_the_clipped_law():
    for e in (0.2, 0.5, 0.9):
        e_in = d.restitution_input(e)
        assert e_in < e                                   # clipping raises e: feed less
        assert d.delivered_restitution(round(e_in, 12)) == pytest.approx(e, abs=1e-8)
    assert d.restitution_input(1.0) == 1.0


def test_sqrt_damping_gamma_delivers_e_at_its_speed():
    m, R, E, v = 1e-2, 0.1, 3e10, 3.9
    g = d.sqrt_damping_gamma(0.2, m, R, E, v)
    k = 4 / 3 * E * math.sqrt(R)

    def rhs(t, y):
        x = max(y[0], 0.0)
        return [y[1], -max(k * x ** 1.5 + g * m * math.sqrt(R * x) * y[1], 0.0) / m]
    out = lambda t, y: y[0]
    out.terminal, out.direction = True, -1
    s = solve_ivp(rhs, (0, 1), [1e-15, v], events=out, rtol=1e-10, atol=1e-16, max_step=1e-6)
    assert -s.y[1, -1] / v == pytest.approx(0.2, rel=2e-3)


def test_rayleigh_time_step_value():
    # glass sphere r = 12.5 um: pi r sqrt(rho/G)/(0.1631 nu + 0.8766)
    G = 63e9 / 2.4
    expect = math.pi * 12.5e-6 * math.sqrt(2500 / G) / (0.1631 * 0.2 + 0.8766)
    assert d.rayleigh_time_step(12.5e-6, 2500, 63e9, 0.2) == pytest.approx(expect)


def test_damped_critical_step_is_shorter():
    assert d.damping_ratio(1.0) == 0.0
    z = d.damping_ratio(0.2)
    assert math.sqrt(1 + z * z) - z == pytest.approx(0.643, abs=2e-3)


def test_yade_wall_young_restores_flat_wall_stiffness():
    from engines.yade.numbers import wall_young
    E, nu = 63e9, 0.2
    target = d.effective_modulus(E, nu, E, nu)            # glass on glass
    Ew = wall_young(E, nu, target, nu, "facet")
    yade_E = d.effective_modulus(E, nu, Ew, nu)
    # YADE: 4/3 E_yade sqrt(2R/3) must equal 4/3 E* sqrt(R)
    assert yade_E * math.sqrt(2 / 3) == pytest.approx(target, rel=1e-12)
    with pytest.raises(d.DerivationError, match="cannot reproduce"):
        wall_young(E, nu, d.effective_modulus(E, nu, 1e3 * E, 0.0), 0.0, "wall")
