"""Plane shear at a fixed normal stress, for the μ calibration of seed 000 §3.2.

Geometry (z up): a box of L × L periodic in x and y, closed in z by two rough walls, each one
layer of grains of the particle material on a square lattice. The walls are perpendicular to
the velocity gradient (z); the top wall moves in the shear direction x, i.e. the confining
walls are the ones the shear stress is measured on (seed: "confining walls perpendicular to the
shear direction and periodic boundary conditions in all other directions"; we read the walls'
normal as the gradient direction, the usual plane-shear set-up of the seed's refs. [3, 10]).
Wall grains move as one rigid body; the bottom wall is fixed.

Protocol, identical for both engines (absolute step ranges computed here):

1. ``compress``: the grains, placed by random sequential addition at volume fraction
   ``loose_fraction``, are compressed by the top wall under a proportional force servo
   v_z = -v_max clamp(k_p (F_target - F_z)/F_target, -1, 1), F_target = σ L²; v_max from the
   compression inertial number I_c = (v_max/H) x₅₀ √(ρ/σ), capped so that the servo's loop gain
   against the dashpots under the wall stays ≤ 0.7 (:func:`servo_dashpot_gain`; binds on the seed
   case: 0.63 -> 0.057 m/s). The stage lasts 1.5 × the travel time at
   v_max plus ``settle_time_constants`` servo time constants.
2. ``shear``: the top wall moves at v_x = I H x₅₀⁻¹ √(σ/ρ) (inertial number ``inertial_number``,
   H the dense height estimate) up to the shear strain ``shear_strain``; the servo keeps σ.

μ_macro = |F_x|/|F_z| on the top wall (time series ``walls/top``), its steady state the mean
over the shear strain ≥ ``steady_from`` × ``shear_strain``.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field

from ..case import Strict, positive
from ..contact_law import dashpot_stable_servo_speed, effective_modulus, wall_dashpot_coefficient
from ..numerics import block_sem, multiple_of
from ..derive import adhesion_force, DerivationError
from ..params import ContactTerms, Params, ScenePart, StabilityInputs
from ..particles_io import ensure_particle_table
from ..psd import lognormal_diameters, mean_sphere_volume, pack_box
from ..units import Pressure
from . import base
from .shear_cell import PSD

STAGES = {"initial": 0, "compressed": 1, "shear": 2}


class Scene(Strict):
    kind: Literal["plane_shear"]
    psd: PSD = Field(default_factory=PSD)
    n_particles: int = Field(300, ge=10, description="mobile grains between the walls (seed: 10 000)")
    width: float = Field(6.0, ge=3, description="periodic box side L in median diameters")
    loose_fraction: float = Field(0.3, gt=0, le=0.35, description="volume fraction of the initial RSA packing")
    dense_fraction: float = Field(0.6, gt=0, lt=0.75, description="assumed fraction after compression (estimates)")
    normal_stress: Pressure = "15 kPa"
    inertial_number: float = Field(1e-3, gt=0, description="I = gamma_dot x50 sqrt(rho/sigma) of the shear")
    compression_inertial_number: float = Field(1e-2, gt=0)
    servo_gain: float = Field(1.0, gt=0)
    settle_time_constants: float = Field(40.0, ge=0)
    shear_strain: float = Field(2.0, gt=0, description="total shear strain of the shear stage")
    steady_from: float = Field(0.5, ge=0, lt=1, description="steady state from this fraction of shear_strain")
    wall_samples: int = Field(400, ge=10, description="wall series samples over the whole run")
    shear_frames: int = Field(4, ge=1, description="frames written during shear")
    wall_grain_diameter: float = Field(1.0, gt=0, description="wall grain diameter in median diameters")

    _pos = positive("normal_stress")


def size_range(case) -> tuple[float, float]:
    p = case.scene.psd
    return p.d_min / 2, max(p.d_max / 2, p.median * case.scene.wall_grain_diameter / 2)


def required_features(case) -> list[str]:
    c = case.contact
    feats = ["hertz", "restitution_damping", "periodic"]
    if c.friction > 0:
        feats.append("sliding_friction")
    if adhesion_force(case) > 0:
        feats.append("adhesion")
    if _has_rolling(c):
        feats.append("rolling_friction_load" if c.rolling.model == "seed000" else "rolling_friction")
    if _has_torsion(c):
        feats.append("torsion_friction")
    if c.damping != "restitution":
        raise DerivationError("contact.damping: the plane-shear scene uses 'restitution' damping")
    return feats


def _has_rolling(c) -> bool:
    return c.rolling is not None and (c.rolling.model == "seed000" or c.rolling.coefficient > 0)


def _has_torsion(c) -> bool:
    return c.torsion is not None and c.torsion.coefficient > 0


def _mean_volume(s) -> float:
    p = s.psd
    return mean_sphere_volume(p.median, p.d_min, p.d_max, p.sigma_ln)


def _time_scale(case) -> float:
    """x50 √(ρ/σ) [s]: the inertial time of a grain under the normal stress."""
    s = case.scene
    return s.psd.median * math.sqrt(case.material.density / s.normal_stress)


def geometry(case) -> dict:
    s = case.scene
    x50 = s.psd.median
    L = s.width * x50
    d_w = s.wall_grain_diameter * x50
    nw = max(3, int(math.floor(L / d_w)))
    v_mean = _mean_volume(s)
    H_loose = s.n_particles * v_mean / (s.loose_fraction * L * L)
    H_dense = s.n_particles * v_mean / (s.dense_fraction * L * L)
    gap = 0.55 * s.psd.d_max
    z_bot = d_w                                 # centres of the bottom wall grains
    z_pack = [z_bot + d_w / 2 + gap, z_bot + d_w / 2 + gap + H_loose]
    z_top = z_pack[1] + gap + d_w / 2           # centres of the top wall grains at the start
    z_top_dense = z_bot + d_w + H_dense          # estimate after compression
    return {"L": L, "d_wall": d_w, "n_wall_side": nw, "n_wall": nw * nw, "H_loose": H_loose, "H_dense": H_dense,
            "z_bottom": z_bot, "z_top": z_top, "z_top_dense": z_top_dense, "z_pack": z_pack,
            "box_lo": [0.0, 0.0, 0.0], "box_hi": [L, L, z_top + 3 * d_w + H_loose]}


def servo_dashpot_gain(case, v_max: float, kp: float) -> float:
    """Loop gain G = v_max kp γ/F_c [-] of the top wall's force servo against the dashpots of the
    grains it pushes (the shear cell's :func:`.shear_cell.servo_dashpot_gain`): the wall is a rigid
    layer of grains, so its contacts are grain-grain (E*, r_eff = x50/4, m* ≈ m50 against the heavy
    wall) at the mean contact force F_c = π x50² σ/(4 φ) + F_adh."""
    s = case.scene
    x50 = s.psd.median
    mat = case.material
    Fc = math.pi * x50 ** 2 * s.normal_stress / (4 * s.dense_fraction) + adhesion_force(case)
    E = effective_modulus(mat.youngs_modulus, mat.poisson_ratio, mat.youngs_modulus, mat.poisson_ratio)
    gamma = wall_dashpot_coefficient(E, x50 / 4, mat.density * math.pi / 6 * x50 ** 3, Fc, case.contact.damping,
                                     case.contact.restitution)
    return v_max * kp * gamma / Fc


def _speeds(case, g=None) -> tuple[float, float]:
    """(servo speed limit, shear speed) [m/s] from the inertial numbers; the servo's capped so that
    its loop gain against the contacts' dashpots stays at contact_law.SERVO_DASHPOT_GAIN (as the shear cell's)."""
    s = case.scene
    g = g or geometry(case)
    T = _time_scale(case)
    v = s.compression_inertial_number * g["H_dense"] / T
    return dashpot_stable_servo_speed(v, servo_dashpot_gain(case, v, s.servo_gain)), s.inertial_number * g["H_dense"] / T


def max_velocity(case) -> float:
    v_servo, v_shear = _speeds(case)
    return 2 * max(v_servo, v_shear)


def stability_inputs(case, params) -> StabilityInputs:
    sc = params.scene
    c = sc.contact
    return StabilityInputs(
        n_particles=sc.n, total_steps=sc.total_steps, box_lo=sc.box_lo, box_hi=sc.box_hi,
        wall_speeds={"servo": sc.servo.v_max, "shear": sc.v_shear},
        confining_stress=case.scene.normal_stress, skin=sc.skin,
        height=sc.geometry.z_top - sc.geometry.z_bottom,
        wall_force_target=sc.servo.target_force, periodic=(True, True, False),
        adhesion_force=c.adhesion_force, restitution=c.restitution.target,
        rolling_stiffness=c.rolling_stiffness, rolling_coefficient=c.rolling_coefficient,
        twisting_stiffness=c.twisting_stiffness, torsion_coefficient=c.torsion_coefficient)


@dataclass(frozen=True)
class PlaneShearParams(ScenePart):
    """The plane-shear scene's numbers (SI). Steps are absolute step numbers of the one run."""
    n: int                 #: all grains, mobile and wall [-]
    n_mobile: int          #: mobile grains [-]
    n_wall: int            #: grains per wall [-]
    ids_mobile: tuple      #: [first, last] id of the mobile grains
    ids_bottom: tuple      #: [first, last] id of the bottom wall's grains
    ids_top: tuple         #: [first, last] id of the top wall's grains
    geometry: dict         #: box and wall geometry (:func:`geometry`) [m]
    box_lo: tuple          #: simulation box [m]
    box_hi: tuple
    stages: dict           #: stage -> [first step, last step] (compress, shear)
    steps: int             #: last step [-]
    total_steps: int       #: = steps
    events: tuple          #: deck events: {step, frame (bool), begin ("shear" or "")}
    frame_steps: tuple     #: steps of the frames
    frame_stage: tuple     #: stage code of each frame (STAGES)
    dump_every: int        #: [-] (frames are written by events)
    restart_every: int     #: steps between restart points
    wall_every: int        #: steps between wall samples
    servo: dict            #: target_force [N], v_max [m/s], kp [-], tau [s], travel [m]
    v_shear: float         #: top wall's shear speed [m/s]
    shear_rate: float      #: nominal shear rate v_shear/H [1/s]
    skin: float            #: neighbour skin [m]
    wall_mass: float       #: mass of one wall [kg]
    contact: ContactTerms  #: contact terms beyond Hertz-Mindlin
    gravity: float         #: [m/s²]
    steady_from_strain: float   #: shear strain the steady state is averaged from [-]


