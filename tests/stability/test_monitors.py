"""A deliberately unstable run is stopped early by the in-deck monitors of either engine and
marked unstable in summary.json with the figure that tripped and when."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from orchestrator.case import load_case
from orchestrator.derive import derive
from orchestrator.runner import run_case

CASE = Path(__file__).resolve().parents[2] / "cases" / "stability" / "mu1.yaml"


@pytest.mark.engine
@pytest.mark.parametrize("engine", ["liggghts", "yade"])
def test_unstable_run_is_stopped_and_marked(engine, runs_root, engines_installed):
    base = derive(load_case(CASE))
    dt = 6 * base["dt_critical"]                     # far above every limit
    case = load_case(CASE, overrides={"timestep": {"dt": f"{dt!r} s", "allow_unsafe": True}})
    out = run_case(case, engine, runs_root=runs_root, progress=False)
    assert out.status == "unstable"
    s = json.loads((out.run_dir / "summary.json").read_text())
    u = s["unstable"]
    assert s["status"] == "unstable"
    assert u["figure"] in ("kinetic_energy", "overlap", "grains_outside", "nan", "wall_force", "wall_force_swing")
    assert u["step"] < s["steps"] / 2                # stopped early, not at the end
    assert u["time"] == pytest.approx(u["step"] * dt)
    if u["figure"] in ("kinetic_energy", "overlap", "wall_force"):
        assert u["value"] > u["limit"]
    assert not (out.run_dir / "frames.h5").exists()
    # a second call reuses the verdict instead of running again
    again = run_case(case, engine, runs_root=runs_root, progress=False)
    assert again.reused and again.status == "unstable"


@pytest.mark.engine
def test_stable_run_is_not_flagged(runs_root, engines_installed):
    out = run_case(load_case(CASE), "liggghts", runs_root=runs_root, progress=False)
    assert out.status == "complete"
    log = (out.run_dir / "engine.log").read_text()
    # the monitors did run (their checks are echoed) but nothing tripped
    assert log.count("if '${ORCH_ke} >") >= 50
    assert "\nORCH_UNSTABLE:" not in log
