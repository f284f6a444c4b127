"""Shear-stage summary figures of the triaxial scene (no engine): the headline peak stress ratio is
taken on running means (the same window as the smoothed σ3 stray), the instantaneous one is kept."""
from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from orchestrator.case import load_case
from orchestrator.clock import step_plan
from orchestrator.compare.report import run_checks
from orchestrator.derive import derive
from orchestrator.scenes.triaxial import peak_stress_ratio, running_mean, smoothing_rows, solid_fraction_profile


def test_smoothing_window():
    assert smoothing_rows(5) == 1
    assert smoothing_rows(55) == 5
    assert smoothing_rows(100) == 10
    assert smoothing_rows(5000) == 10
    # centred, every window full length (shifted inwards at the ends)
    np.testing.assert_allclose(running_mean(np.arange(5.0), 2), [0.5, 0.5, 1.5, 2.5, 3.5])
    np.testing.assert_allclose(running_mean(np.arange(5.0), 3), [1.0, 1.0, 2.0, 3.0, 3.0])
    np.testing.assert_allclose(running_mean(np.arange(3.0), 10), [1.0, 1.0, 1.0])


def test_one_running_mean_for_the_scene_summary_and_the_analysis():
    """The summary's smoothed figures and the triaxial analysis use one running mean
    (orchestrator.numerics): its extremes are those of every run of w consecutive rows, i.e. of the
    'valid' convolution the scene used before, so the scene's figures did not change."""
    rng = np.random.default_rng(3)
    for n, w in ((100, 10), (37, 5), (4, 10), (12, 1)):
        x = rng.standard_normal(n)
        valid = np.convolve(x, np.ones(w) / w, mode="valid") if n >= w else np.array([x.mean()])
        m = running_mean(x, w)
        assert len(m) == n
        np.testing.assert_allclose([m.max(), m.min()], [valid.max(), valid.min()], rtol=1e-12)


def test_peak_stress_ratio_ignores_a_single_noisy_row():
    rng = np.random.default_rng(0)
    n = 100
    s3 = 300e3 * (1 + 0.02 * rng.standard_normal(n))
    ratio = 1.0 + 1.2 * (1 - np.exp(-np.arange(n) / 20.0))        # rises smoothly to ~2.2
    s1 = ratio * 300e3
    s3[60] = 300e3 / 2.3                                           # one row: σ3 dips, σ1/σ3 -> ~5
    w = smoothing_rows(n)
    peak = peak_stress_ratio(s1, s3, w)
    assert peak["rows"] == 10
    assert peak["instantaneous"] > 4.5                             # the spike
    assert 2.1 < peak["smoothed"] < 2.45                           # the 10-row means' peak
    # by construction: the smoothed peak is the ratio of the 10-row means
    expect = np.max(running_mean(s1, w) / running_mean(s3, w))
    assert peak["smoothed"] == expect


def test_peak_stress_ratio_short_series():
    peak = peak_stress_ratio(np.array([2.0, 3.0]), np.array([1.0, 1.0]), smoothing_rows(2))
    assert peak["smoothed"] == 3.0 and peak["instantaneous"] == 3.0


def test_void_ratio_of_a_lattice_sample():
    """A simple cubic lattice of touching spheres (φ = π/6, e = 6/π - 1 = 0.910) in a cylinder:
    the interior void ratio is the lattice's; the boundary and hull ones include the voids along the
    lateral boundary and are larger; with no boundary voids (volume = the lattice's cells) they are exact."""
    from orchestrator.scenes.triaxial import hull_volume, void_ratios
    r, R, H = 1.0, 12.0, 30.0
    g = np.arange(-R, R + 1e-9, 2 * r)
    x, y, z = np.meshgrid(g, g, np.arange(r, H - r + 1e-9, 2 * r), indexing="ij")
    pos = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    pos = pos[np.hypot(pos[:, 0], pos[:, 1]) <= R - r]
    rad = np.full(len(pos), r)
    vs = float(np.sum(4 / 3 * np.pi * rad ** 3))
    vh = hull_volume(pos, rad, 0.0, H)
    e = void_ratios(pos, rad, vs, np.pi * R ** 2 * H, vh, 0.0, H, 2 * r)
    lattice = 6 / np.pi - 1
    assert abs(e["interior"] - lattice) < 0.05 * lattice, e
    assert e["hull"] > e["interior"] and e["boundary"] > e["hull"]
    cells = len(pos) * (2 * r) ** 3
    assert abs(void_ratios(pos, rad, vs, cells, cells, 0.0, H, 2 * r)["boundary"] - lattice) < 1e-12


