"""A convergence ladder of three runs on a tiny case: table, plot, Pareto front, recommendation."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from orchestrator.stability.convergence import ladder, pareto, relative_error

CASE = Path(__file__).resolve().parents[2] / "cases" / "stability" / "mu1.yaml"


def test_pareto_and_errors():
    assert pareto(np.array([1.0, 2.0, 3.0, 4.0]), np.array([0.5, 0.6, 0.1, 0.2])) == [0, 2]
    assert relative_error(1.1, 1.0) == pytest.approx(0.1)
    assert relative_error([1, 1], [1, 2]) == pytest.approx(1 / np.sqrt(5))


@pytest.mark.engine
def test_dt_ladder(runs_root, tmp_path, engines_installed):
    # rungs below the pre-run check's safe limit for this case (0.48 of the critical step, coordination)
    out = ladder(CASE, "dt_fraction", [0.4, 0.2, 0.1], engines=["liggghts"], runs_root=runs_root,
                 target_error=0.2, plot=tmp_path / "ladder.png")
    df = out["table"]
    assert len(df) == 3 and (df["status"] == "complete").all()
    assert df["reference"].tolist() == [False, False, True]
    assert df.loc[2, "error"] == 0.0
    assert np.isfinite(df.loc[:1, "error"]).all()
    # more steps cost more engine time
    t = df["engine_time_s"].to_numpy()
    assert t[0] < t[2]
    assert "err_mu_macro" in df.columns
    assert (tmp_path / "ladder.png").stat().st_size > 5000
    rec = out["recommendation"]["liggghts"]
    assert rec["dt_fraction"] in (0.4, 0.2, 0.1)
    if "note" not in rec:
        assert rec["error"] <= 0.2


def test_refused_rung_is_a_row(runs_root):
    # dt_fraction 1.0 is above the coordination limit's safe fraction for this case: refused, not run
    out = ladder(CASE, "dt_fraction", [1.0], engines=["liggghts"], runs_root=runs_root, reference=1.0)
    assert out["table"].loc[0, "status"] == "refused"
