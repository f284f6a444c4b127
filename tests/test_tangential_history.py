"""contact.tangential_history: which engine keeps the Mindlin spring's history how (LIGGGHTS the
displacement, YADE the force, LAMMPS either), refused where an engine cannot, and LAMMPS' deck
switching between `mindlin` and `mindlin/force` (docs/crossval.md, "The tangential history")."""
from __future__ import annotations

from pathlib import Path

import pytest

from engines.base import UnsupportedFeature
from orchestrator.case import load_case
from orchestrator.derive import derive
from orchestrator.registry import get_engine

CASES = Path(__file__).resolve().parents[1] / "cases"


def _case(history):
    ov = {"contact": {"tangential_history": history}} if history else {}
    return load_case(CASES / "plane_shear_smoke.yaml", overrides=ov)


@pytest.mark.parametrize("history, accepts, refuses", [
    ("force", ["yade", "lammps"], ["liggghts"]),
    ("displacement", ["liggghts", "lammps"], ["yade"]),
    (None, ["yade", "lammps", "liggghts"], []),
])
def test_each_engine_keeps_the_history_it_can(history, accepts, refuses):
    case = _case(history)
    params = derive(case)
    assert (f"tangential_history_{history}" in params.features) == (history is not None)
    for name in accepts:
        eng = get_engine(name)
        eng.check(eng.required_features(case, params), case.contact.substitutes)
    for name in refuses:
        eng = get_engine(name)
        with pytest.raises(UnsupportedFeature, match=f"tangential_history_{history}"):
            eng.check(eng.required_features(case, params), case.contact.substitutes)


def test_no_friction_keeps_no_history():
    case = load_case(CASES / "plane_shear_smoke.yaml", overrides={"contact": {"tangential_history": "force",
                                                                             "friction": 0.0}})
    assert not [f for f in derive(case).features if f.startswith("tangential_history")]


@pytest.mark.parametrize("history, model", [("force", "mindlin/force"), ("displacement", "mindlin"), (None, "mindlin")])
def test_lammps_names_the_model(history, model):
    case = _case(history)
    params = derive(case)
    assert get_engine("lammps").engine_params(case, params.to_dict())["tangential"] == model
