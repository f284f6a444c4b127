"""Derived physical parameters: computed once from a case and handed to *both* engines.

Templates do no physics arithmetic; every number in a deck comes from :func:`derive`. All values
are SI. Formulas:

- effective modulus E* = [(1-ν₁²)/E₁ + (1-ν₂²)/E₂]⁻¹, shear G* = [2(2-ν₁)(1+ν₁)/E₁ +
  2(2-ν₂)(1+ν₂)/E₂]⁻¹ (Johnson 1985, §4 and §7; the same expressions as LIGGGHTS'
  ``normal_model_hertz.h``);
- Hertz impact at relative normal speed v (Johnson 1985, §11.4): maximum overlap
  δ_max = (15 m* v² / (16 E* √R*))^(2/5), contact time t_c = 2.868 (m*²/(R* E*² v))^(1/5),
  peak force F_max = 4/3 E* √R* δ_max^(3/2);
- Rayleigh time step dt_R = π R_min √(ρ/G) / (0.1631 ν + 0.8766) (Li, Xu & Thornton 2005);
- viscous damping from restitution (Tsuji et al. 1992): both engines use
  c_n = -2 √(5/6) β √(2 E* √(R* δ) m*), β = ln e / √(ln² e + π²). Without tensile clipping
  this law delivers exactly the e fed in (Antypov & Elliott 2011, eq. 17): that is YADE's
  Mindlin, measured here to within the time-discretisation error. LIGGGHTS clips the tensile
  force (``limitForce on``), which raises the delivered e (0.55 for 0.5 fed in, 0.32 for 0.2), so
  :func:`restitution_input` integrates the clipped contact once and inverts it;
- critical time step of a damped contact: the undamped one times √(1+ζ²) − ζ, ζ the damping
  ratio that gives e_n (Belytschko, Liu & Moran 2000, eq. 6.3.40 for central differences).
"""
from __future__ import annotations

import math

from .contact_law import (  # noqa: F401  (re-exported: scenes and tests import them from here)
    DerivationError, effective_modulus, effective_shear_modulus, reduced,
    hertz_max_overlap, hertz_contact_time, hertz_peak_force, rayleigh_time_step,
    sliding_limit_tangential_restitution, sliding_threshold_angle, damping_ratio, tsuji_beta,
    delivered_restitution, restitution_input, sqrt_damping_gamma)
from .params import Material, Params, Restitution, WallMaterial
from .registry import get_engine, get_scene
from .stability.checks import check, monitor_limits


def adhesion_force(case) -> float:
    """Pull-off force F_adh [N] at the median contact (seed 000 eq. 1's constant), 0 without
    adhesion: the case's ``contact.adhesion.force``, or DMT 4π γ r_eff from a surface energy with
    r_eff = d50/4 (two median spheres)."""
    a = case.contact.adhesion
    if a is None:
        return 0.0
    if a.force is not None:
        return a.force
    return 4 * math.pi * a.surface_energy * case.scene.psd.median / 4


# ----------------------------------------------------------------------------------------------
# The case -> parameters
# ----------------------------------------------------------------------------------------------
#: a Hertz collision is resolved when it spans at least this many steps (O'Sullivan & Bray 2004
#: show central-difference error below 1 % from ~ 10 steps per contact); the critical step is t_c/10.
HERTZ_STEPS_PER_CONTACT = 10


def wall_material(case) -> tuple[float, float]:
    """(E_wall [Pa], ν_wall) from the case's ``wall`` section."""
    return case.wall_moduli()


def tangential_history_features(case) -> list[str]:
    """``tangential_history_<displacement|force>`` when the case names the Mindlin spring's history
    (``contact.tangential_history``) and has friction to keep one; [] otherwise (each engine's own)."""
    c = case.contact
    return [f"tangential_history_{c.tangential_history}"] if c.tangential_history and c.friction > 0 else []


