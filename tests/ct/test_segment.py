"""Segmentation accuracy on synthetic scans with known grains."""
import numpy as np
import pytest
from scipy.spatial import cKDTree

from orchestrator.ct import segment
from orchestrator.ct.io import Scan

SCHEDULE_MINUTES = 0.15   #: engine-free tests, ~9 s quiet: early in the fast tier (tests/conftest.py schedule_groups)

VS = 1e-5            # voxel size [m], as in conftest.py


def _match(seg, centres, radii):
    g = seg.grains
    d, k = cKDTree(centres).query(g[["x", "y", "z"]].to_numpy())
    ok = d < 0.5 * radii[k]
    return g, d, k, ok


def test_finds_grains_with_subvoxel_centroids(sphere_packing):
    c, r, seg = sphere_packing["centres"], sphere_packing["radii"], sphere_packing["seg"]
    g, d, k, ok = _match(seg, c, r)
    found = len(np.unique(k[ok])) / len(c)
    median_err = np.median(d[ok]) / VS
    print(f"\nsegmentation: found {found:.2%} of {len(c)} grains, {len(g)} labels, "
          f"median centroid error {median_err:.3f} voxel, p90 {np.percentile(d[ok], 90) / VS:.3f}")
    assert found >= 0.995
    assert median_err <= 0.1
    # no spurious grains: every label is one true grain
    assert ok.mean() >= 0.995
    # equivalent radius from partial-volume sums: within 3 % (median)
    assert np.median(np.abs(g["radius"].to_numpy()[ok] / r[k[ok]] - 1)) < 0.03
    # hollow grains were filled: their volume is the full sphere's
    hol = sphere_packing["hollow"][k[ok]] > 0
    assert hol.sum() > 30
    v_true = 4 / 3 * np.pi * r[k[ok]] ** 3
    assert np.median(np.abs(g["n_voxels"].to_numpy()[ok][hol] * VS ** 3 / v_true[hol] - 1)) < 0.1
    assert (g["flag"] == "").mean() > 0.98


def test_contacts_and_pca_normals(sphere_packing):
    c, r, seg = sphere_packing["centres"], sphere_packing["radii"], sphere_packing["seg"]
    g, d, k, ok = _match(seg, c, r)
    lab2true = dict(zip(g["label"][ok], k[ok]))
    ct = seg.contacts()
    pairs = cKDTree(c).query_pairs(2 * r.max(), output_type="ndarray")
    gap = np.linalg.norm(c[pairs[:, 0]] - c[pairs[:, 1]], axis=1) - r[pairs[:, 0]] - r[pairs[:, 1]]
    touching = {tuple(sorted(p)) for p in pairs[gap < 0.05 * VS]}
    found, errs = set(), []
    for row in ct.itertuples():
        a, b = lab2true.get(row.i), lab2true.get(row.j)
        if a is None or b is None:
            continue
        key = tuple(sorted((a, b)))
        found.add(key)
        if key in touching:
            br = c[b] - c[a]
            br /= np.linalg.norm(br)
            errs.append(np.degrees(np.arccos(min(1.0, abs(np.dot(br, [row.nx, row.ny, row.nz]))))))
    recall = len(touching & found) / len(touching)
    med = np.median(errs)
    print(f"\ncontacts: {len(touching)} touching pairs, recall {recall:.2%}, "
          f"median normal error {med:.1f} deg, p90 {np.percentile(errs, 90):.1f} deg, {len(ct)} contacts")
    assert recall >= 0.99
    assert med < 8.0
    # normals point from grain i to grain j
    gi = g.set_index("label")
    br = gi.loc[ct["j"], ["x", "y", "z"]].to_numpy() - gi.loc[ct["i"], ["x", "y", "z"]].to_numpy()
    assert (np.einsum("ij,ij->i", br, ct[["nx", "ny", "nz"]].to_numpy()) > 0).all()


