"""Plane shear with the seed 000 rolling and twisting resistance (as the shear cell): the engines
run it with their named substitutes, the springs are the seed's k_r = k_tw = k_t r_eff², and the
rolling resistance raises the macroscopic friction of the sheared packing."""
from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from orchestrator.case import load_case
from orchestrator.derive import derive
from orchestrator.runner import run_case
from orchestrator.stability.observables import observables

CASE = Path(__file__).resolve().parents[2] / "cases" / "stability" / "mu1.yaml"
ROLL = {"contact": {"rolling": {"model": "seed000"}, "torsion": {"coefficient": 0.58},
                    "substitutes": {"liggghts.rolling_friction_load": "epsd2_constant",
                                    "liggghts.torsion_friction": "epsd2_torsion_torque",
                                    "yade.rolling_friction_load": "mindlin_moment",
                                    "yade.torsion_friction": "mindlin_ktwist_elastic",
                                    "lammps.rolling_friction_load": "sds_constant",
                                    "lammps.torsion_friction": "sds_median_pair"}}}


def test_rolling_springs_are_the_seeds():
    case = load_case(CASE, overrides=ROLL)
    p = derive(case)
    c = p["scene"]["contact"]
    x50 = case.scene.psd.median
    r_eff = x50 / 4
    k_t = 2 / 7 * 4 / 3 * p["E_eff_pp"] * x50 / 2            # seed §3.2
    assert c["rolling_stiffness"] == pytest.approx(k_t * r_eff ** 2)
    assert c["twisting_stiffness"] == pytest.approx(k_t * r_eff ** 2)
    xi = c["expected_overlap"]
    assert c["rolling_coefficient"] * r_eff == pytest.approx(math.sqrt(2 * r_eff * xi))   # seed000 mu_r r_eff
    assert c["torsion_coefficient"] == 0.58
    assert "rolling" in p["stability"]["limits"] and "twisting" in p["stability"]["limits"]


def test_liggghts_torsion_needs_rolling():
    from orchestrator.case import CaseError
    ov = {"contact": {"torsion": {"coefficient": 0.58},
                      "substitutes": {"liggghts.torsion_friction": "epsd2_torsion_torque",
                                      "yade.torsion_friction": "mindlin_ktwist_elastic"}}}
    with pytest.raises(CaseError, match="needs rolling"):
        load_case(CASE, overrides=ov)


@pytest.mark.engine
@pytest.mark.parametrize("engine", ["liggghts", "yade", "lammps"])
def test_plane_shear_with_rolling_runs(engine, runs_root, engines_installed):
    case = load_case(CASE, overrides=ROLL)
    out = run_case(case, engine, runs_root=runs_root, progress=False)
    assert out.status == "complete"
    s = json.loads((out.run_dir / "summary.json").read_text())
    mech = {x["feature"]: x["mechanism"] for x in s["substitutions"]}
    assert mech["rolling_friction_load"] == ROLL["contact"]["substitutes"][f"{engine}.rolling_friction_load"]
    assert mech["torsion_friction"] == ROLL["contact"]["substitutes"][f"{engine}.torsion_friction"]
    deck = (out.run_dir / ("script.py" if engine == "yade" else "deck.in")).read_text()
    assert {"liggghts": "rolling_friction epsd2" in deck and "torsionTorque on" in deck,
            "yade": "law2.includeMoment = True" in deck and "ip2.ktwist" in deck,
            "lammps": "rolling sds" in deck and "twisting sds" in deck}[engine]
    rolled = observables(case, out.run_dir)["mu_macro"]
    plain = run_case(load_case(CASE), engine, runs_root=runs_root, progress=False)
    free = observables(load_case(CASE), plain.run_dir)["mu_macro"]
    assert rolled > free            # grains that cannot roll freely resist shear more
