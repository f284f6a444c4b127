"""The vaned micro shear-tester of seed 000 (§2.1, §3.3): a cylinder closed by two pistons, each
with six vanes in a star; the lower piston carries the normal load (servo), the upper piston and
the sidewall rotate together about the axis.

Protocol (seed §3.3), every stage an absolute step range computed here, identical for both
engines:

1. ``relax``: the random loose packing (volume fraction ``loose_fraction`` ≈ 0.2, no overlaps by
   construction) relaxes under a viscous background force F = -γ v. Criterion: the stage lasts
   ``relax_damping_times`` damping times τ = m₅₀/γ (τ = ``relax_tau_steps`` steps), so the velocity
   of a median particle has decayed by e^-10; the frame written at its end must show no overlap
   above 1 % of r_min (checked by the tests with :func:`orchestrator.psd.max_overlap`).
2. ``compress``: the background damping is removed and the lower piston is driven by a servo
   to the force σ·π R_p² (R_p the piston radius). Its speed limit v_max follows from a
   compression inertial number I_c = (v_max/h) x₅₀ √(ρ/σ); gain kp = 1 (full speed with no load).
   The stage lasts ``travel_time_factor`` (1.5) travel times at v_max plus ``settle_time_constants``
   servo time constants;
   its end criterion, the force averaged over the last ``average_window`` of the stage within 2 %
   of the target, is checked from the wall series (``compression_check`` in the extras).
3. ``shear``: the upper piston and the sidewall rotate at ω, from the quasi-static criterion
   ω √(ρ x₅₀²/σ) = ``quasi_static_number`` (seed: 1e-4) unless ``angular_velocity`` is given,
   up to ``final_angle``; a frame is written at every angle of ``frame_angles`` (seed: every 0.5°
   to 9.5°, then every 5° to 39.5°). The servo keeps the normal load during shear.

Geometry (z up, axis at x = y = 0, lower plate face at z = 0 at the start): see
:func:`geometry_numbers`. Meshes come from :mod:`orchestrator.geometry` and the same STL files go
to both engines.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from ..atomic import write_json
from ..case import Strict, positive
from ..contact_law import (dashpot_stable_servo_speed, effective_modulus, effective_shear_modulus, remembered,
                           wall_dashpot_coefficient)
from ..derive import adhesion_force, DerivationError
from ..numerics import multiple_of
from ..params import ContactTerms, Params, ScenePart, StabilityInputs
from ..geometry import cylinder_shell, vaned_piston, write_stl
from ..particles_io import ensure_particle_table
from ..psd import lognormal_diameters, mean_sphere_volume, pack_cylinder
from ..units import Angle, AngularVelocity, Length, Pressure
from . import base

STAGES = {"initial": 0, "relaxed": 1, "compressed": 2, "shear": 3}
DEG = math.pi / 180


class PSD(Strict):
    """Log-normal diameters around the median, accepted only within [d_min, d_max]
    (seed 000 §3.2: x₅₀ = 30 µm, 25-50 µm, interquartile x₇₅ - x₂₅ ≈ 5 µm ⇒ σ_ln ≈ 0.12)."""
    median: Length = "30 um"
    d_min: Length = "25 um"
    d_max: Length = "50 um"
    sigma_ln: float = Field(0.12, ge=0, description="standard deviation of ln d")

    @model_validator(mode="after")
    def _order(self):
        if not 0 < self.d_min <= self.median <= self.d_max:
            raise ValueError(f"need 0 < d_min <= median <= d_max, got {self.d_min:g}, {self.median:g}, "
                             f"{self.d_max:g} m")
        return self


def _seed_frame_angles():
    return [f"{0.5 * k:g} deg" for k in range(1, 20)] + [f"{9.5 + 5 * k:g} deg" for k in range(1, 7)]


class Scene(Strict):
    kind: Literal["shear_cell"]
    # -- geometry (seed §3.3) -----------------------------------------------------------------
    cell_diameter: Length = Field("1.78 mm", description="inner diameter of the sidewall (seed: 1.78 mm)")
    gap: Length = Field("0.1 mm", description="radial gap piston edge - sidewall (seed: ~0.1 mm in simulation, "
                                              "0.025 mm in the experiment, widened against jamming)")
    vane_height: Length = Field("0.1 mm", description="height of the vanes above the plate face")
    vane_thickness: Length = Field("0.03 mm", description="vane thickness (about one x50)")
    vane_inner_radius: Length | None = Field(None, description="where the vanes start (default 3 thicknesses: "
                                                               "vanes never meet on the axis)")
    plate_thickness: Length = Field("0.1 mm", description="thickness of each piston plate = depth of the gap "
                                                           "pocket closed by the flange behind it")
    flange_clearance: float = Field(0.3, gt=0, lt=1, description="radial clearance flange - sidewall in units "
                                                                 "of d_min: below 1, no particle passes the piston")
    fill_height: Length = Field("1.0 mm", description="sample height between the plate faces after compaction, "
                                                       "used with dense_fraction to set the particle count")
    dense_fraction: float = Field(0.55, gt=0, lt=0.75, description="volume fraction assumed after compaction")
    n_particles: int | None = Field(None, ge=2, description="overrides the count derived from fill_height")
    mesh_segments: int | None = Field(None, ge=12, description="segments around the circumference (default: "
                                                                "chord sagitta below 1 % of r_min)")
    # -- particles --------------------------------------------------------------------------------
    psd: PSD = Field(default_factory=PSD)
    loose_fraction: float = Field(0.2, gt=0, le=0.35, description="volume fraction of the random loose packing")
    # -- protocol ----------------------------------------------------------------------------------
    normal_stress: Pressure = "0.5 kPa"
    relax_tau_steps: int = Field(200, ge=10, description="background damping time τ = m50/γ in time steps")
    relax_damping_times: float = Field(10.0, gt=0, description="relaxation length in damping times")
    compression_inertial_number: float = Field(1e-3, gt=0, description="I_c = (v_max/h) x50 sqrt(rho/sigma) "
                                                                       "fixes the servo speed limit")
    servo_gain: float = Field(1.0, gt=0, description="kp: v = v_max kp (F_target - F)/F_target")
    travel_time_factor: float = Field(1.5, ge=1, description="the compression lasts this many travel times at v_max "
                                                             "(the piston slows where the loose column pushes back) "
                                                             "plus the settling time")
    settle_time_constants: float = Field(40.0, gt=0, description="servo time constants added to the travel time")
    average_window: float = Field(0.25, gt=0, le=1, description="fraction of the settling time (the "
                                                                  "compression's last settle_time_constants servo "
                                                                  "time constants) over which the force is averaged")
    quasi_static_number: float = Field(1e-4, gt=0, description="omega sqrt(rho x50^2/sigma) (seed: 1e-4)")
    angular_velocity: AngularVelocity | None = Field(None, description="overrides the quasi-static criterion")
    final_angle: Angle = "39.5 deg"
    frame_angles: list[Angle] = Field(default_factory=_seed_frame_angles)
    wall_samples: int = Field(2000, ge=10, description="wall time-series samples over the whole run")
    wall_adhesion: bool = Field(False, description="seed §3.3: particle-wall contacts use the visco-elastic part "
                                                   "of eq. 1 only (no adhesion)")
    wall_friction: bool | Literal["shear"] = Field(
        False, description="seed §3.3: particle-wall contacts use the visco-elastic part of eq. 1, the normal "
                           "Hertz + damping terms only, so no Coulomb friction at walls by default; true gives "
                           "walls the particles' Coulomb mu for the whole run; 'shear' only from the start of the "
                           "shear stage, so that the compression against frictionless walls loads the whole "
                           "column to the normal stress (with wall friction the sidewall carries part of it, "
                           "Janssen, and the servo settles short of the target: docs/validation.md). Rolling and "
                           "twisting resistance are never applied at walls")

    _pos = positive("cell_diameter", "gap", "vane_thickness", "plate_thickness", "fill_height", "normal_stress",
                     "final_angle")

    @field_validator("wall_friction", mode="before")
    @classmethod
    def _wall_friction(cls, v):
        if isinstance(v, bool) or v == "shear":
            return v
        raise ValueError("write true (Coulomb friction at the walls for the whole run), false (none, seed §3.3) "
                         "or shear (from the start of the shear stage)")

    @model_validator(mode="after")
    def _check(self):
        if self.psd.d_max >= self.cell_diameter or self.psd.d_max >= self.fill_height:
            raise ValueError(f"particles larger than their container: d_max = {self.psd.d_max:g} m against a cell "
                             f"{self.cell_diameter:g} m wide and a fill {self.fill_height:g} m high; make d_max "
                             "smaller (the seed: 50 um in a 1.78 mm cell) or the cell larger")
        if self.gap >= self.cell_diameter / 2:
            raise ValueError("gap must be smaller than the cell radius")
        if self.gap < self.psd.d_max:
            raise ValueError(f"gap {self.gap:g} m is narrower than d_max {self.psd.d_max:g} m: single particles "
                             "would wedge between piston edge and wall (seed §3.3 widens the gap for this reason)")
        for a in self.frame_angles:
            if not 0 < a <= self.final_angle * (1 + 1e-12):
                raise ValueError(f"frame angle {a / DEG:g} deg must lie in (0, final_angle = "
                                 f"{self.final_angle / DEG:g} deg]")
        if sorted(self.frame_angles) != list(self.frame_angles):
            raise ValueError("frame_angles must be increasing")
        return self


# ------------------------------------------------------------------------------------------------
def size_range(case) -> tuple[float, float]:
    p = case.scene.psd
    return p.d_min / 2, p.d_max / 2


def _mean_volume(scene) -> float:
    p = scene.psd
    return mean_sphere_volume(p.median, p.d_min, p.d_max, p.sigma_ln)


def geometry_numbers(case) -> dict:
    """Lengths [m] of the cell, z of every part at the start, and the particle count."""
    s = case.scene
    R = s.cell_diameter / 2
    Rp = R - s.gap
    t = s.vane_thickness
    r_in = s.vane_inner_radius if s.vane_inner_radius is not None else 3 * t
    if Rp <= r_in or Rp <= t / 2:
        raise DerivationError(
            f"scene.cell_diameter: {s.cell_diameter * 1e3:.3g} mm less twice the gap ({s.gap * 1e3:.3g} mm) leaves a "
            f"piston radius of {Rp * 1e3:.3g} mm, not more than where the vanes start ({r_in * 1e3:.3g} mm"
            + (")" if s.vane_inner_radius is not None else ", 3 vane thicknesses)")
            + f": no room for the vanes; widen the cell to more than {2 * (max(r_in, t / 2) + s.gap) * 1e3:.3g} mm, "
            "or narrow the gap or the vanes")
    x_out = math.sqrt(Rp ** 2 - (t / 2) ** 2)
    vane_vol = 6 * t * (x_out - r_in) * s.vane_height
    v_mean = _mean_volume(s)
    if s.n_particles is not None:
        n = s.n_particles
    else:
        n = int(round(s.dense_fraction * (math.pi * R ** 2 * s.fill_height - 2 * vane_vol) / v_mean))
        if n < 2:
            raise DerivationError("scene.fill_height gives fewer than 2 particles; raise it or set n_particles")
    # loose packing between the vane tips
    L_loose = n * v_mean / (s.loose_fraction * math.pi * R ** 2)
    r_min = s.psd.d_min / 2
    margin = s.psd.d_max
    z_pack_lo = s.vane_height + 0.5 * margin
    z_pack_hi = z_pack_lo + L_loose
    z_upper_face = z_pack_hi + 0.5 * margin + s.vane_height
    h_dense_est = n * v_mean / (s.dense_fraction * math.pi * R ** 2) + 2 * vane_vol / (math.pi * R ** 2)
    travel = max(0.0, z_upper_face - h_dense_est)
    seg = s.mesh_segments or int(math.ceil(math.pi * math.sqrt(R / (2 * 0.01 * r_min))))
    seg = max(24, int(math.ceil(seg / 6)) * 6)
    clearance = 2 * s.psd.d_max
    R_flange = R - s.flange_clearance * s.psd.d_min
    flange_t = s.plate_thickness
    z_can_lo = -2 * s.plate_thickness - clearance
    z_can_hi = z_upper_face + 2 * s.plate_thickness + clearance
    return {"R_cyl": R, "R_piston": Rp, "vane_inner_radius": r_in, "vane_outer": x_out,
            "vane_volume": vane_vol, "n": n, "v_mean": v_mean, "loose_height": L_loose,
            "z_pack": [z_pack_lo, z_pack_hi], "z_lower_face": 0.0, "z_upper_face": z_upper_face,
            "h_dense_estimate": h_dense_est, "travel_estimate": travel, "segments": seg,
            "z_can": [z_can_lo, z_can_hi], "piston_area": math.pi * Rp ** 2,
            "R_flange": R_flange, "flange_thickness": flange_t}


def required_features(case) -> list[str]:
    c = case.contact
    feats = ["hertz", "seed000_damping" if c.damping == "seed000" else "restitution_damping",
             "mesh_walls", "rotating_walls", "servo_wall"]
    if c.friction > 0:
        feats.append("sliding_friction")
    if adhesion_force(case) > 0:
        feats.append("adhesion")
    if c.rolling is not None and (c.rolling.model == "seed000" or c.rolling.coefficient > 0):
        feats.append("rolling_friction_load" if c.rolling.model == "seed000" else "rolling_friction")
    if c.torsion is not None and c.torsion.coefficient > 0:
        feats.append("torsion_friction")
    return feats


def _omega(case) -> float:
    s = case.scene
    if s.angular_velocity is not None:
        return s.angular_velocity
    rho = case.material.density
    return s.quasi_static_number / math.sqrt(rho * s.psd.median ** 2 / s.normal_stress)



def servo_dashpot_gain(case, v_max: float, kp: float) -> float:
    """Loop gain G = v_max kp γ_w / F_c [-] of the force servo against the dashpots of the grains
    it pushes. The servos (LIGGGHTS' mesh servo, measured; YADE's ServoPIDController, the same per-step
    proportional law, not probed) set the piston speed each step from the force of the step before,
    v = v_max kp (1 - F/F_target); a speed v adds N_c γ_w v to F (N_c = F_target/F_c contacts of
    dashpot γ_w at the mean contact force F_c, :func:`_expected_overlap`), so the speed obeys
    v' = v_max kp (1 - F_el/F_target) - G v: the error alternates in sign each step and decays only
    while G < 1. Measured on the medium case (G = 2.7 at 0.47 m/s): the force alternated between ~0 and ~5
    F_target every step, the piston between two positions 30 nm apart, and the mean force stayed
    22 % above the target. γ_w: a grain (x50) on a wall at F_c: seed 000's γ_n √ξ (damping seed000),
    else Tsuji's 2 √(5/6) |β(e)| √(S_n m) with S_n = 2 E*_w √(R ξ) (Tsuji et al. 1992)."""
    s = case.scene
    x50 = s.psd.median
    mat = case.material
    Ew, nuw = case.wall_moduli()
    Fc = _expected_overlap(case, effective_modulus(mat.youngs_modulus, mat.poisson_ratio, mat.youngs_modulus,
                                                   mat.poisson_ratio), adhesion_force(case))[1]
    gamma = wall_dashpot_coefficient(effective_modulus(mat.youngs_modulus, mat.poisson_ratio, Ew, nuw), x50 / 2,
                                     mat.density * math.pi / 6 * x50 ** 3, Fc, case.contact.damping,
                                     case.contact.restitution)
    return v_max * kp * gamma / Fc


