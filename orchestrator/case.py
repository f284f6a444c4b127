"""Case files: YAML validated into a typed model (pydantic v2), units converted once to SI.

Every error names the file, the field path, what was wrong and what would be right. A case may
``extends: other.yaml`` (path relative to the case file) and override any field; mappings merge
recursively, everything else is replaced.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal, Union, get_args

import yaml
from pydantic import (BaseModel, ConfigDict, Field, TypeAdapter, ValidationError, field_validator,
                      model_validator)

from .clumps import library_digest
from .derive import DerivationError, derive
from .analysis_specs import parse_specs
from .hints import did_you_mean, unknown_name_hint
from .registry import engine_names, get_scene, scene_kinds
from .resources import templates_dir
from .units import Acceleration, Density, Force, Length, Pressure, SurfaceEnergy, Time


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
    tangential_history: Literal["displacement", "force"] | None = Field(
        None, description="how the Mindlin tangential spring keeps its history: 'displacement' (the total "
                          "tangential displacement ξ, F_t = k_t(δ) ξ: LIGGGHTS, LAMMPS mindlin) or 'force' "
                          "(the force, incremented by k_t(δ) Δξ each step: YADE, LAMMPS mindlin/force); the two "
                          "differ when the overlap changes under a tangential load. None: each engine's own "
                          "(docs/crossval.md)")
    tangential_damping: bool | None = Field(
        None, description="false: no viscous dashpot on the tangential spring (normal damping only). The "
                          "engines cap the sticking contact's force differently when it has one: LIGGGHTS and "
                          "YADE test only the spring against μF_n and add the dashpot on top, LAMMPS caps spring "
                          "+ dashpot at μF_n; without it all three realise the same law (docs/crossval.md). "
                          "None: on, as each engine's Hertz-Mindlin law has it")
    adhesion: Adhesion | None = None
    rolling: RollingFriction | None = None
    torsion: TorsionFriction | None = None
    substitutes: dict[str, str] = Field(
        default_factory=dict,
        description="physics term -> engine mechanism accepted in place of the exact model")
    match_overlap: float | None = Field(
        None, gt=0, le=10,
        description="the overlap, as a fraction of the expected overlap ξ_σ under the normal stress, at which "
                    "stand-ins whose force or stiffness grows with the overlap are matched to the seed's law "
                    "(LIGGGHTS: sjkr's k, epsd3's rolling spring). None: at ξ_σ. The small shear cell's "
                    "contacts sat at a mean 0.56 ξ_σ (docs/crossval.md). The rolling limit μ_r, shared by "
                    "every engine, stays at ξ_σ")

    @field_validator("tangential_damping")
    @classmethod
    def _dashpot_on_is_the_default(cls, v):
        return None if v is True else v      # true is the engines' own law: the same run as unset

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
    _positive = positive("dt")

    # (a fraction above what the case's stability limits allow is refused by orchestrator.derive,
    # with the largest safe fraction of that case)


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
    _positive = positive("timeout")
    scheduler: str | None = Field(
        None, description="Dask scheduler address (tcp://host:8786; dask-jobqueue's SLURMCluster/PBSCluster "
                          "give one): the whole run, with its MPI ranks or threads, goes to one worker of that "
                          "cluster; runs_root must be on a filesystem the worker shares")


class Output(Strict):
    """What goes into frames.h5 beyond positions."""
    velocity: bool = True
    angular_velocity: bool = False
    orientation: bool = False
    force: bool = False
    torque: bool = False
    stress: bool = False
    contacts: bool = False

    #: per-particle frames.h5 fields, in the order frames.h5 lists them
    FIELDS: ClassVar[tuple[str, ...]] = ("position", "velocity", "angular_velocity", "orientation", "force",
                                         "torque", "stress")

    def fields(self, written: tuple[str, ...] = FIELDS) -> list[str]:
        """The per-particle fields the case asks for (position always), in frames.h5 order, among
        those an engine ``written`` can write (the one output-field selection of every adapter)."""
        return [f for f in self.FIELDS if f in written and (f == "position" or getattr(self, f))]


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
    _positive = positive("h")
    degree: int = Field(15, ge=0, le=30)


class CTTrack(Strict):
    """Tracking between consecutive scans (orchestrator.ct.track): ``displacement`` (seed 000),
    ``rotation`` (image-based local rotation as prediction, seed 000 §2.2) or ``invariants``
    (SH matching, seed 001 Algorithm 1); ``max_disp`` [m] (default d50/2)."""
    method: Literal["displacement", "rotation", "invariants"] = "displacement"
    max_disp: Length | None = None
    rings: int = Field(4, ge=1)
    _positive = positive("max_disp")


class CTSeries(Strict):
    """A scan series to turn into CT frames (``orchestrator ct run CASE``): ``scans`` are files,
    directories or globs, relative to the case file, in time order."""
    scans: list[str]
    voxel_size: Length | None = None
    segment: CTSegment = Field(default_factory=CTSegment)
    _positive = positive("voxel_size")
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
    """The union of every registered scene's case section, told apart by ``kind``."""
    models = [get_scene(k).section for k in scene_kinds()]
    if len(models) == 1:
        return models[0]
    return Annotated[Union[tuple(models)], Field(discriminator="kind")]


