"""The analysis API of issue 17: array functions by name, Frames from arrays, the D²min interior
option and the fixed-cutoff coordination."""
import numpy as np
import pytest

from orchestrator.analysis import analyze_coordination, analyze_d2min, d2min, neighbor_counts, rdf
from orchestrator.frames import Frames

D = 1e-3


def _lattice(m=8):
    g = np.arange(m) * D
    return np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)


def test_array_functions_are_importable_by_name():
    assert callable(d2min) and callable(rdf) and callable(neighbor_counts)


def test_frames_from_arrays_runs_the_analyses_without_a_file():
    p0 = _lattice()
    F = np.array([[1.01, 0.002, 0], [0, 0.99, 0], [0, 0, 1.0]])
    fr = Frames.from_arrays(np.stack([p0, p0 @ F.T]), 0.5 * D, controls={"axial_strain": [0.0, 0.01]})
    assert fr.n_frames == 2 and fr.n_particles == len(p0) and fr.contact_frames == []
    res = analyze_d2min(fr, cutoff=1.5 * D)
    pt = res.tables["particles"]
    # a homogeneous deformation is affine everywhere: D²min 0, Λ = F
    assert np.nanmax(pt["d2min"]) < 1e-24
    assert pt["F_xx"].dropna().to_numpy() == pytest.approx(1.01)
    with pytest.raises(ValueError, match="position must be"):
        Frames.from_arrays(np.zeros((2, 5)), 1.0)
    with pytest.raises(ValueError, match="unknown per-particle fields"):
        Frames.from_arrays(p0, 0.5 * D, speed=np.zeros((1, len(p0))))


def test_d2min_wall_distance_keeps_the_interior_only():
    p0 = _lattice()
    rng = np.random.default_rng(0)
    p1 = p0 + 0.01 * D * rng.normal(size=p0.shape)
    full = d2min(p0, p1, 1.5 * D)
    inner = d2min(p0, p1, 1.5 * D, wall_distance=1.5 * D)
    dist = np.min(np.minimum(p0 - p0.min(0), p0.max(0) - p0), axis=1)
    keep = dist >= 1.5 * D
    assert np.isnan(inner["d2min"][~keep]).all()
    # interior values are unchanged: wall particles still serve as neighbours
    np.testing.assert_array_equal(inner["d2min"][keep], full["d2min"][keep])
    assert np.isfinite(inner["d2min"][keep]).all()


def test_coordination_with_a_fixed_cutoff_counts_lattice_neighbours():
    p0 = _lattice()
    fr = Frames.from_arrays(p0, 0.4 * D)
    res = analyze_coordination(fr, cutoff=1.05 * D, wall_distance=1.5 * D)
    assert res.tables["summary"]["source"].iloc[0] == "cutoff"
    assert set(res.tables["particles"]["z"]) == {6.0}              # simple cubic: 6 face neighbours
    assert neighbor_counts(p0, 1.05 * D).max() == 6
    with pytest.raises(ValueError, match="source 'cutoff'"):
        analyze_coordination(fr, cutoff=1.05 * D, source="geometry")