def frictional_wall_gain_factor(case, g=None) -> float:
    """The servo's loop gain with Coulomb friction at the walls over the frictionless one [-]:
    1 + (γ_t/γ_n) A_axial/A_face. Moving along the axis, the lower piston slides past the grains on
    its axial faces (the six vanes' sides, 2 h_v (r_out - r_in) each, and the plate's rim, 2π R_p t_p),
    whose tangential dashpots (with friction, while they stick) add to the axial force as the normal
    dashpots of the grains on its face (π R_p²) do, with as many contacts per area. γ_t/γ_n =
    √(S_t/S_n) = √(4 G*/E*) for Tsuji's dashpots on Hertz-Mindlin (LIGGGHTS normal_model_hertz.h:
    gammat, gamman). Probed on the medium case (docs/validation.md): at the speed limit that holds
    the frictionless loop at G = 0.7 the frictional one swung at G ≈ 1.4-1.5 (growing swings at 0.75
    of that speed, G ≈ 1.1; settling at 0.5, successive swings 0.7 of each other), where this factor
    (2.63 there) predicts 1.84: conservative by ~25 %, the rim's contacts in the gap counted in full."""
    s = case.scene
    g = g or geometry_numbers(case)
    mat = case.material
    Ew, nuw = case.wall_moduli()
    E_w = effective_modulus(mat.youngs_modulus, mat.poisson_ratio, Ew, nuw)
    G_w = effective_shear_modulus(mat.youngs_modulus, mat.poisson_ratio, Ew, nuw)
    axial = 6 * 2 * s.vane_height * (g["vane_outer"] - g["vane_inner_radius"]) \
        + 2 * math.pi * g["R_piston"] * s.plate_thickness
    return 1.0 + math.sqrt(4 * G_w / E_w) * axial / g["piston_area"]


