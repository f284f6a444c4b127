"""Case files: YAML validated into a typed model (pydantic v2), units converted once to SI.

Every error names the file, the field path, what was wrong and what would be right. A case may
``extends: other.yaml`` (path relative to the case file) and override any field; mappings merge
recursively, everything else is replaced.
"""
from __future__ import annotations

import difflib
import json
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import (BaseModel, ConfigDict, Field, ValidationError, field_validator,
                      model_validator)

from .units import Acceleration, Density, Force, Length, Pressure, SurfaceEnergy, Time

ENGINES = ("liggghts", "yade", "lammps")
#: the engines a case runs on when it names none (LAMMPS runs the scenes it has decks for: ask for it)
DEFAULT_ENGINES = ("liggghts", "yade")


class CaseError(ValueError):
    """A case file that cannot be used, with one line per problem."""

    def __init__(self, path, problems: list[str]):
        self.path = str(path)
        self.problems = problems
        lines = "\n".join(f"  - {p}" for p in problems)
        super().__init__(f"{self.path}: {len(problems)} problem(s) in the case file:\n{lines}")


def positive(*names: str):
    """A pydantic field validator refusing zero or negative values of the fields ``names``
    (quantities are SI by then): ``_positive = positive("radius", "speed")`` in a model."""
    def check(cls, v, info):
        if v is not None and v <= 0:
            raise ValueError(f"{info.field_name} must be positive, got {v:g} (SI)")
        return v
    return field_validator(*names)(check)


class Strict(BaseModel):
    """Base of every case section: unknown keys are errors."""
    model_config = ConfigDict(extra="forbid", validate_default=True)


# ---------------------------------------------------------------------------------------------
# Materials and contact law
# ---------------------------------------------------------------------------------------------
class Material(Strict):
    """Elastic solid. ``youngs_modulus`` [Pa], ``density`` [kg/m^3]."""
    density: Density
    youngs_modulus: Pressure
    poisson_ratio: float

    _positive = positive("density", "youngs_modulus")

    @field_validator("poisson_ratio")
    @classmethod
    def _poisson(cls, v):
        if not -1.0 < v < 0.5:
            raise ValueError(f"Poisson's ratio must lie in (-1, 0.5) for a stable isotropic solid, got {v}; "
                             "typical values: glass 0.2-0.25, quartz 0.08-0.12")
        return v


class RigidWall(Strict):
    """A wall much stiffer than the particles: E_wall = stiffness_ratio × E_particle."""
    stiffness_ratio: float = Field(1e3, gt=1)
    poisson_ratio: float = 0.0


class Adhesion(Strict):
    """Constant pull-off force scaled by the reduced radius (seed 000 eq. 1):
    F = force · r_eff/⟨r_eff⟩ [N]; or from a surface energy γ [J/m²] (DMT: F = 4πγr_eff)."""
    force: Force | None = None
    surface_energy: SurfaceEnergy | None = None

    @model_validator(mode="after")
    def _one(self):
        if (self.force is None) == (self.surface_energy is None):
            raise ValueError("give exactly one of 'force' (e.g. '0.5 uN') or 'surface_energy' (e.g. '0.05 J/m^2')")
        for k in ("force", "surface_energy"):
            v = getattr(self, k)
            if v is not None and v < 0:
                raise ValueError(f"{k} must be >= 0")
        return self


class RollingFriction(Strict):
    """Rolling resistance: a constant coefficient μ_rol, or the seed's load-dependent
    μ_rol = sqrt(2 r_eff ξ) (``model: seed000``)."""
    model: Literal["constant", "seed000"] = "constant"
    coefficient: float = Field(0.0, ge=0)


class TorsionFriction(Strict):
    """Twisting resistance with μ_tor / r_eff = ``coefficient`` (seed 000: equal to μ)."""
    coefficient: float = Field(0.0, ge=0)


