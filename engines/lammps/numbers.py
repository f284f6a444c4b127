"""LAMMPS-specific numbers: what ``pair_style granular`` and ``fix wall/gran granular`` must be
given so that they deliver the case's physics (every other number comes from
:func:`orchestrator.derive.derive`, shared by all engines).

Sources (LAMMPS 22 Jul 2025, ``src/GRANULAR``):

- ``hertz/material E e ν`` between two particles of one material: F = 4/3 E* √R δ^(3/2) with
  E* = E/(2(1-ν²)) (``GranSubMod::mix_stiffnessE``); against a ``fix wall/gran`` wall the same
  E/(2(1-ν²)) of the numbers given to the fix (``mix_stiffnessE_wall``: the wall is taken to be
  of the particle's material). A wall of another material is therefore given the E' that makes
  E'/(2(1-ν²)) the case's particle-wall E* (:func:`wall_young`). The 2021 Debian build used
  E/(2(1-ν)) there, 7.6 % too stiff at ν = 0.2; the 2025 wheel does not (checked by the
  Chung & Ooi sphere-plane cases, whose contact times agree with Hertz to 1e-4);
- ``tangential mindlin k_t x_γt μ``: F_t = -min(μ F_n, |k_t a ξ + η_t v_t|) with the contact
  radius a = √(R δ) and the total tangential displacement ξ, k_t = 8 G* (given explicitly);
  the same no-slip Mindlin stiffness and total-displacement history as LIGGGHTS' ``tangential
  history`` (Chung & Ooi 2011's "Mindlin" is the no-slip k_t = 8 G* a);
- ``damping coeff_restitution`` (``GranSubModDampingCoeffRestitution``): η_n = 2√(5/6)(-β)
  √(m* S_n), S_n = 2 E* a, β = ln e/√(ln²e + π²): LIGGGHTS' and YADE's Tsuji form; with
  ``limit_damping`` the total normal force is clipped at zero as LIGGGHTS' ``limitForce on``,
  so the same inverse (:func:`orchestrator.derive.restitution_input`) delivers the requested e;
- tangential damping η_t = x_γt η_n: LIGGGHTS uses η_t = 2√(5/6)(-β)√(m* S_t), S_t = 8 G* a,
  so x_γt = √(S_t/S_n) = √(4 G*/E*) (:func:`tangential_damping_factor`);
- ``damping viscoelastic``: η_n = η_n0 a m* (Brilliantov et al. 1996): the damping force
  η_n0 m* √R √δ δ̇ is seed 000 eq. 1's γ_n √ξ ξ̇ when η_n0 = γ_n/(m* √R*) (:func:`viscoelastic_eta`).
"""
from __future__ import annotations

import math


def wall_young(E_eff_target: float, nu: float) -> float:
    """Young's modulus [Pa] to give ``fix wall/gran granular hertz/material E' e ν`` so that its
    E'/(2(1-ν²)) equals ``E_eff_target`` [Pa], the case's particle-wall E*."""
    return 2.0 * (1.0 - nu * nu) * E_eff_target


def tangential_damping_factor(E_eff: float, G_eff: float) -> float:
    """x_γt = η_t/η_n = √(S_t/S_n) = √(8 G* a/(2 E* a)) = √(4 G*/E*) [-]: LAMMPS' tangential
    damping equal to LIGGGHTS' (normal_model_hertz.h: γ_t = -2√(5/6) β √(S_t m*))."""
    return math.sqrt(4.0 * G_eff / E_eff)


def restitution_damping(params: dict) -> dict:
    """``damping coeff_restitution`` input: {``e_input``, ``limit_damping``}. With tensile clipping
    (``limit_damping``) the e that LIGGGHTS is fed (the clipped law's inverse); below what the
    clipped law can deliver (``engine_input`` 0) the unclipped law is used and fed the target
    itself, as YADE is (Antypov & Elliott 2011, eq. 17)."""
    r = params["restitution"]
    if r["target"] >= 1.0:
        return {"e_input": 1.0, "limit_damping": True}
    if r["engine_input"] > 0:
        return {"e_input": r["engine_input"], "limit_damping": True}
    return {"e_input": r["target"], "limit_damping": False}


def viscoelastic_eta(gamma_n: float, m_eff: float, R_eff: float) -> float:
    """η_n0 [1/(m s)] of ``damping viscoelastic`` whose force η_n0 m* √(R* δ) δ̇ equals
    γ_n √δ δ̇ (seed 000 eq. 1) for a pair of reduced mass ``m_eff`` [kg] and radius ``R_eff`` [m]."""
    return gamma_n / (m_eff * math.sqrt(R_eff))


def seed_gamma_n(E_eff: float, m_eff: float) -> float:
    """Seed 000's normal damping constant γ_n = √(4/3 E* m*) [kg/(m^½ s)] (section 3.2)."""
    return math.sqrt(4.0 / 3.0 * E_eff * m_eff)


def lammps_numbers(params: dict) -> dict:
    """The numbers the LAMMPS templates need beyond ``params`` (SI)."""
    mat = params["material"]
    d = restitution_damping(params)
    return {
        "damping": d,
        "pair": {"E": mat["E"], "nu": mat["nu"], "kt": 8.0 * params["G_eff_pp"],
                 "xgt": tangential_damping_factor(params["E_eff_pp"], params["G_eff_pp"])},
        "wall": {"E": wall_young(params["E_eff_pw"], mat["nu"]), "nu": mat["nu"], "kt": 8.0 * params["G_eff_pw"],
                 "xgt": tangential_damping_factor(params["E_eff_pw"], params["G_eff_pw"])},
    }