def _v_max(case, g=None, frictional: bool = False) -> float:
    """Servo speed limit [m/s]: from the compression inertial number I_c = (v_max/h) x50 √(ρ/σ),
    capped so that the servo's loop gain against its contacts' dashpots stays at
    :data:`..contact_law.SERVO_DASHPOT_GAIN` (:func:`servo_dashpot_gain`; the cap binds on tall cells, whose
    I_c-speed is high); ``frictional``: with Coulomb friction at the walls, whose tangential dashpots
    add to the gain (:func:`frictional_wall_gain_factor`)."""
    s = case.scene
    g = g or geometry_numbers(case)
    rho = case.material.density
    rate = s.compression_inertial_number / (s.psd.median * math.sqrt(rho / s.normal_stress))
    v = rate * g["h_dense_estimate"]
    gain = servo_dashpot_gain(case, v, s.servo_gain)
    if frictional:
        gain *= frictional_wall_gain_factor(case, g)
    return dashpot_stable_servo_speed(v, gain)


def max_velocity(case) -> float:
    """Largest relative speed [m/s]: the faster of the servo limit and the sidewall's rim speed,
    doubled for particles rebounding off a moving wall."""
    g = geometry_numbers(case)
    return 2 * max(_v_max(case, g), _omega(case) * g["R_cyl"])