class Contact(Strict):
    """Contact law. ``restitution`` is the normal coefficient of restitution e_n ∈ (0, 1];
    ``damping: restitution`` sets the viscous constant from e_n, ``damping: seed000`` uses the
    seed's γ_n = sqrt(4/3 E_eff m_eff)."""
    model: Literal["hertz"] = "hertz"
    restitution: float = 0.9
    damping: Literal["restitution", "seed000"] = "restitution"
    friction: float = Field(0.5, ge=0)
    tangential_stiffness_ratio: float | None = Field(
        None, gt=0, description="k_t/k_n; None = Mindlin's 2(1-ν)/(2-ν), seed 000 uses 2/7")
    adhesion: Adhesion | None = None
    rolling: RollingFriction | None = None
    torsion: TorsionFriction | None = None
    substitutes: dict[str, str] = Field(
        default_factory=dict,
        description="physics term -> engine mechanism accepted in place of the exact model")

    @field_validator("restitution")
    @classmethod
    def _restitution(cls, v):
        if not 0.0 < v <= 1.0:
            raise ValueError(f"restitution must lie in (0, 1], got {v}; 1 is elastic, 0.1 strongly damped")
        return v


class TimeStep(Strict):
    """Time step as a ``fraction`` of the critical one (the smaller of the Rayleigh step and a
    fraction of the Hertz contact time), or an explicit ``dt`` checked against it."""
    fraction: float = Field(0.1, gt=0)
    dt: Time | None = None
    allow_unsafe: bool = False

    @field_validator("fraction")
    @classmethod
    def _frac(cls, v):
        if v > 1:
            raise ValueError(f"a time step fraction of {v} is above the critical time step; use <= 0.3 "
                             "(0.1-0.2 is usual for Hertz contacts)")
        return v


class StabilityOptions(Strict):
    """Pre-run stability check and in-deck monitors (orchestrator.stability). A dt above
    ``safe_fraction`` of any stability limit is refused unless ``timestep.allow_unsafe``."""
    safe_fraction: float = Field(0.5, gt=0, le=1, description="largest accepted dt / stability limit")
    monitors: bool = Field(True, description="in-deck monitors stop an unstable run early")
    monitor_checks: int = Field(100, ge=1, description="monitor checks per run")
    ke_factor: float = Field(100.0, gt=1, description="kinetic energy limit / (1/2 M v_max^2 + M g H)")
    overlap_limit: float = Field(0.9, gt=0, lt=1, description="largest overlap / r_min (raised to 4x the "
                                                                "expected static overlap)")
    wall_force_factor: float = Field(20.0, gt=1, description="wall force (and its swing between checks) "
                                                               "limit / target force")


class EngineOptions(Strict):
    """How to launch the engines: MPI ranks for LIGGGHTS, threads for YADE, a wall-clock limit."""
    mpi_ranks: int = Field(1, ge=1)
    threads: int = Field(1, ge=1)
    timeout: Time = "3600 s"
    progress: bool = True


class Output(Strict):
    """What goes into frames.h5 beyond positions."""
    velocity: bool = True
    angular_velocity: bool = False
    orientation: bool = False
    force: bool = False
    torque: bool = False
    stress: bool = False
    contacts: bool = False


class InitialPacking(Strict):
    """A frame of a frames.h5 (a CT scan or a run) as the initial packing (orchestrator.initial_packing)."""
    frames: str = Field(description="frames.h5 or run directory; relative paths are relative to the case file")
    frame: int = Field(0, description="frame index (negative counts from the end)")


class CTSegment(Strict):
    """Segmentation of each scan (orchestrator.ct.segment): Gaussian ``sigma`` [voxels], marker
    height ``h`` (default one voxel), SH expansion to ``degree`` unless ``shape: false``."""
    sigma: float = Field(1.0, gt=0)
    h: Length | None = None
    shape: bool = True
    degree: int = Field(15, ge=0, le=30)


class CTTrack(Strict):
    """Tracking between consecutive scans (orchestrator.ct.track): ``displacement`` (seed 000),
    ``rotation`` (image-based local rotation as prediction, seed 000 §2.2) or ``invariants``
    (SH matching, seed 001 Algorithm 1); ``max_disp`` [m] (default d50/2)."""
    method: Literal["displacement", "rotation", "invariants"] = "displacement"
    max_disp: Length | None = None
    rings: int = Field(4, ge=1)


