"""The one interface between a scene and the rest: :class:`Scene`.

A scene knows the physics and the protocol of one experiment, never an engine's file formats.
It is registered under the entry-point group ``orchestrator.scenes`` (pyproject.toml) and found
through :func:`orchestrator.registry.get_scene`. Engines hand it their output through the neutral
:class:`EngineOutput` (frame steps, particle positions per frame, the wall sampler's rows); the
scene turns that into per-frame controls, wall series and its summary (:meth:`Scene.post`).

Case terms a scene does not realise in any engine's deck are refused when the case is loaded
(:meth:`Scene.refused_terms`), naming the field and the scene: nothing a case asks for is dropped
silently (docs/architecture.md).
"""
from __future__ import annotations

import math
import json
from abc import ABC, abstractmethod
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Mapping, Protocol

import numpy as np
import yaml

from ..params import Params, ScenePart, StabilityInputs
from ..particles_io import write_particle_table
from ..registry import get_scene, scene_kinds

#: optional case terms a scene may realise, with the test that tells whether a case asks for it
#: (a term whose test is true must be in the scene's ``honoured`` set, else the case is refused)
OPTIONAL_TERMS: dict[str, Any] = {
    "contact.adhesion": lambda case: case.contact.adhesion is not None,
    "contact.rolling": lambda case: case.contact.rolling is not None,
    "contact.torsion": lambda case: case.contact.torsion is not None,
    "contact.damping: seed000": lambda case: case.contact.damping == "seed000",
    "contact.tangential_stiffness_ratio": lambda case: case.contact.tangential_stiffness_ratio is not None,
    "gravity": lambda case: case.gravity != 0,
    "output.contacts": lambda case: bool(case.output.contacts),
    "output.stress": lambda case: bool(case.output.stress),
    "initial_packing": lambda case: case.initial_packing is not None,
}


class EngineOutput(Protocol):
    """What an engine adapter hands a scene after a run (engines/*: their own readers)."""

    run_dir: Path
    #: the step of every frame written, ascending
    frame_steps: np.ndarray

    def positions(self, k: int) -> np.ndarray:
        """(n, 3) positions [m] of frame k, rows in the order of the run's particles.txt (NaN: lost)."""

    def wall_rows(self) -> np.ndarray | None:
        """The deck's wall-sampler rows (columns as the scene's ``wall_columns``), step-sorted
        as written, or None when the deck wrote none."""


@dataclass(frozen=True)
class StepPlan:
    """The step count of a run that is decided while it runs (e.g. a stage that goes on until a
    test passes): ``steps = fixed + unit * k`` with ``1 <= k <= max_units`` chunks of ``unit``
    steps [steps, -]. The derived ``steps`` budget is the largest, ``fixed + unit * max_units``.

    The clock (:mod:`orchestrator.clock`) estimates with the length of the variable part the
    engine's measured runs of the scene took, counted in ``scale`` steps (the scene's physical time
    scale of that part; 0: in chunks). A chunk is often tied to something else (the triaxial's is
    two frame intervals of the loading, so halving the loading rate doubles it) while the variable
    part is not: counted in chunks, a frictionless-prepared 2 000-grain triaxial converged in 7
    chunks of 15 200 steps and a frictional one in 15 of 7 600, 106 400 against 114 000 steps, 6.9
    and 7.4 pressure-ramp lengths (docs/validation.md)."""
    fixed: int
    unit: int
    max_units: int
    #: steps per learned unit (the variable part's physical time scale) [steps]; 0: the chunk ``unit``
    scale: int = 0
    #: what a unit is, as an estimate names it (e.g. "pressure-ramp lengths of stage 1")
    what: str = "units"

    @property
    def _per_unit(self) -> int:
        return int(self.scale) if self.scale and self.scale > 0 else int(self.unit)

    def chunks_of(self, steps_run: int) -> float:
        """How many chunks of ``unit`` steps a run of ``steps_run`` steps took [-]."""
        return (steps_run - self.fixed) / self.unit

    def units_of(self, steps_run: int) -> float:
        """How many units (``scale`` steps, or chunks) the variable part of a run of ``steps_run``
        steps took [-]."""
        return (steps_run - self.fixed) / self._per_unit

    def steps(self, units: float) -> int:
        """Steps of a run whose variable part takes ``units`` units: rounded up to whole chunks (a
        step or two past a chunk boundary, as YADE's last step, is not a chunk more) and clipped to
        [1, max_units] chunks [-]."""
        chunks = units * self._per_unit / self.unit
        k = min(max(math.ceil(chunks - 0.01), 1), self.max_units)
        return self.fixed + self.unit * k