@remembered          # an integration (and scipy's import) per call: kept across processes
def seed000_restitution(E_eff: float, m_eff: float, r_eff: float, v: float) -> float:
    """Restitution [-] that seed 000's damped Hertz law F = 4/3 E* √r ξ^1.5 + γ_n √ξ ξ̇ with
    γ_n = √(4/3 E* m*) delivers at normal impact speed ``v`` [m/s] (force clipped at 0)."""
    k = 4 / 3 * E_eff * math.sqrt(r_eff)
    g = math.sqrt(4 / 3 * E_eff * m_eff)

    def rhs(t, y):
        x, u = y
        f = k * max(x, 0) ** 1.5 + g * math.sqrt(max(x, 0)) * u if x > 0 else 0.0
        return [u, -max(f, 0.0) / m_eff]

    def out(t, y):
        return y[0]
    out.terminal, out.direction = True, -1

    def stuck(t, y):  # force vanished while separating: the rest is free flight
        x, u = y
        return (k * max(x, 1e-300) ** 1.5 + g * math.sqrt(max(x, 1e-300)) * u) if u < 0 else 1.0
    stuck.terminal, stuck.direction = True, -1
    xm = (15 * m_eff * v ** 2 / (16 * E_eff * math.sqrt(r_eff))) ** 0.4
    tc = xm / v * 3
    from scipy.integrate import solve_ivp     # here: scipy.integrate costs ~0.5 s to import (validate, #16)
    sol = solve_ivp(rhs, (0, 50 * tc), [1e-9 * xm, v], events=[out, stuck], rtol=1e-9, atol=1e-12 * xm,
                    max_step=tc / 200)
    return float(max(0.0, -sol.y[1, -1] / v))


def _expected_overlap(case, E_eff: float, F_adh: float) -> tuple[float, float]:
    """(ξ_σ [m], F_c [N]): overlap of a median pair (r_eff = x50/4) carrying the mean contact force
    of a packing under σ, F_c = π x50² σ/(φ z) with z = 4 contacts, plus the adhesion force."""
    s = case.scene
    x50 = s.psd.median
    Fc = math.pi * x50 ** 2 * s.normal_stress / (s.dense_fraction * 4) + F_adh
    r = x50 / 4
    xi = (3 * Fc / (4 * E_eff * math.sqrt(r))) ** (2 / 3)
    return xi, Fc


