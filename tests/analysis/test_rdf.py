import numpy as np
import pytest

from orchestrator.analysis.containers import Box, Cylinder, infer_container
from orchestrator.analysis.rdf import rdf, pair_counts


def _uniform_cylinder(n, R, H, rng):
    u = rng.uniform(size=n)
    th = rng.uniform(0, 2 * np.pi, n)
    return np.c_[R * np.sqrt(u) * np.cos(th), R * np.sqrt(u) * np.sin(th), rng.uniform(0, H, n)]


def test_uniform_sample_in_cylinder_has_g_equal_one_with_edge_correction():
    """Mean g(r) over independent uniform samples is 1 within its standard error (taken from
    the spread between samples, which includes the correlated large-scale fluctuations the
    per-bin counting error g_err leaves out); the uncorrected estimator is far below 1."""
    rng = np.random.default_rng(11)
    R, H = 1e-3, 2e-3
    cyl = Cylinder([0, 0], R, 0, H)
    gs, g0s = [], []
    for _ in range(8):
        p = _uniform_cylinder(4000, R, H, rng)
        gs.append(rdf(p, 0.4 * R, 12, cyl)["g"].to_numpy())
        g0s.append(rdf(p, 0.4 * R, 12, cyl, edge_correction=False)["g"].to_numpy())
    gs, g0s = np.array(gs), np.array(g0s)
    sem = gs.std(axis=0, ddof=1) / np.sqrt(len(gs))
    assert np.all(np.abs(gs.mean(0) - 1) < 4 * sem), (gs.mean(0), sem)
    assert np.all(sem < 0.02)
    # without the correction: many standard errors below 1 at the largest r (the test can fail)
    assert (1 - g0s.mean(0)[-1]) > 20 * sem[-1]
    assert g0s.mean(0)[-1] < 0.85


def test_single_sample_counting_error_is_sane():
    rng = np.random.default_rng(5)
    L = np.array([1.0, 2.0, 1.5]) * 1e-3
    p = rng.uniform(size=(6000, 3)) * L
    g = rdf(p, 0.2e-3, 10, Box([0, 0, 0], L))
    z = (g["g"] - 1) / g["g_err"]
    assert np.all(np.abs(z) < 5)


def test_inferred_container():
    rng = np.random.default_rng(12)
    p = rng.uniform(size=(3000, 3))
    assert isinstance(infer_container(p), Box)
    assert isinstance(infer_container(_uniform_cylinder(3000, 1.0, 1.0, rng)), Cylinder)


@pytest.mark.parametrize("box", [Box([0, 0, 0], [1.0, 2.0, 3.0]), Cylinder([0.1, -0.2], 1.0, 0.0, 2.0)])
def test_set_covariance_matches_monte_carlo(box):
    rng = np.random.default_rng(0)
    M = 400_000
    if isinstance(box, Box):
        x = box.lo + rng.uniform(size=(M, 3)) * (box.hi - box.lo)
    else:
        x = _uniform_cylinder(M, box.radius, box.height, rng) + [box.center[0], box.center[1], box.zmin]
    v = rng.normal(size=(M, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    for r in (0.0, 0.4, 1.1):
        f = box.contains(x + r * v)
        mc = box.volume * f.mean()
        err = box.volume * f.std() / np.sqrt(M)
        assert abs(box.set_covariance(r)[0] - mc) < 4 * err + 1e-12


def test_pair_counts_are_exact_and_ignore_nan():
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 2.5, 0], [np.nan, 0, 0]], float)
    c = pair_counts(p, np.array([0.0, 0.5, 1.5, 2.6, 3.0]))
    # ordered pairs: d=1 (x2), d=2.5 (x2), d=sqrt(7.25)=2.69 (x2)
    np.testing.assert_array_equal(c, [0, 2, 2, 2])


def test_fcc_first_peak_position():
    a = 1.0
    base = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]])
    g = np.arange(6)
    cells = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    p = (cells[:, None, :] + base[None]).reshape(-1, 3) * a
    df = rdf(p, 1.2, 60)
    assert df["r"].iloc[df["g"].idxmax()] == pytest.approx(a / np.sqrt(2), abs=0.02)


def test_g_is_undefined_beyond_the_container_not_infinite():
    """Where the container's set covariance is 0 (a pair distance longer than any chord of it) no
    pair is expected: g and g_err are NaN there, not the inf of a count over zero, and finite
    wherever a pair is expected. The corners of a unit cube are √3 apart, the longest chord."""
    L = 1e-3
    corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float) * L
    g = rdf(corners, 2.0 * L, 20, Box([0, 0, 0], [L, L, L]), r_min=0.0)
    beyond = g["r_lo"] >= np.sqrt(3) * L
    assert beyond.any() and g.loc[beyond, ["g", "g_err"]].isna().all().all()
    assert not np.isinf(g[["g", "g_err"]].to_numpy()).any()
    assert np.isfinite(g.loc[g["r_hi"] <= 1.7 * L, "g"]).all()