class Case(Strict):
    """A simulation case. Everything in SI after loading."""
    #: (section, field) added after runs existed, whose default (None) leaves every deck as it was:
    #: not hashed at that default, so the runs made before them keep their hash (and resume)
    _UNHASHED_AT_DEFAULT: ClassVar[tuple] = (("contact", "match_overlap"), ("contact", "tangential_history"),
                                               ("contact", "tangential_damping"))
    name: str
    description: str = ""
    engines: list[str] = Field(default_factory=lambda: list(engine_names()))
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

    @field_validator("engines")
    @classmethod
    def _engines(cls, v):
        known = engine_names()
        for name in v:
            if name not in known:
                raise ValueError(f"unknown engine {name!r}; installed engines: {', '.join(known)}")
        return v

    @model_validator(mode="after")
    def _default_engines_have_decks(self):
        """A case that names no engines runs on every installed engine that has a deck for its
        scene (LAMMPS has no triaxial deck yet); named engines are kept as given."""
        if "engines" not in self.model_fields_set:
            kind = getattr(self.scene, "kind", None)
            if kind is not None:
                self.engines = [e for e in self.engines if any((templates_dir() / e).glob(f"{kind}.*.j2"))]
        return self

    @field_validator("analysis")
    @classmethod
    def _analysis(cls, v):
        if v:                       # names only: the analysis stack itself is not imported here
            parse_specs(v)
        return v

    @field_validator("scene", mode="before")
    @classmethod
    def _scene(cls, v):
        return TypeAdapter(_scene_union()).validate_python(v)

    def wall_moduli(self) -> tuple[float, float]:
        """(E_wall [Pa], ν_wall) from the ``wall`` section (a rigid wall: stiffness_ratio × E)."""
        w = self.wall
        if isinstance(w, RigidWall):
            return self.material.youngs_modulus * w.stiffness_ratio, w.poisson_ratio
        return w.youngs_modulus, w.poisson_ratio

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
        for section, field in self._UNHASHED_AT_DEFAULT:
            if field in d.get(section, {}) and d[section][field] is None:
                d[section].pop(field)
        # files by what the run reads from them, not by where they lie (absolute paths once loaded):
        # the clump library by its shapes; the initial packing's frames file is hashed by its grains
        # (orchestrator.runner.run_hash, packing_digest), so its path goes
        particles = d.get("scene", {}).get("particles")
        if isinstance(particles, dict) and particles.get("library"):
            particles["library"] = "sha256:" + library_digest(particles["library"])
        if isinstance(d.get("initial_packing"), dict):
            d["initial_packing"].pop("frames", None)
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
    data = yaml_or_case_error(path)
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise CaseError(path, [f"the top level must be a mapping of fields, got {type(data).__name__}"])
    _file_relative(data, path)
    parent = data.pop("extends", None)
    if parent is not None:
        ppath = (path.parent / parent).resolve()
        if ppath in _seen:
            raise CaseError(path, [f"extends: {parent} makes a cycle"])
        if not ppath.exists():
            raise CaseError(path, [f"extends: {parent}: no such file (looked at {ppath})"])
        data = _merge(read_case_data(ppath, _seen + (ppath,)), data)
    return data


def _file_relative(data: dict, path: Path) -> None:
    """A file a case names (``scene.particles.library``) is relative to the case file that names it,
    as ``extends:`` is: made absolute here, file by file along the ``extends:`` chain."""
    particles = (data.get("scene") or {}).get("particles") if isinstance(data.get("scene"), dict) else None
    if isinstance(particles, dict) and isinstance(particles.get("library"), str):
        lib = Path(particles["library"]).expanduser()
        if not lib.is_absolute():
            particles["library"] = str((path.parent / lib).resolve())