def test_interior_void_ratio_of_a_clump_lattice_counts_overlapping_members_once():
    """A cubic lattice (cell L) of two-sphere clumps (radius a, centres d apart, overlapping): the
    interior solid fraction is the clumps' union volume over L³, V = 2·(4/3)πa³ - π(4a + d)(2a - d)²/12
    (the lens of two equal spheres), not the members' summed volume."""
    from orchestrator.scenes.triaxial import hull_volume, void_ratios
    a, d, L, R, H = 1.0, 1.0, 3.2, 16.0, 32.0
    g = np.arange(-R, R + 1e-9, L)
    x, y, z = np.meshgrid(g, g, np.arange(L / 2, H - L / 2 + 1e-9, L), indexing="ij")
    c = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    c = c[np.hypot(c[:, 0], c[:, 1]) <= R - L / 2]
    pos = np.concatenate([c - [d / 2, 0, 0], c + [d / 2, 0, 0]])
    rad = np.full(len(pos), a)
    union = 2 * 4 / 3 * np.pi * a ** 3 - np.pi * (4 * a + d) * (2 * a - d) ** 2 / 12
    vs = union * len(c)
    e = void_ratios(pos, rad, vs, np.pi * R ** 2 * H, hull_volume(pos, rad, 0.0, H), 0.0, H, 2 * a)
    phi = union / L ** 3
    assert abs(e["interior_solid_fraction"] - phi) < 0.03 * phi, (e, phi)
    assert e["interior_solid_fraction"] < 2 * 4 / 3 * np.pi * a ** 3 / L ** 3 * 0.9     # not the summed members


def test_slab_hull_follows_a_neck_the_convex_hull_bridges():
    """A lattice column of radius R0 with a waist of radius R1 < R0 over its middle third: the global
    convex hull fills the waist back to R0, the stacked-slab hull follows it. Both are compared with
    the same column without a waist, whose hulls agree (a straight column is convex)."""
    from orchestrator.scenes.triaxial import hull_volume, slab_hull_volume
    r, R0, R1, H = 0.5, 10.0, 6.0, 60.0
    g = np.arange(-R0, R0 + 1e-9, 2 * r)
    x, y, z = np.meshgrid(g, g, np.arange(r, H - r + 1e-9, 2 * r), indexing="ij")
    pos = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    rho = np.hypot(pos[:, 0], pos[:, 1])
    column = pos[rho <= R0 - r]
    waist = (pos[:, 2] > H / 3) & (pos[:, 2] < 2 * H / 3)
    necked = pos[(rho <= R0 - r) & (~waist | (rho <= R1 - r))]
    slab = 2 * (2 * r)                                   # two diameters, as the controls use
    straight = slab_hull_volume(column, np.full(len(column), r), 0.0, H, slab)
    assert abs(straight / hull_volume(column, np.full(len(column), r), 0.0, H) - 1) < 0.02
    v_slab = slab_hull_volume(necked, np.full(len(necked), r), 0.0, H, slab)
    v_hull = hull_volume(necked, np.full(len(necked), r), 0.0, H)
    # the waist's missing volume relative to the straight column: (R0² - R1²)/R0² over a third of H
    missing = (R0 ** 2 - R1 ** 2) / R0 ** 2 / 3
    assert abs((1 - v_slab / straight) - missing) < 0.03, (v_slab / straight, missing)
    assert v_hull / straight > 0.97                      # the convex hull bridges the waist


