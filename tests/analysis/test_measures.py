"""Profiles, friction, displacements, stress volatility, fabric and force chains."""
import numpy as np
import pytest

from orchestrator.analysis.displacements import analyze_displacements
from orchestrator.analysis.fabric import anisotropy, fabric_tensor, rose, analyze_fabric
from orchestrator.analysis.forcechains import force_chains, analyze_forcechains
from orchestrator.analysis.friction import analyze_friction, mu_macro
from orchestrator.analysis.profiles import density_profile, analyze_profiles
from orchestrator.analysis.stress import (deviatoric_q, love_weber_stress, volatility, analyze_stress)
from orchestrator.frames import Frames, write_frames

D = 30e-6


def test_volume_fraction_and_number_density_of_a_lattice():
    # simple cubic lattice of touching spheres: phi = pi/6, n = 1/D^3 in the interior
    g = np.arange(-10, 11)
    p = np.stack(np.meshgrid(g, g, np.arange(20), indexing="ij"), -1).reshape(-1, 3) * D
    r = np.full(len(p), 0.5 * D)
    prof = density_profile(p, r, np.array([0, 6 * D]), np.array([4.5, 9.5, 14.5]) * D, samples=256)
    assert prof["phi"] == pytest.approx(np.pi / 6, rel=0.03)
    assert prof["n"] == pytest.approx(1 / D ** 3, rel=0.05)
    # a single sphere cut by a bin boundary is shared between the bins, total volume conserved
    one = density_profile(np.zeros((1, 3)), np.array([D]), np.array([0, 2 * D]), np.array([-2, 0, 2]) * D, samples=512)
    tot = (one["phi"] * one["volume"]).sum()
    assert tot == pytest.approx(4 / 3 * np.pi * D ** 3, rel=1e-9)
    assert one["phi"][0, 0] == pytest.approx(one["phi"][0, 1], rel=0.05)


def test_analyze_profiles_shear_cell(shear_cell):
    res = analyze_profiles(shear_cell, z_ref=0.0, radial_z_range=(0, 7 * D), bins_z=10, bins_r=5)
    ax = res.tables["axial"]
    assert set(ax["frame"]) == {0, 5}
    n_tot = (ax.query("frame == 5")["count"]).sum()
    assert n_tot == np.isfinite(shear_cell.position[5]).all(1).sum()
    assert (res.tables["radial"]["phi"] < 0.74).all()


def test_profiles_default_range_covers_every_selected_frame(tmp_path):
    # a sample lifted by far more than its height between the first and the last frame (the shear
    # cell's piston lifts the loose packing by ~0.5 mm): both frames must be counted in full
    rng = np.random.default_rng(3)
    p0 = rng.uniform(0, 20 * D, (300, 3))
    p1 = p0 * [1, 1, 0.5] + [0, 0, 40 * D]
    path = tmp_path / "frames.h5"
    write_frames(path, np.arange(300), np.full(300, 0.5 * D), [0.0, 1.0], np.stack([p0, p1]))
    ax = analyze_profiles(Frames(path), bins_z=20).tables["axial"]
    assert ax.query("frame == 0")["count"].sum() == 300
    assert ax.query("frame == 1")["count"].sum() == 300


def test_radial_profile_default_slab_is_each_frames_filled_height(tmp_path):
    """A frame compacted into half the height it filled before: its radial φ(r) is averaged over
    its own filled height, not the union with the looser frame's (which diluted the default
    case's φ(r) to ~0.15 against ~0.55 in the sheared sample)."""
    a = 2 * (0.5 * D)                               # simple cubic lattice of touching spheres
    g = np.arange(12) * a
    X, Y, Z = np.meshgrid(g, g, g, indexing="ij")
    p0 = np.c_[X.ravel(), Y.ravel(), Z.ravel()]
    keep = np.hypot(p0[:, 0] - g.mean(), p0[:, 1] - g.mean()) < 5 * a
    p0 = p0[keep]
    p1 = p0 * [1, 1, 0.5] + [0, 0, 40 * D]         # overlapping spheres: twice the density
    path = tmp_path / "frames.h5"
    n = len(p0)
    write_frames(path, np.arange(n), np.full(n, 0.5 * D), [0.0, 1.0], np.stack([p0, p1]))
    res = analyze_profiles(Frames(path), center=(g.mean(), g.mean()), r_max=4 * a, bins_r=4, samples=256)
    rad = res.tables["radial"]
    phi0 = rad.query("frame == 0")["phi"].to_numpy()
    phi1 = rad.query("frame == 1")["phi"].to_numpy()
    # the bulk of a simple cubic packing: π/6, less the half-empty top and bottom layers' share
    assert phi0.mean() == pytest.approx(np.pi / 6, rel=0.1)
    assert phi1.mean() == pytest.approx(2 * phi0.mean(), rel=0.1)