class Scene(ABC):
    """One experiment. Subclasses set the class attributes and implement the abstract methods.

    Attributes
    ----------
    kind : the case's ``scene.kind`` and the template name ``templates/<engine>/<kind>.*.j2``.
    section : the pydantic model of the case's ``scene:`` section (``kind: Literal[kind]``).
    honoured : the optional case terms (keys of :data:`OPTIONAL_TERMS`) that every engine's deck
        of this scene realises; a case asking for another is refused at validation.
    controls : per-frame control values written to frames.h5, name -> unit ("1" dimensionless);
        the one declaration frames, analysis, compare and convergence use.
    series_columns : columns of the neutral time-series file every engine's deck writes (empty:
        none), in :attr:`series_file`.
    wall_columns : columns of the wall sampler's rows (:meth:`EngineOutput.wall_rows`).
    observables : convergence observables (orchestrator.stability.observables) for this scene.
    count_field : the ``scene:`` field the convergence knob ``count`` sets (the grain count; None:
        the scene has none).
    clock_terms : the optional terms whose substitute on an engine changes the cost of a step
        (:meth:`clock_variant`).
    default_analyses : analysis specs a report runs when the case lists none.
    """

    kind: ClassVar[str]
    section: ClassVar[type]
    honoured: ClassVar[frozenset[str]] = frozenset()
    controls: ClassVar[Mapping[str, str]] = {}
    series_file: ClassVar[str | None] = None
    series_columns: ClassVar[tuple[str, ...]] = ()
    wall_columns: ClassVar[tuple[str, ...]] = ()
    observables: ClassVar[tuple[str, ...]] = ()
    count_field: ClassVar[str | None] = "n_particles"
    clock_terms: ClassVar[tuple[str, ...]] = ()
    default_analyses: ClassVar[tuple[str, ...]] = ()

    # -- validation ------------------------------------------------------------------------
    def refused_terms(self, case) -> list[str]:
        """One message per case term this scene does not realise (empty: the case is accepted)."""
        out = []
        for term, asked in OPTIONAL_TERMS.items():
            if term not in self.honoured and asked(case):
                out.append(f"{term.split(':')[0]}: the {self.kind} scene does not realise '{term}' in any "
                           f"engine's deck, so the run would silently lack it; remove it from the case "
                           f"(scenes that realise it: {', '.join(_scenes_honouring(term)) or 'none'})")
        return out

    def size_overrides(self, section, scale: float) -> dict | None:
        """The ``scene:`` overrides that scale the system's size by ``scale`` [-] at fixed grains
        (the convergence knob ``size_scale``): the lengths a finite-size error goes with, the
        grains and the protocol kept. ``section`` is the case's ``scene:`` model. None (the
        default): the scene has no size knob."""
        return None

    # -- physics ---------------------------------------------------------------------------
    @abstractmethod
    def required_features(self, case) -> list[str]:
        """Physics features the engines must offer (vocabulary: engines.base.FEATURES)."""

    @abstractmethod
    def derive(self, case, common: Params) -> ScenePart:
        """The scene's numbers for the templates: a frozen dataclass (subclass of
        :class:`orchestrator.params.ScenePart`, units in its field docs), from the case and the
        common parameters (``common.scene`` is not set yet)."""

    @abstractmethod
    def max_velocity(self, case) -> float:
        """Largest expected relative particle speed [m/s] (Hertz time-step limit)."""

    def size_range(self, case) -> tuple[float, float]:
        """(r_min, r_max) [m] of the particles; default: one ``radius``."""
        r = case.scene.radius
        return r, r

    def stability_inputs(self, case, params: Params) -> StabilityInputs:
        """What orchestrator.stability.checks needs from this scene (particle count, steps, box,
        wall speeds [m/s], confining stress [Pa], skin [m], height [m], wall force target [N],
        contact springs): :class:`orchestrator.params.StabilityInputs`; the default knows only the
        particles (fields ``n``, ``steps``) of the scene's numbers."""
        sc = params.scene
        return StabilityInputs(n_particles=int(getattr(sc, "n", 0)), total_steps=int(getattr(sc, "steps", 0)),
                               box_lo=getattr(sc, "box_lo", None), box_hi=getattr(sc, "box_hi", None))

    def sample_problems(self, run_dir: Path) -> list[str]:
        """Why the complete run in ``run_dir`` did not prepare the sample its case asks for, one
        sentence each, from the run's own checks (empty, the default: nothing to say). A run with a
        problem still ran and is kept; a convergence ladder leaves it out of its extrapolation
        (:func:`orchestrator.stability.convergence.ladder`), as its observables measure another
        sample than the rung's."""
        return []

    def clock_features(self, scene: Mapping) -> tuple[str, ...]:
        """Names of what in the case's ``scene:`` section (a plain mapping) changes the cost of a
        step on every engine (the run-time model keys on them after the substitutes:
        :meth:`clock_variant`); empty (the default): nothing does."""
        return ()

    def clock_variant(self, engine: str, substitutes: dict, scene: Mapping | None = None) -> str | None:
        """A name for the variant of this scene's deck on ``engine`` that the case selects where it
        changes the cost of a step (the run-time model keys on it:
        :func:`orchestrator.clock.clock_key`): the engine's ``contact.substitutes`` for the terms of
        :attr:`clock_terms`, then the :meth:`clock_features` of the ``scene:`` section, joined by
        "+"; None without one. The order matters: a variant not measured yet falls back to the
        entry without its last part (:func:`orchestrator.clock.key_fallbacks`)."""
        picked = [substitutes.get(f"{engine}.{term}") for term in self.clock_terms]
        picked += list(self.clock_features(scene or {}))
        return "+".join(p for p in picked if p) or None

    def step_plan(self, scene_params: Mapping) -> StepPlan | None:
        """The variable part of the run's step count (:class:`StepPlan`), from the scene's numbers
        (``params.json``'s ``scene``); None (the default): the derived ``steps`` are what a run takes."""
        return None

    # -- files -----------------------------------------------------------------------------
    def prepare(self, case, params: Params, run_dir: Path) -> tuple[dict, ScenePart]:
        """Write the shared input files (particle table, meshes) into ``run_dir``; return their
        paths by name for the templates, and the scene's numbers completed with what preparing
        found (e.g. the packed geometry; parameters are frozen: a new object)."""
        sc = params.scene
        if not (Path(run_dir) / "particles.txt").exists():
            write_particle_table(Path(run_dir) / "particles.txt", sc.ids, sc.radius, case.material.density,
                                 sc.position, getattr(sc, "velocity", None))
        return {}, sc

    def post(self, run_dir: Path, params: Params, output: EngineOutput) -> dict:
        """Controls per frame (``{"controls": {name: array}}``, names as :attr:`controls`) and wall
        series (``{"walls": {name: {"time": ..., ...}}}``) from an engine's output; may write
        ``scene_summary.json`` into ``run_dir``."""
        return {"controls": {}}


