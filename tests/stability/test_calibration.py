"""μ calibration: the saturating fit on known data, and a smoke calibration with LIGGGHTS."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from orchestrator.stability.calibration import calibrate, fit_saturating, invert, saturating

CASE = Path(__file__).resolve().parents[2] / "cases" / "plane_shear_smoke.yaml"


def test_fit_recovers_parameters_and_inverts():
    mu = np.array([0.0, 0.1, 0.2, 0.4, 0.7, 1.0])
    y = saturating(mu, 0.1, 0.3, 0.25)
    f = fit_saturating(mu, y)
    assert f["mu0"] == pytest.approx(0.1, abs=1e-6) and f["A"] == pytest.approx(0.3, abs=1e-6)
    assert f["mu_c"] == pytest.approx(0.25, rel=1e-5)
    target = float(saturating(0.58, 0.1, 0.3, 0.25))
    assert invert(target, f) == pytest.approx(0.58, rel=1e-5)
    with pytest.raises(ValueError, match="outside"):
        invert(0.45, f)


@pytest.mark.engine
def test_smoke_calibration(runs_root, tmp_path, engines_installed):
    out = calibrate(CASE, [0.0, 0.2, 0.5, 1.0], target=None, engines=["liggghts"], runs_root=runs_root,
                    workers=1, plot=tmp_path / "cal.png")
    df = out["table"]
    assert (df["status"] == "complete").all()
    mu_macro = df.sort_values("contact.friction")["mu_macro"].to_numpy()
    # frictionless spheres shear far more easily than frictional ones (a loose, honest bound)
    assert mu_macro[0] < 0.2 and mu_macro[1:].min() > mu_macro[0] + 0.05
    f = out["fits"]["liggghts"]
    assert f["mu0"] == pytest.approx(mu_macro[0], abs=0.05)
    target = f["mu0"] + 0.5 * f["A"]
    mu = invert(target, f)
    assert 0 < mu < 1.0
    assert (tmp_path / "cal.png").exists()