def test_mu_macro_disc_formula(shear_cell):
    assert mu_macro(3.0, 2.0, 0.5) == pytest.approx(1.5 * 3 / (0.5 * 2))
    assert mu_macro(-3.0, 2.0, 0.5, "ring") == pytest.approx(3.0)
    res = analyze_friction(shear_cell, radius=1e-3, torque_wall="top", force_wall="bottom")
    assert res.scalars["mu_mean"] == pytest.approx(1.5 * 2e-6 / (1e-3 * 1e-2))
    with pytest.raises(KeyError, match="no wall"):
        analyze_friction(shear_cell, torque_wall="nope")


def test_displacements(shear_cell):
    res = analyze_displacements(shear_cell, pairs=[[0, 5]])
    t = res.tables["particles"]
    assert len(t) == np.isfinite(shear_cell.position[[0, 5]]).all(-1).all(0).sum()
    u = shear_cell.position[5] - shear_cell.position[0]
    row = shear_cell.row(t["id"].iloc[0])
    assert t["u"].iloc[0] == pytest.approx(np.linalg.norm(u[row]))
    assert res.tables["pdf"]["pdf"].sum() > 0


def test_q_and_volatility_formulas():
    s = np.zeros((3, 3))
    s[0, 1] = s[1, 0] = 2.0
    assert deviatoric_q(s) == pytest.approx(2.0)          # sqrt(1/2 * 2 * 2^2)
    assert deviatoric_q(7.0 * np.eye(3)) == pytest.approx(0.0)
    q = np.array([[1.0, 2.0], [2.0, 2.0], [1.0, 2.0], [2.0, 2.0]])   # returns ln2, -ln2, ln2 ; 0, 0, 0
    V = volatility(q)
    assert V[0] == pytest.approx(np.std([np.log(2), -np.log(2), np.log(2)], ddof=1))
    assert V[1] == 0.0


def test_love_weber_two_spheres_pressed_together():
    p = np.array([[0, 0, 0], [D, 0, 0]], float)
    r = np.full(2, 0.5 * D)
    f = np.array([[-1.0, 0, 0]])                           # compressive force on particle 0
    s = love_weber_stress(p, r, np.array([0]), np.array([1]), np.array([[0.5 * D, 0, 0]]), f)
    V = 4 / 3 * np.pi * (0.5 * D) ** 3
    assert s[0, 0, 0] == pytest.approx(-0.5 * D / V)        # compression negative
    np.testing.assert_allclose(s[0], s[1])


def test_stress_volatility_correlates_with_d2min(tmp_path):
    rng = np.random.default_rng(0)
    n, T = 1500, 8
    p0 = rng.uniform(0, 12 * D, (n, 3))
    act = rng.uniform(0, 1, n)                              # activity drives both measures
    pos = np.stack([p0 + (k / (T - 1)) * act[:, None] * rng.normal(scale=0.05 * D, size=(n, 3)) for k in range(T)])
    q = np.exp(np.cumsum(rng.normal(size=(T, n)) * (0.05 + act), axis=0)) * 1e3
    stress = np.zeros((T, n, 3, 3))
    stress[..., 0, 1] = stress[..., 1, 0] = q
    fr = Frames(write_frames(tmp_path / "f.h5", np.arange(n), np.full(n, 0.5 * D), np.arange(T), pos,
                             controls={"axial_strain": 0.0025 * np.arange(T)}, stress=stress))
    res = analyze_stress(fr, window=(0.0, 0.0175), interval=0.0025)
    assert res.scalars["n_states"] == T
    assert res.scalars["pearson_r"] > 0.3 and res.scalars["pearson_p"] < 1e-6
    v = res.tables["volatility"].set_index("id")["V"]
    assert v.loc[0] == pytest.approx(np.std(np.diff(np.log(q[:, 0])), ddof=1))


