"""Seed 000's contact law for one contact, integrated independently of any DEM engine (SciPy).

Seed 000 eq. 1 (§3.1) for the normal force of a pair with overlap ξ > 0:

    F_n(ξ, ξ̇) = 4/3 E_eff √r_eff ξ^(3/2) + γ_n √ξ ξ̇ − F_adh r_eff/⟨r_eff⟩,

with γ_n = √(4/3 E_eff m_eff) (§3.2) and E_eff = E/(2(1−ν²)). Sliding is limited by
μ |F_n + F_adh r_eff/⟨r_eff⟩| (§3.1: "proportional to |Fn+Fadh|"), i.e. by μ times the Hertz and
damping parts. This module integrates a head-on collision (normal law alone) and the tangential
impulse of an oblique collision that slides throughout (the limit alone), as references for the
engines' single-contact tests; SI units throughout.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp


@dataclass(frozen=True)
class SeedPair:
    """One contact of the seed's law: E_eff [Pa], m_eff [kg], r_eff [m], γ_n [kg/(m^½ s)],
    the pair's pull-off force F_adh r_eff/⟨r_eff⟩ [N] and the sliding coefficient μ [-]."""
    E_eff: float
    m_eff: float
    r_eff: float
    gamma_n: float
    f_adh: float
    mu: float = 0.0

    def normal_force(self, xi: float, xidot: float) -> float:
        """Seed 000 eq. 1 [N] (repulsive positive) for ξ > 0."""
        return 4.0 / 3.0 * self.E_eff * math.sqrt(self.r_eff) * xi ** 1.5 + \
            self.gamma_n * math.sqrt(xi) * xidot - self.f_adh


@dataclass(frozen=True)
class Collision:
    """A head-on collision: times [s] and overlaps [m] while in contact, the relative normal
    speeds at contact and at separation [m/s] (NaN when the pair sticks), contact time [s],
    largest overlap [m], normal restitution [-] and the sliding-limit integrals
    ∫ μ|F_n + F_adh| dt (seed) and ∫ μ(F_Hertz + F_adh) dt [N s]."""
    t: np.ndarray
    xi: np.ndarray
    v_in: float
    v_out: float
    contact_time: float
    max_overlap: float
    restitution: float
    seed_tangential_impulse: float
    hertz_plus_adhesion_impulse: float


def head_on(pair: SeedPair, v_in: float, t_max: float | None = None) -> Collision:
    """Integrate m_eff ξ̈ = −F_n(ξ, ξ̇) from first touch (ξ = 0, ξ̇ = ``v_in`` > 0) to separation
    (ξ back to 0). Tolerances 1e-11 relative: far below the engines' time-step error."""
    k = 4.0 / 3.0 * pair.E_eff * math.sqrt(pair.r_eff)
    # the elastic contact time sets the scale of the integration window
    tc = 2.868 * (pair.m_eff ** 2 / (pair.r_eff * pair.E_eff ** 2 * v_in)) ** 0.2
    t_max = 50 * tc if t_max is None else t_max

    def rhs(t, y):
        xi, xd = max(y[0], 0.0), y[1]
        fn = pair.normal_force(xi, xd)
        fh = k * xi ** 1.5
        seed = pair.mu * abs(fn + pair.f_adh)
        lmp = pair.mu * (fh + pair.f_adh)
        return [xd, -fn / pair.m_eff, seed, lmp]

    def separated(t, y):
        return y[0]
    separated.terminal = True
    separated.direction = -1
    sol = solve_ivp(rhs, (0.0, t_max), [0.0, v_in, 0.0, 0.0], events=separated, rtol=1e-11, atol=1e-20,
                    max_step=tc / 2000, dense_output=False)
    done = sol.status == 1
    v_out = -float(sol.y[1, -1]) if done else float("nan")
    return Collision(t=sol.t, xi=sol.y[0], v_in=v_in, v_out=v_out, contact_time=float(sol.t[-1]) if done else float("nan"),
                     max_overlap=float(sol.y[0].max()), restitution=v_out / v_in,
                     seed_tangential_impulse=float(sol.y[2, -1]), hertz_plus_adhesion_impulse=float(sol.y[3, -1]))


def seed_pair(E: float, nu: float, rho: float, r1: float, r2: float, f_adh_median: float, d50: float,
              mu: float = 0.0) -> SeedPair:
    """The seed's contact between spheres of radii ``r1``, ``r2`` [m] of one material (E [Pa],
    ν, ρ [kg/m³]): E_eff = E/(2(1−ν²)), γ_n = √(4/3 E_eff m_eff), pull-off
    F_adh r_eff/⟨r_eff⟩ with ⟨r_eff⟩ = d50/4 (two median spheres, as orchestrator.derive)."""
    E_eff = E / (2.0 * (1.0 - nu * nu))
    m1, m2 = (rho * 4.0 / 3.0 * math.pi * r ** 3 for r in (r1, r2))
    m_eff = m1 * m2 / (m1 + m2)
    r_eff = r1 * r2 / (r1 + r2)
    return SeedPair(E_eff=E_eff, m_eff=m_eff, r_eff=r_eff, gamma_n=math.sqrt(4.0 / 3.0 * E_eff * m_eff),
                    f_adh=f_adh_median * r_eff / (d50 / 4.0), mu=mu)