def derive(case, common: Params) -> PlaneShearParams:
    s = case.scene
    g = geometry(case)
    dt = common.dt
    rho = case.material.density
    x50 = s.psd.median
    v_max, v_shear = _speeds(case, g)
    F_target = s.normal_stress * g["L"] ** 2
    E_pp = common.E_eff_pp
    E_bulk = (E_pp ** 2 * s.normal_stress) ** (1 / 3)
    k_bulk = E_bulk * g["L"] ** 2 / g["H_dense"]
    tau_servo = F_target / (v_max * s.servo_gain * k_bulk)
    travel = max(0.0, g["z_top"] - g["z_top_dense"])
    n_compress = int(math.ceil((1.5 * travel / v_max + s.settle_time_constants * tau_servo) / dt))
    gamma_dot = v_shear / g["H_dense"]
    n_shear = int(math.ceil(s.shear_strain / gamma_dot / dt))
    s1, s2 = n_compress, n_compress + n_shear
    skin = max(0.25 * s.psd.d_max, 2.5 * max(v_max, v_shear) * dt)
    if max(v_max, v_shear) * dt > skin / 2:
        raise DerivationError(f"plane_shear: a wall moves {max(v_max, v_shear) * dt:.3g} m per step, more than half "
                              f"the skin {skin:.3g} m")
    shear_frames = [s1 + int(round(n_shear * (k + 1) / s.shear_frames)) for k in range(s.shear_frames)]
    frame_steps = [0, s1] + shear_frames
    if len(set(frame_steps)) != len(frame_steps):
        raise DerivationError("plane_shear: two frames fall on one step; lower shear_frames")
    frame_stage = [STAGES["initial"], STAGES["compressed"]] + [STAGES["shear"]] * s.shear_frames
    wall_every = max(10, (s2 // s.wall_samples) // 10 * 10)
    events = [{"step": st, "frame": st in frame_steps, "begin": "shear" if st == s1 else ""}
              for st in sorted(set(frame_steps) | {s1, s2})]
    n_mobile = s.n_particles
    nw = g["n_wall"]
    # contact terms
    F_adh = adhesion_force(case)
    contact = {"adhesion_force": F_adh, "restitution": common.restitution.to_dict(), "r_eff_mean": x50 / 4,
               "median_radius": x50 / 2}
    c = case.contact
    # overlap of a median pair (r_eff = x50/4) under the mean contact force of the packing,
    # F_c = π x50² σ/(4 φ) + F_adh (4 contacts per grain; as scenes.shear_cell._expected_overlap)
    r_eff = x50 / 4
    Fc = s.normal_stress * x50 ** 2 / (s.dense_fraction * 4 / math.pi) + F_adh
    xi = (3 * Fc / (4 * E_pp * math.sqrt(r_eff))) ** (2 / 3)
    if F_adh > 0:
        contact["expected_overlap"] = xi
    # rolling and twisting resistance exactly as the shear cell (scenes/shear_cell.py): seed §3.2
    # springs k_r = k_tw = k_t r_eff² with k_t = 2/7 k_n, k_n = 4/3 E* x50/2; rolling limit
    # M = μ_r r_eff |F_n| (seed000: μ_r r_eff = √(2 r_eff ξ)); engines' stand-ins are substitutes
    kt_seed = 2 / 7 * (4 / 3 * E_pp * x50 / 2)
    if _has_rolling(c):
        mu_r = math.sqrt(2 * r_eff * xi) / r_eff if c.rolling.model == "seed000" else c.rolling.coefficient
        contact["rolling_coefficient"] = mu_r
        contact["rolling_stiffness"] = kt_seed * r_eff ** 2
        contact["expected_overlap"] = xi
    if _has_torsion(c):
        contact["torsion_coefficient"] = c.torsion.coefficient
        contact["twisting_stiffness"] = kt_seed * r_eff ** 2
    return PlaneShearParams(
        n=n_mobile + 2 * nw, n_mobile=n_mobile, n_wall=nw,
        ids_mobile=[1, n_mobile], ids_bottom=[n_mobile + 1, n_mobile + nw],
        ids_top=[n_mobile + nw + 1, n_mobile + 2 * nw],
        geometry=g, box_lo=g["box_lo"], box_hi=g["box_hi"],
        stages={"compress": [0, s1], "shear": [s1, s2]}, steps=s2, total_steps=s2,
        events=events, frame_steps=frame_steps, frame_stage=frame_stage,
        dump_every=max(1, s2), restart_every=multiple_of(max(1000, s2 // 5), wall_every), wall_every=wall_every,
        servo={"target_force": F_target, "v_max": v_max, "kp": s.servo_gain, "tau": tau_servo, "travel": travel},
        v_shear=v_shear, shear_rate=gamma_dot, skin=skin,
        wall_mass=nw * rho * math.pi / 6 * g["d_wall"] ** 3,
        contact=ContactTerms(**contact), gravity=case.gravity, steady_from_strain=s.steady_from * s.shear_strain)


# ------------------------------------------------------------------------------------------------
def sample_particles(case, params) -> dict:
    s = case.scene
    sc = params["scene"]
    g = sc["geometry"]
    rng = np.random.default_rng(case.seed)
    d = lognormal_diameters(s.n_particles, s.psd.median, s.psd.d_min, s.psd.d_max, s.psd.sigma_ln, rng)
    try:
        pos = pack_box(d / 2, g["L"], g["z_pack"][0], g["z_pack"][1], rng)
    except ValueError as exc:
        raise DerivationError(f"plane_shear: cannot place {len(d)} grains at the loose fraction (RSA jammed: {exc}); "
                              "lower scene.loose_fraction") from None
    nw1 = g["n_wall_side"]
    a = g["L"] / nw1
    xy = (np.stack(np.meshgrid(np.arange(nw1), np.arange(nw1), indexing="ij"), -1).reshape(-1, 2) + 0.5) * a
    bottom = np.column_stack([xy, np.full(len(xy), g["z_bottom"])])
    top = np.column_stack([xy + 0.25 * a, np.full(len(xy), g["z_top"])])     # staggered: no aligned channels
    top[:, :2] %= g["L"]
    radius = np.concatenate([d / 2, np.full(2 * len(xy), g["d_wall"] / 2)])
    position = np.vstack([pos, bottom, top])
    return {"id": np.arange(1, len(radius) + 1), "radius": radius, "position": position}


def prepare(case, params, run_dir) -> tuple[dict, PlaneShearParams]:
    table = ensure_particle_table(run_dir, case, lambda: sample_particles(case, params))
    return {"particles": str(table)}, params.scene


# ------------------------------------------------------------------------------------------------
def _strain_of_step(params, steps):
    sc = params["scene"]
    s1 = sc["stages"]["shear"][0]
    return np.clip(np.asarray(steps, float) - s1, 0, None) * params["dt"] * sc["shear_rate"]


def _controls(params, steps) -> dict:
    sc = params["scene"]
    lookup = dict(zip(sc["frame_steps"], sc["frame_stage"]))
    return {"shear_strain": _strain_of_step(params, steps),
            "stage": np.array([lookup.get(int(s), np.nan) for s in steps], float)}


def _walls(params, a: np.ndarray) -> dict:
    """Rows: step, z_top, Fx Fy Fz (top), Fx Fy Fz (bottom): forces the grains exert on each wall."""
    a = a[np.argsort(a[:, 0], kind="stable")]
    keep = np.concatenate([[True], np.diff(a[:, 0]) > 0])
    a = a[keep]
    t = a[:, 0] * params["dt"]
    z = a[:, 1]
    zero = np.zeros_like(z)
    return {"top": {"time": t, "position": np.column_stack([zero, zero, z]), "force": a[:, 2:5],
                    "strain": _strain_of_step(params, a[:, 0])},
            "bottom": {"time": t, "force": a[:, 5:8]}}


def mu_macro_series(frames) -> "pd.DataFrame":
    """μ_macro(strain) = |F_x|/|F_z| on the top wall, from a run's frames.h5."""
    import pandas as pd        # on demand: pandas costs ~0.3 s to import
    w = frames.wall("top")
    with np.errstate(invalid="ignore", divide="ignore"):
        mu = np.abs(w["force_x"].to_numpy()) / np.abs(w["force_z"].to_numpy())
    return pd.DataFrame({"time": w["time"], "strain": w["strain"], "mu": mu, "normal_force": w["force_z"],
                         "shear_force": w["force_x"], "z_top": w["position_z"]})


def steady_mu(frames, params_or_summary: dict | None = None, steady_from_strain: float | None = None) -> dict:
    """Steady-state μ_macro: mean, standard deviation and standard error (over ~independent blocks)
    of |F_x|/|F_z| for strain ≥ ``steady_from_strain`` (default: from the run's params)."""
    df = mu_macro_series(frames)
    if steady_from_strain is None:
        steady_from_strain = (params_or_summary or {}).get("scene", {}).get("steady_from_strain", 0.0)
    sel = df[(df.strain >= steady_from_strain) & (df.strain > 0)]
    mu = sel["mu"].to_numpy()
    if len(mu) == 0:
        return {"mu": float("nan"), "std": float("nan"), "sem": float("nan"), "n": 0}
    # μ from the mean forces (less biased by noise in F_z than the mean of the ratio)
    mu_f = float(np.abs(sel["shear_force"]).mean() / np.abs(sel["normal_force"]).mean())
    return {"mu": mu_f, "mu_mean_ratio": float(mu.mean()), "std": float(mu.std()),
            "sem": block_sem(mu),
            "n": int(len(mu)), "steady_from_strain": steady_from_strain,
            "normal_stress_rel_error": float(np.abs(sel["normal_force"]).mean() / frames_target(frames) - 1)
            if frames_target(frames) else float("nan")}


def frames_target(frames) -> float | None:
    try:
        meta = frames.meta
        case = meta.get("case") if isinstance(meta, dict) else None
        if isinstance(case, str):
            case = json.loads(case)
        s = case["scene"]
        L = s["width"] * float(str(s["psd"]["median"]).split()[0])
        return float(str(s["normal_stress"]).split()[0]) * L * L
    except Exception:
        return None


class PlaneShearScene(base.Scene):
    """Periodic plane shear between two rough walls (module docstring). Controls per frame: the
    imposed ``shear_strain`` (γ = v_shear t / h) and the protocol ``stage``; wall series ``top``
    (with its ``strain``) and ``bottom``."""
    kind = "plane_shear"
    section = Scene
    honoured = frozenset({"contact.adhesion", "contact.rolling", "contact.torsion", "gravity", "initial_packing"})
    controls = {"shear_strain": "1", "stage": "1"}
    #: the decks' wall sampler: step, z_top, Fx Fy Fz on the top wall, Fx Fy Fz on the bottom wall
    wall_columns = ("step", "z_top", "fx_top", "fy_top", "fz_top", "fx_bottom", "fy_bottom", "fz_bottom")
    observables = ("mu_macro",)

    def size_overrides(self, section, scale):
        """The periodic box side × ``scale`` at the same sample height (grains × scale²)."""
        return {"width": section.width * float(scale),
                "n_particles": max(10, round(section.n_particles * float(scale) ** 2))}

    required_features = staticmethod(required_features)
    derive = staticmethod(derive)
    max_velocity = staticmethod(max_velocity)
    size_range = staticmethod(size_range)
    stability_inputs = staticmethod(stability_inputs)
    prepare = staticmethod(prepare)

    def post(self, run_dir, params, output):
        rows = output.wall_rows()
        out = {"controls": _controls(params, output.frame_steps)}
        if rows is not None and rows.size:
            out["walls"] = _walls(params, rows)
        return out
