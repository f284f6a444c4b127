import numpy as np
import pytest

from orchestrator.analysis.clusters import (cluster_properties, find_clusters, fractal_dimension, powerlaw_fit,
                                            analyze_clusters)
from orchestrator.analysis.d2min import analyze_d2min
from orchestrator.analysis._fits import log_binned

D = 1e-4


def _shapes(kind, sizes, spacing=D):
    """Separated clusters: straight lines (d_f = 1), square plates (d_f = 2), cubes (d_f = 3)."""
    pts, offset = [], 0.0
    for s in sizes:
        if kind == "line":
            q = np.c_[np.arange(s), np.zeros(s), np.zeros(s)] * spacing
        elif kind == "plane":
            g = np.arange(s)
            q = np.stack(np.meshgrid(g, g, [0], indexing="ij"), -1).reshape(-1, 3) * spacing
        else:
            g = np.arange(s)
            q = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3) * spacing
        q = q + [0, 0, offset]
        offset += (np.ptp(q[:, 2]) if len(q) else 0) + 10 * spacing
        pts.append(q)
    return np.concatenate(pts)


@pytest.mark.parametrize("kind,df,sizes", [("line", 1, [8, 12, 20, 30, 50, 80, 120]),
                                           ("plane", 2, [4, 6, 8, 11, 15, 20]),
                                           ("cube", 3, [6, 8, 10, 12, 14, 16])])
def test_fractal_dimension_of_known_shapes(kind, df, sizes):
    p = _shapes(kind, sizes)
    # random polydisperse volumes: R_g is volume weighted (eq. 13) but the shapes stay d_f-dimensional
    rng = np.random.default_rng(0)
    vol = rng.uniform(0.8, 1.2, len(p)) * D ** 3
    lab = find_clusters(p, np.ones(len(p), bool), 1.05 * D)
    cp = cluster_properties(p, vol, lab)
    assert len(cp) == len(sizes)
    f = fractal_dimension(cp["size"], cp["rg"], s_min=3)
    assert f["d_f"] == pytest.approx(df, abs=0.12)
    assert f["d_f_err"] < 0.2


def test_radius_of_gyration_is_volume_weighted():
    p = np.array([[0, 0, 0], [1, 0, 0]], float) * D
    lab = find_clusters(p, np.ones(2, bool), 1.5 * D)
    cp = cluster_properties(p, np.array([3.0, 1.0]), lab)
    # centre at x = 0.25 D; Rg^2 = (3 * 0.25^2 + 1 * 0.75^2) / 4 D^2
    assert cp["rg"].iloc[0] == pytest.approx(np.sqrt((3 * 0.0625 + 0.5625) / 4) * D)
    assert cp["x"].iloc[0] == pytest.approx(0.25 * D)


def test_powerlaw_mle_recovers_exponent():
    rng = np.random.default_rng(3)
    tau = 2.2
    support = np.arange(3, 200_001)
    pmf = support ** -tau
    s = rng.choice(support, size=5000, p=pmf / pmf.sum())
    f = powerlaw_fit(s, s_min=3)
    assert abs(f["tau"] - tau) < max(4 * f["tau_err"], 0.05)
    assert 0 < f["tau_err"] < 0.05


def test_unselected_and_absent_particles_are_not_clustered():
    p = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [np.nan] * 3], float) * D
    lab = find_clusters(p, np.array([True, False, True, True]), 1.5 * D)
    assert lab[1] == -1 and lab[3] == -1
    assert lab[0] != lab[2]           # the middle particle is not selected: the line is cut


def test_analyze_clusters_end_to_end(shear_cell):
    d = analyze_d2min(shear_cell, pairs=[[0, 5]])
    res = analyze_clusters(shear_cell, d2min_result=d, top_fraction=0.1)
    t = res.tables["particles"]
    n_valid = np.isfinite(d.tables["particles"]["d2min"]).sum()
    assert abs(len(t) - 0.1 * n_valid) <= 2
    assert res.tables["clusters"]["size"].sum() == len(t)
    assert res.tables["size_distribution"]["p"].sum() == pytest.approx(1)


def test_log_binned_points_follow_the_power_law_where_the_per_size_tail_is_flat():
    """P(s) ∝ s^-2 sampled as counts: beyond a few hundred clusters every large size is seen once or
    not at all, so the per-size histogram's tail is flat at 1/N; averaged over logarithmic bins the
    points follow s^-2 (Clauset, Shalizi & Newman 2009, fig. 1), as the plot shows them."""
    s = np.arange(1, 2001, dtype=float)
    exact = s ** -2.0 / np.sum(s ** -2.0)
    c, d = log_binned(s, exact)
    assert np.all(np.abs(d / (c ** -2.0 / np.sum(s ** -2.0)) - 1) < 0.2), d
    rng = np.random.default_rng(1)
    sizes = rng.choice(s, size=600, p=exact)
    seen, counts = np.unique(sizes, return_counts=True)
    p = counts / counts.sum()
    tail = seen >= 20
    assert np.all(p[tail] <= 2 / counts.sum())                       # the floor: seen once or twice
    c, d = log_binned(seen, p)
    slope = np.polyfit(np.log(c[c >= 2]), np.log(d[c >= 2]), 1)[0]
    assert -2.5 < slope < -1.5, slope