class CTSeries(Strict):
    """A scan series to turn into CT frames (``orchestrator ct run CASE``): ``scans`` are files,
    directories or globs, relative to the case file, in time order."""
    scans: list[str]
    voxel_size: Length | None = None
    segment: CTSegment = Field(default_factory=CTSegment)
    track: CTTrack = Field(default_factory=CTTrack)

    @field_validator("scans")
    @classmethod
    def _scans(cls, v):
        if not v:
            raise ValueError("give at least one scan file, directory or glob, e.g. ['scans/scan_*.tif']")
        return v


# ---------------------------------------------------------------------------------------------
# The case
# ---------------------------------------------------------------------------------------------
def _scene_union():
    from .scenes import scene_models
    models = scene_models()
    if len(models) == 1:
        return models[0]
    from typing import Union
    return Annotated[Union[tuple(models)], Field(discriminator="kind")]


class Case(Strict):
    """A simulation case. Everything in SI after loading."""
    name: str
    description: str = ""
    engines: list[Literal["liggghts", "yade", "lammps"]] = Field(default_factory=lambda: list(DEFAULT_ENGINES))
    seed: int = 12345
    material: Material
    wall: Material | RigidWall = Field(default_factory=RigidWall)
    contact: Contact = Field(default_factory=Contact)
    timestep: TimeStep = Field(default_factory=TimeStep)
    gravity: Acceleration = 0.0
    scene: Any
    output: Output = Field(default_factory=Output)
    engine_options: EngineOptions = Field(default_factory=EngineOptions)
    stability: StabilityOptions = Field(default_factory=StabilityOptions)
    analysis: list[str | dict] = Field(default_factory=list)
    ct: CTSeries | None = None
    initial_packing: InitialPacking | None = None

    @field_validator("analysis")
    @classmethod
    def _analysis(cls, v):
        if v:                                  # imported only when a case asks for analyses
            from .analysis import parse_specs
            parse_specs(v)
        return v

    @field_validator("scene", mode="before")
    @classmethod
    def _scene(cls, v):
        from pydantic import TypeAdapter
        return TypeAdapter(_scene_union()).validate_python(v)

    @property
    def source(self) -> str | None:
        return getattr(self, "_source", None)

    def resolved(self) -> dict:
        """The case as plain JSON-able data, quantities as SI strings (round-trips through load)."""
        d = self.model_dump(mode="json")
        d["scene"] = self.scene.model_dump(mode="json")
        return d

    def hash_input(self) -> str:
        """What determines the engine run: the resolved case without its analyses and without
        launch settings that do not change the result (progress bar, wall-clock limit)."""
        d = self.resolved()
        d.pop("analysis", None)
        d.pop("ct", None)
        d.pop("description", None)
        d.get("engine_options", {}).pop("progress", None)
        d.get("engine_options", {}).pop("timeout", None)
        return json.dumps(d, sort_keys=True)


# ---------------------------------------------------------------------------------------------
# Loading
# ---------------------------------------------------------------------------------------------
def _merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = v
    return out


def read_case_data(path, _seen=()) -> dict:
    """Read YAML, following ``extends:`` chains (relative to each file)."""
    path = Path(path)
    if not path.exists():
        raise CaseError(path, ["file not found"])
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise CaseError(path, [f"not valid YAML: {exc}"]) from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise CaseError(path, [f"the top level must be a mapping of fields, got {type(data).__name__}"])
    parent = data.pop("extends", None)
    if parent is not None:
        ppath = (path.parent / parent).resolve()
        if ppath in _seen:
            raise CaseError(path, [f"extends: {parent} makes a cycle"])
        if not ppath.exists():
            raise CaseError(path, [f"extends: {parent}: no such file (looked at {ppath})"])
        data = _merge(read_case_data(ppath, _seen + (ppath,)), data)
    return data


def _hint_extra(model_fields: list[str], key: str) -> str:
    near = difflib.get_close_matches(key, model_fields, n=1)
    alt = f"did you mean '{near[0]}'? " if near else ""
    return f"unknown field; {alt}allowed here: {', '.join(sorted(model_fields))}"


