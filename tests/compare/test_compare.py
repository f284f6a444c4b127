"""compare / crossval / grain errors on real engine runs and a synthetic CT series."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from orchestrator.compare import MEASURES, compare
from orchestrator.compare.distances import ks, l2, rel_error

pytestmark = pytest.mark.engine
SCHEDULE_MINUTES = 4


def test_distances_basic():
    x = np.linspace(0, 1, 50)
    assert l2(x, np.sin(x) + 1, x, np.sin(x) + 1).value == 0
    d = l2(x, np.ones_like(x), x, 1.1 * np.ones_like(x))
    assert d.value == pytest.approx(0.1, rel=1e-9)
    rng = np.random.default_rng(0)
    a = rng.normal(size=2000)
    assert ks(a, a).value == 0
    assert ks(a, a + 1).value > 0.3
    assert rel_error(2.0, 2.5).value == pytest.approx(0.25)
    assert rel_error(0.0, 0.5).metric == "abs_diff"


def test_run_compared_with_itself_gives_zero(liggghts_run, tmp_path):
    cmp = compare(liggghts_run, liggghts_run, out_dir=tmp_path)
    t = cmp.table
    computed = [m for m, o in cmp.outcomes.items() if not o.skipped]
    assert not [o.error for o in cmp.outcomes.values() if o.error]
    # every measure the smoke shear cell supports produced distances, and all of them are 0
    assert set(computed) == set(MEASURES)
    d = t.distance.to_numpy(float)
    fin = np.isfinite(d)
    assert fin.sum() >= 40
    assert np.all(d[fin] == 0), t[fin & (d != 0)]
    # NaN distances only where a fit failed on both sides (the smoke cell has no resolvable band)
    assert set(t[~fin].measure) <= {"shearband"}
    g = cmp.grain.scalars
    assert g["identity"] == "ids" and g["grains_identified"] == 228
    assert g["max_median_error_d50"] == 0 and g["min_fraction_agree"] == 1
    assert (tmp_path / "comparison.csv").exists() and (tmp_path / "report.html").exists()


def test_crossval_smoke_produces_every_table_and_plot(crossval_smoke):
    cv = crossval_smoke
    cmp = cv.comparison
    out = cmp.out_dir
    # each engine's wall time
    wt = cv.wall_times
    assert set(wt.engine) == {"liggghts", "yade"}
    assert (wt.wall_time_total_s > 0).all() and (wt.engine_s > 0).all()
    assert (out / "wall_times.csv").exists()
    # every measure computed on both sides, with distances and an overlay plot
    for name in MEASURES:
        o = cmp.outcomes[name]
        assert o.error is None and o.skipped is None, (name, o.error, o.skipped)
        assert o.rows and o.overlay is not None
        if name == "macro":                 # wall series and controls: no analysis Result behind it
            continue
        assert o.result_a.plot() is not None and o.result_b.plot() is not None
        for tname in o.result_a.tables:
            assert (out / f"a_{name}_{tname}.csv").exists() and (out / f"b_{name}_{tname}.csv").exists()
    t = pd.read_csv(out / "comparison.csv")
    assert set(t.measure) == set(MEASURES)
    # the engines differ (chaotic divergence): distances and grain errors are not zero
    fin = t[np.isfinite(t.distance)]
    assert (fin.distance.abs() > 0).mean() > 0.8
    assert cmp.grain.scalars["identity"] == "ids"          # one particle table for both engines
    assert cmp.grain.scalars["max_median_error_d50"] > 0.01
    # substitutions noted beside the numbers they affect
    assert t.substitutions.fillna("").str.contains("seed000_damping").all()
    html = (out / "report.html").read_text()
    assert "wall time" in html.lower() and html.count("data:image/png;base64,") >= 3 * len(MEASURES) - 2
    assert "http://" not in html and "https://" not in html
    # in a notebook: one line each, and tables in HTML (a dataclass's repr printed every DataFrame)
    line = repr(cv)
    assert "\n" not in line and line.startswith("<CrossValidation shear_cell_smoke:")
    assert "<Comparison liggghts vs yade:" in line and f"{len(MEASURES)} of {len(MEASURES)} measures" in line
    page = cv._repr_html_()
    assert page.count("<table") == 2 and "largest |distance|" in page and "wall_time_total_s" in page


def test_crossval_on_three_engines_compares_the_first_with_each(crossval_smoke, runs_root, tmp_path):
    """Three engines: A (the first named) against each of the others, one directory a pair; the
    LIGGGHTS and YADE runs are crossval_smoke's, the LAMMPS run tests/test_lammps_shear_cell.py's."""
    from orchestrator.compare import crossval
    from tests.compare.conftest import SMOKE
    cv = crossval(SMOKE, runs_root=runs_root, out_dir=tmp_path, engines=["liggghts", "yade", "lammps"])
    assert list(cv.comparisons) == ["yade", "lammps"] and cv.comparison is cv.comparisons["yade"]
    assert list(cv.wall_times.engine) == ["liggghts", "yade", "lammps"]
    for b, cmp in cv.comparisons.items():
        out = tmp_path / f"liggghts_vs_{b}"
        assert cmp.out_dir == out and (out / "comparison.csv").exists() and (out / "report.html").exists()
        assert (cmp.alignment.a.label, cmp.alignment.b.label) == ("liggghts", b)
        # one particle table for every engine: grain by grain by id, all 228 grains
        assert cmp.grain.scalars["identity"] == "ids" and cmp.grain.scalars["grains_identified"] == 228
        assert cmp.grain.scalars["max_median_error_d50"] > 0          # different engines, chaotic divergence


def test_synthetic_ct_compares_back_with_near_zero_grain_error(liggghts_run, ct_frames, tmp_path):
    cmp = compare(liggghts_run, ct_frames, out_dir=tmp_path)
    al = cmp.alignment
    assert al.control == "angle" and len(al.states) == 5
    assert al.identity.method == "position"                 # CT ids are the tracker's, not the engine's
    assert al.identity.n >= 0.95 * 228
    g = cmp.grain
    s = g.tables["states"]
    # sub-voxel agreement: 3 um voxels, d50 = 30 um
    assert g.scalars["max_median_error_d50"] < 0.03, s
    assert g.scalars["max_p90_error_d50"] < 0.06, s
    assert g.scalars["min_fraction_agree"] >= 0.95, s
    # distributions of the kinematic measures agree too. Per 1-degree increment the grains move
    # only 0.2-1.3 um (median 0.5 um), close to the CT centroid error (0.08 voxel = 0.23 um), so the
    # per-increment KS measures the segmentation more than the comparison (0.09-0.15 measured):
    # it is reported, and checked loosely; the 0.15 check applies over the whole shear (0 -> 4 deg:
    # KS 0.076 measured)
    t = cmp.table
    ks_u = t[(t.measure == "displacements") & (t.metric == "KS")].distance
    assert len(ks_u) == 4 and ks_u.max() < 0.25, ks_u
    ends = compare(liggghts_run, ct_frames, out_dir=tmp_path / "ends", measures=["displacements"],
                   at=[al.states.value.iloc[0], al.states.value.iloc[-1]], html=False)
    ks_end = ends.table[(ends.table.measure == "displacements") & (ends.table.metric == "KS")].distance
    assert len(ks_end) == 1 and ks_end.max() < 0.15, ks_end
    assert cmp.outcomes["friction"].skipped and "no wall" in cmp.outcomes["friction"].skipped


def test_identity_falls_back_to_positions_and_rejects_far_grains(liggghts_run, ct_frames):
    from orchestrator.compare import align
    al = align(liggghts_run, ct_frames, max_distance=1e-9)     # a cut-off below the centroid error
    assert al.identity.n < 0.5 * 228


def test_simulation_from_scanned_packing(ct_frames, runs_root, tmp_path):
    from orchestrator.case import CaseError, load_case
    from orchestrator.frames import Frames, write_frames
    from orchestrator.runner import run_case
    SMOKE = Path(__file__).resolve().parents[2] / "cases" / "shear_cell_smoke.yaml"
    ct = Frames(ct_frames)
    present = np.isfinite(ct.position[0]).all(1)
    over = {"stability": {"monitors": False}, "name": "shear_cell_smoke_from_ct",
            "initial_packing": {"frames": str(ct_frames), "frame": 0}}
    out = run_case(load_case(SMOKE, overrides=over), "liggghts", runs_root=runs_root, progress=False)
    assert out.status == "complete"
    fr = out.frames
    # the run starts from exactly the scanned grains (ids shifted by +1: LIGGGHTS ids are positive)
    assert fr.n_particles == present.sum()
    rows = [fr.row(i + 1) for i in ct.ids[present]]
    np.testing.assert_allclose(fr.position[0][rows], ct.position[0][present], rtol=0, atol=1e-15)
    np.testing.assert_allclose(fr.radius[rows], ct.radius[present], rtol=1e-15)
    assert out.summary["wall_time"]["engine"] > 0
    # and compares with the scans grain by grain
    cmp = compare(ct_frames, out.run_dir, out_dir=tmp_path / "cmp")
    assert cmp.alignment.identity.method == "ids (initial packing)"
    assert cmp.grain is not None and cmp.alignment.identity.n == present.sum()
    assert np.isfinite(cmp.grain.tables["states"].median_error_d50).all()
    # a packing outside the cell is refused before the engine starts, naming the wall
    bad = tmp_path / "outside.h5"
    write_frames(bad, ct.ids, ct.radius, ct.time[:1], ct.position[:1] + np.array([1e-4, 0, 0]))
    over_bad = dict(over, name="shear_cell_smoke_bad_packing", initial_packing={"frames": str(bad)})
    with pytest.raises(CaseError, match="sidewall"):
        run_case(load_case(SMOKE, overrides=over_bad), "liggghts", runs_root=runs_root, progress=False)
