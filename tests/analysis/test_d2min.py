import numpy as np
import pytest

from orchestrator.analysis.d2min import d2min, local_strain, analyze_d2min
from orchestrator.frames import Frames, write_frames

D = 30e-6


def _random_packing(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0, 14 * D, (n, 3))


def test_affine_deformation_gives_zero_d2min_and_exact_strain():
    p0 = _random_packing()
    F = np.array([[1.01, 0.004, 0.0], [-0.002, 0.995, 0.003], [0.001, 0.0, 0.98]])
    p1 = p0 @ F.T + np.array([1e-5, -2e-6, 3e-6])       # affine map plus a rigid translation
    r = d2min(p0, p1, 1.5 * D)
    ok = np.isfinite(r["d2min"])
    assert ok.mean() > 0.98
    assert np.nanmax(r["d2min"]) < 1e-12 * D ** 2
    np.testing.assert_allclose(r["F"][ok], np.broadcast_to(F, (ok.sum(), 3, 3)), atol=1e-10)
    eps = 0.5 * (F + F.T) - np.eye(3)
    dev = eps - np.trace(eps) / 3 * np.eye(3)
    np.testing.assert_allclose(r["eps_q"][ok], np.sqrt(2 / 3 * np.sum(dev * dev)), rtol=1e-8)
    np.testing.assert_allclose(r["eps_v"][ok], np.trace(eps), atol=1e-10)


def test_nonaffine_noise_gives_expected_d2min():
    # an isolated random kick of amplitude s on every particle: D2min ~ (1 + 1/N_i) * 2 s^2 minus fit
    p0 = _random_packing(seed=1)
    rng = np.random.default_rng(2)
    s = 0.01 * D
    p1 = p0 + rng.normal(scale=s, size=p0.shape)
    r = d2min(p0, p1, 1.5 * D)
    med = np.nanmedian(r["d2min"])
    # mean |u_k - u_i|^2 = 6 s^2, the affine fit removes 9 of ~3 N_i degrees of freedom
    assert 3 * s ** 2 < med < 6.5 * s ** 2


def test_nan_rows_are_skipped_and_neighbour_count_checked():
    p0 = _random_packing(800, seed=3)
    p1 = p0.copy()
    p0[10] = np.nan
    p1[20] = np.nan
    r = d2min(p0, p1, 1.5 * D)
    assert np.isnan(r["d2min"][[10, 20]]).all()
    assert r["n_neighbors"][10] == 0 and r["n_neighbors"][20] == 0
    # isolated particle (no neighbours) -> NaN, not 0
    p0[30] = p1[30] = [1.0, 1.0, 1.0]
    r = d2min(p0, p1, 1.5 * D)
    assert np.isnan(r["d2min"][30])
    assert np.nanmax(r["d2min"]) < 1e-20


def test_local_strain_simple_shear():
    g = 0.02
    F = np.eye(3)
    F[0, 2] = g
    s = local_strain(F[None])
    # Green-Lagrange: E_xz = g/2, E_zz = g^2/2; eps_xz = g/2, eps_q = sqrt(2/3 * 2 (g/2)^2) = g / sqrt(3)
    assert s["eps_q"][0] == pytest.approx(g / np.sqrt(3))
    assert s["eps_v"][0] == pytest.approx(0.0)
    assert s["shear_vm"][0] == pytest.approx(np.sqrt((g / 2) ** 2 + 2 * (g * g / 2) ** 2 / 6), rel=1e-9)


def test_analyze_d2min_on_frames(tmp_path):
    p0 = _random_packing(1500, seed=4)
    F = np.diag([1.0, 1.0, 0.99])
    pos = np.stack([p0, p0 @ F.T, p0 @ F.T @ F.T])
    r = np.full(len(p0), 0.5 * D)
    fr = Frames(write_frames(tmp_path / "frames.h5", np.arange(len(p0)), r, [0, 1, 2], pos,
                             controls={"axial_strain": [0.0, 0.01, 0.0199]}))
    res = analyze_d2min(fr, interval=0.01)
    t = res.tables["particles"]
    assert set(zip(t.frame0, t.frame1)) == {(0, 1), (1, 2)}
    assert res.scalars["cutoff_m"] == pytest.approx(1.5 * D)
    v = t["F_zz"].dropna()
    assert np.allclose(v, 0.99)
    assert t["d2min"].max() < 1e-20
    assert len(res.tables["summary"]) == 2


def test_incremental_measures_default_to_the_loading_stage():
    """Seed 001 measures D²min while loading: a triaxial run's isotropic stage (stage 1, ε_a < 0)
    is left out unless asked for, and the state ending it (ε_a = 0) is the first reference."""
    from orchestrator.analysis import frame_pairs
    from orchestrator.analysis._common import loading_frames
    p0 = _random_packing(600, seed=5)
    eps = np.array([-0.03, -0.02, -0.01, 0.0, 0.01, 0.02, 0.03])
    stage = np.array([1, 1, 1, 1, 2, 2, 2])
    # preparation: isotropic shrinkage plus noise (non-affine); loading: affine axial compression
    rng = np.random.default_rng(6)
    pos = [p0 * (1 + 0.5 * e) + rng.normal(scale=0.01 * D, size=p0.shape) for e in eps[stage == 1]]
    pos += [pos[-1] * np.array([1 + 0.25 * e, 1 + 0.25 * e, 1 - e]) for e in eps[stage == 2]]
    f = Frames.from_arrays(np.stack(pos), np.full(600, D / 2),
                           controls={"axial_strain": eps, "stage": stage.astype(float)})
    assert loading_frames(f) == [3, 4, 5, 6]
    assert frame_pairs(f, interval=0.01) == [(3, 4), (4, 5), (5, 6)]
    assert frame_pairs(f) == [(3, 4), (4, 5), (5, 6)]
    assert frame_pairs(f, interval=0.01, stages="all")[0] == (0, 1)
    r = analyze_d2min(f, interval=0.01)
    s = r.tables["summary"]
    assert s["control0"].min() == 0.0
    # frames 4..6 are affine images of frame 3's positions: D²min vanishes on the loading pairs
    assert s["d2min_p90"].max() < 1e-20
    r_all = analyze_d2min(f, interval=0.01, stages="all")
    assert r_all.tables["summary"]["d2min_p90"].max() > 1e-6 * D ** 2
    with pytest.raises(ValueError, match="stages must be"):
        frame_pairs(f, stages="loadin")
    # no stage control: every frame counts
    g = Frames.from_arrays(np.stack(pos), np.full(600, D / 2), controls={"axial_strain": eps})
    assert loading_frames(g) == list(range(7))
