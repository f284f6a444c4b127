"""Typed, frozen parameters: what :func:`orchestrator.derive.derive` returns and templates receive.

:class:`Params` holds the numbers every scene and engine share (SI units, stated per field);
``Params.scene`` is the scene's own typed part (each scene module defines its subclass of
:class:`ScenePart` and returns it from ``Scene.derive``). Engine-specific numbers are not here:
each engine package derives them from these (``Engine.engine_params``) and hands them to its
templates as ``engine``.

Everything is immutable: dataclasses are ``frozen``, nested tables are :class:`FrozenMap`
(read-only, attribute access for Jinja's ``a.b``) and lists are tuples. A stage that completes the
parameters (a scene's ``prepare``, the runner's file names) makes a new object with
:meth:`Frozen.replace`.

``to_dict()`` is the JSON form, written to ``params.json`` and covered by the run hash
(orchestrator.runner.run_hash, with the engine's own numbers).

For callers that read parameters either from a run's ``params.json`` (a dict) or from memory,
:class:`Frozen` also answers ``p["key"]``, ``p.get("key")`` and ``"key" in p`` (read-only; a
field that is None counts as absent, as a missing key did).
"""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any


class FrozenMap(dict):
    """A read-only dict with attribute access (``m.key`` and ``m["key"]``). A dict subclass so that
    ``json`` and Jinja's ``tojson`` serialise it as they did the plain dicts; every mutating method
    raises."""

    __slots__ = ()

    def __getattr__(self, k):
        try:
            return self[k]
        except KeyError:
            raise AttributeError(k) from None

    def _frozen(self, *a, **k):
        raise TypeError("parameters are frozen: make a new object (Frozen.replace) instead of changing one")

    __setitem__ = __delitem__ = __setattr__ = __delattr__ = _frozen
    clear = pop = popitem = setdefault = update = __ior__ = _frozen

    def __repr__(self):
        return f"FrozenMap({dict.__repr__(self)})"

    def __hash__(self):
        return hash(tuple(sorted(self)))

    def __reduce__(self):
        return (FrozenMap, (dict(self),))


def freeze(v):
    """dicts -> :class:`FrozenMap`, lists -> tuples, recursively; other values as they are (numpy
    scalars stay numpy scalars: the run hash serialises them as before)."""
    if isinstance(v, Frozen | FrozenMap):
        return v
    if isinstance(v, Mapping):
        return FrozenMap((k, freeze(x)) for k, x in v.items())
    if isinstance(v, list | tuple):
        return tuple(freeze(x) for x in v)
    return v


