"""LIGGGHTS' SI guard on Young's modulus: below 5 MPa it refuses a deck unless `soft_particles yes`
(a stiffness ladder's lower rungs hit it: stiffness_scale 0.5 of the small shear cell's 5 MPa failed
at its first `run`). The decks now lift the bound that the case's softest material crosses, and a
2 MPa glass impact still meets Hertz's contact time and peak force."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from orchestrator.case import load_case
from orchestrator.frames import Frames
from orchestrator.runner import prepare, run_case
from orchestrator.verify import impact_metrics, verification_table

REPO = Path(__file__).resolve().parents[1]
#: the softest material of each case below 5 MPa (the triaxial and impact decks share
#: partials/materials.j2 with the same guard: the impact below runs it on the engine)
SOFT = {"shear_cell_smoke.yaml": {"material": {"youngs_modulus": "2.5 MPa"}, "wall": {"youngs_modulus": "2.5 MPa"}},
        "plane_shear_smoke.yaml": {"material": {"youngs_modulus": "2.5 MPa"}}}


@pytest.mark.parametrize("case_rel", ["shear_cell_smoke.yaml", "plane_shear_smoke.yaml"])
def test_decks_lift_the_bound_the_softest_material_crosses(case_rel, tmp_path):
    from engines import get_engine
    eng = get_engine("liggghts")
    for overrides, soft in ((None, False), (SOFT[case_rel], True)):
        case = load_case(REPO / "cases" / case_rel, overrides=overrides)
        run_dir = tmp_path / f"{case_rel}-{soft}"
        params, _ = prepare(case, "liggghts", run_dir)
        deck = eng.render(case, params, run_dir).read_text()
        assert "hard_particles  yes" in deck            # always (rigid platens of 1000 E exceed 1e9 Pa)
        assert ("soft_particles  yes" in deck) == soft


@pytest.mark.engine
def test_soft_glass_impact_on_liggghts_meets_hertz(runs_root, engines_installed):
    case = load_case(REPO / "cases" / "verification" / "chung_ooi_1_sphere_sphere_glass.yaml",
                     overrides={"material": {"youngs_modulus": "2 MPa"}})
    out = run_case(case, "liggghts", runs_root=runs_root, progress=False)
    assert out.status == "complete"
    assert "soft_particles  yes" in (out.run_dir / "deck.in").read_text()
    params = json.loads((out.run_dir / "params.json").read_text())
    table = verification_table(impact_metrics(Frames(out.run_dir / "frames.h5"), params), "liggghts", case.name, 0.0)
    assert {"contact_time", "peak_force"} <= set(table.quantity)
    bad = table[~table["pass"]]
    assert bad.empty, "\n" + bad.to_string()