@dataclass(frozen=True)
class ShearCellParams(ScenePart):
    """The shear cell's numbers (SI). Steps are absolute step numbers of the one run."""
    n: int                       #: grains [-]
    geometry: dict               #: cell geometry (:func:`geometry_numbers`) [m, m², m³]
    psd: dict                    #: the case's size distribution (diameters [m])
    stages: dict                 #: stage -> [first step, last step] (relax, compress, shear)
    steps: int                   #: last step [-]
    total_steps: int             #: = steps [-]
    events: tuple                #: deck events: {step, frame (bool), begin (stage name or "")}
    frame_steps: tuple           #: steps of the frames [-]
    frame_angles: tuple          #: shear angle of each frame [rad]
    frame_stage: tuple           #: stage code of each frame (STAGES)
    dump_every: int              #: [-] (frames are written by events)
    restart_every: int           #: steps between restart points [-]
    wall_every: int              #: steps between wall samples [-]
    average_window_steps: int    #: compression check's averaging window [steps]
    gamma_visc: float            #: relaxation drag γ, F = -γ v [N s/m]
    relax_tau_steps: int         #: relaxation time m50/γ [steps]
    m50: float                   #: mass of a median grain [kg]
    servo: dict                  #: target_force [N], v_max, v_max_shear [m/s], kp [-], tau [s], E_bulk_estimate [Pa], travel_time [s]
    omega: float                 #: angular velocity of the rotating parts [rad/s]
    rotation_period: float       #: 2π/ω [s]
    quasi_static_number: float   #: ω √(ρ x50²/σ) [-]
    contact: ContactTerms        #: contact terms beyond Hertz-Mindlin
    gravity: float               #: [m/s²]
    skin: float                  #: neighbour skin [m]
    box_lo: tuple                #: simulation box [m]
    box_hi: tuple
    wall_adhesion: bool          #: walls keep the adhesion
    wall_friction: bool | str    #: walls have Coulomb friction (True, False or "shear")
    wall_mu: float               #: wall friction coefficient once it applies [-]
    wall_friction_from: int      #: first step of wall_mu (0: the whole run; the shear stage's start for "shear")


