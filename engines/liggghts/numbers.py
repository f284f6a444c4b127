"""LIGGGHTS-specific numbers: what ``pair_style gran`` must be given so that it delivers the case's
physics (every other number comes from :func:`orchestrator.derive.derive`, shared by all engines).
Handed to the templates as ``engine`` (:meth:`engines.liggghts.adapter.Liggghts.engine_params`).

- ``model hertz`` with ``coefficientRestitution`` is Tsuji damping, and ``limitForce on`` clips
  the tensile force, which raises the delivered e (0.55 for 0.5 fed in): it is fed the inverse of
  the clipped law (:func:`orchestrator.contact_law.restitution_input`). ``coefficientRestitution``
  must exceed 0.05 (``global_properties.cpp``), so ``model hertz`` delivers at least e_n = 0.214;
  below that the case must accept the substitute ``low_restitution: hertz_stiffness_calibrated``
  (``model hertz/stiffness`` with a damping γ calibrated at the largest impact speed,
  :func:`orchestrator.contact_law.sqrt_damping_gamma`);
- ``cohesion sjkr``: F = k A with the contact area A ≈ 2π r_eff ξ, so k = F_adh/(2π r_eff ξ_σ)
  gives the seed's pull-off at the overlap ξ_σ expected under the normal stress (substitute
  ``sjkr_matched_overlap``);
- the decks realise ``adhesion`` and ``torsion_friction`` by one substitute each (the shear cell
  and plane shear decks), and torsion (``epsd2 torsionTorque``) only together with rolling.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from orchestrator.contact_law import DerivationError, restitution_input, sqrt_damping_gamma, tsuji_beta
from orchestrator.params import Frozen, FrozenMap, Params, opt

#: LIGGGHTS' ``coefficientRestitution`` must exceed 0.05 (global_properties.cpp)
MIN_RESTITUTION_INPUT = 0.05
#: the substitutes each scene's deck implements, by feature
DECK_SUBSTITUTES = {
    "shear_cell": {"adhesion": "sjkr_matched_overlap", "torsion_friction": "epsd2_torsion_torque"},
    "plane_shear": {"torsion_friction": "epsd2_torsion_torque"},
}


@dataclass(frozen=True)
class LiggghtsNumbers(Frozen):
    """The LIGGGHTS templates' own numbers (``engine`` in the templates)."""
    restitution_input: float        #: ``coefficientRestitution`` [-] (0: below what the clipped law delivers)
    beta: float                     #: Tsuji β of that input [-] (-1 when the input is 0)
    low_restitution: bool           #: the input is at or below MIN_RESTITUTION_INPUT: the case needs the substitute
    hertz_stiffness: FrozenMap | None = opt("low_restitution substitute: kn_pp, kn_pw [Pa], kt_pp, kt_pw [Pa], "
                                            "gamman_pp, gamman_pw [1/(m s)], calibrated_at_speed [m/s]")
    contact_restitution_input: float | None = opt("``coefficientRestitution`` [-] for the scene's own contact "
                                                  "restitution (shear cell, plane shear)")
    contact_beta: float | None = opt("Tsuji β of that input [-]")
    cohesion_energy_density: float | None = opt("``cohesionEnergyDensity`` k of cohesion sjkr [J/m³]")


def clipped_input(e_target: float) -> float:
    """The e fed to ``coefficientRestitution`` so that a collision delivers ``e_target``; 0 when the
    clipped law cannot deliver it at all (the substitute's case)."""
    try:
        return restitution_input(e_target)
    except DerivationError:
        return 0.0


