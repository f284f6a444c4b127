import numpy as np
import pytest

from orchestrator.analysis.shearband import (analyze_shearband, erf_profile, fit_erf_profile, rotation_center)
from tests.analysis.conftest import CENTER, D, W_SB, Z_SB


def test_noisy_erf_profile_recovered_within_uncertainty():
    rng = np.random.default_rng(4)
    z = np.linspace(0, 20 * D, 40)
    zs, ws, sig = 7.3 * D, 2.6 * D, 0.04
    hits_z = hits_w = 0
    for _ in range(40):
        v = erf_profile(z, zs, ws) + rng.normal(scale=sig, size=z.size)
        f = fit_erf_profile(z, v, np.full(z.size, sig))
        assert f["ok"]
        hits_z += abs(f["z_sb"] - zs) < f["z_sb_err"]
        hits_w += abs(f["w_sb"] - ws) < f["w_sb_err"]
        assert abs(f["z_sb"] - zs) < 4 * f["z_sb_err"]
        assert abs(f["w_sb"] - ws) < 4 * f["w_sb_err"]
        assert f["z_sb_err"] < 0.5 * D
    # the 1-sigma errors are honest: ~68 % coverage
    assert 20 <= hits_z <= 36 and 20 <= hits_w <= 36


def test_fit_without_sigma_and_failure_flag():
    z = np.linspace(0, 1, 30)
    f = fit_erf_profile(z, erf_profile(z, 0.4, 0.1))
    assert f["z_sb"] == pytest.approx(0.4, abs=1e-6) and f["ok"]
    assert not fit_erf_profile(z[:3], z[:3])["ok"]


def test_rotation_center_off_axis():
    rng = np.random.default_rng(1)
    p0 = rng.uniform(-1, 1, (500, 3))
    c = np.array([0.13, -0.07])
    th = 0.01
    rel = p0[:, :2] - c
    p1 = p0.copy()
    p1[:, 0] = c[0] + np.cos(th) * rel[:, 0] - np.sin(th) * rel[:, 1]
    p1[:, 1] = c[1] + np.sin(th) * rel[:, 0] + np.cos(th) * rel[:, 1]
    cx, cy, dth = rotation_center(p0, p1)
    assert (cx, cy) == pytest.approx(tuple(c), abs=2e-3)
    assert dth == pytest.approx(th, rel=1e-2)


def test_shear_cell_band_position_width_and_steady_state(shear_cell):
    res = analyze_shearband(shear_cell, control="angle", bins_z=10, steady_from=np.radians(0.9))
    fits = res.tables["fits"]
    assert fits["ok"].all()
    # synthetic data is noise-free, so the fit reproduces eq. 2 up to binning in z
    b = res.tables["band"]
    assert np.allclose(b["z_sb"], Z_SB, atol=0.15 * D)
    assert np.allclose(b["w_sb"], W_SB, atol=0.3 * D)
    assert np.allclose(fits[["center_x", "center_y"]].to_numpy(), CENTER, atol=0.02 * D)
    st = res.tables["steady"]
    assert len(st) == 4 and (st["n_fits"] == 4).all()      # pairs ending at 1.0, 1.5, 2.0, 2.5 deg
    # the wrong rotation centre (cell axis) scatters the particles' angular velocities in a ring
    res_axis = analyze_shearband(shear_cell, control="angle", bins_z=10, center="axis")
    top = lambda r: r.tables["profiles"].query("z > @Z_SB + 0.5 * @W_SB")["v_err"].mean()
    assert top(res_axis) > 5 * top(res)
