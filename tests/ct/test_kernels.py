"""The compiled volume passes of the segmentation (orchestrator/ct/_kernels.py) against scipy, and the
compiled rendering (orchestrator/ct/_render.py) and ray casting against their NumPy references."""
import numpy as np
import pytest
from scipy import ndimage
from scipy.spatial.transform import Rotation as Rot

from orchestrator.ct import shape, synth
from orchestrator.ct._kernels import edt
from orchestrator.ct.segment import distance_map


@pytest.mark.parametrize("shape,p", [((40, 50, 60), 0.9), ((64, 48, 32), 0.995), ((5, 7, 3), 0.5), ((1, 9, 1), 0.7)])
def test_edt_equals_scipy(shape, p):
    rng = np.random.default_rng(3)
    b = rng.random(shape) < p
    b.flat[0] = False                                    # at least one zero voxel
    want = ndimage.distance_transform_edt(b).astype(np.float32)
    assert np.array_equal(edt(b), want)
    assert np.array_equal(distance_map(b), want)


def test_edt_of_a_ball_and_of_integer_input():
    z, y, x = np.ogrid[-20:21, -20:21, -20:21]
    ball = (z * z + y * y + x * x) <= 15 ** 2
    d = edt(ball.astype(np.int32))
    want = ndimage.distance_transform_edt(ball).astype(np.float32)
    assert np.array_equal(d, want)
    assert d[20, 20, 20] == pytest.approx(np.sqrt(226.0))  # nearest pore voxel: offset (15, 1, 0)
    assert (d[~ball] == 0).all()


def _labels(shape=(30, 34, 38), seed=5):
    """Random blobs: labelled, with background between them."""
    rng = np.random.default_rng(seed)
    c = rng.uniform(0, 1, (25, 3)) * np.array(shape)
    r = rng.uniform(3, 7, 25)
    g = np.stack(np.meshgrid(*[np.arange(s) for s in shape], indexing="ij"), -1).astype(float)
    lab = np.zeros(shape, np.int32)
    for k in range(25):
        lab[((g - c[k]) ** 2).sum(-1) < r[k] ** 2] = k + 1
    return lab


def test_grow_labels_equals_the_maximum_filter_shells():
    from orchestrator.ct.segment import grow_labels
    lab = _labels()
    for distance in (1.0, 1.5, 2.0):
        k = int(np.floor(distance))
        g = np.mgrid[-k:k + 1, -k:k + 1, -k:k + 1]
        d2 = (g ** 2).sum(0)
        want = lab.copy()
        for r2 in np.unique(d2[(d2 > 0) & (d2 <= distance ** 2)]):
            grown = ndimage.maximum_filter(lab, footprint=d2 == r2, mode="constant", cval=0)
            fill = (want == 0) & (grown > 0)
            want[fill] = grown[fill]
        assert np.array_equal(grow_labels(lab, distance), want)


def test_region_sums_and_label_stats_equal_scipy():
    from orchestrator.ct._kernels import label_stats, region_sums
    lab = _labels()
    rng = np.random.default_rng(1)
    raw = rng.normal(0.5, 0.4, lab.shape).astype(np.float32)
    n = int(lab.max())
    idx = np.arange(1, n + 1)
    s = region_sums(lab, raw, 0.1, 0.9, n)[1:]
    w = np.clip((raw - np.float32(0.1)) / np.float32(0.9 - 0.1), 0, 1)
    assert np.array_equal(s[:, 0], ndimage.sum_labels(w, lab, idx))
    com = np.array(ndimage.center_of_mass(w, lab, idx))
    assert np.allclose(s[:, 1:] / s[:, :1], com, rtol=0, atol=1e-12)
    dist = rng.random(lab.shape).astype(np.float32)
    cnt, box, peak = label_stats(lab, dist, n)
    assert np.array_equal(cnt[1:], np.bincount(lab.ravel(), minlength=n + 1)[1:])
    for k, sl in enumerate(ndimage.find_objects(lab, max_label=n), start=1):
        assert list(box[k]) == ([q.start for q in sl] + [q.stop for q in sl] if sl else [0] * 6)
    assert np.array_equal(peak[1:], ndimage.maximum(dist, lab, idx).astype(np.float32))


def test_hull_candidates_hold_every_hull_vertex():
    from scipy.spatial import ConvexHull
    from orchestrator.ct._kernels import extreme_candidates
    lab = _labels()
    cand = extreme_candidates(lab)
    for k in range(1, int(lab.max()) + 1):
        pts = np.argwhere(lab == k)
        if len(pts) < 20 or len(np.unique(pts[:, 0])) < 2:
            continue
        h = ConvexHull(pts)
        assert cand[tuple(pts[h.vertices].T)].all()
        assert cand[lab == k].sum() < len(pts)              # and it does drop interior points


