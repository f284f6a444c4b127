"""YADE-specific numbers: what ``Ip2_FrictMat_FrictMat_MindlinPhys`` / ``Law2_ScGeom_MindlinPhys_Mindlin``
and the decks' bodies must be given so that they deliver the case's physics (every other number
comes from :func:`orchestrator.derive.derive`, shared by all engines). Handed to the templates as
``engine`` (:meth:`engines.yade.adapter.Yade.engine_params`).

- Mindlin does not clip the tensile damping force: the Tsuji law delivers exactly the e it is fed
  (Antypov & Elliott 2011, eq. 17), so ``en`` = the requested e_n;
- Mindlin takes r_eff = R1 R2/(R1+R2) from the contact geometry: a Wall gives R/2, a Facet
  (refR1 = 2R) 2R/3, instead of the flat-wall Hertz value R. Measured: a sphere on a utils.wall had
  a Hertz contact time 2^(1/5) = 1.149 times too long. Facet walls get the modulus that restores
  the flat-wall stiffness (:func:`wall_young`);
- a rigid plane in the impact scene is, for each impacting sphere, a fixed sphere
  :data:`PLANE_SPHERE_FACTOR` times larger centred under that sphere's contact point: r_eff =
  R (1 - 1e-4), and the surface sags by (v_t t_c)²/(2 R_b) ~ 1e-8 R over the contact's sliding
  distance; the triaxial platens are fixed spheres 1e6 R0 large (sag over the sample radius:
  R0 · 5e-7);
- adhesion: DMT F = 4π γ r_eff, exact for the seed's F_adh r_eff/⟨r_eff⟩ with γ = F_adh/(4π ⟨r_eff⟩);
  rolling: M_max = η R̄ |F_n| with R̄ the mean radius (x50/2), so η = μ_r r_eff/R̄; the rolling
  and twisting springs ``krot``, ``ktwist`` are the seed's k_t r_eff² (scene numbers);
- the shear cell's relaxation drag F = -γ v is a Stokes drag 6π ν r of the median grain
  (ν = γ/(6π x50/2)), its servo a gain kP = v_max kp / F_target [m/(N s)].
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from orchestrator.contact_law import DerivationError
from orchestrator.params import Frozen, Params, opt

#: Mindlin's r_eff at a wall, as a fraction of the sphere's radius
WALL_RADIUS_RATIO = {"wall": 0.5, "facet": 2.0 / 3.0}
#: impact scene: a rigid plane is a fixed sphere this many times the impacting sphere's radius
PLANE_SPHERE_FACTOR = 1e4
#: triaxial scene: the platens are fixed spheres this many times the sample's radius
PLATEN_SPHERE_FACTOR = 1e6


def wall_young(E: float, nu: float, E_eff_target: float, nu_wall: float, kind: str = "facet") -> float:
    """Young's modulus [Pa] to give a YADE wall of ``kind`` so that Mindlin's k_n = 4/3 E* √r_eff
    (and its Tsuji damping) equals the flat-wall Hertz value with ``E_eff_target``: YADE uses
    r_eff = ratio·R, so its E* must be E_eff_target/√ratio. Raises DerivationError when no
    positive modulus can do it (a near-rigid wall): use a large fixed sphere instead."""
    ratio = WALL_RADIUS_RATIO[kind]
    need = E_eff_target / math.sqrt(ratio)
    inv = 1.0 / need - (1 - nu ** 2) / E
    if inv <= 0:
        raise DerivationError(f"a YADE {kind} wall cannot reproduce E* = {E_eff_target:.3e} Pa at r_eff = R "
                              f"(it would need E* = {need:.3e} Pa > E/(1-nu^2) = {E / (1 - nu ** 2):.3e} Pa)")
    return (1 - nu_wall ** 2) / inv


@dataclass(frozen=True)
class YadeNumbers(Frozen):
    """The YADE templates' own numbers (``engine`` in the templates)."""
    restitution_input: float                      #: Mindlin ``en`` = ``es`` [-]
    contact_restitution_input: float | None = opt("``en`` for the scene's own contact restitution [-]")
    wall_young: float | None = opt("facet walls' Young's modulus [Pa] (shear cell)")
    gamma: float | None = opt("DMT surface energy γ [J/m²]")
    eta: float | None = opt("rolling limit η: M_max = η R̄ |F_n| [-]")
    krot: float | None = opt("rolling spring [N m/rad]")
    ktwist: float | None = opt("twisting spring [N m/rad]")
    drag_nu: float | None = opt("relaxation drag as a viscosity ν, F = -6π ν r v [Pa s] (shear cell)")
    servo_kP: float | None = opt("servo gain kP = v_max kp / F_target [m/(N s)] (shear cell)")
    plane_spheres: tuple | None = opt("impact on a plane: centre (x, y, z) [m] of each plane sphere")
    plane_sphere_radius: float | None = opt("their radius [m]")
    platen_radius: float | None = opt("triaxial: radius of the platen spheres [m]")