def yaml_or_case_error(path: Path):
    """Parse a YAML case file; a missing, unreadable, binary or malformed one is a CaseError that
    says what the file is and what to give instead."""
    fix = "give a YAML case file, e.g. cases/shear_cell_smoke.yaml"
    if not path.exists():
        raise CaseError(path, [f"file not found; {fix}"])
    if path.is_dir():
        raise CaseError(path, [f"is a directory, not a case file; {fix}"])
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise CaseError(path, [f"not a text file (byte {exc.start} is not UTF-8); {fix}"]) from None
    except PermissionError:
        raise CaseError(path, [f"cannot be read (permission denied); make it readable (chmod u+r {path})"]) from None
    if "\x00" in text:
        raise CaseError(path, [f"not a text file (it holds NUL bytes); {fix}"])
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise CaseError(path, [f"not valid YAML: {exc}"]) from None


def allowed_fields(loc: tuple, scene_kind: str | None = None) -> list[str]:
    """Field names allowed at the parent of ``loc`` (best effort, for hints); ``scene_kind``
    picks the scene model below ``scene``."""
    model: Any = Case
    for part in loc[:-1]:
        if isinstance(part, int):
            continue
        fields = getattr(model, "model_fields", {})
        if part == "scene" and model is Case and scene_kind:
            model = get_scene(scene_kind).section
        elif part in fields:
            ann = fields[part].annotation
            model = _first_model(ann)
        elif part == "scene":
            model = None
        else:
            for m in (get_scene(k).section for k in scene_kinds()):
                if m.__name__ == part or getattr(m, "_kind", None) == part:
                    model = m
                    break
        if model is None:
            return []
    return list(getattr(model, "model_fields", {}).keys())


def _first_model(ann):
    if isinstance(ann, type) and issubclass(ann, BaseModel):
        return ann
    for a in get_args(ann):
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
        kind = None
        if len(clean) > 1 and clean[0] == "scene":
            if clean[1] in scene_kinds():        # the discriminated union's tag
                kind = clean[1]
                clean = clean[:1] + clean[2:]
        path = ".".join(str(p) for p in clean) or "(top level)"
        typ = e["type"]
        msg = e["msg"]
        if msg.startswith("Value error, "):
            msg = msg[len("Value error, "):]
        if typ == "extra_forbidden":
            allowed = allowed_fields(clean, kind)
            problems.append(f"{path}: {unknown_name_hint(allowed, str(clean[-1])) if allowed else 'unknown field; remove it'}")
        elif typ == "missing":
            problems.append(f"{path}: required field is missing; add it")
        elif typ == "union_tag_invalid" or typ == "union_tag_not_found":
            tag = (e.get("ctx") or {}).get("tag")
            kinds = ", ".join(scene_kinds())
            if tag is None:
                problems.append(f"scene.kind: required field is missing; set it to one of {kinds}")
            else:
                problems.append(f"scene.kind: {tag!r} is not a scene; {did_you_mean(scene_kinds(), str(tag))}"
                                f"set it to one of {kinds}")
        else:
            got = e.get("input")
            got_s = f" (got {got!r})" if got is not None and not isinstance(got, dict) else ""
            problems.append(f"{path}: {msg}{got_s}{_fix_hint(typ, e, clean, kind, got)}")
    return problems


#: pydantic's bound errors -> the words of the fix
_BOUNDS = {"greater_than": "above {gt}", "greater_than_equal": "of at least {ge}", "less_than": "below {lt}",
           "less_than_equal": "of at most {le}"}


def _field_default(loc: tuple, kind: str | None):
    """The default of the field at ``loc`` (None when it has none or cannot be found)."""
    from pydantic_core import PydanticUndefined
    model: Any = Case
    for k, part in enumerate(loc):
        if isinstance(part, int):
            continue
        if part == "scene" and model is Case and kind:
            model = get_scene(kind).section
            continue
        f = getattr(model, "model_fields", {}).get(part)
        if f is None:
            return None
        if k == len(loc) - 1 or (k == len(loc) - 2 and isinstance(loc[-1], int)):
            d = f.default
            return None if d is PydanticUndefined or isinstance(d, (BaseModel, dict, list)) else d
        model = _first_model(f.annotation)
        if model is None:
            return None
    return None


