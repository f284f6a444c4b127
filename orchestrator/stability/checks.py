"""Pre-run stability checks: every critical time step a case implies, the chosen dt as a fraction
of each, and the limits the in-deck monitors trip on. All SI.

Limits (each for the *stiffest* contact the case can produce):

- ``rayleigh``: Rayleigh-wave step of the smallest sphere, π r_min √(ρ/G)/(0.1631ν+0.8766)
  (Li, Xu & Thornton 2005);
- ``hertz``: central-difference stability 2/ω of the stiffest Hertz contact, ω² = k_tan/m*,
  k_tan = dF/dδ = 2E*√(R*δ) at the largest expected overlap δ: the larger of the elastic impact
  overlap at the largest expected relative speed (particle speeds *and* wall speeds, doubled for
  a rebound off a moving wall) and the static overlap under the confining force (plus adhesion);
  computed for two smallest spheres (the largest k/m*) and for the smallest sphere on a wall;
- ``tangential``: 2/ω_t of the tangential (Mindlin) spring k_t = (4G*/E*) k_n on the contact
  point's effective mass m*/3.5 (translation plus rotation of spheres), with the damping ratio
  ζ√3.5 that the same restitution gives it;
- ``coordination``: the same tangential spring and dashpot on a grain that turns against Z = 6
  contacts at once (rotational row of the packing's stiffness matrix, O'Sullivan & Bray 2004);
- ``contact_time``: the Hertz contact time t_c at that speed: dt ≤ t_c/10 resolves a collision
  (an accuracy limit; the safe fraction of it is 1);
- ``rolling`` / ``twisting``: 2/ω of the rolling (twisting) spring on the rotational inertia of
  the smallest sphere, ω² = k_r/(I/2), I = 2/5 m r²; k_r is YADE's absolute ``krot`` or
  LIGGGHTS' epsd2 k_r = 2.25 k_n μ_r² R*² (whichever is larger);
- ``skin``: a wall or grain may move at most half the neighbour skin per step, v dt ≤ skin/2.

Every contact limit is multiplied by √(1+ζ²) − ζ, ζ the damping ratio of the restitution
(central differences with viscous damping; Belytschko, Liu & Moran 2000, eq. 6.3.40).

A dt above ``stability.safe_fraction`` of any stability limit (``contact_time``: above t_c/10)
is refused unless ``timestep.allow_unsafe``; :func:`check` raises
:class:`orchestrator.derive.DerivationError` with every number.
"""
from __future__ import annotations

import math

from ..contact_law import (DerivationError, damping_ratio, hertz_contact_time, hertz_max_overlap,
                           rayleigh_time_step)
from ..params import StabilityInputs
from ..registry import get_scene

#: limits that are about stability (dt must stay below safe_fraction × limit)
STABILITY_LIMITS = ("rayleigh", "hertz", "tangential", "coordination", "rolling", "twisting", "skin")
#: contacts per grain assumed by the ``coordination`` limit (jammed spheres: 4-6, Silbert et al. 2002)
COORDINATION = 6
#: a collision spans at least this many steps (accuracy; derive.HERTZ_STEPS_PER_CONTACT)
STEPS_PER_CONTACT = 10


def scene_inputs(case, params) -> StabilityInputs:
    """What the checks need from the scene, asked of it (``Scene.stability_inputs``,
    :class:`orchestrator.params.StabilityInputs`): particles, steps, box, confining stress [Pa],
    wall speeds [m/s], neighbour skin [m] (default r_max/2), height of the granular region [m],
    contact springs and limits."""
    inp = get_scene(case.scene.kind).stability_inputs(case, params)
    if inp.skin is None:
        inp = inp.replace(skin=0.5 * params.r_max)
    return inp


def _static_overlap(F: float, E_eff: float, R_eff: float) -> float:
    """Hertz overlap [m] under a normal force F [N]."""
    return (3 * F / (4 * E_eff * math.sqrt(R_eff))) ** (2 / 3) if F > 0 else 0.0