def test_fabric_tensor_and_rose():
    rng = np.random.default_rng(0)
    iso = rng.normal(size=(200000, 3))
    phi = fabric_tensor(iso)
    assert np.trace(phi) == pytest.approx(1)
    assert anisotropy(phi)[1] < 0.05
    up = np.tile([0, 0, 1.0], (10, 1))
    assert anisotropy(fabric_tensor(up))[1] == pytest.approx(7.5)
    r = rose(up, "xz", 4)
    # psi = 90 deg (bin 1) and 270 deg (bin 3)
    np.testing.assert_allclose(r["fraction"], [0, 0.5, 0, 0.5])
    r = rose(up, "xz", 4, values=np.full(10, 2.0))
    assert r["mean"].iloc[1] == 2.0


def test_analyze_fabric_and_forcechains(shear_cell):
    res = analyze_fabric(shear_cell)
    t = res.tables["tensor"]
    assert {"a_c", "a_n", "phi_zz"} <= set(t.columns)
    # the synthetic forces favour vertical contacts: force anisotropy is positive
    assert (t["a_n"] > 0.1).all()
    fc = analyze_forcechains(shear_cell)
    assert {"chains", "links", "summary"} <= set(fc.tables)


def test_force_chain_detects_a_loaded_column():
    # a vertical column of 6 particles under vertical compression, among unstressed neighbours
    col = np.c_[np.zeros(6), np.zeros(6), np.arange(6)] * D
    side = np.c_[np.full(6, D), np.zeros(6), np.arange(6)] * D
    p = np.concatenate([col, side])
    stress = np.zeros((12, 3, 3))
    stress[:6, 2, 2] = -1e4
    stress[6:, 0, 0] = -1e2
    i = np.r_[np.arange(5), np.arange(5) + 6, np.arange(6)]
    j = np.r_[np.arange(5) + 1, np.arange(5) + 7, np.arange(6) + 6]
    out = force_chains(p, stress, i, j)
    assert (out["labels"][:6] == 0).all() and (out["labels"][6:] == -1).all()
    assert out["links"][:5].all() and not out["links"][5:].any()


def test_stress_reads_the_loading_stage_and_its_window(tmp_path):
    """Two isotropic frames (stage 1, ε_a < 0) before eight loading frames: the default and a
    window both start at the loading's reference state (ε_a = 0), ``stages="all"`` adds them."""
    rng = np.random.default_rng(1)
    n, T = 400, 10
    p0 = rng.uniform(0, 10 * D, (n, 3))
    pos = np.stack([p0 + rng.normal(scale=0.01 * D, size=(n, 3)) for _ in range(T)])
    q = np.exp(np.cumsum(rng.normal(size=(T, n)) * 0.1, axis=0)) * 1e3
    stress = np.zeros((T, n, 3, 3))
    stress[..., 0, 1] = stress[..., 1, 0] = q
    eps = 0.0025 * (np.arange(T) - 2.0)
    stage = np.where(np.arange(T) < 3, 1.0, 2.0)           # frame 2 (ε_a = 0) ends stage 1
    fr = Frames.from_arrays(pos, np.full(n, 0.5 * D), controls={"axial_strain": eps, "stage": stage},
                            stress=stress)
    assert analyze_stress(fr).scalars["frame_first"] == 2
    assert analyze_stress(fr, stages="all").scalars["frame_first"] == 0
    r = analyze_stress(fr, window=(0.005, 0.0175), interval=0.005)
    assert (r.scalars["frame_first"], r.scalars["frame_last"], r.scalars["n_states"]) == (4, 8, 3)     # ε_a 0.5, 1.0, 1.5 %