def _scenes_honouring(term: str) -> list[str]:
    return [k for k in scene_kinds() if term in get_scene(k).honoured]


def run_case_scene(run_dir, summary: dict | None = None) -> tuple[dict, str]:
    """The ``scene`` section of a run's resolved ``case.yaml`` ({} when unreadable) and the case
    file the run came from (``summary.json`` → ``case_source``, read unless the caller has the
    ``summary``; "" when unknown): what a sample check quotes when it names the case field that
    fixes a run (:func:`case_field`)."""
    run_dir = Path(run_dir)
    try:
        scene = (yaml.safe_load((run_dir / "case.yaml").read_text()) or {}).get("scene") or {}
    except (OSError, ValueError, AttributeError):
        scene = {}
    if summary is None:
        try:
            summary = json.loads((run_dir / "summary.json").read_text())
        except (OSError, ValueError):
            summary = {}
    return scene, str((summary or {}).get("case_source") or "")


def case_field(prefix: str, section: dict | None, field: str, model, case_file: str = "") -> str:
    """A case field as a fix names it: ``PREFIX.FIELD in CASE_FILE (now VALUE)``, the value from the
    run's resolved ``section`` of the case or, where the case is silent, ``model``'s default."""
    value = (section or {}).get(field, model.model_fields[field].default)
    return f"{prefix}.{field}{f' in {case_file}' if case_file else ''} (now {value})"