def critical_steps(case, params: dict) -> dict:
    """All limits [s] and the inputs they came from (see the module docstring)."""
    mat = case.material
    E, nu, rho = mat.youngs_modulus, mat.poisson_ratio, mat.density
    r_min, r_max = params.r_min, params.r_max
    m_min = rho * 4 / 3 * math.pi * r_min ** 3
    inp = scene_inputs(case, params)
    v_walls = max(inp.wall_speeds.values(), default=0.0)
    # particle speeds from the scene (derive's v_max) and twice any wall speed (rebound off a wall)
    v = max(params.v_max, 2 * v_walls)
    e = case.contact.restitution
    if inp.restitution is not None:
        e = min(e, inp.restitution)      # e.g. the restitution seed000 damping delivers
    zeta = damping_ratio(e)
    fd = math.sqrt(1 + zeta ** 2) - zeta
    sigma = inp.confining_stress
    F_adh = inp.adhesion_force or 0.0
    # a big grain's share of the confining force, pressed onto the smallest contact (conservative)
    F_conf = sigma * (2 * r_max) ** 2 / 0.6 + F_adh
    pairs = {"particle-particle": (m_min / 2, r_min / 2, params.E_eff_pp),
             "particle-wall": (m_min, r_min, params.E_eff_pw)}
    hertz, tc, detail = math.inf, math.inf, {}
    for name, (m, R, Es) in pairs.items():
        d_imp = hertz_max_overlap(m, R, Es, v) if v > 0 else 0.0
        d_sta = _static_overlap(F_conf, Es, R)
        d = max(d_imp, d_sta, 1e-12 * R)
        k_tan = 2 * Es * math.sqrt(R * d)
        w = math.sqrt(k_tan / m)
        t_c = hertz_contact_time(m, R, Es, v) if v > 0 else math.inf
        detail[name] = {"overlap": d, "overlap_impact": d_imp, "overlap_static": d_sta, "k_tangent": k_tan,
                        "omega": w, "contact_time": t_c}
        hertz = min(hertz, 2 / w * fd)
        tc = min(tc, t_c)
    limits = {"rayleigh": rayleigh_time_step(r_min, rho, E, nu) * fd, "hertz": hertz,
              "contact_time": tc * fd / STEPS_PER_CONTACT}
    if case.contact.friction > 0:
        # the tangential spring k_t = 8 G* a = (4 G*/E*) k_n acts on the contact point, whose
        # effective mass is m*/(1 + m* R²/I*) = m*/3.5 for spheres (translation + rotation); both
        # engines damp it like the normal spring (c_t from e with k_t and m*), so its damping
        # ratio relative to that mass is ζ √3.5. Measured (YADE, e = 0.15): unstable at 0.37 of
        # the normal Hertz limit, which this limit reproduces (docs/stability.md).
        G_pp = params.G_eff_pp
        kt_ratio = 4 * G_pp / params.E_eff_pp
        w_t = math.sqrt(kt_ratio * 3.5) * detail["particle-particle"]["omega"]
        zeta_t = zeta * math.sqrt(3.5)
        fd_t = math.sqrt(1 + zeta_t ** 2) - zeta_t
        limits["tangential"] = 2 / w_t * fd_t
        detail["tangential"] = {"omega": w_t, "damping_ratio": zeta_t, "damping_factor": fd_t}
        # a grain in a packing turns against all its Z contacts at once: the rotational row of the
        # global stiffness matrix of the smallest grain is Z k_t r²/I (O'Sullivan & Bray 2004, Eng.
        # Comput. 21:278, who bound the critical step of DEM packings through that matrix: it grows
        # with the coordination number), so ω_rot² = Z k_t r²/I = 2.5 Z k_t/m against the pair's
        # contact-point ω_t² = 3.5 k_t/m* = 7 k_t/m. Each contact's tangential dashpot
        # c_t = 2 ζ_t ω_t m/7 adds c_t r² to the rotational damping: ζ_rot = ζ_t (Z/2.8)(ω_t/ω_rot).
        # Z = 6, the isostatic (largest) coordination of jammed frictionless spheres; frictional
        # packings have 4-6 (Silbert et al. 2002, PRE 65:031304). Measured: YADE with e = 0.15 heats
        # the settled packing from f = 0.6 while the pair limits accepted 0.69 (docs/stability.md).
        Z = COORDINATION
        w_rot = math.sqrt(2.5 * Z / 7) * math.sqrt(kt_ratio * 3.5) * detail["particle-particle"]["omega"]
        zeta_rot = zeta_t * Z / 2.8 * w_t / w_rot
        fd_rot = math.sqrt(1 + zeta_rot ** 2) - zeta_rot
        limits["coordination"] = 2 / w_rot * fd_rot
        detail["coordination"] = {"omega": w_rot, "damping_ratio": zeta_rot, "damping_factor": fd_rot,
                                  "coordination_number": Z}
    I_half = 0.5 * 0.4 * m_min * r_min ** 2
    kn = detail["particle-particle"]["k_tangent"]
    R_pp = r_min / 2
    k_r = [k for k in (inp.rolling_stiffness,
                       2.25 * kn * inp.rolling_coefficient ** 2 * R_pp ** 2 if inp.rolling_coefficient else None)
           if k]
    if k_r:
        limits["rolling"] = 2 / math.sqrt(max(k_r) / I_half) * fd
    k_t = [k for k in (inp.twisting_stiffness,
                       2.25 * kn * inp.torsion_coefficient ** 2 * R_pp ** 2 if inp.torsion_coefficient else None)
           if k]
    if k_t:
        limits["twisting"] = 2 / math.sqrt(max(k_t) / I_half) * fd
    skin = inp.skin
    if v > 0 and skin > 0:
        limits["skin"] = 0.5 * skin / v
    return {"limits": limits, "damping_ratio": zeta, "damping_factor": fd, "speed": v,
            "wall_speeds": dict(inp.wall_speeds), "confining_stress": sigma, "confining_force": F_conf,
            "skin": skin, "contacts": detail, "inputs": inp}


