"""Drained triaxial compression of a cylindrical sample in a flexible membrane (seed 001 §2.1, §3.2).

Stages, identical in both engines (every number below is computed here, once):

1. **Isotropic compression.** The grains, packed by :func:`pack_cylinder` (collective
   rearrangement, no overlaps) to ``packing_fraction``, are confined laterally by the membrane
   (YADE) or its substitute (LIGGGHTS) carrying the confining pressure p (ramped over
   ``isotropic.ramp_steps``), and axially by a rigid smooth top platen servo-controlled to the same
   p: v_top = -v_max · clip(g · (1 - σ₁/p), -1, 1). The stage runs in chunks of ``iso_chunk``
   steps and ends after the first chunk whose *chunk-averaged* σ₁ and σ₃ are both within
   ``isotropic.tolerance`` of p (or after ``isotropic.max_chunks`` chunks; the test then fails).
2. **Strain-controlled axial loading.** The top platen moves down at constant speed
   v = ε̇ H₀ (H₀ = height at the end of stage 1) for ``shear_steps`` steps, which gives exactly
   the requested axial strain. ε̇ comes from the inertial number stated in the case:
   I = ε̇ d₅₀ √(ρ/p) (GDR MiDi 2004); I ≤ 1e-3 is the usual quasi-static bound.

Lateral boundary:

- YADE: a membrane of GridNodes/GridConnections/PFacets (yade.gridpfacet) wrapped on the sample;
  the pressure is applied as nodal forces p·A_f/3 along each facet's current inward normal,
  recomputed every ``membrane.update_every`` steps (follow-the-surface load, ``O.forces.setPermF``).
  The membrane extends one row beyond each platen and its ends are free.
- LIGGGHTS-PUBLIC has no membrane. Substitute ``shell_pressure`` (named in
  ``contact.substitutes``): the sample is cut into ``lateral.bands`` horizontal bands between the
  platens; in each band the outer envelope radius R_k is the largest ρ_i + r_i of its grains, the
  grains with ρ_i + r_i > R_k - w (w = ``lateral.shell_thickness`` × d₅₀) form the shell, and
  each shell grain receives the radial inward force p · 2πR_k h_k · r_i²/Σ_shell r_j², recomputed
  every ``lateral.update_every`` steps. The lateral force on every band therefore equals p times
  its envelope area; the sample bulges freely.

Measured (time series every ``series_every`` steps, written by the engine into ``triax.txt``):
σ₁ = F_top / A with A = V/H (the loading piston's force, as in the laboratory; F_bottom is
recorded too: in YADE the membrane, tied to the platens, carries a small part of the axial load); σ₃ = (radial force the lateral boundary exerts on the
grains) / (lateral boundary area); ε_a = (H₀ - H)/H₀; ε_v = (V₀ - V)/V₀ (compression positive,
stage-2 reference). The volume V is measured three ways, the last two from the grains alone:

- ``boundary``: the volume enclosed by the lateral boundary and the platens. YADE: the membrane's
  inner surface (closed polyhedron of node centres by the divergence theorem, minus node radius ×
  area); LIGGGHTS: Σ π R_k² h_k of the band envelopes;
- ``hull``: the convex hull of the grains' surfaces (points on every sphere near the hull),
  computed in Python from the frame's positions and radii (:func:`hull_volume`); it bridges a
  waist, so it overstates the volume of a sample that necks;
- ``slab_hull``: the stacked 2-D hulls of the grains' sections in slabs of 2 d50
  (:func:`slab_hull_volume`), convex within a slab only: it follows a neck.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from ..atomic import cache_dir, write_json, write_text
from ..case import Strict, positive
from ..clumps import bounding_radius, equivalent_scale, load_library, mass_properties, place, random_quaternions
from ..derive import DerivationError
from ..frames import load as load_frames
from ..numerics import running_mean
from ..params import Params, ScenePart, StabilityInputs, opt
from ..psd import Cylinder, lognormal_mu_for_mean, portable, relax_overlaps, truncated_lognormal
from ..particles_io import read_particle_table, write_particle_table
from ..units import Length, Pressure
from . import base, servo_loop


# scipy.spatial is imported on first use (scipy.optimize: in orchestrator.psd): every case load
# imports this scene, and they cost ~0.6 s (validate within 2 s, #16)
def cKDTree(*args, **kwargs):  # noqa: N802 - scipy's name (deferred as ConvexHull below)
    from scipy.spatial import cKDTree as f
    return f(*args, **kwargs)


def ConvexHull(*args, **kwargs):  # noqa: N802 - scipy's name
    from scipy.spatial import ConvexHull as f
    return f(*args, **kwargs)


#: per-frame controls written to frames.h5 (see module docstring)
CONTROLS: dict[str, str] = {
    "stage": "1", "axial_strain": "1", "volumetric_strain": "1", "volumetric_strain_hull": "1",
    "sigma1": "Pa", "sigma3": "Pa", "stress_ratio": "1", "volume_boundary": "m^3", "volume_hull": "m^3",
    "sigma3_hull": "Pa", "volume_slab_hull": "m^3", "volumetric_strain_slab_hull": "1"}

#: slab thickness of :func:`slab_hull_volume` in the controls [d50]: thin enough to follow a neck
#: (seed 2 of the small quasistatic case necks over ~5 d50), thick enough for a few grains per slab;
#: 1, 2 and 4 d50 on the 2 000-grain runs: docs/triaxial.md, "Volume, three ways"
SLAB_HULL_D50 = 2.0

#: columns of the engines' time-series file ``triax.txt`` (both engines write the same)
SERIES_COLUMNS = ("step", "time", "stage", "z_bottom", "z_top", "f_bottom", "f_top", "f_lateral",
                  "area_lateral", "volume", "pressure")


# ---------------------------------------------------------------------------------------------
# Case section
# ---------------------------------------------------------------------------------------------
class PSD(Strict):
    """Grain-size distribution. Either a truncated log-normal by number with the given arithmetic
    ``mean`` diameter between ``min`` and ``max`` (log standard deviation ``spread``), or a
    ``table`` of [diameter, cumulative mass fraction passing] rows (diameters with units)."""
    min: Length | None = None
    max: Length | None = None
    mean: Length | None = None
    spread: float = Field(0.3, gt=0, le=2)
    table: list[tuple[Length, float]] | None = None

    @model_validator(mode="after")
    def _check(self):
        if self.table is None:
            if None in (self.min, self.max, self.mean):
                raise ValueError("give min, max and mean diameters (e.g. '0.3 mm', '1.03 mm', '0.551 mm') or a table")
            if not 0 < self.min < self.mean < self.max:
                raise ValueError(f"need 0 < min < mean < max, got {self.min:g}, {self.mean:g}, {self.max:g} m")
        else:
            d = [r[0] for r in self.table]
            f = [r[1] for r in self.table]
            if len(d) < 2 or any(b <= a for a, b in zip(d, d[1:])) or any(b < a for a, b in zip(f, f[1:])):
                raise ValueError("table rows must have increasing diameters and non-decreasing fractions")
            if abs(f[0]) > 1e-9 or abs(f[-1] - 1) > 1e-9:
                raise ValueError("table fractions must run from 0 to 1")
        return self

    def bounds(self) -> tuple[float, float]:
        if self.table is not None:
            return self.table[0][0], self.table[-1][0]
        return self.min, self.max

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """n diameters [m]."""
        if self.table is not None:
            d = np.array([r[0] for r in self.table])
            F = np.array([r[1] for r in self.table])
            # mass fraction -> number fraction within each bin (d^-3 weighting of bin midpoints)
            dm = np.sqrt(d[1:] * d[:-1])
            w = np.diff(F) / dm ** 3
            w = w / w.sum()
            b = rng.choice(len(w), size=n, p=w)
            u = rng.random(n)
            # uniform in log d inside the bin
            return np.exp(np.log(d[b]) + u * (np.log(d[b + 1]) - np.log(d[b])))
        mu = lognormal_mu_for_mean(self.mean, self.spread, self.min, self.max)
        return truncated_lognormal(n, mu, self.spread, self.min, self.max, rng)

    def mean_diameter(self) -> float:
        """d50 by number (table: by mass) [m], the grain size in the inertial number."""
        if self.table is not None:
            d = np.array([r[0] for r in self.table])
            F = np.array([r[1] for r in self.table])
            return float(np.interp(0.5, F, d))
        return self.mean


class Isotropic(Strict):
    """Stage 1: pressure ramp, axial servo, convergence test."""
    inertial_number: float = Field(1e-3, gt=0, le=0.1,
                                   description="sets the servo's largest platen speed v_max = I/(d√(ρ/p))·H")
    gain: float | None = Field(None, gt=0, description="servo gain g in v = -v_max clip(g(1-σ_top/p), -1, 1); None: "
                                                       "half the servo's stability limit (derive(): above it the platen "
                                                       "chatters or diverges, the sample is hammered)")
    ramp_steps: int | None = Field(None, ge=0, description="steps over which p is ramped up (None: derived)")
    tolerance: float = Field(0.01, gt=0, lt=0.5, description="|σ/p - 1| to end the stage (chunk averages)")
    max_chunks: int = Field(60, ge=1)
    chunk_frames: int = Field(2, ge=1, description="frames per convergence chunk")
    drag: bool = Field(True, description="Stokes drag F = -6πνr v on the grains during stage 1 only, with ν "
                                         "such that a grain pushed by p d50² drifts at drag_inertial_number·√(p/ρ): "
                                         "keeps the compaction of the loose packing from turning into a collapse")
    drag_inertial_number: float = Field(0.05, gt=0, le=1)
    drag_free_end: bool = Field(True, description="when stage 1 converges with the drag on, switch the drag off and "
                                                  "continue stage 1 until it converges again without it: the loose "
                                                  "sample's collapse then happens before loading, not at its start")
    drag_ramp: float = Field(1.0, ge=0, description="the drag is not switched off at once but its coefficient falls "
                                                    "linearly to zero over this many relaxation times T = 18ν/p "
                                                    "(derive(): the rearrangement time under the initial drag, "
                                                    "t_i²/τ_d; ~2 d50 of drift at the terminal speed), rounded up to "
                                                    "whole chunks; 0: off at once (the sample burst: 6-11 m/s)")
    creep_tolerance: float | None = Field(None, gt=0, lt=0.1, description="stage 1 with the drag ends (the drag's "
                                          "ramp begins) only when, besides the stresses, the boundary volume "
                                          "changed by less than this fraction between the means of the last two "
                                          "chunks: the drag-supported sample creeps (densifies) long after its "
                                          "stresses converge, and collapses when the drag goes (docs/triaxial.md). "
                                          "None: the stresses alone")
    friction: float | None = Field(None, ge=0, description="grain-grain friction coefficient during stage 1 (sample "
                                                       "preparation; None: contact.friction). A lower value gives a "
                                                       "denser sample, as the seed's vibrated, tapped one (seed 001 "
                                                       "§2.1); contact.friction is restored when stage 1 ends, which "
                                                       "leaves the isotropic equilibrium unchanged (a wider Coulomb "
                                                       "cone admits the same contact forces)")
    restore_friction: Literal["at_loading", "before_drag_ramp"] = Field(
        "at_loading", description="when contact.friction replaces the preparation friction: at the start of loading "
                                  "(default), or when stage 1 has converged with the drag, before the drag's ramp "
                                  "to zero, so that the drag leaves a frictional packing (fewer contacts at their "
                                  "Coulomb limit) that is less prone to local collapse once nothing damps it")


class Membrane(Strict):
    """YADE membrane: latex sheet (seed: 0.3 mm thick)."""
    youngs_modulus: Pressure = "1.4 MPa"
    thickness: Length = "0.3 mm"
    density: float = Field(1000.0, gt=0, description="kg/m^3")
    friction: float = Field(0.0, ge=0, description="grain-membrane friction coefficient")
    spacing: float = Field(3.0, gt=0.2, description="node spacing / d50 (3: facets bridge the surface voids like the "
                                                    "latex sheet, whose bending stiffness the GridNode mesh lacks; "
                                                    "1.5 let the membrane sink into the voids, docs/triaxial.md)")
    theta_spacing: float | None = Field(None, gt=0.2, description="node spacing around the sample / d50 (None: "
                                                                  "spacing); smaller values flatten the angle between "
                                                                  "neighbouring facets (30 deg for the 12-sided minimum)")
    node_radius: float = Field(0.15, gt=0, le=0.5, description="node (= half sheet thickness) radius / d50")
    contact_stiffness: float = Field(1.0, gt=0, description="grain-membrane kn as a multiple of the Hertz "
                                                              "tangent stiffness of a d50 grain on a flat wall at p")
    update_every: int = Field(5, ge=1, description="steps between updates of the nodal forces")
    damping: float = Field(0.5, ge=0, description="membrane internal viscosity as a fraction of critical "
                                                  "for a node on a grain contact (relative to its neighbours)")
    correction_limit: float = Field(0.1, ge=0, lt=0.5, description="largest membrane correction |p_applied/p - 1|")
    correction_rows: int = Field(20, ge=1, description="averaging window (time-series rows) of the correction")
    correction_gain: float = Field(0.5, ge=0)
    contact_damping: float = Field(0.3, ge=0, description="grain-membrane normal dashpot, fraction of critical "
                                                          "(a Python PyRunner every step: slow; 0 switches it off)")
    node_damping: float = Field(0.0, ge=0, lt=1, description="Cundall local damping of NewtonIntegrator (C++) on the "
                                                             "membrane nodes only; grains stay undamped (State.isDamped)")
    contact_damping_lagged: bool = Field(False, description="apply the dashpots with the pressure every update_every "
                                                            "steps (permanent forces) instead of every step: faster")
    node_drag: bool = Field(False, description="keep the stage-1 Stokes drag on the membrane nodes (only) once the "
                                               "grains' drag is off (end of stage 1 and loading): numerical damping "
                                               "of the sheet's own motion")


class Lateral(Strict):
    """LIGGGHTS substitute (shell_pressure): bands and shell definition."""
    bands: int | None = Field(None, ge=1, description="None: one band per ~3 d50 of height")
    sectors: int = Field(8, ge=1, description="angular sectors per band (cells = bands x sectors)")
    shell_thickness: float = Field(0.5, gt=0, le=2, description="w / d50")
    update_every: int = Field(20, ge=1)


class Particles(Strict):
    """Grain shape: ``spheres`` (default) or ``clumps`` built from a shape library (orchestrator.clumps:
    YAML ``shapes: [{spheres: [[x, y, z, r], ...]}]`` or NPZ ``spheres``/``shape``). Each grain takes a
    random library shape and orientation, scaled to the volume of its sampled PSD diameter; the
    packing places the clumps' bounding spheres. YADE builds them with ``O.bodies.clump`` at those
    places (feature ``placed_clumps``). LIGGGHTS-PUBLIC cannot place a multisphere body (they only
    enter through ``fix insert/*``): with the substitute ``inserted_clumps`` accepted in
    ``contact.substitutes`` it inserts the same shapes, the same number of grains of each shape, in
    ``size_classes`` volume-mean sizes, at random places and orientations into the sample cylinder
    (:func:`inserted_clumps`)."""
    shape: Literal["spheres", "clumps"] = "spheres"
    library: str | None = Field(None, description="clump library file (.yaml/.yml or .npz); relative paths "
                                                  "are taken from the working directory")
    discretization: int = Field(20, ge=5, le=200, description="YADE clump() grid cells per clump diameter for "
                                                              "the union's mass and inertia")
    size_classes: int = Field(3, ge=1, le=12, description="LIGGGHTS (inserted_clumps): the sampled diameters are "
                              "cut into this many equal-count classes, each inserted at its volume-mean diameter "
                              "(one particletemplate/multisphere per library shape and class)")
    insertion_attempts: int = Field(500, ge=1, description="LIGGGHTS (inserted_clumps): insert/pack maxattempt, "
                                    "tries per clump to find a place free of overlaps")

    @model_validator(mode="after")
    def _check(self):
        if self.shape == "clumps":
            if not self.library:
                raise ValueError("particles.shape: clumps needs particles.library (a .yaml or .npz shape library)")
            load_library(self.library)          # raises LibraryError (a ValueError) naming file and shape
        elif self.library is not None:
            raise ValueError("particles.library is only used with particles.shape: clumps")
        return self


class Scene(Strict):
    kind: Literal["triaxial"]
    diameter: Length = "12 mm"
    height: Length = "25 mm"
    grains: int | None = Field(None, ge=20, description="scale the sample (same height/diameter) to hold about "
                                                         "this many grains; None: as many as fit")
    psd: PSD
    particles: Particles = Field(default_factory=Particles)
    packing_fraction: float = Field(0.52, gt=0.3, lt=0.56, description="solid fraction of the generated packing")
    confining_pressure: Pressure = "300 kPa"
    axial_strain: float = Field(0.2, gt=0, lt=0.5, description="axial strain at the end of loading")
    inertial_number: float = Field(1e-3, gt=0, le=0.1, description="I = ε̇ d50 √(ρ/p) during axial loading")
    platen_friction: float = Field(0.0, ge=0, description="grain-platen friction (smooth platens: 0)")
    isotropic: Isotropic = Field(default_factory=Isotropic)
    membrane: Membrane = Field(default_factory=Membrane)
    lateral: Lateral = Field(default_factory=Lateral)
    frames: int = Field(20, ge=2, description="frames written during axial loading")
    series_every: int | None = Field(None, ge=1, description="steps between time-series rows (None: derived)")
    verlet_distance: float = Field(0.05, gt=0, le=1, description="YADE collider verletDist / d50: 0.3 gave ~10 "
                                   "potential sphere-PFacet interactions per real one and made the InteractionLoop "
                                   "the main cost")

    _pos = positive("diameter", "height", "confining_pressure")


# ---------------------------------------------------------------------------------------------
# Scene contract
# ---------------------------------------------------------------------------------------------
def required_features(case) -> list[str]:
    feats = ["hertz", "restitution_damping", "sliding_friction", "membrane"]
    if case.scene.particles.shape == "clumps":
        feats.append("placed_clumps")
    if case.output.stress:
        feats.append("particle_stress")
    if case.output.contacts:
        feats.append("contact_output")
    return feats


def size_range(case) -> tuple[float, float]:
    """Smallest and largest sphere radius [m] the engine integrates (clumps: member spheres of the
    library shapes scaled to the PSD's smallest and largest diameters; the time step follows)."""
    lo, hi = case.scene.psd.bounds()
    if case.scene.particles.shape == "clumps":
        shapes = _clump_library(case.scene.particles.library)
        r_lo = min(float(sh[:, 3].min()) * equivalent_scale(sh, lo, v) for sh, (v, _), _ in shapes)
        r_hi = max(float(sh[:, 3].max()) * equivalent_scale(sh, hi, v) for sh, (v, _), _ in shapes)
        return r_lo, r_hi
    return lo / 2, hi / 2


_LIB_CACHE: dict = {}


def _clump_library(path) -> list:
    """[(shape (m, 4), (union volume, centre of mass), bounding radius about it)] of a clump library
    in the library's units, cached by path."""
    key = str(Path(path).resolve())
    if key not in _LIB_CACHE:
        out = []
        for sh in load_library(path):
            mp = mass_properties(sh)
            out.append((sh, (mp["volume"], mp["center"]), bounding_radius(sh, mp["center"])))
        _LIB_CACHE[key] = out
    return _LIB_CACHE[key]


def _clump_draw(case, d: np.ndarray):
    """Per grain: library shape index, orientation quaternion, scale to the volume of diameter d,
    bounding-sphere radius [m]; and f = (Σ r_b³ / Σ (d/2)³)^(1/3), the factor by which the sample
    grows so that the bounding spheres fill it at the case's packing fraction."""
    lib = _clump_library(case.scene.particles.library)
    rng = np.random.default_rng(case.seed + 3)
    k = rng.integers(len(lib), size=len(d))
    q = random_quaternions(len(d), rng)
    scale = np.array([equivalent_scale(lib[kk][0], di, lib[kk][1][0]) for kk, di in zip(k, d)])
    rb = np.array([lib[kk][2] * sc for kk, sc in zip(k, scale)])
    return k, q, scale, rb, float((np.sum(rb ** 3) / np.sum((d / 2) ** 3)) ** (1 / 3))


def _member_count(case, d: np.ndarray) -> int:
    """Member spheres the engines integrate for clump grains of diameters ``d`` (the shape draw of
    :func:`_clump_draw`)."""
    members = np.array([len(sh) for sh, _, _ in _clump_library(case.scene.particles.library)])
    return int(members[_clump_draw(case, d)[0]].sum())


def build_clumps(case, d: np.ndarray, R: float, H: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Clumps for grains of volume-equivalent diameters ``d`` [m]: a random library shape and a
    uniformly random orientation each, scaled to the grain's volume; their bounding spheres packed
    by :func:`pack_cylinder` in the cylinder of radius R, height H [m] (:func:`derive` has enlarged
    it by :func:`_clump_draw`'s f). Returns (member spheres (M, 4) [m], clump index of each member (M,),
    clump mass centres (n, 3), packing geometry of the members)."""
    lib = _clump_library(case.scene.particles.library)
    k, q, scale, rb, f = _clump_draw(case, d)
    centres, _ = cached_packing(rb, R, H, case.seed + 2)
    members, owner = [], []
    for i in range(len(d)):
        sh, (_, com), _ = lib[k[i]]
        members.append(place(sh, centres[i], scale[i], q[i], com))
        owner.append(np.full(len(sh), i))
    m = np.vstack(members)
    rr = np.hypot(m[:, 0], m[:, 1])
    geo = {"radius0": float(np.max(rr + m[:, 3])), "z_bottom0": float(np.min(m[:, 2] - m[:, 3])),
           "z_top0": float(np.max(m[:, 2] + m[:, 3])), "clump_count": int(len(d)),
           "clump_members": int(len(m)), "clump_bounding_scale": float(f)}
    geo["height0"] = geo["z_top0"] - geo["z_bottom0"]
    return m, np.concatenate(owner), centres, geo


#: inserted clumps (LIGGGHTS): steps over which the platens close on the inserted sample
CLOSE_STEPS = 100


def _prime_at_least(n: int) -> int:
    """The smallest prime >= n (LIGGGHTS wants prime random seeds above 10000)."""
    n = max(int(n), 10007)
    while any(n % q == 0 for q in range(2, int(n ** 0.5) + 1)):
        n += 1
    return n


def inserted_clumps(case, d: np.ndarray) -> dict:
    """Substitute ``inserted_clumps`` (LIGGGHTS-PUBLIC 3.8): what the deck needs to insert the grains
    of volume-equivalent diameters ``d`` [m] as multisphere bodies.

    The grains keep the library shape each one drew in :func:`_clump_draw` (same seed as YADE's
    placed clumps, so both engines hold the same number of grains of each shape and the same member
    count). ``particletemplate/multisphere`` has one size per template, so the sorted diameters are
    cut into ``particles.size_classes`` classes of equal count and every grain of a class takes the
    class's volume-mean diameter d_c = (mean d^3)^(1/3): the total solid volume and the count of each
    shape are exact; the spread of d inside a class is lost. One template per (shape, class) with at
    least one grain: member spheres [m] in the shape's frame, centred on the union's centre of mass,
    scaled to the volume of d_c; mass [kg] = density x union volume and the inertia tensor [kg m^2]
    about the centre of mass (:func:`orchestrator.clumps.mass_properties`, 60^3 grid), handed to
    LIGGGHTS with ``mass ... inertia_tensor ... use_density`` (LIGGGHTS manual,
    fix_particletemplate_multisphere: "the body's mass and inertia tensor can be specified directly
    via keywords mass and inertia_tensor", only together, with use_volume or use_density); LIGGGHTS
    still runs its Monte Carlo (``mc_tries``) over the template for its own bookkeeping (centre,
    bounding sphere).
    The weights of ``particledistribution/discrete/numberbased`` are count/n: with
    ``random_distribute exact`` LIGGGHTS inserts exactly these counts (checked on the installed
    binary: 300 bodies of two templates at 40/60 % gave 120/180)."""
    P = case.scene.particles
    lib = _clump_library(P.library)
    k = _clump_draw(case, d)[0]
    rho = case.material.density
    K = max(1, min(P.size_classes, len(d)))
    groups = np.array_split(np.argsort(d, kind="stable"), K)
    templates, classes = [], []
    for c, g in enumerate(groups):
        dc = float(np.mean(d[g] ** 3) ** (1 / 3))
        classes.append({"diameter": dc, "count": int(len(g)), "d_min": float(d[g].min()), "d_max": float(d[g].max())})
        for s in range(len(lib)):
            count = int(np.sum(k[g] == s))
            if count == 0:
                continue
            sh, (V, com), _ = lib[s]
            scale = equivalent_scale(sh, dc, V)
            sp = np.column_stack([(sh[:, :3] - com) * scale, sh[:, 3] * scale])   # centred on the centre of mass
            # the union's properties scale with the shape (the integration grid scales with its bounding box):
            # volume s^3, inertia rho s^5 times those of the library shape (remembered, unit density)
            mp0 = mass_properties(sh)
            vol = mp0["volume"] * scale ** 3
            I = rho * mp0["inertia"] * scale ** 5
            templates.append({
                "shape": s, "size_class": c, "diameter": dc, "count": count, "nspheres": int(len(sp)),
                "spheres": sp.tolist(), "mass": rho * vol, "volume": vol,
                "inertia": [I[0, 0], I[0, 1], I[0, 2], I[1, 1], I[1, 2], I[2, 2]],
                "principal": (rho * mp0["principal"] * scale ** 5).tolist(),
                "bounding_radius": float(np.max(np.linalg.norm(sp[:, :3], axis=1) + sp[:, 3])),
            })
    n = len(d)
    base = 10007 + 7919 * int(case.seed)
    seeds = []
    for _ in range(len(templates) + 2):
        seeds.append(_prime_at_least(base if not seeds else seeds[-1] + 1))
    for t, sd in zip(templates, seeds):
        t["seed"] = sd
        t["weight"] = t["count"] / n
    v_min = min(t["volume"] for t in templates)
    return {
        "templates": templates, "classes": classes, "count": n,
        "members": int(sum(t["count"] * t["nspheres"] for t in templates)),
        "seed_distribution": seeds[-2], "seed_insert": seeds[-1],
        # LIGGGHTS refuses templates below volume_limit (default 1e-12 m^3, larger than a sand grain)
        "volume_limit": 1e-3 * v_min,
        # Monte Carlo tries: a template's mass properties (LIGGGHTS' own bookkeeping; mass and inertia
        # are given) and the region volume (unused with particles_in_region)
        "mc_tries": 100000, "attempts": P.insertion_attempts,
        # the platens close on the inserted sample over these steps (one step of insertion first):
        # a mesh moving at most a bounding radius in 100 steps stays far below the skin per step
        "close_steps": CLOSE_STEPS, "start_step": 1 + CLOSE_STEPS,
        "volume_error_classes": float(sum(t["count"] * t["volume"] for t in templates)
                                      / np.sum(np.pi / 6 * d ** 3) - 1),
    }


def strain_rate(case) -> float:
    """ε̇ [1/s] from the inertial number: I = ε̇ d50 √(ρ/p)."""
    s = case.scene
    return s.inertial_number / (s.psd.mean_diameter() * math.sqrt(case.material.density / s.confining_pressure))


def max_velocity(case) -> float:
    """Largest expected relative contact speed [m/s]: the faster of the loading platen and the
    isotropic servo's v_max, times 4 for local rearrangements."""
    s = case.scene
    d = s.psd.mean_diameter()
    rate_iso = s.isotropic.inertial_number / (d * math.sqrt(case.material.density / s.confining_pressure))
    H = _sample_size(case)[1]
    return 2.0 * max(strain_rate(case), rate_iso) * H


_SIZE_CACHE: dict = {}


def _sample_size(case) -> tuple[float, float, int, np.ndarray]:
    """(diameter, height, n, diameters): the sample and its grains' sampled diameters."""
    key = (case.scene.model_dump_json(), case.seed)
    if key not in _SIZE_CACHE:
        _SIZE_CACHE.clear()
        _SIZE_CACHE[key] = _sample_size_uncached(case)
    return _SIZE_CACHE[key]


def _sample_size_uncached(case):
    s = case.scene
    rng = np.random.default_rng(case.seed)
    probe = s.psd.sample(20000, np.random.default_rng(case.seed + 1))
    v_grain = float(np.mean(np.pi / 6 * probe ** 3))
    D, H = s.diameter, s.height
    v_sample = np.pi / 4 * D ** 2 * H
    n_fit = v_sample * s.packing_fraction / v_grain
    if s.grains is not None:
        scale = (s.grains / n_fit) ** (1 / 3)
        D, H, n = D * scale, H * scale, s.grains
    else:
        n = int(round(n_fit))
    d = s.psd.sample(n, rng)
    # rescale the sample so that the *sampled* grains fill it at packing_fraction exactly
    vs = float(np.sum(np.pi / 6 * d ** 3))
    k = (vs / s.packing_fraction / (np.pi / 4 * D ** 2 * H)) ** (1 / 3)
    if s.particles.shape == "clumps":
        k *= _clump_draw(case, d)[4]          # the clumps' bounding spheres fill it at packing_fraction
    return D * k, H * k, n, d


def stage1_problems(run_dir: Path) -> list[str]:
    """The run's stage-1 convergence as a problem sentence (empty: converged, or not reported)."""
    try:
        summary = json.loads((run_dir / "summary.json").read_text())
        tol = json.loads((run_dir / "params.json").read_text())["scene"]["iso"]["tolerance"]
    except (OSError, ValueError, KeyError):
        return []
    iso = (summary.get("scene") or {}).get("isotropic_end") or {}
    if iso.get("converged") is not False:
        return []
    return [f"stage 1 ended unconverged: σ1/p = {iso.get('sigma1_error', math.nan) + 1:.3f}, "
            f"σ3/p = {iso.get('sigma3_error', math.nan) + 1:.3f} (tolerance {tol:g}) when loading began: "
            + stage1_advice(*base.run_case_scene(run_dir, summary))]


def stage1_advice(scene: dict | None = None, case_file: str = "") -> str:
    """The case field that lets an unconverged stage 1 converge: its chunk budget
    (``scene.isotropic.max_chunks``, the value in ``scene`` quoted), or a slower servo
    (``isotropic.inertial_number``) where the stresses swing about p rather than creep toward it
    (YADE's PFacet membrane at 2 000 grains: σ1/p between 0.77 and 1.27 over seven chunks,
    docs/validation.md)."""
    iso = (scene or {}).get("isotropic")
    return (f"raise {base.case_field('scene.isotropic', iso, 'max_chunks', Isotropic, case_file)} so that the "
            f"stresses can settle before the loading, or, where they swing about p, lower "
            f"{base.case_field('scene.isotropic', iso, 'inertial_number', Isotropic, case_file)}")


def step_plan(scene_params) -> base.StepPlan:
    """Stage 1 goes on chunk by chunk until the stresses are within tolerance (at most
    ``iso.max_chunks`` chunks; the drag ramp's chunks and the loading are fixed): the step count
    a run takes is ``drag_ramp_steps + shear_steps + chunk * (chunks it took)``. The clock counts
    stage 1 in lengths of the pressure ramp (``iso.ramp_steps``, the compression time scale at the
    stage's inertial number): the chunk is two frame intervals of the loading, not a stage-1 time.

    The variable part holds the pressure ramp too: both decks run it to the first chunk boundary
    at or after ``ramp_steps`` (``ramp_end`` in the LIGGGHTS deck; YADE's first test there) before
    the ``max_chunks`` tested chunks, so a run takes at most ``ceil(ramp_steps / chunk) +
    max_chunks`` chunks besides the fixed part (LIGGGHTS, triaxial_small with I x 2: 5 ramp chunks,
    9 tested with the drag, 20 of drag ramp, 7 tested without: 21 chunks and the fixed part)."""
    iso = scene_params["iso"]
    chunk = int(iso["chunk"])
    ramp_chunks = -(-int(iso.get("ramp_steps") or 0) // chunk)
    return base.StepPlan(fixed=int(iso["drag_ramp_steps"]) + int(scene_params["shear_steps"]),
                         unit=chunk, max_units=int(iso["max_chunks"]) + ramp_chunks,
                         scale=int(iso.get("ramp_steps") or 0), what="pressure-ramp lengths in stage 1")


def stability_inputs(case, params) -> StabilityInputs:
    """What orchestrator.stability's pre-run check and in-deck monitors need: the confining
    pressure, the platen speeds (stage-1 servo limit, stage-2 loading), the sample height and the
    top platen's force scale p·πD²/4 (the monitors' wall-force figure trips at
    ``stability.wall_force_factor`` times it)."""
    sc = params.scene
    return StabilityInputs(
        n_particles=sc.n, n_spheres=sc.n_spheres, total_steps=sc.total_steps, box_lo=sc.box_lo, box_hi=sc.box_hi,
        wall_speeds={"servo": sc.iso.v_max, "loading": sc.strain_rate * sc.height},
        confining_stress=sc.pressure, skin=sc.skin, height=sc.height,
        wall_force_target=sc.pressure * math.pi * sc.diameter ** 2 / 4)


@dataclass(frozen=True)
class TriaxialParams(ScenePart):
    """The triaxial scene's numbers (SI). The packing's fields (``radius0`` ...) and the box are set
    by :func:`prepare`, which packs the grains."""
    n: int                    #: grains [-]
    ids: tuple                #: their ids 1..n
    n_spheres: int | None     #: clumps: member spheres the engines integrate [-]
    diameter: float           #: sample diameter [m]
    height: float             #: sample height [m]
    d50: float                #: mean diameter [m]
    pressure: float           #: confining pressure [Pa]
    axial_strain: float       #: final axial strain [-]
    strain_rate: float        #: loading strain rate [1/s]
    inertial_number: float    #: loading inertial number [-]
    shear_steps: int          #: steps of the loading stage [-]
    iso: dict                 #: stage-1 servo: chunk [steps], max_chunks, tolerance [-], v_max [m/s], gain, gain_limit [-], gain_integral [1/step], integral_steps, integral_window (|e| summed only below it) [-], ramp_steps, strain_rate_max [1/s], drag_viscosity [Pa s], drag_free_end, friction [-], drag_coefficient [Pa s], drag_ramp_steps (linear ramp of the drag to zero, whole chunks; 0: off at once), drag_ramp_time [s], creep_tolerance (only when asked: largest relative change of the chunk-mean boundary volume for the drag stage to end) [-]
    dump_every: int           #: steps between frames [-]
    series_every: int         #: steps between series rows [-]
    steps: int                #: steps of both stages [-]
    total_steps: int          #: = steps
    restart_every: int        #: steps between resume points [-]
    platen_friction: float    #: platen Coulomb μ [-]
    clumps: dict | None       #: clumps: discretization and the inserted-clumps templates (:func:`inserted_clumps`)
    membrane: dict            #: membrane mesh and springs: n_theta, n_z [-], node_radius [m], E_conn, E_facet [Pa], k_contact [N/m], node_mass [kg], damping [N s/m] ...
    lateral: dict             #: shell boundary: bands, sectors [-], shell [m], update_every [steps]
    skin: float               #: neighbour skin [m]
    series_columns: tuple     #: columns of triax.txt
    servo_every: int          #: steps between servo updates [-]
    diameters: tuple | None = opt("sampled volume-equivalent diameters [m] (dropped once packed)")
    radius0: float | None = opt("packed sample radius [m]")
    z_bottom0: float | None = opt("packed sample's lowest point [m]")
    z_top0: float | None = opt("packed sample's highest point [m]")
    height0: float | None = opt("packed sample height [m]")
    packing_fraction0: float | None = opt("packed solid fraction [-]")
    packing_iterations: int | None = opt("collective-rearrangement iterations [-]")
    clump_count: int | None = opt("clumps packed [-]")
    clump_members: int | None = opt("member spheres packed [-]")
    clump_bounding_scale: float | None = opt("bounding-sphere scale of the clump draw [-]")
    box_lo: tuple | None = opt("simulation box, lower corner [m]")
    box_hi: tuple | None = opt("simulation box, upper corner [m]")


def derive(case, common: Params) -> TriaxialParams:
    s = case.scene
    D, H, n, d = _sample_size(case)
    rho = case.material.density
    p = s.confining_pressure
    dt = common.dt
    d50 = s.psd.mean_diameter()
    rate = strain_rate(case)
    # --- frames and chunks --------------------------------------------------------------------
    shear_total = s.axial_strain / rate / dt           # steps at the nominal rate
    dump_every = max(1, int(round(shear_total / s.frames)))
    series_every = s.series_every or max(1, min(dump_every // 10, 200))
    dump_every = max(1, int(round(dump_every / series_every))) * series_every
    shear_steps = dump_every * s.frames
    rate = s.axial_strain / (shear_steps * dt)           # exact: shear_steps give the requested strain
    iso_chunk = dump_every * s.isotropic.chunk_frames
    # time for a pressure wave to cross the sample ~ H / sqrt(E*/rho)... the slow part is the
    # rearrangement; ramp the pressure over ~10 servo time scales t = H / v_max
    rate_iso = s.isotropic.inertial_number / (d50 * math.sqrt(rho / p))
    v_iso = rate_iso * H
    ramp = s.isotropic.ramp_steps if s.isotropic.ramp_steps is not None else \
        int(min(iso_chunk * s.isotropic.max_chunks / 3, 0.02 / rate_iso / dt))
    # --- lateral boundary numbers -------------------------------------------------------------
    bands = s.lateral.bands or max(1, int(round(H / (3 * d50))))
    m = s.membrane
    E_pw = common.E_eff_pw
    # Hertz overlap and tangent stiffness of a d50 grain on a flat wall carrying F = p d50^2
    delta, k_hertz = servo_loop.wall_contact(p, d50, E_pw)
    R = d50 / 2
    k_contact = m.contact_stiffness * k_hertz
    r_node = m.node_radius * d50
    # Ip2_FrictMat_CpmMat_FrictPhys: kn = 2 E1 r1 E2 r2/(E1 r1 + E2 r2) with the grain (E, r) and
    # the facet (E_f, r_node); solve for E_f at r1 = R
    E1R1 = case.material.youngs_modulus * R
    if k_contact >= 2 * E1R1:
        k_contact = 1.9 * E1R1
    e2r2 = k_contact * E1R1 / (2 * E1R1 - k_contact)
    E_facet = e2r2 / r_node
    # connections: CohFrictPhys kn = E_c r_node; a square-with-diagonal sheet of springs k at
    # spacing L has a 2-D modulus ~ k: E_c = E_m t / r_node
    E_conn = m.youngs_modulus * m.thickness / r_node
    spacing = m.spacing * d50
    n_theta = max(12, int(round(math.pi * D / ((m.theta_spacing or m.spacing) * d50))))
    n_z = max(4, int(round(H / spacing)))
    # node mass: the sheet's own mass, raised if needed so that a node on a grain contact is
    # stable at dt (m >= k (dt/0.2)^2)
    a_node = math.pi * D * H / (n_theta * n_z)
    m_node = max(m.density * m.thickness * a_node, 2.0 * k_contact * (dt / 0.2) ** 2)
    # stage 1 at most: the chunks the pressure ramp spans, then max_chunks tested ones (step_plan)
    total_iso = iso_chunk * (s.isotropic.max_chunks + -(-max(1, ramp) // iso_chunk))
    # --- stage-1 servo: v = -v_max clip(g e + g_i S, -1, 1) on the relative force error e = 1 - F/(pA) and
    # its sum S (orchestrator/scenes/servo_loop.py, docs/triaxial.md "Servo"). The platen's contacts
    # act as a spring K ~ (A/d50^2) k_hertz and a dashpot C ~ (A/d50^2) c (one d50 grain per d50^2 of
    # platen at F = p d50^2); the dashpot answers a speed change in the same step, and above
    # b = g v_max C/(pA) = 1 + a/2 the error flips sign every update (the even/odd chatter the 4 000-clump
    # YADE sample showed at the old default g = 0.8 pA/(v_max n dt K)). Default g: half the largest gain
    # stable over K in [0.5, 2] and C in [0.3, 1.5] x the estimates. The integral (time constant a tenth
    # of a chunk) removes the steady error of a creeping sample, e = v_creep/(v_max g), that a
    # proportional law leaves: a sample that compacts at the platen's pace otherwise reads sigma1 < p.
    servo_every = int(max(1, min(series_every, 0.1 * delta / (v_iso * dt))))
    c_platen = servo_loop.platen_damping(p, d50, E_pw, rho, common.restitution.damping_ratio or 0.0)
    servo_alpha = v_iso * servo_every * dt * k_hertz / (p * d50 ** 2)
    servo_beta = v_iso * c_platen / (p * d50 ** 2)
    gain_limit = servo_loop.stability_limit(servo_alpha, servo_beta)
    gain = s.isotropic.gain if s.isotropic.gain is not None else servo_loop.GAIN_MARGIN * gain_limit
    if gain >= gain_limit:
        raise DerivationError(f"scene.isotropic.gain = {gain:.3g} is at or above the servo's stability limit "
                              f"{gain_limit:.3g} (the platen's contact stiffness and damping, docs/triaxial.md "
                              f"\"Servo\"): the platen would chatter or diverge; use a gain below {gain_limit:.3g} "
                              f"or leave it out (default {servo_loop.GAIN_MARGIN:g} x the limit)")
    integral_steps = max(servo_every, int(round(servo_loop.INTEGRAL_FRACTION_OF_CHUNK * iso_chunk)))
    gain_integral = gain / integral_steps          # per step of error summed
    # stage-1 drag (same law in both engines): terminal speed v_t = I_iso sqrt(p/rho) for F = p d50^2
    v_t = s.isotropic.drag_inertial_number * math.sqrt(p / rho)
    nu = p * d50 / (3 * math.pi * v_t) if s.isotropic.drag else 0.0
    if nu > 0:
        r_min = common.r_min
        tau = 2 * rho * r_min ** 2 / (9 * nu)          # m/b of the smallest grain
        if dt > tau:
            raise DerivationError(f"scene.isotropic.drag: the drag time m/b = {tau:.3g} s of the smallest grain is "
                                  f"below dt = {dt:.3g} s (explicit drag unstable); raise "
                                  "scene.isotropic.inertial_number or set drag: false")
    # drag removal (issue #14: switched off at once, the drag-supported sample burst, 6-8 m/s on 300 grains and
    # 11 m/s on 2 000 on both engines). Under the drag b = 6 pi nu r a grain of mass m relaxes in tau_d = m/b
    # (d50: rho d50^2/(18 nu)); a grain pushed by p d50^2 through its neighbours rearranges overdamped in
    # T = t_i^2/tau_d with t_i = d50 sqrt(rho/p) the inertial time (GDR MiDi 2004): T = 18 nu/p, independent of
    # d50, the time to drift ~2 d50 at the terminal speed (6 d50/(pi v_t)). Letting b fall at the rate at which
    # the sample relaxes at the current drag, db/dt = -b/T(b) with T(b) = t_i^2 b/m, gives db/dt = -m/t_i^2:
    # a LINEAR ramp from b0 to zero lasting T(b0). It ends at a chunk boundary (both decks test chunks).
    if s.isotropic.creep_tolerance and not (nu > 0 and s.isotropic.drag_free_end):
        raise DerivationError("scene.isotropic.creep_tolerance tests the volume creep of the drag stage, but this case "
                              "has no drag stage (isotropic.drag or drag_free_end is false): remove creep_tolerance or "
                              "turn the drag stage on")
    drag_ramp_time = s.isotropic.drag_ramp * 18 * nu / p if nu > 0 else 0.0
    drag_ramp_steps = int(math.ceil(drag_ramp_time / dt / iso_chunk - 1e-9)) * iso_chunk if drag_ramp_time > 0 else 0
    params = {
        "n": n, "ids": list(range(1, n + 1)), "diameters": d.tolist(),
        # clumps: the member spheres the engines integrate (same shape draw in both engines)
        "n_spheres": (None if s.particles.shape != "clumps" else _member_count(case, d)),
        "diameter": D, "height": H, "d50": d50, "pressure": p, "axial_strain": s.axial_strain,
        "strain_rate": rate, "inertial_number": s.inertial_number, "shear_steps": shear_steps,
        "iso": {"chunk": iso_chunk, "max_chunks": s.isotropic.max_chunks, "tolerance": s.isotropic.tolerance,
                "v_max": v_iso, "gain": gain, "gain_limit": gain_limit, "gain_integral": gain_integral,
                "integral_steps": integral_steps, "integral_window": servo_loop.INTEGRAL_WINDOW, "ramp_steps": max(1, ramp),
                "strain_rate_max": rate_iso, "drag_viscosity": nu,
                "drag_free_end": bool(s.isotropic.drag_free_end and nu > 0),
                # preparation friction (stage 1), restored to contact.friction for loading
                "friction": (s.isotropic.friction if s.isotropic.friction is not None else case.contact.friction),
                "restore_friction": s.isotropic.restore_friction,
                "drag_coefficient": 6 * math.pi * nu,
                # linear ramp of the drag coefficient to zero once stage 1 has converged with it (whole chunks)
                "drag_ramp_steps": drag_ramp_steps, "drag_ramp_time": drag_ramp_time,
                # the volume-creep test of the drag stage (a key only when asked: runs without it keep their hash)
                **({"creep_tolerance": s.isotropic.creep_tolerance} if s.isotropic.creep_tolerance and nu > 0 else {})},
        "dump_every": dump_every, "series_every": series_every,
        "steps": total_iso + drag_ramp_steps + shear_steps, "total_steps": total_iso + drag_ramp_steps + shear_steps,
        # resume points every frame interval: YADE checkpoints (O.save) at the start of every
        # dump_every-th iteration; LIGGGHTS restart files every dump_every steps of loading and after
        # every stage-1 chunk test (a chunk is chunk_frames frames). At most one frame interval of
        # work is lost; the cost is measured in docs/triaxial.md (Resume)
        "restart_every": dump_every,
        "platen_friction": s.platen_friction,
        "clumps": ({"discretization": s.particles.discretization, "inserted": inserted_clumps(case, d)}
                   if s.particles.shape == "clumps" else None),
        "membrane": {"n_theta": n_theta, "n_z": n_z, "node_radius": r_node, "E_conn": E_conn,
                     "E_facet": E_facet, "k_contact": k_contact, "node_mass": m_node,
                     "friction": m.friction, "update_every": m.update_every, "density": m.density,
                     # relative (membrane-internal) viscosity: critical for a node on a grain contact
                     "damping": m.damping * 2 * math.sqrt(k_contact * m_node),
                     "correction_limit": m.correction_limit, "correction_rows": m.correction_rows,
                     "correction_gain": m.correction_gain, "node_drag": m.node_drag,
                     "contact_damping": m.contact_damping, "node_damping": m.node_damping,
                     "contact_damping_lagged": m.contact_damping_lagged},
        "lateral": {"bands": bands, "sectors": s.lateral.sectors, "shell": s.lateral.shell_thickness * d50,
                    "update_every": s.lateral.update_every},
        "skin": s.verlet_distance * d50,
        "series_columns": list(SERIES_COLUMNS),
        # servo update period: the platen moves at most ~ one tenth of a d50 grain's contact
        # overlap at p per update
        "servo_every": servo_every,
    }
    return TriaxialParams(**params)


def prepare(case, params: Params, run_dir: Path) -> tuple[dict, TriaxialParams]:
    """Pack the grains (cached in run_dir), write particles.txt and the platen meshes; return the
    files and the scene's numbers completed with the packed geometry."""
    sc = params.scene
    run_dir = Path(run_dir)
    geo_path = run_dir / "packing.json"
    if geo_path.exists() and (run_dir / "particles.txt").exists():
        geo = json.loads(geo_path.read_text())
    elif case.scene.particles.shape == "clumps":
        # one particles.txt row per member sphere (frames.h5 holds the spheres); clumps.txt maps
        # each member id to its clump (0 ... n-1)
        m, owner, _, geo = build_clumps(case, np.asarray(sc["diameters"]), sc["diameter"] / 2, sc["height"])
        ids = np.arange(1, len(m) + 1)
        write_particle_table(run_dir / "particles.txt", ids, m[:, 3], case.material.density, m[:, :3])
        write_text(run_dir / "clumps.txt", "# member_id clump\n" +
                   "".join(f"{i} {c}\n" for i, c in zip(ids, owner)))
        write_json(geo_path, geo)
    else:
        r = np.asarray(sc["diameters"]) / 2
        pos, geo = cached_packing(r, sc["diameter"] / 2, sc["height"], case.seed + 2)
        write_particle_table(run_dir / "particles.txt", sc["ids"], r, case.material.density, pos)
        write_json(geo_path, geo)
    R0 = geo["radius0"]
    half = 3.0 * R0
    sc = sc.replace(**geo, diameters=None, box_lo=[-half, -half, geo["z_bottom0"] - 2 * R0],
                    box_hi=[half, half, geo["z_top0"] + 2 * R0])
    files = {}
    for name, z in (("bottom", geo["z_bottom0"]), ("top", geo["z_top0"])):
        f = run_dir / f"platen_{name}.stl"
        _write_square_stl(f, 1.6 * R0 * 1.5, z, up=(name == "bottom"))
        files[f"platen_{name}"] = str(f)
    return files, sc


def _write_square_stl(path: Path, half: float, z: float, up: bool):
    """A square plate of half-width ``half`` at height z, two triangles, normal +z if ``up``."""
    a, b, c, dd = (-half, -half, z), (half, -half, z), (half, half, z), (-half, half, z)
    tris = [(a, b, c), (a, c, dd)] if up else [(a, c, b), (a, dd, c)]
    nz = 1.0 if up else -1.0
    out = ["solid platen"]
    for t in tris:
        out.append(f"facet normal 0 0 {nz}\n outer loop")
        out += [f"  vertex {v[0]!r} {v[1]!r} {v[2]!r}" for v in t]
        out.append(" endloop\nendfacet")
    out.append("endsolid platen")
    write_text(path, "\n".join(out) + "\n")


# ---------------------------------------------------------------------------------------------
# Packing
# ---------------------------------------------------------------------------------------------
def cached_packing(r: np.ndarray, R: float, H: float, seed: int) -> tuple[np.ndarray, dict]:
    """:func:`pack_cylinder`, cached by its inputs in ``$ORCHESTRATOR_CACHE/packings`` (default
    ``~/.cache/orchestrator``), so that both engines' runs of a case pack once. The key's last
    field is the packer's version (2: :func:`~orchestrator.psd.relax_overlaps` on a Verlet list,
    whose sums differ from version 1's in the last bits; 3: the random start rounded by
    :func:`~orchestrator.psd.portable`; 4: the push's volume weights by
    :func:`~orchestrator.psd.portable_cube`, the same on CPUs with AVX-512 as on the others), so a
    cache never mixes them."""
    h = hashlib.sha256(np.asarray(r, dtype=np.float64).tobytes() + repr((float(R), float(H), int(seed), 4)).encode())
    root = cache_dir("packings")
    f = root / f"{h.hexdigest()[:24]}.npz"
    if f.exists():
        d = np.load(f)
        return d["position"], json.loads(str(d["geometry"]))
    pos, geo = pack_cylinder(r, R, H, np.random.default_rng(seed))
    root.mkdir(parents=True, exist_ok=True)
    tmp = f.with_name(f.name + ".partial.npz")
    np.savez(tmp, position=pos, geometry=json.dumps(geo))
    os.replace(tmp, f)
    return pos, geo


def pack_cylinder(r: np.ndarray, R: float, H: float, rng: np.random.Generator, tol: float = 1e-3,
                  max_iter: int = 4000) -> tuple[np.ndarray, dict]:
    """Overlap-free random packing of spheres with radii ``r`` [m] in the cylinder ρ ≤ R,
    0 ≤ z ≤ H, by collective rearrangement: random centres, then repeated pairwise push-apart
    of overlapping spheres (each moved in inverse proportion to its volume) and projection into
    the cylinder, until the largest overlap is below ``tol`` × r_min; the remaining overlaps are
    removed by a uniform expansion about the centre. Returns (positions, geometry)."""
    n = len(r)
    u = rng.random(n)
    th = rng.random(n) * 2 * np.pi
    rho = np.sqrt(u) * np.maximum(R - r, 0)
    # rounded (psd.portable): NumPy's vectorised sin and cos take another SIMD path on AVX-512 CPUs and
    # differ by an ulp; rounded, a seed gives the same packing on every x86 CPU
    pos = portable(np.column_stack([rho * np.cos(th), rho * np.sin(th), r + rng.random(n) * np.maximum(H - 2 * r, 0)]))
    rmax = r.max()
    pos, it, worst = relax_overlaps(pos, r, Cylinder(R, 0.0, H), tol, r.min(), max_iter)
    if worst >= tol:
        raise RuntimeError(f"packing {n} grains at the requested packing fraction did not converge "
                           f"(largest overlap {worst:.3g} r_min after {max_iter} iterations); lower packing_fraction")
    # remove the remaining overlaps exactly: expand about the centre
    tree = cKDTree(pos)
    pairs = tree.query_pairs(2 * rmax, output_type="ndarray")
    c = np.array([0.0, 0.0, H / 2])
    if len(pairs):
        i, j = pairs[:, 0], pairs[:, 1]
        dist = np.linalg.norm(pos[j] - pos[i], axis=1)
        need = np.max((r[i] + r[j]) / dist)
        if need > 1:
            pos = c + (pos - c) * need * (1 + 1e-9)
    rr = np.hypot(pos[:, 0], pos[:, 1])
    geo = {
        "radius0": float(np.max(rr + r)),
        "z_bottom0": float(np.min(pos[:, 2] - r)),
        "z_top0": float(np.max(pos[:, 2] + r)),
        "packing_iterations": it,
    }
    geo["height0"] = geo["z_top0"] - geo["z_bottom0"]
    geo["packing_fraction0"] = float(np.sum(4 / 3 * np.pi * r ** 3) / (np.pi * geo["radius0"] ** 2 * geo["height0"]))
    return pos, geo


# ---------------------------------------------------------------------------------------------
# Volumes
# ---------------------------------------------------------------------------------------------
_SPHERE_DIRS: np.ndarray | None = None


def _sphere_dirs(k: int = 96) -> np.ndarray:
    """k nearly uniform unit vectors (Fibonacci sphere)."""
    global _SPHERE_DIRS
    if _SPHERE_DIRS is None or len(_SPHERE_DIRS) != k:
        i = np.arange(k) + 0.5
        phi = np.arccos(1 - 2 * i / k)
        th = np.pi * (1 + 5 ** 0.5) * i
        _SPHERE_DIRS = np.column_stack([np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)])
    return _SPHERE_DIRS


def hull_volume(pos: np.ndarray, r: np.ndarray, z_bottom: float | None = None, z_top: float | None = None) -> float:
    """Volume [m³] of the convex hull of the grains' surfaces, clipped to the platens
    z_bottom ≤ z ≤ z_top when given. Surfaces are sampled with 96 points per sphere for the
    spheres whose centre lies within 2 r_max of the centres' hull (the others cannot touch it)."""
    ok = ~np.isnan(pos).any(axis=1)
    pos, r = pos[ok], r[ok]
    h0 = ConvexHull(pos)
    eq = h0.equations                                   # n·x + d <= 0 inside
    depth = np.min(-(pos @ eq[:, :3].T + eq[:, 3]), axis=1)  # distance to the nearest hull plane
    near = depth < 2 * r.max()
    pts = (pos[near, None, :] + r[near, None, None] * _sphere_dirs()[None]).reshape(-1, 3)
    if z_bottom is not None:
        pts[:, 2] = np.clip(pts[:, 2], z_bottom, z_top)
    return float(ConvexHull(np.vstack([pts, pos])).volume)


def slab_hull_volume(pos: np.ndarray, r: np.ndarray, z_bottom: float, z_top: float, slab: float,
                     points: int = 32) -> float:
    """Volume [m³] of the grains' stacked-slab hull: the sample between the platens cut into
    horizontal slabs about ``slab`` [m] thick, each contributing the area of the 2-D convex hull of
    the grains' widest sections inside it times its thickness. A sphere of radius r whose centre
    lies a distance d outside a slab enters it with the section radius √(r² - d²); each section is a
    circle of ``points`` points.

    Unlike :func:`hull_volume` it follows an outline that is concave along the axis (a neck, the
    step of a shear band): the global hull bridges such a waist and reads it as volume the sample
    does not have (docs/triaxial.md, "Volume, three ways"); the slab hull is convex within a slab
    only. Thinner slabs follow the outline more closely and count fewer grains per slab; two
    median diameters is the default of :func:`compute_extras`."""
    ok = ~np.isnan(pos).any(axis=1)
    pos, r = pos[ok], r[ok]
    n = max(1, int(round((z_top - z_bottom) / slab)))
    edges = np.linspace(z_bottom, z_top, n + 1)
    t = np.linspace(0.0, 2 * np.pi, points, endpoint=False)
    circle = np.column_stack([np.cos(t), np.sin(t)])
    rmax = float(r.max())
    volume = 0.0
    for a, b in zip(edges[:-1], edges[1:]):
        d = np.maximum(0.0, np.maximum(a - pos[:, 2], pos[:, 2] - b))   # centre's distance outside the slab
        inside = d < r
        if np.count_nonzero(inside) < 3:
            continue
        c, rs = pos[inside, :2], np.sqrt(r[inside] ** 2 - d[inside] ** 2)
        if len(c) > 16:                                   # only sections near the centres' hull can touch the hull
            eq = ConvexHull(c).equations
            near = np.min(-(c @ eq[:, :2].T + eq[:, 2]), axis=1) < 2 * rmax
            c, rs = c[near], rs[near]
        pts = (c[:, None, :] + rs[:, None, None] * circle[None]).reshape(-1, 2)
        volume += ConvexHull(pts).volume * (b - a)       # a 2-D hull's "volume" is its area
    return float(volume)


def _solid_volume(sc: dict, r: np.ndarray) -> float | None:
    """Solid volume [m³] of the sample: Σ 4/3 π r³ of the spheres. For clumps (members overlap) the
    inserted-clumps table's union volumes times their counts, which derive() writes for every engine:
    its size classes keep the sampled PSD's total solid volume (to 1e-12), the volume YADE's placed
    clumps are scaled to as well (docs/triaxial.md, Clumps); None when the table is missing."""
    cl = sc.get("clumps")
    if not cl:
        return float(np.sum(4 / 3 * np.pi * r ** 3))
    tpl = (cl.get("inserted") or {}).get("templates") if isinstance(cl, dict) else None
    return float(sum(t["volume"] * t["count"] for t in tpl)) if tpl else None


def void_ratios(pos: np.ndarray, r: np.ndarray, solid_volume: float, volume_boundary: float,
                volume_hull: float, z_bottom: float, z_top: float, d50: float) -> dict:
    """Void ratio e = V_voids / V_solid [-] of the sample three ways: inside the lateral boundary
    (``boundary``: the membrane's or shell's volume between the platens), inside the grains' convex
    hull (``hull``), and in an interior measurement cylinder (``interior``: radius 0.6 R with R the
    hull's equivalent radius, 2 d50 clear of each platen; the solid fraction is the fraction of a
    regular grid of points, d50/6 apart, that lie inside a sphere, as a CT void ratio counts voxels).
    The first two include the voids along the boundary, which a CT void ratio of the specimen's
    interior does not (seed 001 §2: e = 0.593 before loading). ``pos``, ``r``: the spheres, or a
    clump sample's member spheres (the grid counts a point inside overlapping members once, so the
    interior figure is the clumps' own). ``solid_volume`` [m³]: :func:`_solid_volume`."""
    out = {"boundary": volume_boundary / solid_volume - 1, "hull": volume_hull / solid_volume - 1, "interior": None,
           "solid_volume": solid_volume}
    ok = ~np.isnan(pos).any(axis=1)
    H = z_top - z_bottom
    lo, hi = z_bottom + 2 * d50, z_top - 2 * d50
    if hi <= lo or not ok.any():
        return out
    pos, r = pos[ok], r[ok]
    rc = 0.6 * np.sqrt(volume_hull / (np.pi * H))
    h = d50 / 6
    gx = np.arange(-rc + h / 2, rc, h)
    X, Y = np.meshgrid(gx, gx, indexing="ij")
    disk = np.hypot(X, Y).ravel() < rc
    xy = np.column_stack([X.ravel()[disk], Y.ravel()[disk]])
    solid, total = _grid_solid(pos, r, xy, np.zeros(len(xy), int), 1, z_bottom, z_top, d50)
    phi = float(solid[0] / total[0]) if total[0] else 0.0
    out["interior"] = 1 / phi - 1 if phi > 0 else None
    out["interior_solid_fraction"] = phi
    return out


def solid_fraction_profile(pos: np.ndarray, r: np.ndarray, z_bottom: float, z_top: float, d50: float,
                           rings: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Radial profile of the solid fraction [-]: the fraction of points inside a sphere (as
    :func:`void_ratios`' interior figure: a grid d50/6 apart, 2 d50 clear of each platen) in ``rings`` annuli of equal width about the sample's axis, out to the
    farthest centre. Returns (ring edges [m], solid fraction per ring). Shows a crust round a looser
    core, or the loose layer along the boundary."""
    ok = ~np.isnan(pos).any(axis=1)
    pos, r = pos[ok], r[ok]
    R = np.hypot(pos[:, 0], pos[:, 1])
    edges = np.linspace(0.0, float(R.max()), rings + 1)
    g = np.arange(-edges[-1], edges[-1], d50 / 6)
    X, Y = np.meshgrid(g, g, indexing="ij")
    ring = np.digitize(np.hypot(X, Y).ravel(), edges) - 1
    keep = ring < rings
    xy, ring = np.column_stack([X.ravel(), Y.ravel()])[keep], ring[keep]
    solid, total = _grid_solid(pos, r, xy, ring, rings, z_bottom, z_top, d50)
    return edges, np.divide(solid, total, out=np.full(rings, np.nan), where=total > 0)


def _grid_solid(pos: np.ndarray, r: np.ndarray, xy: np.ndarray, label: np.ndarray, n: int, z_bottom: float,
                z_top: float, d50: float) -> tuple[np.ndarray, np.ndarray]:
    """The CT-like point count of :func:`void_ratios` and :func:`solid_fraction_profile`: layers of the
    points ``xy`` [m], d50/6 apart from 2 d50 above the bottom platen to 2 d50 below the top one, one
    layer at a time; returns (points inside a sphere, points) per ``label`` (0..n-1) [-]."""
    tree = cKDTree(pos)
    solid, total = np.zeros(n), np.zeros(n)
    h = d50 / 6
    for z in np.arange(z_bottom + 2 * d50 + h / 2, z_top - 2 * d50, h):
        inside = _inside_any_sphere(tree, r, np.column_stack([xy, np.full(len(xy), z)]))
        solid += np.bincount(label, weights=inside, minlength=n)
        total += np.bincount(label, minlength=n)
    return solid, total


def _void_ratios_at(sc: dict, series: dict, j: int, pos: np.ndarray, r: np.ndarray, volume_hull: float) -> dict | None:
    """:func:`void_ratios` of the frame at series row ``j`` (positions ``pos``, radii ``r``, hull
    volume [m³]) with the scene's numbers ``sc``; None without a solid volume."""
    vs = _solid_volume(sc, r)
    if not vs:
        return None
    return void_ratios(pos, r, vs, float(series["volume"][j]), volume_hull, float(series["z_bottom"][j]),
                       float(series["z_top"][j]), float(sc["d50"]))


def void_ratios_at_loading(run_dir: Path) -> dict | None:
    """:func:`void_ratios` when loading begins (the frame nearest the end of stage 1) of a run with
    its ``frames.h5``, computed again from its files: what ``scene_summary.json``'s
    ``isotropic_end.void_ratio`` holds, for runs post-processed before their grains' interior figure
    was counted (clump samples until 28 Nov 2026). None without frames or a stage 1."""
    run_dir = Path(run_dir)
    if not (run_dir / "frames.h5").exists():
        return None
    sc = json.loads((run_dir / "params.json").read_text())["scene"]
    s = read_series(run_dir)
    a = analyse(s, sc["pressure"])
    if a["k0"] <= 0:
        return None
    fr = load_frames(run_dir / "frames.h5")
    k0 = int(np.argmin(np.abs(np.asarray(fr.step, dtype=float) - s["step"][a["k0"]])))
    pos, r = fr[k0].position, np.asarray(fr.radius, dtype=float)
    j0 = a["k0"]
    vh = hull_volume(pos, r, float(s["z_bottom"][j0]), float(s["z_top"][j0]))
    return _void_ratios_at(sc, s, j0, pos, r, vh)


def _inside_any_sphere(tree: cKDTree, r: np.ndarray, pts: np.ndarray, k: int = 24) -> np.ndarray:
    """Whether each point of ``pts`` (m, 3) lies inside at least one sphere (centres in ``tree``,
    radii ``r``). Only centres within the largest radius can hold a point: each point's ``k`` nearest
    such centres are tested, and the points whose k-th nearest is still that close are asked again
    with 2k, until none is left out (a clump's overlapping members crowd more centres near a point
    than a sphere packing does)."""
    r_max = float(r.max())
    radius = np.append(r, 0.0)                            # index n: no centre within r_max
    inside = np.zeros(len(pts), bool)
    todo = np.arange(len(pts))
    while len(todo):
        kk = min(k, tree.n)
        dist, idx = tree.query(pts[todo], k=kk, distance_upper_bound=r_max)
        dist, idx = dist.reshape(len(todo), kk), idx.reshape(len(todo), kk)
        inside[todo] = (dist < radius[idx]).any(axis=1)
        crowded = ~inside[todo] & np.isfinite(dist[:, -1])
        if kk >= tree.n or not crowded.any():
            break
        todo, k = todo[crowded], 2 * kk
    return inside


# ---------------------------------------------------------------------------------------------
# Post-processing hooks (engine adapters call these before writing frames.h5)
# ---------------------------------------------------------------------------------------------
def read_series(run_dir: Path) -> dict:
    a = np.loadtxt(Path(run_dir) / "triax.txt", ndmin=2, comments="#")
    if a.shape[1] != len(SERIES_COLUMNS):
        raise ValueError(f"{run_dir}/triax.txt: {a.shape[1]} columns, expected {len(SERIES_COLUMNS)}")
    # a time series may repeat a step at a stage boundary: keep the last row of each step
    _, idx = np.unique(a[::-1, 0], return_index=True)
    a = a[::-1][idx]
    return {c: a[:, k] for k, c in enumerate(SERIES_COLUMNS)}


def analyse(series: dict, p: float) -> dict:
    """Derived time series (σ1, σ3, ε_a, ε_v from the boundary volume) and the stage-1 end."""
    s = series
    H = s["z_top"] - s["z_bottom"]
    A = s["volume"] / H
    sigma1 = s["f_top"] / A             # the loading piston's force, as in the laboratory
    sigma3 = s["f_lateral"] / s["area_lateral"]
    shear = s["stage"] >= 2
    if shear.any():
        k0 = max(0, int(np.argmax(shear)) - 1)       # the last stage-1 row: the state at the switch
        H0, V0 = H[k0], s["volume"][k0]
    else:
        k0, H0, V0 = len(H) - 1, H[-1], s["volume"][-1]
    return {"H": H, "A": A, "sigma1": sigma1, "sigma3": sigma3, "axial_strain": (H0 - H) / H0,
            "volumetric_strain": (V0 - s["volume"]) / V0, "k0": k0, "H0": H0, "V0": V0, "shear": shear}


def _window_mean(steps, values, at, half):
    m = np.abs(steps - at) <= half
    return float(np.mean(values[m])) if m.any() else float(np.interp(at, steps, values))


def smoothing_rows(n: int) -> int:
    """Rows of the running mean used for the shear-stage summary figures: 10, or a tenth of the
    n loading rows when there are fewer than 100 (at least 1)."""
    return max(1, min(10, n // 10))


def peak_stress_ratio(sigma1: np.ndarray, sigma3: np.ndarray, w: int) -> dict:
    """Peak σ1/σ3 during loading: ``smoothed`` = the largest ratio of the w-row running means of
    σ1 and σ3 (the same window as ``sigma3_error_max_abs_smoothed``), ``instantaneous`` = the
    largest row-by-row ratio (sensitive to single noisy rows)."""
    s1, s3 = np.asarray(sigma1, dtype=float), np.asarray(sigma3, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        inst = s1 / s3
        sm = running_mean(s1, w) / running_mean(s3, w)
    return {"smoothed": float(np.nanmax(sm)), "instantaneous": float(np.nanmax(inst)), "rows": w}


def compute_extras(run_dir: Path, params: dict, frame_steps: np.ndarray, positions) -> dict:
    """Controls per frame, wall/time series and the scene summary (``scene_summary.json``)."""
    sc = params["scene"]
    p = sc["pressure"]
    s = read_series(run_dir)
    a = analyse(s, p)
    r = read_particle_table(Path(run_dir) / "particles.txt")["radius"]
    st = s["step"]
    half = sc["dump_every"] / 2
    ctl = {k: [] for k in CONTROLS}
    for k, step in enumerate(frame_steps):
        pos = positions(k)
        j = int(np.argmin(np.abs(st - step)))
        zb, zt = float(s["z_bottom"][j]), float(s["z_top"][j])
        vh = hull_volume(pos, r, zb, zt)
        ctl["volume_slab_hull"].append(slab_hull_volume(pos, r, zb, zt, SLAB_HULL_D50 * float(sc["d50"])))
        ctl["stage"].append(float(s["stage"][j]))
        ctl["axial_strain"].append(float(a["axial_strain"][j]))
        ctl["volume_boundary"].append(float(s["volume"][j]))
        ctl["volume_hull"].append(vh)
        ctl["volumetric_strain"].append(float(a["volumetric_strain"][j]))
        s1 = _window_mean(st, a["sigma1"], step, half)
        s3 = _window_mean(st, a["sigma3"], step, half)
        ctl["sigma1"].append(s1)
        ctl["sigma3"].append(s3)
        # the same lateral force over the lateral area of the hull's equivalent cylinder
        H = zt - zb
        f_lat = _window_mean(st, s["f_lateral"], step, half)
        ctl["sigma3_hull"].append(f_lat / (2 * np.pi * np.sqrt(vh / (np.pi * H)) * H))
        ctl["stress_ratio"].append(s1 / s3 if s3 else np.nan)
    # hull-based volumetric strain, referenced to the same instant as the boundary one: the frame
    # at the end of stage 1 (series row k0); referencing it to the first *shear* frame, one dump
    # interval later, offset the two measurements by the strain of that interval
    vh = np.asarray(ctl["volume_hull"])
    k0 = int(np.argmin(np.abs(np.asarray(frame_steps, dtype=float) - st[a["k0"]])))
    ctl["volumetric_strain_hull"] = ((vh[k0] - vh) / vh[k0]).tolist()
    vsh = np.asarray(ctl["volume_slab_hull"])
    ctl["volumetric_strain_slab_hull"] = ((vsh[k0] - vsh) / vsh[k0]).tolist()
    controls = {k: np.asarray(v, dtype=float) for k, v in ctl.items()}
    # summary numbers
    shear = a["shear"]
    iso_end = np.arange(len(st)) < a["k0"]
    chunk = sc["iso"]["chunk"]
    last_iso = iso_end & (st > st[a["k0"]] - chunk) if a["k0"] > 0 else iso_end
    summ = {"pressure_target": p}
    if last_iso.any():
        s1i, s3i = float(np.mean(a["sigma1"][last_iso])), float(np.mean(a["sigma3"][last_iso]))
        summ["isotropic_end"] = {"sigma1": s1i, "sigma3": s3i, "stress_ratio": s1i / s3i,
                                 "sigma3_error": s3i / p - 1, "sigma1_error": s1i / p - 1,
                                 "applied_pressure": float(np.mean(s["pressure"][last_iso])),
                                 "steps": int(st[a["k0"]]),
                                 # both chunk means within isotropic.tolerance of p (else stage 1 ended
                                 # at isotropic.max_chunks and loading started from this state)
                                 "converged": bool(abs(s1i / p - 1) < sc["iso"]["tolerance"]
                                                   and abs(s3i / p - 1) < sc["iso"]["tolerance"])}
        # the void ratio when loading begins (the frame at the end of stage 1), seed 001 §2: 0.593 (CT)
        e = _void_ratios_at(sc, s, a["k0"], positions(k0), np.asarray(r, dtype=float), float(vh[k0]))
        if e:
            summ["isotropic_end"]["void_ratio"] = e
    if shear.any():
        # lateral stress stray during shear, on averages over one series window of 10 rows
        e3 = a["sigma3"][shear] / p - 1
        w = smoothing_rows(len(e3))
        e3s = running_mean(e3, w)
        peak = peak_stress_ratio(a["sigma1"][shear], a["sigma3"][shear], w)
        summ["shear"] = {
            "final_axial_strain": float(a["axial_strain"][-1]),
            "sigma3_error_mean": float(np.mean(e3)), "sigma3_error_rms": float(np.sqrt(np.mean(e3 ** 2))),
            "sigma3_error_max_abs": float(np.max(np.abs(e3))),
            "sigma3_error_max_abs_smoothed": float(np.max(np.abs(e3s))), "smoothing_rows": w,
            # headline: the peak of sigma1/sigma3 on w-row means (the instantaneous rows of YADE's
            # membrane sample spike: 5.0 on a run whose 10-row means peak at ~2.2)
            "peak_stress_ratio": peak["smoothed"],
            "peak_stress_ratio_instantaneous": peak["instantaneous"],
        }
        fs = controls["stage"] >= 2
        if fs.any():
            e3h = controls["sigma3_hull"][fs] / p - 1
            summ["shear"]["sigma3_hull_error_max_abs"] = float(np.max(np.abs(e3h)))
            summ["shear"]["sigma3_hull_error_mean"] = float(np.mean(e3h))
        vb, vhh = controls["volume_boundary"], controls["volume_hull"]
        ev = controls["volumetric_strain"]
        loading = fs if fs.any() else np.ones(len(ev), bool)
        summ["volume_methods"] = {
            "boundary_over_hull_max_dev": float(np.max(np.abs(vb / vhh - 1))),
            # while loading (issue #14 item 4: within 0.01); stage 1 compacts before the reference frame
            "volumetric_strain_max_abs_diff": float(np.max(np.abs(ev - controls["volumetric_strain_hull"])[loading])),
            # the slab hull follows a necked outline, which the global hull bridges (slab_hull_volume)
            "volumetric_strain_max_abs_diff_slab_hull": float(np.max(np.abs(
                ev - controls["volumetric_strain_slab_hull"])[loading])),
        }
    write_json(Path(run_dir) / "scene_summary.json", summ)        # runner copies it into summary.json
    walls = {
        "platen_top": {"time": s["time"], "position": np.column_stack([0 * st, 0 * st, s["z_top"]]),
                       "force": np.column_stack([0 * st, 0 * st, -s["f_top"]])},
        "platen_bottom": {"time": s["time"], "position": np.column_stack([0 * st, 0 * st, s["z_bottom"]]),
                          "force": np.column_stack([0 * st, 0 * st, s["f_bottom"]])},
        "triaxial": {"time": s["time"], "step": st, "stage": s["stage"], "sigma1": a["sigma1"],
                     "sigma3": a["sigma3"], "axial_strain": a["axial_strain"],
                     "volumetric_strain": a["volumetric_strain"], "volume": s["volume"],
                     "applied_pressure": s["pressure"], "lateral_area": s["area_lateral"]},
    }
    return {"controls": controls, "walls": walls}


class TriaxialScene(base.Scene):
    """The membrane triaxial test (module docstring): both engines' decks write the neutral
    time series ``triax.txt`` (:data:`SERIES_COLUMNS`); :meth:`post` turns it and the frames'
    positions into the per-frame :data:`CONTROLS`, the wall series and ``scene_summary.json``."""
    kind = "triaxial"
    #: the lateral boundary's substitute changes the cost of a step: YADE's deck on the shell pressure
    #: runs 1.3-1.7 ms a step on 2 000 grains, on its PFacet membrane 5.3 ms (docs/validation.md)
    clock_terms = ("membrane",)
    section = Scene
    #: not ``initial_packing``: prepare generates the specimen (inside its membrane) whatever the case
    #: names, so a scanned packing is refused when the case is validated, not after the packing
    honoured = frozenset({"output.contacts", "output.stress"})
    controls = CONTROLS
    series_file = "triax.txt"
    series_columns = SERIES_COLUMNS
    observables = ("peak_stress_ratio", "sigma3_error")
    count_field = "grains"

    def clock_features(self, scene):
        """``clumps`` for grains of measured shapes: a step costs more than the member spheres' count
        says (each clump's rigid-body update and its members' force sums; LIGGGHTS' multisphere
        fix, YADE's clump members)."""
        return ("clumps",) if ((scene or {}).get("particles") or {}).get("shape") == "clumps" else ()

    def size_overrides(self, section, scale):
        """The sample's diameter and height × ``scale`` (the aspect kept): ``grains`` × scale³
        where the case sets it, else the two lengths."""
        s = float(scale)
        if section.grains is not None:
            return {"grains": max(20, round(section.grains * s ** 3))}
        return {"diameter": f"{section.diameter * s!r} m", "height": f"{section.height * s!r} m"}

    required_features = staticmethod(required_features)
    derive = staticmethod(derive)
    max_velocity = staticmethod(max_velocity)
    size_range = staticmethod(size_range)
    stability_inputs = staticmethod(stability_inputs)
    prepare = staticmethod(prepare)
    step_plan = staticmethod(step_plan)

    def sample_problems(self, run_dir):
        """Stage 1 ended unconverged (``isotropic_end.converged`` false: its last chunk means of σ1
        or σ3 outside ``isotropic.tolerance`` of p after ``isotropic.max_chunks`` chunks, and the
        loading began from there)."""
        return stage1_problems(Path(run_dir))

    def post(self, run_dir, params, output):
        return compute_extras(run_dir, params, output.frame_steps, output.positions)
