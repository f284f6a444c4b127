"""Stress–strain–volume figures of the triaxial analysis against closed forms."""
import numpy as np
import pytest

from orchestrator.analysis.triaxial import (analyze_triaxial, dilatancy_angle, friction_angle, local_slope,
                                            running_mean, triaxial_curves)
from orchestrator.frames import Frames, write_frames


def test_friction_angle_mohr_coulomb():
    # R = (1 + sin φ)/(1 − sin φ): φ = 30° gives R = 3
    assert np.degrees(friction_angle(3.0)) == pytest.approx(30.0, abs=1e-12)
    assert friction_angle(1.0) == 0.0


def test_dilatancy_angle_of_a_straight_dilating_line():
    """ε_v = −a ε_a: sin ψ = a/(2 + a) everywhere (Vermeer & de Borst 1984)."""
    ea = np.linspace(0, 0.1, 201)
    for a in (0.0, 0.3, 1.0):
        psi = dilatancy_angle(ea, -a * ea, window=0.01)
        assert psi == pytest.approx(np.arcsin(a / (2 + a)), abs=1e-12)


def test_local_slope_ignores_noise_and_order():
    rng = np.random.default_rng(0)
    x = rng.permutation(np.linspace(0, 1, 2001))
    y = 3 * x + rng.normal(0, 1e-3, x.size)
    assert np.median(local_slope(x, y, 0.2)) == pytest.approx(3, rel=1e-3)


def test_running_mean_is_exact_on_lines_and_keeps_length():
    x = np.arange(50, dtype=float)
    m = running_mean(x, 10)
    assert m.shape == x.shape
    assert m[10:-10] == pytest.approx(x[10:-10] - 0.5)       # an even window is centred half a row early
    assert running_mean(x, 1) == pytest.approx(x)
    # the ends use the first / last full window
    assert m[:5] == pytest.approx(np.full(5, 4.5)) and m[-5:] == pytest.approx(np.full(5, 44.5))


def test_running_mean_valid_mode_is_every_full_window():
    rng = np.random.default_rng(1)
    x = rng.normal(size=37)
    v = running_mean(x, 5, mode="valid")
    assert v == pytest.approx(np.convolve(x, np.ones(5) / 5, mode="valid"), abs=1e-13)
    # the centred values are the valid windows, shifted by rows // 2, in the interior
    assert running_mean(x, 5)[2:-2] == pytest.approx(v, abs=1e-13)
    assert running_mean(np.arange(5.0), 2, mode="valid") == pytest.approx([0.5, 1.5, 2.5, 3.5])
    assert running_mean(x[:3], 5, mode="valid") == pytest.approx([np.mean(x[:3])])
    with pytest.raises(ValueError, match="mode"):
        running_mean(x, 5, mode="full")


def test_analyze_triaxial_peak_and_residual(tmp_path):
    """A synthetic test: R rises to a peak of 3 at ε_a = 0.05 and softens to 2; the sample dilates
    at a constant rate dε_v/dε_a = −0.5 (ψ = asin(0.5/2.5))."""
    t = np.linspace(0, 1, 2001)
    stage = np.where(t < 0.2, 1.0, 2.0)
    ea = np.where(stage == 2, (t - 0.2) * 0.15 / 0.8, 0.0)
    g = np.exp(-((ea - 0.05) / 0.02) ** 2)
    ratio = np.where(stage == 1, 1.0, np.where(ea <= 0.05, 1 + 2 * g, 2 + g))
    s3 = np.full_like(t, 3e5)
    walls = {"triaxial": {"time": t, "stage": stage, "axial_strain": ea, "sigma1": ratio * s3, "sigma3": s3,
                          "volumetric_strain": -0.5 * ea, "volume": 1e-6 * (1 + 0.5 * ea)}}
    pos = np.zeros((2, 2, 3))
    pos[:, 1, 0] = 1e-3
    fr = Frames(write_frames(tmp_path / "f.h5", [1, 2], [1e-4, 1e-4], [0, 1], pos, walls=walls))
    res = analyze_triaxial(fr, smoothing_rows=1)
    s = res.scalars
    assert s["peak_stress_ratio"] == pytest.approx(3.0, rel=1e-4)
    assert s["axial_strain_at_peak"] == pytest.approx(0.05, abs=1e-3)
    assert s["peak_friction_angle_deg"] == pytest.approx(30.0, abs=0.01)
    assert s["residual_stress_ratio"] == pytest.approx(2.0, abs=1e-3)
    assert s["max_dilatancy_angle_deg"] == pytest.approx(np.degrees(np.arcsin(0.2)), abs=1e-6)
    assert s["final_axial_strain"] == pytest.approx(0.15)
    assert len(res.tables["curves"]) == int((stage == 2).sum())
    assert res.plot().axes
    with pytest.raises(ValueError, match="triaxial"):
        analyze_triaxial(fr, wall="membrane")