def safe_fractions(case) -> dict:
    sf = case.stability.safe_fraction
    return {k: (1.0 if k == "contact_time" else sf) for k in ("rayleigh", "hertz", "tangential", "coordination",
                                                              "contact_time", "rolling", "twisting", "skin")}


def largest_safe_dt(case, params: dict) -> tuple[float, str]:
    """(largest dt [s] within every stability limit's safe fraction, the binding limit)."""
    cs = critical_steps(case, params)
    safe = safe_fractions(case)
    binding = min(cs["limits"], key=lambda k: cs["limits"][k] * safe[k])
    return cs["limits"][binding] * safe[binding], binding


def check(case, params: dict) -> dict:
    """The stability report for ``params['dt']``; raises DerivationError when dt is above a safe
    fraction of any limit and the case does not set ``timestep.allow_unsafe``."""
    cs = critical_steps(case, params)
    dt = params.dt
    safe = safe_fractions(case)
    fractions = {k: dt / v for k, v in cs["limits"].items()}
    over = {k: f for k, f in fractions.items() if f > safe[k]}
    binding = min(cs["limits"], key=lambda k: cs["limits"][k] * safe[k])
    dt_max = cs["limits"][binding] * safe[binding]
    report = {"dt": dt, "limits": cs["limits"], "fractions": fractions, "safe_fractions": safe,
              "binding": binding, "dt_max_safe": dt_max, "dt_max_safe_fraction_of_critical": dt_max / params.dt_critical,
              "ok": not over, "forced": bool(over) and case.timestep.allow_unsafe,
              "damping_factor": cs["damping_factor"], "damping_ratio": cs["damping_ratio"],
              "speed": cs["speed"], "wall_speeds": cs["wall_speeds"], "confining_stress": cs["confining_stress"],
              "skin": cs["skin"], "contacts": cs["contacts"]}
    worst = max(c["overlap"] for c in cs["contacts"].values() if "overlap" in c) / params.r_min
    if worst > 0.1:
        report["warnings"] = [f"the stiffest contact is expected at an overlap of {worst:.2g} r_min (a big grain's "
                              f"share of the confining force on two smallest grains): Hertz is not valid there; the "
                              f"overlap monitor is raised accordingly and watches for blow-up only "
                              f"(cases/stability/very_soft: docs/stability.md)"]
    if over and not case.timestep.allow_unsafe:
        lines = [f"{k}: dt/limit = {fractions[k]:.3g} > {safe[k]:g} (limit {cs['limits'][k]:.3e} s)" for k in over]
        raise DerivationError(
            f"stability: dt = {dt:.3e} s is unsafe: " + "; ".join(lines)
            + f". Limits include the damping factor {cs['damping_factor']:.3f} (zeta = {cs['damping_ratio']:.3f}); "
            f"largest expected speed {cs['speed']:.3g} m/s (walls: "
            + (", ".join(f"{n} {s:.3g} m/s" for n, s in cs["wall_speeds"].items()) or "none")
            + f"), confining stress {cs['confining_stress']:.3g} Pa, skin {cs['skin']:.3g} m. "
            f"The largest safe dt is {dt_max:.3e} s ({binding}): use timestep.fraction <= "
            f"{int(dt_max / params.dt_critical * 1000) / 1000:g} or a dt below {dt_max:.3e} s, "
            "or set timestep.allow_unsafe: true to run anyway (the monitors still watch the run)")
    return report