def test_basin_saddles_equal_the_face_pair_reduction():
    from orchestrator.ct._kernels import basin_saddles
    from orchestrator.ct.segment import face_pairs
    lab = _labels()
    h = np.random.default_rng(2).random(lab.shape).astype(np.float32)
    keys, sad, base = basin_saddles(lab, h)
    got = {}
    for k, s in zip(keys.tolist(), sad.tolist()):
        got[k] = max(got.get(k, -1.0), s)
    la, lb, ia, ib, _ = face_pairs(lab, connectivity=3)
    want = {}
    for a, b, s in zip(np.minimum(la, lb).tolist(), np.maximum(la, lb).tolist(),
                       np.minimum(h.ravel()[ia], h.ravel()[ib]).tolist()):
        want[a * base + b] = max(want.get(a * base + b, -1.0), s)
    assert got == want and len(got) > 20


def test_label_sizes_and_table_mask():
    from orchestrator.ct._kernels import label_sizes, table_mask
    lab = _labels()
    n = int(lab.max())
    assert np.array_equal(label_sizes(lab, n), np.bincount(lab.ravel(), minlength=n + 1))
    table = np.random.default_rng(0).random(n + 1) < 0.5
    base = np.random.default_rng(1).random(lab.shape) < 0.2
    assert np.array_equal(table_mask(lab, table, base), base | table[lab])
    assert np.array_equal(table_mask(lab, table, np.empty(0, bool)), table[lab])


def _grain_boxes():
    """A solid and a hollow sphere, an irregular SH grain unrotated and rotated, off the voxel grid,
    one of them cut by the volume's face (voxel size 1e-5 m)."""
    vs = 1e-5
    rad = synth._GridRadial(synth.random_sh_grains(1, 6 * vs, seed=4)[0], 15)
    R = Rot.random(random_state=3).as_matrix()
    return vs, [synth.Grain(np.array([12.3, 11.7, 12.9]) * vs, 7.2 * vs),
                synth.Grain(np.array([11.6, 12.4, 1.5]) * vs, 6.4 * vs, hollow=0.5),
                synth.Grain(np.array([12.1, 12.8, 11.4]) * vs, rad.rmax, rad),
                synth.Grain(np.array([12.1, 12.8, 11.4]) * vs, rad.rmax, rad, R, hollow=0.4)]


@pytest.mark.parametrize("supersample", [3, 4])
def test_compiled_coverage_equals_the_numpy_reference(supersample):
    vs, grains = _grain_boxes()
    offs = synth._offsets(supersample)
    for g in grains:
        vol = np.zeros((26, 26, 26), np.float32)
        vol[::3] = 0.37                                   # earlier grains: combined by the maximum
        c = np.asarray(g.centre)[::-1] / vs
        lo = np.maximum(np.floor(c - g.rmax / vs - 2).astype(int), 0)
        hi = np.minimum(np.ceil(c + g.rmax / vs + 2).astype(int) + 1, vol.shape)
        zz, yy, xx = np.meshgrid(*[np.arange(a, b) for a, b in zip(lo, hi)], indexing="ij")
        p = np.stack([zz, yy, xx], -1).reshape(-1, 3).astype(float) - c
        want = vol.copy()
        sub = want[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
        np.maximum(sub, synth._coverage(p, g, vs, offs).reshape(sub.shape).astype(np.float32), out=sub)
        synth._coverage_compiled(vol[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]], lo, c, g, vs, offs)
        assert 0 < (vol > 0.37).sum() and ((vol > 0) & (vol < 1)).any()
        assert np.array_equal(vol, want)


def test_compiled_ray_profile_equals_map_coordinates():
    rng = np.random.default_rng(6)
    z, y, x = np.ogrid[:17, :15, :19]
    field = np.clip(1.2 - np.sqrt((z - 8.2) ** 2 + (y - 7.1) ** 2 + (x - 9.3) ** 2) / 6, 0, 1)
    field = (field + 0.2 * rng.random(field.shape)).astype(np.float32)
    u, _, _ = shape.fibonacci_directions(600)
    s = np.arange(0, 14.0 + 0.25, 0.25)
    # inside: every ray crosses; from a corner of the crop: most rays leave it without crossing (NaN)
    for c, finite in ((np.array([8.2, 7.1, 9.3]), (600, 600)), (np.array([0.0, 14.0, 3.5]), (10, 100))):
        got = shape.radial_profile(field, c, u, 14.0)
        want = shape._radial_profile_sampled(field, c, u, s, 0.25, 0.5)
        assert finite[0] <= np.isfinite(got).sum() <= finite[1]
        assert np.array_equal(got, want, equal_nan=True)
