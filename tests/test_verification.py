"""Contact-level verification (issue #2, Chung & Ooi 2011 tests 1-4) on the three real engines, with
the time step the derived-parameter module chooses: contact time and peak force within 1 % of
Hertz, normal restitution within 1 % of the requested value, tangential restitution within 2 % of
the rigid sliding limit beyond the threshold angle."""
from __future__ import annotations

import json

import pytest

from orchestrator.case import load_case
from orchestrator.frames import Frames
from orchestrator.runner import run_case
from orchestrator.verify import impact_metrics, verification_cases, verification_table

CASES = verification_cases()
pytestmark = pytest.mark.engine


@pytest.mark.parametrize("engine", ["liggghts", "yade", "lammps"])
@pytest.mark.parametrize("path", CASES, ids=[p.stem for p in CASES])
def test_impact_matches_analytic(path, engine, runs_root, engines_installed):
    case = load_case(path)
    out = run_case(case, engine, runs_root=runs_root, progress=False)
    assert out.status == "complete"
    params = json.loads((out.run_dir / "params.json").read_text())
    metrics = impact_metrics(Frames(out.run_dir / "frames.h5"), params)
    table = verification_table(metrics, engine, case.name, 0.0)
    assert len(table), "no quantity was compared"
    bad = table[~table["pass"]]
    assert bad.empty, "\n" + bad.to_string()
    quantities = set(table.quantity)
    if case.contact.restitution == 1.0:
        assert {"contact_time", "peak_force", "e_n"} <= quantities
    else:
        assert "e_n" in quantities
    if case.contact.friction > 0:
        assert (table.quantity == "e_t").sum() >= 5        # every angle beyond the threshold


def test_oblique_case_covers_angles_beyond_sliding_threshold():
    from orchestrator.derive import sliding_threshold_angle
    import math
    case = load_case([p for p in CASES if "oblique" in p.name][0])
    thr = math.degrees(sliding_threshold_angle(case.contact.friction, case.contact.restitution))
    angles = [math.degrees(a) for a in case.scene.angles]
    assert min(angles) < thr < max(angles)


def test_summary_records_time_split_and_substitutions(runs_root, engines_installed):
    case = load_case([p for p in CASES if p.name.endswith("e02.yaml")][0])
    out = run_case(case, "liggghts", runs_root=runs_root, progress=False)
    s = json.loads((out.run_dir / "summary.json").read_text())
    assert s["status"] == "complete" and s["engine_version"].startswith("LIGGGHTS")
    assert {"render", "engine", "parse"} <= set(s["wall_time"])
    assert [x["mechanism"] for x in s["substitutions"]] == ["hertz_stiffness_calibrated"]
    assert "hertz/stiffness" in (out.run_dir / "deck.in").read_text()


def test_low_restitution_without_accepted_substitute_is_refused(runs_root, engines_installed):
    from engines.base import UnsupportedFeature
    path = [p for p in CASES if p.name.endswith("e02.yaml")][0]
    case = load_case(path)
    case.contact.substitutes.clear()
    with pytest.raises(UnsupportedFeature, match="low_restitution.*hertz_stiffness_calibrated"):
        run_case(case, "liggghts", runs_root=runs_root, progress=False)
    assert run_case(case, "yade", runs_root=runs_root, progress=False).status == "complete"
