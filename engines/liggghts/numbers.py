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
- rolling: ``rolling_friction epsd2`` (substitute ``epsd2_constant``: its spring k_r = k_t(ξ) r_eff²
  with LIGGGHTS' Mindlin k_t = 8 G* √(r_eff ξ), 0.36 of the seed's k_t r_eff² at ξ_σ on the seed
  shear cell, and no dashpot; rolling_model_epsd2.h) or ``rolling_friction epsd3`` (substitute
  ``epsd3_matched``: k_r = C k_n μ_r² r_eff² with LIGGGHTS' Hertz k_n = 4/3 E* √(r_eff ξ)
  (normal_model_hertz.h), C = ``rollingStiffness`` set so that k_r is the seed's k_t r_eff² at the
  matched overlap, and the dashpot η 2√(I_r k_r), I_r = 1.4 m* r*² of the pair, with η giving the
  seed's 2√(k_r m_eff r_eff²) for the median pair; rolling_model_epsd3.h). The limit μ_r r_eff
  |F_n| is the same in both;
- the overlap-dependent stand-ins (sjkr's k, epsd3's C) are matched at ``contact.match_overlap``
  x ξ_σ (default ξ_σ);
- the decks realise ``adhesion`` by one substitute and ``torsion_friction`` by the rolling model's
  ``torsionTorque`` (the twist loads the rolling spring), so torsion only together with rolling.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from orchestrator.contact_law import DerivationError, restitution_input, sqrt_damping_gamma, tsuji_beta
from orchestrator.params import Frozen, FrozenMap, Params, opt

#: LIGGGHTS' ``coefficientRestitution`` must exceed 0.05 (global_properties.cpp)
MIN_RESTITUTION_INPUT = 0.05
#: the substitutes each scene's deck implements, by feature (the first is the default)
DECK_SUBSTITUTES = {
    "shear_cell": {"adhesion": ("sjkr_matched_overlap",),
                   "rolling_friction_load": ("epsd2_constant", "epsd3_matched"),
                   "torsion_friction": ("epsd2_torsion_torque", "epsd3_torsion_torque")},
    "plane_shear": {"rolling_friction_load": ("epsd2_constant", "epsd3_matched"),
                    "torsion_friction": ("epsd2_torsion_torque", "epsd3_torsion_torque")},
}
#: the rolling model each rolling or torsion substitute runs on (torsion rides on the rolling spring)
SUBSTITUTE_ROLLING_MODEL = {"epsd2_constant": "epsd2", "epsd3_matched": "epsd3",
                            "epsd2_torsion_torque": "epsd2", "epsd3_torsion_torque": "epsd3"}
#: I_r / (m_eff r_eff²) for an equal pair in epsd3's dashpot: I_r = 1.4 (m r²)²/(2 m r²) = 0.7 m r²,
#: m_eff r_eff² = (m/2)(r/2)² = m r²/8 (rolling_model_epsd3.h)
EPSD3_INERTIA_RATIO = 0.7 * 8.0


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
    rolling_model: str | None = opt("``rolling_friction`` model: epsd2 or epsd3")
    rolling_stiffness_coefficient: float | None = opt("epsd3 ``rollingStiffness`` C [-]: k_r = C k_n μ_r² r_eff²")
    rolling_viscous_damping: float | None = opt("epsd3 ``coefficientRollingViscousDamping`` η [-]")


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
        xi_m = matched_overlap(case, c)
        if c.adhesion_force > 0:
            # sjkr: F = k A, A ≈ 2 pi r_eff ξ; matched at the matched overlap (ξ_σ unless the case says)
            out["cohesion_energy_density"] = c.adhesion_force / (2 * math.pi * c.r_eff_mean * xi_m)
        if c.rolling_coefficient is not None:
            out.update(rolling_numbers(case, params, c, xi_m))
    return LiggghtsNumbers(restitution_input=e_in, beta=tsuji_beta(e_in) if e_in > 0 else -1.0,
                           low_restitution=low, hertz_stiffness=hs, **out)


def matched_overlap(case, c) -> float | None:
    """The overlap [m] at which LIGGGHTS' overlap-dependent stand-ins are matched: ``contact.match_overlap``
    x ξ_σ (ξ_σ when the case leaves it out)."""
    if c.expected_overlap is None:
        return None
    return c.expected_overlap * (case.contact.match_overlap or 1.0)


def _chosen(case, feat: str) -> str | None:
    subs = case.contact.substitutes
    return subs.get(f"liggghts.{feat}", subs.get(feat))


def hertz_kn(E_eff: float, r_eff: float, xi: float):
    """LIGGGHTS' ``model hertz`` normal stiffness k_n = 4/3 E* √(r_eff ξ) [N/m] (normal_model_hertz.h;
    F_n = k_n ξ), the k_n epsd3's spring C k_n μ_r² r_eff² scales with. ``xi`` may be an array."""
    return 4.0 / 3.0 * E_eff * np.sqrt(r_eff * xi)


def rolling_model(case) -> str:
    """The rolling model the case's LIGGGHTS deck runs: epsd2 unless ``rolling_friction_load:
    epsd3_matched``."""
    return SUBSTITUTE_ROLLING_MODEL[_chosen(case, "rolling_friction_load") or "epsd2_constant"]


def rolling_numbers(case, params: Params, c, xi_m: float) -> dict:
    """The rolling model and, for epsd3, C and η: k_r = C k_n(ξ_m) μ_r² r_eff² equals the seed's
    k_t r_eff² (``rolling_stiffness``) for the median pair at the matched overlap ξ_m, with LIGGGHTS'
    Hertz k_n = 4/3 E* √(r_eff ξ) (normal_model_hertz.h); η 2√(I_r k_r) equals the seed's
    2√(k_r m_eff r_eff²) (seed 000 §3.2: every friction spring critically damped)."""
    model = rolling_model(case)
    out = {"rolling_model": model}
    if model == "epsd3":
        kn = float(hertz_kn(params.E_eff_pp, c.r_eff_mean, xi_m))
        out["rolling_stiffness_coefficient"] = c.rolling_stiffness / (kn * c.rolling_coefficient ** 2
                                                                      * c.r_eff_mean ** 2)
        out["rolling_viscous_damping"] = math.sqrt(1.0 / EPSD3_INERTIA_RATIO)
    return out


def _check_substitutes(case, params: Params) -> None:
    implemented = DECK_SUBSTITUTES.get(case.scene.kind, {})
    c = case.contact
    for feat, names in implemented.items():
        chosen = _chosen(case, feat)
        if feat in params.features and chosen not in (None, *names):
            raise DerivationError(f"contact.substitutes: the {case.scene.kind} scene's LIGGGHTS deck implements "
                                  f"'{feat}' only as {' or '.join(repr(n) for n in names)}, not '{chosen}'")
    if "placed_clumps" in params.features and _chosen(case, "placed_clumps") == "inserted_clumps" \
            and case.engine_options.mpi_ranks > 1:
        # measured (session 19, the 100-clump smoke case on 2 ranks): fix insert/pack put 310 of the 311
        # member spheres in, a clump across the two subdomains lost one (docs/engines.md)
        raise DerivationError(f"engine_options.mpi_ranks: {case.engine_options.mpi_ranks} ranks, but LIGGGHTS-PUBLIC's "
                              "multisphere clumps (substitute 'inserted_clumps') run on one process: a clump "
                              "across two ranks' subdomains loses member spheres; set engine_options.mpi_ranks: 1 "
                              "(or run the case on YADE)")
    if "torsion_friction" in implemented and "torsion_friction" in params.features and not (
            c.rolling is not None and (c.rolling.model == "seed000" or c.rolling.coefficient > 0)):
        raise DerivationError("contact.torsion: LIGGGHTS' torsion substitute (the rolling model's torsionTorque) "
                              "needs rolling friction too; add contact.rolling")
    tors = _chosen(case, "torsion_friction")
    if "torsion_friction" in params.features and tors in SUBSTITUTE_ROLLING_MODEL \
            and SUBSTITUTE_ROLLING_MODEL[tors] != rolling_model(case):
        roll = _chosen(case, "rolling_friction_load") or "epsd2_constant"
        raise DerivationError(f"contact.substitutes: LIGGGHTS' torsion rides on the rolling model, so "
                              f"rolling_friction_load '{roll}' needs torsion_friction "
                              f"'{rolling_model(case)}_torsion_torque', not '{tors}'")


def seed_term_ratios(case, params: Params, xs) -> list:
    """Engine.seed_term_ratios: sjkr adhesion k·A(ξ) (k matched at the matched overlap), the rolling
    spring (epsd2: LIGGGHTS' k_t(ξ) r_eff²; epsd3: C k_n(ξ) μ_r² r_eff²) against the seed's k_t r_eff²,
    the rolling limit μ_r r_eff |F| with μ_r frozen at ξ_σ, and the torsion sharing the rolling limit."""
    c = params.scene.contact
    R = case.scene.psd.median / 2
    r_eff = R / 2
    xs = np.asarray(xs, float)
    rows = []
    num = liggghts_numbers(case, params)
    at = "ξ_σ" if not case.contact.match_overlap else f"{case.contact.match_overlap:g} ξ_σ"
    k = num.cohesion_energy_density
    if k is not None:
        d = 2 * R - xs
        area = np.abs(np.pi / 4 * ((d - 2 * R) * d * d * (d + 2 * R)) / d ** 2)   # sphere-intersection disc
        rows.append(("adhesion", f"sjkr k·A(ξ), k matched at {at}", list(k * area / c.adhesion_force)))
    if c.rolling_coefficient is not None:
        model = num.rolling_model
        if c.rolling_stiffness:
            if model == "epsd3":
                kr = (num.rolling_stiffness_coefficient * hertz_kn(params.E_eff_pp, r_eff, xs)
                      * c.rolling_coefficient ** 2 * r_eff ** 2)
                label = f"epsd3 C k_n(ξ) μ_r² r_eff², matched at {at}"
            else:
                kr = 8.0 * params.G_eff_pp * np.sqrt(r_eff * xs) * r_eff ** 2
                label = "epsd2 k_t(ξ) r_eff² (LIGGGHTS' Mindlin k_t)"
            rows.append(("rolling stiffness", label, list(kr / c.rolling_stiffness)))
        lever_seed = np.sqrt(2 * r_eff * xs)
        rows.append(("rolling limit", f"{model} μ_r r_eff |F| (μ_r frozen at ξ_σ)",
                     list(c.rolling_coefficient * r_eff / lever_seed)))
    if c.torsion_coefficient is not None and c.rolling_coefficient is not None:
        lever_seed = c.torsion_coefficient * r_eff
        rows.append(("torsion limit", f"{num.rolling_model} torsion shares the rolling limit",
                     [c.rolling_coefficient * r_eff / lever_seed] * len(xs)))
    return rows
