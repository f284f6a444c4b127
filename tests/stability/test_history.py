"""very_soft (σ/E = 5 %): the large overlap is physics (already there at a small time step, with the
settled packing at rest), the numerical instability is the heating of the settled packing at a
large one — the evidence behind the overlap monitor's limit (docs/stability.md)."""
from __future__ import annotations

from pathlib import Path

import pytest

from orchestrator.stability.history import history

CASE = Path(__file__).resolve().parents[2] / "cases" / "stability" / "very_soft.yaml"


@pytest.mark.engine
def test_very_soft_overlap_is_physics_heating_is_instability(tmp_path, engines_installed):
    small, large = history(CASE, "liggghts", [0.2, 2.0], runs_root=tmp_path, overlap_limit=4.0)
    assert small["tripped"] is None and small["checks"] >= 90
    assert small["overlap_max"] > 0.6                 # ~0.8 r_min: Hertz under 15 kPa on 0.3 MPa grains
    assert small["ke_settled"] < 1e-13                # the compressed packing comes to rest (~1e-14 J)
    assert large["ke_settled"] > 100 * small["ke_settled"]     # at f = 2 it heats up instead