def _allowed_fields(loc: tuple) -> list[str]:
    """Field names allowed at the parent of ``loc`` (best effort, for hints)."""
    model: Any = Case
    for part in loc[:-1]:
        if isinstance(part, int):
            continue
        fields = getattr(model, "model_fields", {})
        if part in fields:
            ann = fields[part].annotation
            model = _first_model(ann)
        elif part == "scene":
            model = None
        else:
            from .scenes import scene_models
            for m in scene_models():
                if m.__name__ == part or getattr(m, "_kind", None) == part:
                    model = m
                    break
        if model is None:
            return []
    return list(getattr(model, "model_fields", {}).keys())


def _first_model(ann):
    import typing
    if isinstance(ann, type) and issubclass(ann, BaseModel):
        return ann
    for a in typing.get_args(ann):
        m = _first_model(a)
        if m is not None:
            return m
    return None


def format_validation_error(exc: ValidationError, prefix: tuple = ()) -> list[str]:
    problems = []
    for e in exc.errors():
        loc = prefix + tuple(e["loc"])
        # strip discriminator tags pydantic inserts for unions (e.g. 'impact')
        clean = tuple(p for p in loc if not (isinstance(p, str) and p.endswith("]")))
        if len(clean) > 1 and clean[0] == "scene":
            from .scenes import scene_kinds
            if clean[1] in scene_kinds():        # the discriminated union's tag
                clean = clean[:1] + clean[2:]
        path = ".".join(str(p) for p in clean) or "(top level)"
        typ = e["type"]
        msg = e["msg"]
        if msg.startswith("Value error, "):
            msg = msg[len("Value error, "):]
        if typ == "extra_forbidden":
            allowed = _allowed_fields(clean)
            problems.append(f"{path}: {_hint_extra(allowed, str(clean[-1])) if allowed else 'unknown field; remove it'}")
        elif typ == "missing":
            problems.append(f"{path}: required field is missing; add it")
        elif typ == "union_tag_invalid" or typ == "union_tag_not_found":
            from .scenes import scene_kinds
            problems.append(f"{path}: {msg}; scene.kind must be one of {', '.join(scene_kinds())}")
        else:
            got = e.get("input")
            got_s = f" (got {got!r})" if got is not None and not isinstance(got, dict) else ""
            problems.append(f"{path}: {msg}{got_s}")
    return problems


def load_case(path, overrides: dict | None = None, check_timestep: bool = True) -> Case:
    """Load, merge ``extends``, apply ``overrides`` (nested dict), validate and derive-check."""
    path = Path(path)
    data = read_case_data(path)
    if overrides:
        data = _merge(data, overrides)
    ip = data.get("initial_packing")
    if isinstance(ip, dict) and isinstance(ip.get("frames"), str) and not Path(ip["frames"]).is_absolute():
        data["initial_packing"] = dict(ip, frames=str((path.parent / ip["frames"]).resolve()))
    return case_from_dict(data, source=path, check_timestep=check_timestep)


def case_from_dict(data: dict, source="<dict>", check_timestep: bool = True) -> Case:
    try:
        case = Case.model_validate(data)
    except ValidationError as exc:
        # errors raised inside the scene's TypeAdapter come back nested in one error: unwrap
        problems = []
        for e in exc.errors():
            ctx_err = (e.get("ctx") or {}).get("error")
            if e["loc"] and e["loc"][0] == "scene" and isinstance(ctx_err, ValidationError):
                problems += format_validation_error(ctx_err, ("scene",))
            else:
                problems += format_validation_error(ValidationError.from_exception_data(
                    exc.title, [e]) if False else _single(exc, e))
        raise CaseError(source, problems) from None
    object.__setattr__(case, "_source", str(source))
    if check_timestep:
        from .derive import derive, DerivationError
        try:
            derive(case)
        except DerivationError as exc:
            raise CaseError(source, [str(exc)]) from None
    return case


def _single(exc: ValidationError, e: dict) -> ValidationError:
    class _One:
        def errors(self_inner):
            return [e]
    return _One()  # type: ignore[return-value]