def test_flags_under_and_over_segmentation(sphere_packing):
    c, scan = sphere_packing["centres"], sphere_packing["scan"]
    # markers from the plain IsoData distance map with a high h merge many touching pairs
    seg = segment.segment(scan, h=2.5 * VS, marker_level=None)
    g = seg.grains
    v = np.rint(scan.to_voxel(c)).astype(int)
    count = np.bincount(seg.labels[tuple(v.T)], minlength=seg.labels.max() + 1)[g["label"].to_numpy()]
    merged, single = count >= 2, count == 1
    assert merged.sum() >= 20
    caught = (g["flag"].to_numpy()[merged] == "under").mean()
    false = (g["flag"].to_numpy()[single] == "under").mean()
    print(f"\nunder-segmentation: {merged.sum()} merged labels, {caught:.0%} flagged; "
          f"{false:.0%} of {single.sum()} single grains flagged")
    assert caught >= 0.8
    # false alarms on a good segmentation (every label one grain)
    clean = sphere_packing["seg"].grains
    assert (clean["flag"] == "under").mean() < 0.02
    # over-segmentation: cut every grain of a clean scan in two along a plane through its centre
    lab = sphere_packing["seg"].labels.copy()
    gg = sphere_packing["seg"].grains
    zc = np.rint(scan.to_voxel(gg[["x", "y", "z"]].to_numpy())[:, 0]).astype(int)
    cut = np.arange(0, len(gg), 7)
    zz = np.arange(lab.shape[0])[:, None, None]
    nxt = lab.max() + 1
    for q, t in enumerate(cut):
        m = (lab == gg["label"].iloc[t]) & (zz > zc[t])
        lab[m] = nxt + q
    seg2 = sphere_packing["seg"]
    from scipy import ndimage
    dist = ndimage.distance_transform_edt(lab > 0).astype(np.float32)
    fake = segment.Segmentation(scan, lab, None, seg2.threshold, seg2.pore_level, seg2.solid_level, seg2.smoothed)
    tab = segment._grain_table(fake, dist, 0.9, 1.7)
    halves = np.concatenate([gg["label"].to_numpy()[cut], nxt + np.arange(len(cut))])
    flagged = (tab.set_index("label").loc[halves, "flag"] == "over").mean()
    others = tab[~tab["label"].isin(halves)]
    print(f"over-segmentation: {flagged:.0%} of split halves flagged, {(others['flag'] == 'over').mean():.1%} false flags")
    assert flagged >= 0.9
    assert (others["flag"] == "over").mean() < 0.05


def test_empty_scan_gives_clear_error():
    import pytest
    s = Scan(np.full((20, 20, 20), 100, np.uint16), VS, source="flat.tif")
    with pytest.raises(segment.SegmentationError, match="flat.tif"):
        segment.segment(s)


def test_basin_merging_equals_h_maxima_watershed(sphere_packing):
    """The markers: merging the basins of all regional maxima whose peak is at most h above the
    saddle to a higher basin gives the partition of the watershed seeded by the h-maxima
    (morphological reconstruction): the same grains for h = 1 and h = 2.5 voxels, and the same voxels
    up to ties for the default h = 1. (With a large h a basin that is not an h-maximum goes whole to
    the neighbour across its highest saddle, where the reference floods it from every neighbour.)"""
    from scipy import ndimage
    from skimage.morphology import local_maxima, reconstruction
    from skimage.segmentation import watershed
    binary = sphere_packing["seg"].labels > 0
    dist = ndimage.distance_transform_edt(binary).astype(np.float32)
    peaks, _ = segment._peak_markers(dist)
    basins = watershed(-dist, peaks, mask=binary)
    for h in (1.0, 2.5):
        ours = segment._merge_shallow_basins(basins, dist, h, peaks)
        rec = reconstruction(np.maximum(dist - h, 0), dist, method="dilation")
        ref_markers, n_ref = ndimage.label(local_maxima(rec, connectivity=3) & binary, np.ones((3, 3, 3)))
        ref = watershed(-dist, ref_markers, mask=binary)
        # voxels whose label agrees after matching each of our labels to its majority reference label
        # (our label, reference label) pairs as one integer key: np.unique(axis=1) sorts the pairs as
        # byte strings, ~10x slower
        base = int(ref.max()) + 1
        key, cnt = np.unique(ours[binary].astype(np.int64) * base + ref[binary], return_counts=True)
        a = key // base
        best = np.zeros(ours.max() + 1, np.int64)
        np.maximum.at(best, a, cnt)
        agree = best.sum() / binary.sum()
        print(f"\nh = {h}: {ours.max()} labels (reference {n_ref}), {agree:.4%} of solid voxels agree")
        assert abs(int(ours.max()) - n_ref) <= 0.005 * n_ref
        assert agree > (0.995 if h == 1.0 else 0.85)