def derive(case, common: Params) -> ShearCellParams:
    s = case.scene
    g = geometry_numbers(case)
    mat = case.material
    rho = mat.density
    dt = common.dt
    n = g["n"]
    x50 = s.psd.median
    m50 = rho * math.pi / 6 * x50 ** 3
    if case.contact.tangential_stiffness_ratio is not None:
        raise DerivationError("contact.tangential_stiffness_ratio: neither LIGGGHTS' nor YADE's Hertz-Mindlin law "
                              "takes a free k_t/k_n (both use 2(1-nu)/(2-nu)); remove the field for the shear cell")
    # ---- stage 1: relaxation
    tau_steps = s.relax_tau_steps
    gamma_visc = m50 / (tau_steps * dt)                         # N s/m, F = -gamma v
    n_relax = int(math.ceil(s.relax_damping_times * tau_steps))
    # ---- stage 2: compression
    v_max = _v_max(case, g, frictional=s.wall_friction is True)
    # the shear stage's limit: lower when the walls become frictional there (wall_friction: shear)
    v_max_shear = _v_max(case, g, frictional=bool(s.wall_friction))
    F_target = s.normal_stress * g["piston_area"]
    E_pp = common.E_eff_pp
    # bulk modulus of a Hertz packing under σ: E_b ~ (E*² σ)^(1/3) (effective-medium scaling)
    E_bulk = (E_pp ** 2 * s.normal_stress) ** (1 / 3)
    k_bulk = E_bulk * g["piston_area"] / g["h_dense_estimate"]
    tau_servo = F_target / (v_max * s.servo_gain * k_bulk)
    t_travel = g["travel_estimate"] / v_max
    n_settle = int(math.ceil(s.settle_time_constants * tau_servo / dt))
    n_compress = int(math.ceil(s.travel_time_factor * t_travel / dt)) + n_settle
    skin = max(0.5 * s.psd.d_max / 2, 2.5 * v_max * dt * 1.0)
    if v_max >= skin / (2 * dt):
        raise DerivationError(f"servo speed {v_max:.3g} m/s exceeds skin/(2 dt) = {skin / (2 * dt):.3g} m/s")
    # ---- stage 3: shear
    omega = _omega(case)
    n_shear = int(math.ceil(s.final_angle / (omega * dt)))
    s0 = 0
    s1 = n_relax
    s2 = s1 + n_compress
    s3 = s2 + n_shear
    frame_steps = [s0, s1, s2] + [s2 + int(round(a / (omega * dt))) for a in s.frame_angles]
    frame_angles = [0.0, 0.0, 0.0] + [float(a) for a in s.frame_angles]
    frame_stage = [STAGES["initial"], STAGES["relaxed"], STAGES["compressed"]] + [STAGES["shear"]] * len(s.frame_angles)
    if frame_steps[-1] != s3 and s.frame_angles and abs(s.frame_angles[-1] - s.final_angle) < 1e-12:
        frame_steps[-1] = s3
    if len(set(frame_steps)) != len(frame_steps):
        raise DerivationError("two frames fall on the same step: frame_angles closer than omega*dt")
    wall_every = max(10, (s3 // s.wall_samples) // 10 * 10)   # a multiple of 10 (YADE averages 10 samples)
    # the deck is a list of events: run up to a step, then write a frame and/or begin a stage
    begins = {s1: "compress", s2: "shear"}
    events = []
    for st in sorted(set(frame_steps) | set(begins) | {s3}):
        events.append({"step": st, "frame": st in frame_steps, "begin": begins.get(st, "")})
    # ---- contact terms (every engine gets the same numbers; engines/<name>/numbers.py turn them
    # into their own law's inputs)
    F_adh = adhesion_force(case)
    r_eff_mean = x50 / 4
    xi, Fc = _expected_overlap(case, E_pp, F_adh)
    kn_seed = 4 / 3 * E_pp * x50 / 2            # seed §3.2: k_n = 4/3 E_eff x50/2
    kt_seed = 2 / 7 * kn_seed
    c = case.contact
    contact = {"adhesion_force": F_adh, "expected_overlap": xi, "expected_contact_force": Fc,
               "kn_seed": kn_seed, "kt_seed": kt_seed, "r_eff_mean": r_eff_mean, "median_radius": x50 / 2}
    if c.rolling is not None and (c.rolling.model == "seed000" or c.rolling.coefficient > 0):
        # rolling torque limit M = mu_r r_eff |F|; seed000: mu_r r_eff = sqrt(2 r_eff ξ)
        mu_r = math.sqrt(2 * r_eff_mean * xi) / r_eff_mean if c.rolling.model == "seed000" else c.rolling.coefficient
        contact["rolling_coefficient"] = mu_r
        contact["rolling_stiffness"] = kt_seed * r_eff_mean ** 2      # rolling spring k_r = k_t r_eff^2
    if c.torsion is not None and c.torsion.coefficient > 0:
        contact["torsion_coefficient"] = c.torsion.coefficient
        contact["twisting_stiffness"] = kt_seed * r_eff_mean ** 2
    # damping: seed000 -> the restitution seed's gamma_n delivers at the servo speed
    if c.damping == "seed000":
        v_char = max(v_max, omega * g["R_cyl"])
        e_seed = seed000_restitution(E_pp, m50 / 2, x50 / 4, v_char)
        e_seed = min(max(e_seed, 0.05), 1.0)
        contact["restitution"] = {"target": e_seed, "from": f"seed000 gamma_n at v = {v_char:.3g} m/s"}
    else:
        contact["restitution"] = dict(common.restitution.to_dict(), **{"from": "contact.restitution"})
    skin = max(skin, 0.25 * s.psd.d_max)
    box_margin = 2 * s.psd.d_max
    R = g["R_cyl"]
    return ShearCellParams(
        n=n, geometry=g, psd=s.psd.model_dump(),
        stages={"relax": [s0, s1], "compress": [s1, s2], "shear": [s2, s3]},
        steps=s3, total_steps=s3,
        events=events, frame_steps=frame_steps, frame_angles=frame_angles, frame_stage=frame_stage,
        dump_every=max(1, s3), restart_every=multiple_of(max(1000, s3 // 10), wall_every), wall_every=wall_every,
        average_window_steps=max(wall_every, int(math.ceil(s.average_window * n_settle))),
        gamma_visc=gamma_visc, relax_tau_steps=tau_steps, m50=m50,
        servo={"target_force": F_target, "v_max": v_max, "v_max_shear": v_max_shear, "kp": s.servo_gain,
               "tau": tau_servo,
               "E_bulk_estimate": E_bulk, "travel_time": t_travel},
        omega=omega, rotation_period=2 * math.pi / omega,
        quasi_static_number=omega * math.sqrt(rho * x50 ** 2 / s.normal_stress),
        contact=ContactTerms(**contact), gravity=case.gravity, skin=skin,
        box_lo=[-R - box_margin, -R - box_margin, g["z_can"][0] - box_margin],
        box_hi=[R + box_margin, R + box_margin, g["z_can"][1] + box_margin],
        wall_adhesion=s.wall_adhesion,
        # seed §3.3: walls are Hertz + damping (eq. 1's visco-elastic part): Coulomb mu only if asked
        wall_friction=s.wall_friction, wall_mu=case.contact.friction if s.wall_friction else 0.0,
        wall_friction_from=s2 if s.wall_friction == "shear" else 0)


# ------------------------------------------------------------------------------------------------
def build_meshes(case, params) -> dict:
    """The three solids (Mesh objects): ``lower`` piston (vanes up, plate face at z = 0), ``upper``
    piston (vanes down), ``cylinder`` (closed can around both)."""
    s = case.scene
    g = params["scene"]["geometry"]
    seg = g["segments"]
    kw = dict(flange_radius=g["R_flange"], flange_thickness=g["flange_thickness"])
    lower = vaned_piston(g["R_piston"], s.plate_thickness, seg, s.vane_height, s.vane_thickness,
                         g["vane_inner_radius"], **kw)
    upper = vaned_piston(g["R_piston"], s.plate_thickness, seg, s.vane_height, s.vane_thickness,
                         g["vane_inner_radius"], **kw).flipped_z().rotated_z(math.pi / 6).translated(
        [0, 0, g["z_upper_face"]])
    cyl = cylinder_shell(g["R_cyl"], g["z_can"][0], g["z_can"][1], seg, max_aspect=20.0)
    return {"lower": lower, "upper": upper, "cylinder": cyl}


def sample_particles(case, params) -> dict:
    """Diameters and loose positions, sampled once from the case's seed (same for all engines)."""
    s = case.scene
    g = params["scene"]["geometry"]
    rng = np.random.default_rng(case.seed)
    d = lognormal_diameters(g["n"], s.psd.median, s.psd.d_min, s.psd.d_max, s.psd.sigma_ln, rng)
    pos = pack_cylinder(d / 2, g["R_cyl"], g["z_pack"][0], g["z_pack"][1], rng, wall_clearance=0.02 * s.psd.d_min)
    return {"id": np.arange(1, g["n"] + 1), "radius": d / 2, "position": pos}


def prepare(case, params, run_dir) -> tuple[dict, ShearCellParams]:
    """Write particles.txt (and LIGGGHTS' particles.data) and the three STL meshes."""
    run_dir = Path(run_dir)
    files = {}
    meshes = build_meshes(case, params)
    for name, m in meshes.items():
        p = run_dir / f"{name}.stl"
        write_stl(m, p, name)
        files[name] = str(p)
    table = ensure_particle_table(run_dir, case, lambda: sample_particles(case, params))
    files["particles"] = str(table)
    return files, params.scene


# ------------------------------------------------------------------------------------------------
def _angle_of_step(params, steps):
    sc = params["scene"]
    s2 = sc["stages"]["shear"][0]
    dt = params["dt"]
    return np.clip(np.asarray(steps, dtype=float) - s2, 0, None) * dt * sc["omega"]


def _frame_controls(params, steps) -> dict:
    sc = params["scene"]
    lookup = {s: (a, st) for s, a, st in zip(sc["frame_steps"], sc["frame_angles"], sc["frame_stage"])}
    angle = np.array([lookup.get(int(s), (np.nan, np.nan))[0] for s in steps])
    stage = np.array([lookup.get(int(s), (np.nan, np.nan))[1] for s in steps], dtype=float)
    return {"angle": angle, "stage": stage}


#: the compression check's tolerance: the piston's mean force over the last averaging window of the
#: compression stage within this fraction of the target, else the sample is not the case's [-]
COMPRESSION_TOLERANCE = 0.02


def compression_advice(relative_error: float | None, scene: dict | None = None, case_file: str = "") -> str:
    """What a compression check's error says about the run and the case field that fixes it; ""
    within :data:`COMPRESSION_TOLERANCE`.

    ``relative_error`` is (mean piston force − target)/target over the stage's last averaging
    window [-]; ``scene`` the case's ``scene`` section (its current values are quoted); ``case_file``
    the case file the run came from (the run's ``summary.json`` → ``case_source``).

    - Below the target: the piston had not reached the load when the stage's fixed length ran out,
      the column still collapsing (the smoke cell's second packing: -82 % on LAMMPS, -37 % on YADE
      at ``travel_time_factor`` 1.5, both within 2 % at 2; docs/shear_cell.md): lengthen the stage.
    - Above it: the piston pushed past the load faster than the servo could stop it (YADE's small
      cell at 4x the compression rate: +55 %; docs/validation.md): a slower piston.
    """
    if relative_error is None or abs(relative_error) <= COMPRESSION_TOLERANCE:
        return ""
    if relative_error < 0:
        return (f"the piston had not reached the load when the stage ended (the column still collapsing): "
                f"raise {base.case_field('scene', scene, 'travel_time_factor', Scene, case_file)}, "
                f"e.g. to 2, and run again")
    return (f"the piston overshot the load (the servo could not stop it at its speed): lower "
            f"{base.case_field('scene', scene, 'compression_inertial_number', Scene, case_file)} and run again")


def _compression_check(params, time, step, force_z) -> dict:
    sc = params["scene"]
    a, b = sc["stages"]["compress"]
    w = sc["average_window_steps"]
    sel = (step > b - w) & (step <= b)
    target = sc["servo"]["target_force"]
    if not np.any(sel):
        return {"mean_force": None, "target_force": target, "relative_error": None}
    mean = float(np.mean(np.abs(force_z[sel])))
    return {"mean_force": mean, "target_force": target, "relative_error": (mean - target) / target,
            "window_steps": [int(b - w), int(b)]}


def _wall_result(params, step, z_lower, f_lower, t_rot, t_lower):
    order = np.argsort(step, kind="stable")
    step = step[order]
    keep = np.concatenate([[True], np.diff(step) > 0])
    step = step[keep]
    sel = lambda a: np.asarray(a)[order][keep]
    z_lower, f_lower, t_rot, t_lower = sel(z_lower), sel(f_lower), sel(t_rot), sel(t_lower)
    time = step * params["dt"]
    angle = _angle_of_step(params, step)
    return {
        "lower_piston": {"time": time, "position": np.column_stack([np.zeros_like(z_lower), np.zeros_like(z_lower), z_lower]),
                         "force": f_lower, "torque": t_lower},
        "rotating": {"time": time, "angle": angle, "torque": t_rot},
    }, step


def _write_check(run_dir, params, walls, step):
    chk = _compression_check(params, walls["lower_piston"]["time"], step, walls["lower_piston"]["force"][:, 2])
    write_json(Path(run_dir) / "shear_cell_checks.json", {"compression": chk})
    return chk


def _with_walls(out: dict, rows: list, run_dir, params) -> dict:
    """Add the wall series from sampled rows (columns: step, z_lower, fx fy fz (lower),
    tz_lower, tz_upper, tz_cylinder) and write the compression check."""
    rows = [r for r in rows if r.size]
    if rows:
        a = np.vstack(rows)
        zeros = np.zeros(len(a))
        walls, st = _wall_result(params, a[:, 0].astype(np.int64), a[:, 1], a[:, 2:5],
                                 np.column_stack([zeros, zeros, a[:, 6] + a[:, 7]]),
                                 np.column_stack([zeros, zeros, a[:, 5]]))
        _write_check(run_dir, params, walls, st)
        out["walls"] = walls
    return out


class ShearCellScene(base.Scene):
    """The vaned micro shear cell (module docstring). Controls per frame: the rotating piston's
    ``angle`` [rad] and the protocol ``stage``; wall series ``lower_piston`` and ``rotating``."""
    kind = "shear_cell"
    section = Scene
    honoured = frozenset({"contact.adhesion", "contact.rolling", "contact.torsion", "contact.damping: seed000",
                          "gravity", "output.contacts", "output.stress", "initial_packing"})
    controls = {"angle": "rad", "stage": "1"}
    #: the decks' wall sampler (LIGGGHTS fix ave/time, YADE's sampler): one row per sample
    wall_columns = ("step", "z_lower", "fx_lower", "fy_lower", "fz_lower", "tz_lower", "tz_upper", "tz_cylinder")
    observables = ("torque", "angle")

    def clock_features(self, scene):
        """``smooth_sidewall`` while the walls are frictionless (``wall_friction`` off, seed §3.3):
        LIGGGHTS then renders the sidewall as its analytic cylinder, which made the default cell's
        whole run 1.43x faster than the 720-triangle mesh a frictional, rotating sidewall needs
        (docs/speed.md); the other engines' decks do not change, and their keys fall back to
        ``shear_cell`` (:func:`orchestrator.clock.key_fallbacks`)."""
        return () if (scene or {}).get("wall_friction") else ("smooth_sidewall",)

    def size_overrides(self, section, scale):
        """The cell's diameter × ``scale`` at the same fill height, vanes and gap (the grain count
        grows as scale²; an explicit ``n_particles`` with it)."""
        out = {"cell_diameter": f"{section.cell_diameter * float(scale)!r} m"}
        if section.n_particles is not None:
            out["n_particles"] = max(2, round(section.n_particles * float(scale) ** 2))
        return out

    required_features = staticmethod(required_features)
    derive = staticmethod(derive)
    max_velocity = staticmethod(max_velocity)
    size_range = staticmethod(size_range)

    def stability_inputs(self, case, params):
        sc = params.scene
        c = sc.contact
        return StabilityInputs(
            n_particles=sc.n, total_steps=sc.total_steps, box_lo=sc.box_lo, box_hi=sc.box_hi,
            wall_speeds={"servo": sc.servo.v_max, "rotating_rim": sc.omega * sc.geometry.R_cyl},
            confining_stress=case.scene.normal_stress, skin=sc.skin, height=sc.box_hi[2] - sc.box_lo[2],
            wall_force_target=sc.servo.target_force, adhesion_force=c.adhesion_force,
            restitution=c.restitution.target, rolling_stiffness=c.rolling_stiffness,
            rolling_coefficient=c.rolling_coefficient, twisting_stiffness=c.twisting_stiffness,
            torsion_coefficient=c.torsion_coefficient)

    prepare = staticmethod(prepare)

    def sample_problems(self, run_dir):
        """The compression stage missed the load: the piston's mean force over the stage's last
        averaging window more than :data:`COMPRESSION_TOLERANCE` off the target
        (``shear_cell_checks.json``), with the case field that fixes it
        (:func:`compression_advice`)."""
        try:
            chk = json.loads((Path(run_dir) / "shear_cell_checks.json").read_text())["compression"]
        except (OSError, ValueError, KeyError):
            return []
        e = chk.get("relative_error")
        if e is None or abs(e) <= COMPRESSION_TOLERANCE:
            return []
        advice = compression_advice(e, *base.run_case_scene(run_dir))
        return [f"compression ended {100 * e:+.1f} % off the target load (tolerance ± {100 * COMPRESSION_TOLERANCE:g} %)"
                + (f": {advice}" if advice else "")]

    def post(self, run_dir, params, output):
        """Wall series from the sampler's rows and the per-frame ``angle``/``stage`` controls of
        the frames the engine wrote; writes the compression check."""
        rows = output.wall_rows()
        out = {"controls": _frame_controls(params, [int(st) for st in output.frame_steps])}
        return _with_walls(out, [] if rows is None else [rows], run_dir, params)