def test_slab_hull_of_one_sphere_converges_to_its_volume():
    """Thin slabs: each slab's widest section, √(a² - d²) outside the centre's slab, times its
    thickness sums to the sphere's volume from above; the 32-gon sections lose 0.64 %."""
    from orchestrator.scenes.triaxial import slab_hull_volume
    a = 1.0
    pos = np.array([[0.0, 0.0, 0.0], [1e-3, 0.0, 0.0], [0.0, 1e-3, 0.0]])   # a 2-D hull needs 3 sections
    v = slab_hull_volume(pos, np.full(3, a), -a, a, 2 * a / 400)
    assert abs(v / (4 / 3 * np.pi * a ** 3) - 1) < 0.01, v / (4 / 3 * np.pi * a ** 3)


def test_solid_fraction_profile_shows_a_crust_round_a_looser_core():
    """A simple cubic lattice of touching spheres (φ = π/6) in a cylinder reads flat across the rings
    (within 10 % of π/6: a regular grid on a regular lattice aliases a little, which a random packing
    does not); with every other sphere taken out of the core (radius < 12 r), the core's rings read
    half the crust's."""
    r, R, H = 1.0, 30.0, 14.0
    g = np.arange(-R, R + 1e-9, 2 * r)
    x, y, z = np.meshgrid(g, g, np.arange(r, H - r + 1e-9, 2 * r), indexing="ij")
    pos = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    pos = pos[np.hypot(pos[:, 0], pos[:, 1]) <= R - r]
    d50 = 2.1 * r                                   # a grid d50/6 apart, not commensurate with the lattice
    edges, full = solid_fraction_profile(pos, np.full(len(pos), r), 0.0, H, d50, rings=5)
    assert len(edges) == 6 and edges[-1] == pytest.approx(np.hypot(pos[:, 0], pos[:, 1]).max())
    assert np.all(np.abs(full - np.pi / 6) < 0.1 * np.pi / 6) and np.ptp(full) < 0.05 * full.mean(), full
    core = (np.hypot(pos[:, 0], pos[:, 1]) < 12 * r) & (np.rint((pos.sum(axis=1) - 1) / 2).astype(int) % 2 == 0)
    _, crust = solid_fraction_profile(pos[~core], np.full(int((~core).sum()), r), 0.0, H, d50, rings=5)
    assert np.allclose(crust[:2] / full[:2], 0.5, atol=0.03) and np.allclose(crust[3:], full[3:]), crust


def test_the_report_checks_a_triaxials_steps_against_its_plan_not_its_budget(tmp_path):
    """A triaxial ends stage 1 when it converges, so it takes fewer steps than its budget: the run
    report's check reads the plan (the fixed part and whole chunks; YADE's last step may be one
    past a chunk's end) and passes such a run, where it used to say FAIL for every triaxial that
    converged early (88 320 of 222 720 steps, LIGGGHTS smoke); a run that stopped inside a chunk,
    and a fixed-length scene short of its steps, still fail."""
    params = derive(load_case("cases/triaxial_smoke.yaml")).to_dict()
    plan = step_plan("triaxial", params["scene"])
    (tmp_path / "params.json").write_text(json.dumps(params, default=str))
    shutil.copy("cases/triaxial_smoke.yaml", tmp_path / "case.yaml")
    budget = params["scene"]["total_steps"]

    def status(steps_run, planned=budget):
        rows = run_checks(tmp_path, None, {"steps": planned, "steps_run": steps_run, "status": "complete"})
        return rows[rows.check.str.startswith("steps run")].status.item()
    for chunks, extra in ((8, 0), (5, 1), (plan.max_units, 0)):
        assert status(plan.fixed + chunks * plan.unit + extra) == "ok"
    assert status(plan.fixed + 5 * plan.unit + plan.unit // 2) == "FAIL"       # stopped inside a chunk
    assert status(plan.fixed - plan.unit) == "FAIL"                             # before its fixed part
    assert status(budget) == "ok"
    (tmp_path / "case.yaml").write_text("scene: {kind: shear_cell}\n")           # a fixed step count
    assert status(plan.fixed + 8 * plan.unit) == "FAIL"