def _fix_hint(typ: str, e: dict, loc: tuple, kind, got) -> str:
    """The fix for a pydantic type or bound error: what to write instead (pydantic's own text says
    only what was wrong)."""
    field = ".".join(str(p) for p in loc)
    default = _field_default(loc, kind)
    example = f" (default {default!r})" if default is not None and not isinstance(default, bool) else ""
    if typ in _BOUNDS:
        return f"; set {field} to a value {_BOUNDS[typ].format(**(e.get('ctx') or {}))}{example}"
    if typ.endswith(("_type", "_parsing")) and isinstance(got, (list, tuple, dict)):
        return f"; {field} takes one value, not a {type(got).__name__}: write e.g. {field.split('.')[-1]}: " \
               f"{default if default is not None else '...'}"
    if typ.endswith(("_type", "_parsing")):
        words = _TYPE_WORDS.get(typ.split("_")[0], "a " + typ.split("_")[0])
        shown = str(default).lower() if isinstance(default, bool) else repr(default)    # YAML's true/false
        return f"; write {field} as {words}{', e.g. ' + shown if default is not None else ''}"
    return ""


#: pydantic's type names as the fix says them ("write scene.isotropic.max_chunks as an integer")
_TYPE_WORDS = {"int": "an integer", "float": "a number", "bool": "true or false", "string": "a string",
               "list": "a list", "dict": "a mapping"}


def load_case(path, overrides: dict | None = None, check_timestep: bool = True) -> Case:
    """Load, merge ``extends``, apply ``overrides`` (nested dict), validate and derive-check."""
    path = Path(path)
    data = read_case_data(path)
    if overrides:
        data = _merge(data, overrides)
    ip = data.get("initial_packing")
    if isinstance(ip, dict) and isinstance(ip.get("frames"), str) and not Path(ip["frames"]).is_absolute():
        data["initial_packing"] = dict(ip, frames=str((path.parent / ip["frames"]).resolve()))
    try:
        return case_from_dict(data, source=path, check_timestep=check_timestep)
    except CaseError as exc:
        raise _blame_parents(path, exc, overrides) from None


def _extends_chain(path: Path) -> list[tuple[Path, dict]]:
    """(file, its own fields) along the ``extends:`` chain, the case file first."""
    out, seen = [], set()
    while path is not None and path not in seen:
        seen.add(path)
        try:
            data = yaml.safe_load(path.read_text()) or {}
        except Exception:
            break
        if not isinstance(data, dict):
            break
        out.append((path, data))
        parent = data.get("extends")
        path = (path.parent / parent).resolve() if isinstance(parent, str) else None
    return out


def _depth(node, keys: list[str]) -> int:
    """How many leading ``keys`` the nested mapping ``node`` sets."""
    depth = 0
    for k in keys:
        if not isinstance(node, dict) or k not in node:
            break
        node, depth = node[k], depth + 1
    return depth


def _override_shown(overrides: dict, keys: list[str]) -> str:
    """``contact.friction=abc``: the override that sets the field ``keys``, as ``--set`` writes it."""
    node = overrides
    for k in keys:
        node = node[k]
    return f"{'.'.join(keys)}={node}" if not isinstance(node, (dict, list)) else ".".join(keys)


def _blame_parents(path: Path, exc: CaseError, overrides: dict | None = None) -> CaseError:
    """Report each problem against what sets the field: the file of the ``extends:`` chain (an
    error in a parent case is fixed in the parent, not in the case that extends it), or the
    ``overrides`` given with the case (``sweep --set``, a ladder's rung: fixed on the command line,
    not in any file). The message still names the case file."""
    chain = _extends_chain(path)
    if len(chain) < 2 and not overrides:
        return exc
    files = []
    problems = []
    for prob in exc.problems:
        field = prob.split(":", 1)[0].strip()
        keys = field.split(".") if field and " " not in field else []
        if keys and overrides and _depth(overrides, keys) == len(keys):     # applied last: the override's value
            files.append("overrides")
            problems.append(f"{prob} [the value comes from the overrides ({_override_shown(overrides, keys)}, "
                            f"e.g. --set), not from the case file]")
            continue
        owner, best = None, 0
        for f, d in chain:                       # the nearest file that sets the most of this field's path
            depth = _depth(d, keys)
            if depth > best:
                owner, best = f, depth
        files.append(owner)
        problems.append(prob if owner is None or owner == chain[0][0] else f"{prob} [set in {owner}]")
    owners = set(files)
    if len(owners) == 1 and None not in owners and "overrides" not in owners and files[0] != chain[0][0]:
        return CaseError(f"{files[0]} (extended by {path})", exc.problems)
    return CaseError(path, problems)


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
    # a term the scene does not realise in any engine's deck is refused, never dropped silently
    refused = get_scene(case.scene.kind).refused_terms(case)
    if refused:
        raise CaseError(source, refused)
    if check_timestep:
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
