"""Typed, frozen parameters (issue #13 item 1) and engine numbers behind the Engine interface
(item 2). Engine-free: nothing here starts an engine."""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from orchestrator.case import load_case
from orchestrator.derive import derive
from orchestrator.params import FrozenMap, Params, ScenePart, StabilityInputs
from orchestrator.registry import engine_names, get_engine, get_scene
from bench_util import load_benchmark
from tests.conftest import CASES

REPO = Path(__file__).resolve().parents[1]
SMOKE = {"impact": "verification/chung_ooi_4_oblique.yaml", "shear_cell": "shear_cell_smoke.yaml",
         "plane_shear": "plane_shear_smoke.yaml", "triaxial": "triaxial_smoke.yaml"}


@pytest.fixture(scope="module")
def derived():
    return {kind: (load_case(CASES / rel), derive(load_case(CASES / rel))) for kind, rel in SMOKE.items()}


def test_derive_returns_typed_frozen_params(derived):
    for kind, (case, p) in derived.items():
        assert isinstance(p, Params) and isinstance(p.scene, ScenePart), kind
        assert type(p.scene).__name__.lower().startswith(kind.replace("_", "")), type(p.scene)
        with pytest.raises(dataclasses.FrozenInstanceError):
            p.dt = 1.0
        with pytest.raises(dataclasses.FrozenInstanceError):
            p.scene.steps = 1
        assert isinstance(p.monitors, FrozenMap)
        with pytest.raises(TypeError, match="frozen"):
            p.monitors["every"] = 1
        # every field documents its unit (a #: comment or an opt() doc): the dataclass has fields only
        assert {f.name for f in dataclasses.fields(p.scene)}


def test_to_dict_is_json_and_matches_attribute_access(derived):
    for kind, (case, p) in derived.items():
        d = json.loads(json.dumps(p.to_dict()))
        assert d["dt"] == p.dt and d["scene"]["steps"] == p.scene.steps, kind
        assert d["material"] == {"E": p.material.E, "nu": p.material.nu, "rho": p.material.rho, "G": p.material.G}
        # the read-only mapping view answers like the dict of params.json
        assert p["scene"]["steps"] == d["scene"]["steps"] and ("files" in p) is ("files" in d)


def test_stability_checks_ask_the_scene(derived, monkeypatch):
    """checks.critical_steps takes the confining stress and wall speeds from Scene.stability_inputs,
    not from keys it finds in the parameters: a scene reporting 100x the stress gets a smaller
    Hertz limit, and its wall speed sets the skin limit."""
    from orchestrator.stability import checks
    case, p = derived["plane_shear"]
    scene = get_scene("plane_shear")
    base = checks.critical_steps(case, p)
    orig = scene.stability_inputs

    def louder(case_, params_):
        inp = orig(case_, params_)
        return inp.replace(confining_stress=100 * inp.confining_stress, wall_speeds={"servo": 50.0})
    monkeypatch.setattr(scene, "stability_inputs", louder)
    other = checks.critical_steps(case, p)
    assert other["confining_stress"] == 100 * base["confining_stress"]
    assert other["limits"]["hertz"] < base["limits"]["hertz"]
    assert other["speed"] == 100.0 and other["limits"]["skin"] == pytest.approx(0.5 * other["skin"] / 100.0)
    assert isinstance(orig(case, p), StabilityInputs)


def test_engine_numbers_are_frozen_and_only_in_engine_packages(derived):
    for kind, (case, p) in derived.items():
        for name in case.engines:
            own = get_engine(name).engine_params(case, p)
            if own is None:
                continue
            assert dataclasses.is_dataclass(own) or isinstance(own, FrozenMap), (name, kind)
            if dataclasses.is_dataclass(own):
                with pytest.raises(dataclasses.FrozenInstanceError):
                    setattr(own, dataclasses.fields(own)[0].name, 0)
    # the shared parameters name no engine
    flat = json.dumps({k: p.to_dict() for k, (_, p) in derived.items()}).lower()
    for name in engine_names():
        assert name not in flat


def test_low_restitution_is_the_clipped_engines_requirement():
    """e_n = 0.2 is below what LIGGGHTS' model hertz can be fed: LIGGGHTS requires the feature
    'low_restitution' (a substitute), the engines that take e_n as it is do not."""
    case = load_case(CASES / "verification/chung_ooi_3_restitution_e02.yaml")
    p = derive(case)
    assert "low_restitution" not in p.features
    lig = get_engine("liggghts")
    assert lig.engine_params(case, p).low_restitution and "low_restitution" in lig.required_features(case, p)
    assert lig.engine_params(case, p).hertz_stiffness.calibrated_at_speed == p.v_max
    assert "low_restitution" not in get_engine("yade").required_features(case, p)


def test_no_module_outside_engines_names_an_engine():
    """benchmarks/architecture_metrics.py: no module outside engines/ names an engine in code
    (comments, docstrings and messages aside)."""
    m = load_benchmark("architecture_metrics")
    named = [f.relative_to(REPO).as_posix() for f in m.py_files(REPO)
             if not f.relative_to(REPO).as_posix().startswith("engines/") and m.ENGINE_NAME.search(m._code_only(f.read_text()))]
    assert named == []