def derive(case) -> Params:
    """All numbers the templates need (:class:`orchestrator.params.Params`, SI units). Every
    engine the case names derives its own numbers from them once here (``Engine.engine_params``),
    so a case an engine cannot realise is refused when it is validated."""
    mod = get_scene(case.scene.kind)
    mat = case.material
    E, nu, rho = mat.youngs_modulus, mat.poisson_ratio, mat.density
    Ew, nuw = wall_material(case)
    r_min, r_max = size_range(case)
    m_min = rho * 4 / 3 * math.pi * r_min ** 3
    E_pp = effective_modulus(E, nu, E, nu)
    E_pw = effective_modulus(E, nu, Ew, nuw)
    G_pp = effective_shear_modulus(E, nu, E, nu)
    G_pw = effective_shear_modulus(E, nu, Ew, nuw)
    e_target = case.contact.restitution
    v_max = float(mod.max_velocity(case))
    dt_R = rayleigh_time_step(r_min, rho, E, nu)
    # Hertz limit: smallest pair (m* = m/2, R* = r/2) and smallest sphere on a wall at v_max
    tc_pp = hertz_contact_time(m_min / 2, r_min / 2, E_pp, v_max) if v_max > 0 else math.inf
    tc_pw = hertz_contact_time(m_min, r_min, E_pw, v_max) if v_max > 0 else math.inf
    zeta = damping_ratio(e_target)
    damping_factor = math.sqrt(1 + zeta ** 2) - zeta
    dt_H = min(tc_pp, tc_pw) / HERTZ_STEPS_PER_CONTACT * damping_factor
    dt_crit = min(dt_R * damping_factor, dt_H)
    ts = case.timestep
    dt = ts.dt if ts.dt is not None else ts.fraction * dt_crit
    too_big = None
    if dt > dt_crit and not ts.allow_unsafe:   # refused below, with this case's largest safe fraction
        too_big = (f"timestep: dt = {dt:.3e} s is above the critical time step {dt_crit:.3e} s "
                   f"(Rayleigh {dt_R:.3e} s for r_min = {r_min:.3e} m; Hertz t_c/{HERTZ_STEPS_PER_CONTACT} = "
                   f"{dt_H / damping_factor:.3e} s at v = {v_max:.3g} m/s; both times {damping_factor:.3f} for the "
                   f"damping ratio {zeta:.3f} of e_n = {e_target}); ")
    params = Params(
        material=Material(E=E, nu=nu, rho=rho, G=E / (2 * (1 + nu))), wall=WallMaterial(E=Ew, nu=nuw),
        E_eff_pp=E_pp, E_eff_pw=E_pw, G_eff_pp=G_pp, G_eff_pw=G_pw,
        restitution=Restitution(target=e_target, damping_ratio=zeta),
        friction=case.contact.friction, tangential_stiffness_ratio=case.contact.tangential_stiffness_ratio,
        tangential_damping=case.contact.tangential_damping is not False,
        r_min=r_min, r_max=r_max, dt=dt, dt_rayleigh=dt_R, dt_hertz=dt_H, dt_critical=dt_crit,
        dt_fraction=dt / dt_crit, v_max=v_max, dt_damping_factor=damping_factor,
        gravity=case.gravity, gravity_vector=[0.0, 0.0, -case.gravity],
        features=list(mod.required_features(case)) + tangential_history_features(case), scene=None)
    params = params.replace(scene=mod.derive(case, params))
    if too_big:
        from .stability.checks import largest_safe_dt
        dt_max, binding = largest_safe_dt(case, params)
        raise DerivationError(too_big + f"the largest safe dt for this case is {dt_max:.3e} s ({binding} limit): use "
                              f"timestep.fraction <= {int(dt_max / dt_crit * 1000) / 1000:g} or a dt below {dt_max:.3e} s, or set "
                              "timestep.allow_unsafe: true")
    # every stability limit (Rayleigh, Hertz at the largest speed incl. walls, damping, rolling and
    # twisting springs, skin) and the in-deck monitors' thresholds (orchestrator.stability.checks)
    report = check(case, params)
    params = params.replace(stability=report, monitors=monitor_limits(case, params, report))
    for name in case.engines:          # engine-specific refusals (DerivationError) at validation
        get_engine(name).engine_params(case, params)
    return params


def size_range(case) -> tuple[float, float]:
    """(r_min, r_max) [m] of the case's particles."""
    return get_scene(case.scene.kind).size_range(case)