def monitor_limits(case, params: dict, report: dict) -> dict:
    """Thresholds for the in-deck monitors (handed to the templates as ``p.monitors``)."""
    o = case.stability
    inp = scene_inputs(case, params)
    n = int(inp.n_particles)
    rho = case.material.density
    r_min, r_max = params.r_min, params.r_max
    steps = int(inp.total_steps)
    m_mean = rho * 4 / 3 * math.pi * ((r_min + r_max) / 2) ** 3
    mass = n * m_mean
    v = report["speed"]
    ke_scale = 0.5 * mass * v ** 2 + mass * abs(case.gravity) * inp.height
    ke_scale = max(ke_scale, 0.5 * mass * (1e-3 * math.sqrt(case.material.youngs_modulus / rho)) ** 2 * 1e-6)
    expected = max(c["overlap"] for c in report["contacts"].values() if "overlap" in c) / r_min
    # The overlap figure looks for blow-up, not for accuracy: it trips above overlap_limit, raised to
    # 4x the largest overlap the check expects from the physics (a big grain's share of the confining
    # force on the smallest contact), up to the geometric bound 2 r_max / r_min (two of the largest
    # grains with coinciding centres: no repulsive contact law integrated stably gets there). Soft
    # grains under high stress (very_soft, sigma/E = 5 %) reach overlaps of 0.8-0.93 r_min in runs
    # that are stable at every f (docs/stability.md): a fixed 0.9 flagged that physics as
    # instability. Where the limit is raised, blow-ups are caught by the kinetic energy, NaN,
    # grains-outside and wall-force figures (measured: docs/stability.md).
    overlap_limit = max(o.overlap_limit, min(4 * expected, 2 * r_max / r_min))
    out = {"enabled": bool(o.monitors), "every": max(1, steps // o.monitor_checks) if steps else 1000,
           "ke_limit": o.ke_factor * ke_scale, "ke_scale": ke_scale,
           "overlap_limit": overlap_limit, "r_min": r_min,
           # spheres the engine integrates: a clump scene's member spheres (scene key n_spheres)
           "n_particles": int(inp.n_spheres or n), "wall_force_target": inp.wall_force_target,
           "wall_force_factor": o.wall_force_factor}
    if inp.box_lo is not None:
        out["box_lo"], out["box_hi"] = list(inp.box_lo), list(inp.box_hi)
        out["periodic"] = list(inp.periodic)
    if out["wall_force_target"]:
        out["wall_force_limit"] = o.wall_force_factor * out["wall_force_target"]
    return out