def thaw(v):
    """The JSON-able form: :class:`Frozen` -> dict, :class:`FrozenMap` -> dict, tuples -> lists."""
    if isinstance(v, Frozen):
        return v.to_dict()
    if isinstance(v, Mapping):
        return {k: thaw(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [thaw(x) for x in v]
    return v


def opt(doc: str = "") -> Any:
    """An optional field (default None) that ``to_dict`` leaves out while it is None, and that
    ``"name" in params`` reports absent."""
    return field(default=None, metadata={"omit_none": True, "doc": doc})


@dataclass(frozen=True)
class Frozen:
    """Base of the parameter dataclasses (module docstring)."""

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            fv = freeze(v)
            if fv is not v:
                object.__setattr__(self, f.name, fv)

    def _items(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if v is None and f.metadata.get("omit_none"):
                continue
            yield f.name, v

    def to_dict(self) -> dict:
        """The JSON form (params.json, the run hash)."""
        return {k: thaw(v) for k, v in self._items()}

    def replace(self, **changes):
        return dataclasses.replace(self, **changes)

    # read-only mapping access (module docstring)
    def __getitem__(self, k):
        f = self.__dataclass_fields__.get(k) if isinstance(k, str) else None
        if f is None:
            raise KeyError(k)
        v = getattr(self, k)
        if v is None and f.metadata.get("omit_none"):
            raise KeyError(k)
        return v

    def get(self, k, default=None):
        v = getattr(self, k, None) if isinstance(k, str) else None
        return default if v is None else v

    def __contains__(self, k):
        return isinstance(k, str) and getattr(self, k, None) is not None

    def keys(self):
        return [k for k, _ in self._items()]

    def items(self):
        return list(self._items())


# ----------------------------------------------------------------------------------------------
# The common part
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Material(Frozen):
    """The particles' material."""
    E: float      #: Young's modulus [Pa]
    nu: float     #: Poisson's ratio [-]
    rho: float    #: density [kg/m³]
    G: float      #: shear modulus E/(2(1+ν)) [Pa]


@dataclass(frozen=True)
class WallMaterial(Frozen):
    """The walls' material (the case's ``wall`` section)."""
    E: float      #: Young's modulus [Pa]
    nu: float     #: Poisson's ratio [-]


@dataclass(frozen=True)
class Restitution(Frozen):
    """The normal restitution the contacts must deliver (engines derive what to feed their law)."""
    target: float           #: e_n the collisions must deliver [-]
    damping_ratio: float    #: ζ = -ln e/√(π² + ln² e) of that e_n [-]


@dataclass(frozen=True)
class ScenePart(Frozen):
    """Base of a scene's typed numbers (``Params.scene``). Every scene part names its particle
    count, steps and output interval; the rest is the scene's own."""


@dataclass(frozen=True)
class ContactTerms(Frozen):
    """Contact terms beyond Hertz-Mindlin that a granular scene derives (seed 000 §3.2), engine-free."""
    adhesion_force: float                         #: pull-off force F_adh at the median contact [N] (0: none)
    restitution: FrozenMap                        #: {target [-], damping_ratio [-] (optional), from (text, optional)}
    expected_overlap: float | None = opt("overlap ξ_σ [m] of a median pair under the mean contact force")
    expected_contact_force: float | None = opt("mean contact force F_c under the normal stress [N]")
    kn_seed: float | None = opt("seed normal stiffness k_n = 4/3 E* x50/2 [N/m]")
    kt_seed: float | None = opt("seed tangential stiffness k_t = 2/7 k_n [N/m]")
    r_eff_mean: float | None = opt("effective radius x50/4 of a median pair [m]")
    rolling_coefficient: float | None = opt("rolling limit μ_r: M = μ_r r_eff |F_n| [-]")
    torsion_coefficient: float | None = opt("twisting limit μ_tor [-]")
    rolling_stiffness: float | None = opt("rolling spring k_r = k_t r_eff² [N m/rad] (seed §3.2)")
    twisting_stiffness: float | None = opt("twisting spring k_tw = k_t r_eff² [N m/rad] (seed §3.2)")
    median_radius: float | None = opt("x50/2 [m], the lever R̄ of a rolling limit η R̄ |F_n|")


@dataclass(frozen=True)
class Params(Frozen):
    """The derived numbers of a case, shared by every engine (SI units)."""
    material: Material
    wall: WallMaterial
    E_eff_pp: float               #: particle-particle effective modulus E* [Pa]
    E_eff_pw: float               #: particle-wall effective modulus E* [Pa]
    G_eff_pp: float               #: particle-particle effective shear modulus G* [Pa]
    G_eff_pw: float               #: particle-wall effective shear modulus G* [Pa]
    restitution: Restitution
    friction: float               #: Coulomb μ [-]
    tangential_stiffness_ratio: float | None   #: k_t/k_n when the case sets it [-]
    tangential_damping: bool          #: the tangential spring has its viscous dashpot (contact.tangential_damping)
    r_min: float                  #: smallest particle radius [m]
    r_max: float                  #: largest particle radius [m]
    dt: float                     #: time step [s]
    dt_rayleigh: float            #: Rayleigh time step of the smallest sphere [s]
    dt_hertz: float               #: Hertz limit t_c/10 times the damping factor [s]
    dt_critical: float            #: the smaller of the two [s]
    dt_fraction: float            #: dt / dt_critical [-]
    v_max: float                  #: largest expected relative particle speed [m/s]
    dt_damping_factor: float      #: √(1+ζ²) − ζ [-]
    gravity: float                #: gravitational acceleration (along −z) [m/s²]
    gravity_vector: tuple         #: (0, 0, −g) [m/s²]
    features: tuple               #: physics features the engines must offer (engines.base.FEATURES)
    scene: ScenePart              #: the scene's own numbers
    stability: FrozenMap | None = None   #: pre-run stability report (orchestrator.stability.checks.check)
    monitors: FrozenMap | None = None    #: in-deck monitor thresholds (checks.monitor_limits)
    files: FrozenMap | None = opt("input files the scene's prepare wrote, by name (paths)")
    initial_packing: FrozenMap | None = opt("summary of the case's initial packing")


@dataclass(frozen=True)
class StabilityInputs(Frozen):
    """What the pre-run stability checks and the in-deck monitors need from a scene
    (``Scene.stability_inputs``)."""
    n_particles: int = 0                   #: grains (clumps count once) [-]
    n_spheres: int | None = None           #: spheres the engine integrates when not n (clump members) [-]
    total_steps: int = 0                   #: steps of the whole run [-]
    wall_speeds: FrozenMap = field(default_factory=dict)   #: name -> largest wall speed [m/s]
    confining_stress: float = 0.0          #: confining / normal stress [Pa]
    skin: float | None = None              #: neighbour skin [m] (None: r_max/2)
    height: float = 0.0                    #: height of the granular region [m]
    wall_force_target: float | None = None #: force a servo wall drives to [N]
    periodic: tuple = (False, False, False)
    box_lo: tuple | None = None            #: simulation box [m]
    box_hi: tuple | None = None
    adhesion_force: float = 0.0            #: pull-off force [N]
    restitution: float | None = None       #: e_n the scene's contacts deliver when it sets its own [-]
    rolling_stiffness: float | None = None #: rolling spring [N m/rad]
    rolling_coefficient: float | None = None
    twisting_stiffness: float | None = None
    torsion_coefficient: float | None = None
