"""Tracking accuracy: (a) displacement linking, (b) image-based rotation as prediction, lost/new."""
import numpy as np
import pytest
from scipy.spatial import cKDTree

from orchestrator.ct import segment, synth, track

VS = 1e-5


def test_link_shear_step_03d():
    """4000 touching grains, simple shear with the largest step 0.3 d, non-affine fluctuations of
    0.05 d and centroid noise of 0.1 voxel: >= 99.9 % correct links."""
    rng = np.random.default_rng(1)
    n = 4000
    r = rng.uniform(0.8, 1.2, n) * 5 * VS
    L = (np.sum(4 / 3 * np.pi * r ** 3) / 0.5) ** (1 / 3)
    a = synth.pack_spheres(r, box=((0, 0, 0), (L, L, L)), seed=2)
    d = 2 * np.median(r)
    b = a.copy()
    b[:, 0] += 0.3 * d * a[:, 2] / L                                # largest step 0.3 d at the top
    b += rng.normal(0, 0.05 * d, b.shape) + rng.normal(0, 0.1 * VS, b.shape)
    a_meas = a + rng.normal(0, 0.1 * VS, a.shape)
    perm = rng.permutation(n)
    lk = track.link(a_meas, b[perm], max_disp=0.5 * d)
    correct = (perm[lk.a_to_b] == np.arange(n)) & (lk.a_to_b >= 0)
    print(f"\nlinking, step 0.3 d: {correct.mean():.4%} correct of {n}")
    assert correct.mean() >= 0.999
    # a nearest-neighbour guess is not the same thing: the optimum is global
    assert np.all(lk.cost[lk.a_to_b >= 0] <= 0.5 * d)


def test_link_reports_lost_and_new():
    rng = np.random.default_rng(3)
    a = rng.random((500, 3)) * 100 * VS
    keep = np.ones(500, bool)
    keep[::50] = False                                              # 10 grains leave
    b = np.vstack([a[keep] + rng.normal(0, 0.2 * VS, (keep.sum(), 3)),
                   rng.random((5, 3)) * 100 * VS + 200 * VS])      # 5 new far away
    lk = track.link(a, b, max_disp=2 * VS)
    assert set(lk.lost) == set(np.nonzero(~keep)[0])
    assert set(lk.new) == set(range(keep.sum(), keep.sum() + 5))
    assert np.array_equal(lk.a_to_b[keep], np.arange(keep.sum()))
    # NaN rows are never linked
    a[0] = np.nan
    assert track.link(a, b, 2 * VS).a_to_b[0] == -1


@pytest.fixture(scope="module")
def sheared_cylinder():
    """Grains in a cylinder (R = 58 voxels), the upper part rotated by up to 5 deg with a shear band
    at mid-height and a radial variation; non-affine fluctuations 0.03 d; overlaps relaxed."""
    rng = np.random.default_rng(4)
    R, H, nxy = 58 * VS, 92 * VS, 128
    centre = np.array([(nxy - 1) / 2, (nxy - 1) / 2]) * VS
    vol = np.pi * (R / VS) ** 2 * (H / VS - 4)
    rmean = 5.6
    n = int(0.47 * vol / (4 / 3 * np.pi * rmean ** 3 * 1.02))
    r = rng.uniform(5.0, 6.2, n) * VS
    cyl = (centre[0], centre[1], R, 2 * VS, H)
    a = synth.pack_spheres(r, cylinder=cyl, seed=5)
    rho = np.hypot(a[:, 0] - centre[0], a[:, 1] - centre[1])
    zc = 0.5 * (2 * VS + H)
    angle = np.deg2rad(5) / (1 + np.exp(-(a[:, 2] - zc) / (6 * VS))) * (0.7 + 0.3 * rho / R)
    b = synth.twist(a, centre, angle) + rng.normal(0, 0.03 * 2 * rmean * VS, a.shape)
    b = synth.pack_spheres(r, cylinder=cyl, initial=b)
    shape = (int(H / VS) + 3, nxy, nxy)
    scans = synth.render_sequence(shape, VS, np.stack([a, b]), r, noise=0.1, psf_sigma=0.8, supersample=4)
    segs = [segment.segment(s) for s in scans]
    return dict(a=a, b=b, r=r, scans=scans, segs=segs, angle=angle, centre=centre)


def _truth(seg, x, r):
    d, k = cKDTree(x).query(seg.grains[["x", "y", "z"]].to_numpy())
    return np.where(d < 0.5 * r[k], k, -1)


def test_rotation_estimate_and_tracking_5deg(sheared_cylinder):
    s = sheared_cylinder
    ta, tb = _truth(s["segs"][0], s["a"], s["r"]), _truth(s["segs"][1], s["b"], s["r"])
    field = track.estimate_rotation(*s["scans"], centre=s["centre"], n_rings=4, slab=4 * VS)
    # the estimated angle at each grain vs the imposed one
    err = np.degrees(np.abs(field.angle_at(s["a"]) - s["angle"]))
    pa = s["segs"][0].grains[["x", "y", "z"]].to_numpy()
    pb = s["segs"][1].grains[["x", "y", "z"]].to_numpy()
    d = 2 * np.median(s["r"])
    lk = track.link(pa, pb, max_disp=0.4 * d, predicted=field.predict(pa))
    trackable = (ta >= 0) & np.isin(ta, tb)
    got = np.where(lk.a_to_b >= 0, tb[np.maximum(lk.a_to_b, 0)], -2)
    acc = (got[trackable] == ta[trackable]).mean()
    plain = track.link(pa, pb, max_disp=0.4 * d)
    got0 = np.where(plain.a_to_b >= 0, tb[np.maximum(plain.a_to_b, 0)], -2)
    acc0 = (got0[trackable] == ta[trackable]).mean()
    wall = np.degrees(s["angle"]).max()
    print(f"\nsheared cylinder: {trackable.sum()} grains, largest rotation {wall:.2f} deg "
          f"({np.max(np.linalg.norm(s['b'] - s['a'], axis=1)) / d:.2f} d); angle error median "
          f"{np.median(err):.3f} deg, p95 {np.percentile(err, 95):.3f} deg; correct links with (b) "
          f"{acc:.2%}, without prediction {acc0:.2%}")
    assert trackable.sum() >= 0.99 * len(s["a"])
    assert np.median(err) < 0.25
    assert acc >= 0.989