def liggghts_numbers(case, params: Params) -> LiggghtsNumbers:
    """Raises DerivationError when a case asks for a substitute the scene's deck does not implement."""
    _check_substitutes(case, params)
    e_target = params.restitution.target
    e_in = clipped_input(e_target)
    low = e_in <= MIN_RESTITUTION_INPUT and "restitution_damping" in params.features
    hs = None
    if low:
        E_pp, E_pw, r_max, v_max = params.E_eff_pp, params.E_eff_pw, params.r_max, params.v_max
        m_ref = params.material.rho * 4 / 3 * math.pi * r_max ** 3
        hs = {"kn_pp": 4.0 / 3.0 * E_pp, "kn_pw": 4.0 / 3.0 * E_pw,
              "kt_pp": 8.0 * params.G_eff_pp, "kt_pw": 8.0 * params.G_eff_pw,
              "gamman_pp": sqrt_damping_gamma(e_target, m_ref / 2, r_max / 2, E_pp, v_max),
              "gamman_pw": sqrt_damping_gamma(e_target, m_ref, r_max, E_pw, v_max),
              "calibrated_at_speed": v_max}
    out = {}
    c = getattr(params.scene, "contact", None)
    if c is not None:
        ec = c.restitution.target
        ec_in = e_in if ec == e_target else restitution_input(ec)
        out.update(contact_restitution_input=ec_in, contact_beta=tsuji_beta(ec_in) if ec_in > 0 else -1.0)
        if c.adhesion_force > 0:
            # sjkr: F = k A, A ≈ 2 pi r_eff ξ; matched at the expected overlap
            out["cohesion_energy_density"] = c.adhesion_force / (2 * math.pi * c.r_eff_mean * c.expected_overlap)
    return LiggghtsNumbers(restitution_input=e_in, beta=tsuji_beta(e_in) if e_in > 0 else -1.0,
                           low_restitution=low, hertz_stiffness=hs, **out)


def _check_substitutes(case, params: Params) -> None:
    implemented = DECK_SUBSTITUTES.get(case.scene.kind, {})
    subs = case.contact.substitutes
    c = case.contact
    for feat, name in implemented.items():
        chosen = subs.get(f"liggghts.{feat}", subs.get(feat))
        if feat in params.features and chosen not in (None, name):
            raise DerivationError(f"contact.substitutes: the {case.scene.kind} scene's LIGGGHTS deck implements "
                                  f"'{feat}' only as '{name}', not '{chosen}'")
    if "torsion_friction" in implemented and "torsion_friction" in params.features and not (
            c.rolling is not None and (c.rolling.model == "seed000" or c.rolling.coefficient > 0)):
        raise DerivationError("contact.torsion: LIGGGHTS' torsion substitute (epsd2 torsionTorque) needs rolling "
                              "friction too; add contact.rolling")


def seed_term_ratios(case, params: Params, xs) -> list:
    """Engine.seed_term_ratios: sjkr adhesion k·A(ξ) (k matched at ξ_σ), the epsd2 rolling limit
    μ_r r_eff |F| with μ_r frozen at ξ_σ, and epsd2's torsion sharing the rolling limit."""
    c = params.scene.contact
    R = case.scene.psd.median / 2
    r_eff = R / 2
    xs = np.asarray(xs, float)
    rows = []
    k = liggghts_numbers(case, params).cohesion_energy_density
    if k is not None:
        d = 2 * R - xs
        area = np.abs(np.pi / 4 * ((d - 2 * R) * d * d * (d + 2 * R)) / d ** 2)   # sphere-intersection disc
        rows.append(("adhesion", "sjkr k·A(ξ), k matched at ξ_σ", list(k * area / c.adhesion_force)))
    if c.rolling_coefficient is not None:
        lever_seed = np.sqrt(2 * r_eff * xs)
        rows.append(("rolling limit", "epsd2 μ_r r_eff |F| (μ_r frozen at ξ_σ)",
                     list(c.rolling_coefficient * r_eff / lever_seed)))
    if c.torsion_coefficient is not None and c.rolling_coefficient is not None:
        lever_seed = c.torsion_coefficient * r_eff
        rows.append(("torsion limit", "epsd2 torsion shares the rolling limit",
                     [c.rolling_coefficient * r_eff / lever_seed] * len(xs)))
    return rows
