"""Bisection on a tiny case finds a stable fraction, and the pre-run check is on its safe side."""
from __future__ import annotations

from pathlib import Path

import pytest

from orchestrator.stability.bisection import bisect, table

CASE = Path(__file__).resolve().parents[2] / "cases" / "stability" / "mu1.yaml"


@pytest.mark.engine
def test_bisection_liggghts_safe_side(runs_root, engines_installed):
    b = bisect(CASE, "liggghts", runs_root=runs_root, rel_tol=0.3)
    assert b.stable_fraction is not None and b.unstable_fraction is not None
    assert b.stable_fraction < b.unstable_fraction <= b.stable_fraction * 1.3 + 1e-12
    assert b.tripped and b.tripped["figure"]
    # every probe at or below the stable fraction completed, every one at or above the unstable one did not
    for p in b.probes:
        if p["fraction"] <= b.stable_fraction:
            assert p["stable"]
        if p["fraction"] >= b.unstable_fraction:
            assert not p["stable"]
    assert b.check_fraction <= b.stable_fraction
    assert b.safe_side is True
    df = table([b])
    assert df.loc[0, "check_safe_side"] and df.loc[0, "margin"] >= 1