def yade_numbers(case, params: Params) -> YadeNumbers:
    sc = params.scene
    out = {}
    c = getattr(sc, "contact", None)
    if c is not None:
        out["contact_restitution_input"] = c.restitution.target
        r_eff = c.r_eff_mean
        if c.adhesion_force > 0:
            out["gamma"] = c.adhesion_force / (4 * math.pi * r_eff)
        if c.rolling_coefficient is not None:
            out["eta"] = c.rolling_coefficient * r_eff / c.median_radius
            out["krot"] = c.rolling_stiffness
        if c.torsion_coefficient is not None:
            out["ktwist"] = c.twisting_stiffness
    kind = case.scene.kind
    if kind == "shear_cell":
        try:
            out["wall_young"] = wall_young(params.material.E, params.material.nu, params.E_eff_pw,
                                           params.wall.nu, "facet")
        except DerivationError as exc:
            raise DerivationError(f"wall: {exc}. The seed uses the particle material for the walls "
                                  "(wall: {youngs_modulus: ..., poisson_ratio: ..., density: ...})") from None
        x50 = case.scene.psd.median
        out["drag_nu"] = sc.gamma_visc / (6 * math.pi * x50 / 2)
        out["servo_kP"] = sc.servo.v_max * sc.servo.kp / sc.servo.target_force
    elif kind == "impact" and sc.target == "plane":
        Rb = PLANE_SPHERE_FACTOR * sc.radius
        out["plane_spheres"] = [[x, y, -Rb] for x, y in sc.contact_points]
        out["plane_sphere_radius"] = Rb
    elif kind == "triaxial" and sc.radius0 is not None:
        out["platen_radius"] = PLATEN_SPHERE_FACTOR * sc.radius0
    return YadeNumbers(restitution_input=params.restitution.target, **out)


def seed_term_ratios(case, params: Params, xs) -> list:
    """Engine.seed_term_ratios: DMT adhesion 4πγ r_eff (constant), Mindlin's rolling moment η R̄ |F|,
    Mindlin's ktwist (elastic, no limit)."""
    c = params.scene.contact
    R = case.scene.psd.median / 2
    r_eff = R / 2
    xs = np.asarray(xs, float)
    y = yade_numbers(case, params)
    rows = []
    if y.gamma is not None:
        rows.append(("adhesion", "DMT 4πγ r_eff (constant)", [4 * math.pi * y.gamma * r_eff / c.adhesion_force] * len(xs)))
    if y.eta is not None:
        rows.append(("rolling limit", "Mindlin moment η R̄ |F|", list(y.eta * R / np.sqrt(2 * r_eff * xs))))
    if c.torsion_coefficient is not None:
        rows.append(("torsion limit", "Mindlin ktwist: elastic, no limit", [math.inf] * len(xs)))
    return rows
