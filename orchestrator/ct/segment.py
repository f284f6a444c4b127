"""Segmentation of a tomogram into grains (seed 000 §2.2, seed 001 §2.2).

Pipeline of :func:`segment`:

1. Gaussian filter (``sigma`` [voxels]) to suppress noise;
2. IsoData threshold (:func:`skimage.filters.threshold_isodata`) -> binary solid phase;
3. filling of small enclosed pores (hollow grains), at most ``max_pore_volume`` [m^3] each,
   and removal of solid specks smaller than ``min_volume`` [m^3];
4. Euclidean distance transform of the solid; markers are its h-maxima (``h`` [m]);
5. marker-based watershed (:func:`skimage.segmentation.watershed`) on the negative distance map,
   restricted to the solid;
6. a grain table (:attr:`Segmentation.grains`), flags of likely over- and under-segmentation,
   and the contacts between grains with normals from a principal-component analysis of the contact
   voxels (:meth:`Segmentation.contacts`).

Centroids and volumes use the partial-volume information of the grey values: every voxel of a
grain and every pore voxel within one voxel of it contributes its solid fraction (normalised grey
value). This is what makes centroids accurate to a small fraction of a voxel.
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy import ndimage

from .io import Scan

__all__ = ["segment", "Segmentation", "contacts_from_labels", "SegmentationError"]


class SegmentationError(RuntimeError):
    pass


@dataclass
class Segmentation:
    """Result of :func:`segment`. ``labels`` (int32, 0 = pore) has the scan's shape; ``grains`` is
    the grain table (one row per label, SI units); ``timings`` [s] per step."""
    scan: Scan
    labels: np.ndarray
    grains: pd.DataFrame
    threshold: float
    pore_level: float
    solid_level: float
    smoothed: np.ndarray
    params: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    _regions: np.ndarray | None = None

    def solid_fraction(self) -> np.ndarray:
        """Smoothed grey values mapped to [0, 1] (pore level -> 0, solid level -> 1), float32."""
        f = (self.smoothed - np.float32(self.pore_level)) / np.float32(self.solid_level - self.pore_level)
        return np.clip(f, 0, 1, out=f)

    def raw_fraction(self) -> np.ndarray:
        """Unfiltered grey values mapped to [0, 1] like :meth:`solid_fraction` (keeps the full
        partial-volume resolution; noise averages out over a grain)."""
        f = (self.scan.volume.astype(np.float32) - np.float32(self.pore_level)) / np.float32(self.solid_level - self.pore_level)
        return np.clip(f, 0, 1, out=f)

    def grain_regions(self, distance: float = 1.5) -> np.ndarray:
        """Labels grown by ``distance`` voxels into the pore space (each pore voxel goes to its nearest
        grain): the region whose partial-volume grey values belong to each grain."""
        if self._regions is None:
            from skimage.segmentation import expand_labels
            self._regions = expand_labels(self.labels, distance)
        return self._regions

    def contacts(self, min_voxels: int = 1) -> pd.DataFrame:
        """Contacts between grains (see :func:`contacts_from_labels`), with grain labels i < j."""
        return contacts_from_labels(self.labels, self.scan, min_voxels, self.grains)

    def summary(self) -> dict:
        g = self.grains
        return {"grains": int(len(g)), "threshold": float(self.threshold),
                "flagged_over": int((g["flag"] == "over").sum()),
                "flagged_under": int((g["flag"] == "under").sum()),
                "median_radius_m": float(g["radius"].median()) if len(g) else float("nan"),
                "timings_s": {k: round(v, 3) for k, v in self.timings.items()}}


def segment(scan: Scan, sigma: float = 1.0, threshold: float | None = None, h: float | None = None,
            max_pore_volume: float | None = None, min_volume: float | None = None,
            marker_level: float | None = 0.7, over_ratio: float = 0.9, under_ratio: float = 1.7,
            compactness: float = 0.0,
            progress: bool = False) -> Segmentation:
    """Segment a scan into grains.

    sigma : Gaussian filter standard deviation [voxels] (0 = none).
    threshold : grey-level threshold; None = IsoData on the filtered image.
    h : minimum height [m] of a distance-map maximum to seed a grain (default 1 voxel).
    marker_level : markers are the h-maxima of the distance map of the solid thresholded at this
        fraction between the pore and solid grey levels (0.7: tighter than IsoData, so the bridges that
        blur creates between touching grains do not join their markers); None = same map as the
        watershed.
    max_pore_volume : largest enclosed pore [m^3] filled as solid (default 1000 voxels).
    min_volume : smallest grain [m^3] kept (default 30 voxels).
    over_ratio : flag two grains as over-segmented when the distance map on their shared face (the
        saddle) reaches this fraction of the smaller grain's peak: one grain cut in two.
    under_ratio : flag a grain as under-segmented when the ratio of its volume to that of its
        largest inscribed sphere exceeds this multiple of the lower-quartile ratio (two merged
        spheres: about 2); a grain is also flagged when the volume of the convex hull of its voxels
        per voxel exceeds 1.15 times the lower quartile (the hull bridges two merged grains).
    """
    from skimage.filters import threshold_isodata
    from skimage.segmentation import watershed

    vs = scan.voxel_size
    v3 = vs ** 3
    h_vox = 1.0 if h is None else h / vs
    max_pore = 1000 if max_pore_volume is None else max_pore_volume / v3
    min_vox = 30 if min_volume is None else min_volume / v3
    timings = {}
    steps = ["gaussian filter", "threshold", "pores", "distance map", "markers", "watershed", "grain table"]
    prog = None
    if progress:
        from rich.progress import Progress
        prog = Progress(transient=True)
        prog.start()
        task = prog.add_task("segmenting", total=len(steps))

    def tick(name, t0):
        timings[name] = _time.perf_counter() - t0
        if prog is not None:
            prog.update(task, advance=1, description=f"segmenting: {name} done")
        return _time.perf_counter()

    try:
        t0 = _time.perf_counter()
        img = scan.volume.astype(np.float32, copy=False)
        sm = ndimage.gaussian_filter(img, sigma) if sigma > 0 else img.astype(np.float32, copy=True)
        t0 = tick("gaussian filter", t0)
        lo_, hi_ = float(sm.min()), float(sm.max())
        if threshold is None and hi_ - lo_ <= 1e-6 * max(abs(hi_), 1.0):
            raise SegmentationError(f"{scan.source}: the volume has a single grey value ({lo_:.4g}); "
                                    "nothing to segment")
        thr = float(threshold_isodata(sm) if threshold is None else threshold)
        binary = sm > thr
        pore_level = float(sm[~binary].mean()) if (~binary).any() else thr
        solid_level = float(sm[binary].mean()) if binary.any() else thr
        if not binary.any() or binary.all():
            raise SegmentationError(f"{scan.source}: threshold {thr:.4g} leaves no {'solid' if not binary.any() else 'pore'}"
                                    " voxels; is this a tomogram of grains?")
        t0 = tick("threshold", t0)
        binary = _fill_small_pores(binary, max_pore)
        lab0, n0 = ndimage.label(binary)
        size = np.bincount(lab0.ravel())
        keep = size >= min_vox
        keep[0] = False
        binary = keep[lab0]
        del lab0
        t0 = tick("pores", t0)
        dist = ndimage.distance_transform_edt(binary).astype(np.float32)
        t0 = tick("distance map", t0)
        if marker_level is not None and marker_level > 0.5:
            tight = sm > np.float32(pore_level + marker_level * (solid_level - pore_level))
            tight = _fill_small_pores(tight, max_pore) & binary
            mdist = ndimage.distance_transform_edt(tight).astype(np.float32)
            del tight
        else:
            mdist = dist
        markers, nm = _h_maxima_markers(mdist, h_vox)
        del mdist
        t0 = tick("markers", t0)
        labels = watershed(-dist, markers, mask=binary, compactness=compactness).astype(np.int32)
        del markers
        t0 = tick("watershed", t0)
        seg = Segmentation(scan, labels, pd.DataFrame(), thr, pore_level, solid_level, sm,
                           dict(sigma=sigma, threshold=threshold, h=h_vox * vs, max_pore_volume=max_pore * v3,
                                min_volume=min_vox * v3, over_ratio=over_ratio, under_ratio=under_ratio),
                           timings)
        seg.grains = _grain_table(seg, dist, over_ratio, under_ratio)
        tick("grain table", t0)
    finally:
        if prog is not None:
            prog.stop()
    return seg


def _fill_small_pores(binary, max_voxels):
    """Fill enclosed pores (not connected to the volume border) of at most ``max_voxels`` voxels."""
    holes = ndimage.binary_fill_holes(binary) & ~binary
    if holes.any():
        hl, nh = ndimage.label(holes)
        size = np.bincount(hl.ravel())
        small = size <= max_voxels
        small[0] = False
        binary = binary | small[hl]
    return binary


def _h_maxima_markers(dist, h):
    """Markers = regional maxima of the morphological reconstruction of ``dist - h`` under ``dist``
    (the h-maxima of the distance map, i.e. peaks at least ``h`` voxels above the saddle that joins
    them to a higher peak). Plateaus are handled exactly (skimage's ``h_maxima`` compares floats with
    a tolerance that can drop or split maxima). Returns (markers int32, count)."""
    from skimage.morphology import local_maxima, reconstruction
    sl = ndimage.find_objects((dist > 0).astype(np.int8))
    markers = np.zeros(dist.shape, np.int32)
    if not sl or sl[0] is None:
        return markers, 0
    sub = dist[sl[0]].astype(np.float64)
    rec = reconstruction(np.maximum(sub - h, 0), sub, method="dilation")
    peaks = local_maxima(rec, connectivity=3, allow_borders=True) & (sub > 0)
    lab, n = ndimage.label(peaks, structure=np.ones((3, 3, 3)))
    markers[sl[0]] = lab
    return markers, n


def _hull_ratio(labels, objs) -> np.ndarray:
    """Volume of the convex hull of each grain's voxel centres divided by its voxel count. Convex
    grains have nearly the same value (set by discretisation); two grains merged into one label
    have a larger one (the hull bridges the gap between them)."""
    from scipy.spatial import ConvexHull, QhullError
    out = np.full(len(objs), np.nan)
    for k, sl in enumerate(objs):
        if sl is None:
            continue
        m = labels[sl] == k + 1
        n = int(m.sum())
        if n < 20:
            continue
        surf = m & ~ndimage.binary_erosion(m)
        pts = np.argwhere(surf)
        try:
            out[k] = ConvexHull(pts).volume / n
        except QhullError:
            pass
    return out


def _grain_table(seg: Segmentation, dist, over_ratio, under_ratio, under_hull=1.15) -> pd.DataFrame:
    labels = seg.labels
    scan = seg.scan
    vs = scan.voxel_size
    n = int(labels.max())
    idx = np.arange(1, n + 1)
    if n == 0:
        return pd.DataFrame(columns=["label", "x", "y", "z", "volume", "radius", "n_voxels", "z0", "y0", "x0",
                                     "z1", "y1", "x1", "inscribed_radius", "flag"])
    nvox = ndimage.sum_labels(np.ones_like(labels, dtype=np.float32), labels, idx)
    # partial-volume centroid and volume over each grain's region (grain + nearest pore voxels)
    reg = seg.grain_regions()
    w = seg.raw_fraction()
    vol = ndimage.sum_labels(w, reg, idx)
    cz, cy, cx = (np.zeros(n) for _ in range(3))
    objs = ndimage.find_objects(reg, max_label=n)
    for k, sl in enumerate(objs):
        if sl is None:
            continue
        m = reg[sl] == k + 1
        ww = w[sl] * m
        s = ww.sum()
        if s <= 0:
            continue
        zz, yy, xx = np.ogrid[sl[0], sl[1], sl[2]]
        cz[k] = (ww.sum(axis=(1, 2)) * zz.ravel()).sum() / s
        cy[k] = (ww.sum(axis=(0, 2)) * yy.ravel()).sum() / s
        cx[k] = (ww.sum(axis=(0, 1)) * xx.ravel()).sum() / s
    world = scan.to_world(np.column_stack([cz, cy, cx]))
    inscribed = ndimage.maximum(dist, labels, idx)
    bobj = ndimage.find_objects(labels, max_label=n)
    bbox = np.array([[s.start for s in sl] + [s.stop for s in sl] if sl is not None else [0] * 6 for sl in bobj])
    volume = vol * vs ** 3
    radius = np.cbrt(3 * volume / (4 * np.pi))
    t = pd.DataFrame({"label": idx, "x": world[:, 0], "y": world[:, 1], "z": world[:, 2],
                      "volume": volume, "radius": radius, "n_voxels": nvox.astype(np.int64),
                      "z0": bbox[:, 0], "y0": bbox[:, 1], "x0": bbox[:, 2],
                      "z1": bbox[:, 3], "y1": bbox[:, 4], "x1": bbox[:, 5],
                      "inscribed_radius": (inscribed + 0.5) * vs})
    # touching the scan border: centroid and volume are not trustworthy
    t["at_border"] = ((bbox[:, :3] == 0) | (bbox[:, 3:] == np.array(labels.shape))).any(axis=1)
    flag = np.array([""] * n, dtype=object)
    ratio = volume / (4 / 3 * np.pi * t["inscribed_radius"].to_numpy() ** 3)
    t["volume_ratio"] = ratio
    hull = _hull_ratio(labels, bobj)
    t["hull_ratio"] = hull
    # reference: the lower quartile, i.e. typical single grains even when many labels are merged
    ref_h = np.nanpercentile(hull, 25) if np.isfinite(hull).any() else np.nan
    ref_r = np.percentile(ratio, 25)
    suspect = (ratio > under_ratio * ref_r) | (hull > under_hull * ref_h)
    flag[suspect & ~t["at_border"].to_numpy()] = "under"
    c = contacts_from_labels(labels, scan, 1, None, normals=False, dist=dist)
    if len(c):
        pmin = np.minimum(inscribed[c["i"].to_numpy() - 1], inscribed[c["j"].to_numpy() - 1])
        big = c["saddle"].to_numpy() >= over_ratio * pmin
        for col in ("i", "j"):
            flag[c[col].to_numpy()[big] - 1] = "over"
    med = np.median(volume)
    flag[volume < 0.15 * med] = "over"
    t["flag"] = flag
    return t


def contacts_from_labels(labels, scan: Scan, min_voxels: int = 1, grains: pd.DataFrame | None = None,
                         normals: bool = True, dist=None) -> pd.DataFrame:
    """Contacts between labelled grains (seed 001 §2.2).

    Every pair of face-adjacent voxels carrying two different grain labels contributes one contact
    element at the midpoint of the shared face. A pair (i, j) with more than ``min_voxels`` elements
    is a contact. Its normal is the direction of least variance of its elements (principal-component
    analysis), oriented from grain i to grain j; with fewer than 3 elements, or a degenerate cloud, the
    branch vector (centroid j - centroid i) is used and ``normal_from`` says so.

    Returns a DataFrame: ``i``, ``j`` (labels, i < j), ``n_voxels``, ``area`` [m^2], contact point
    ``px, py, pz`` [m], normal ``nx, ny, nz``, ``normal_from`` ("pca" or "branch"); with a distance
    map ``dist`` [voxels] also ``saddle``, its largest value across the shared face [voxels].
    """
    vs = scan.voxel_size
    keys, pts, sad = [], [], []
    for ax in range(3):
        a = np.moveaxis(labels, ax, 0)
        lo, hi = a[:-1], a[1:]
        m = (lo != hi) & (lo > 0) & (hi > 0)
        if not m.any():
            continue
        idx = np.nonzero(m)
        la, lb = lo[idx], hi[idx]
        i, j = np.minimum(la, lb).astype(np.int64), np.maximum(la, lb).astype(np.int64)
        coord = np.stack(idx, -1).astype(np.float64)
        coord[:, 0] += 0.5
        # back to (z, y, x) order
        order = np.argsort([ax] + [k for k in range(3) if k != ax])
        coord = coord[:, order]
        keys.append(i * (int(labels.max()) + 1) + j)
        pts.append(coord)
        if dist is not None:
            D = np.moveaxis(dist, ax, 0)
            sad.append(np.minimum(D[:-1][idx], D[1:][idx]))
    cols = ["i", "j", "n_voxels", "area", "px", "py", "pz", "nx", "ny", "nz", "normal_from"]
    if not keys:
        return pd.DataFrame(columns=cols)
    key = np.concatenate(keys)
    p = np.concatenate(pts)
    uk, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
    base = int(labels.max()) + 1
    i, j = uk // base, uk % base
    mean = np.stack([np.bincount(inv, p[:, k]) for k in range(3)], -1) / cnt[:, None]
    out = pd.DataFrame({"i": i, "j": j, "n_voxels": cnt, "area": cnt * vs ** 2})
    world = scan.to_world(mean)
    out["px"], out["py"], out["pz"] = world[:, 0], world[:, 1], world[:, 2]
    if dist is not None:
        saddle = np.zeros(len(uk))
        np.maximum.at(saddle, inv, np.concatenate(sad))
        out["saddle"] = saddle
    keep = cnt > min_voxels - 1 if min_voxels <= 1 else cnt > min_voxels
    if not normals:
        return out[keep].reset_index(drop=True)
    d = p - mean[inv]
    cov = np.zeros((len(uk), 3, 3))
    for a in range(3):
        for b in range(a, 3):
            cov[:, a, b] = cov[:, b, a] = np.bincount(inv, d[:, a] * d[:, b]) / cnt
    evals, evecs = np.linalg.eigh(cov)
    nrm = evecs[:, :, 0][:, ::-1]                       # smallest-variance direction, (z,y,x) -> (x,y,z)
    # branch vectors from centroids
    if grains is not None and len(grains):
        g = grains.set_index("label")
        ci = g.loc[i, ["x", "y", "z"]].to_numpy()
        cj = g.loc[j, ["x", "y", "z"]].to_numpy()
        branch = cj - ci
    else:
        branch = np.zeros((len(uk), 3))
    bn = np.linalg.norm(branch, axis=1)
    use_branch = (cnt < 3) | (evals[:, 1] < 1e-9) | (evals[:, 0] > 0.5 * evals[:, 1])
    use_branch &= bn > 0
    nrm = np.where(use_branch[:, None], branch / np.where(bn > 0, bn, 1)[:, None], nrm)
    sign = np.sign(np.einsum("ij,ij->i", nrm, branch))
    sign[sign == 0] = 1
    nrm *= sign[:, None]
    out["nx"], out["ny"], out["nz"] = nrm[:, 0], nrm[:, 1], nrm[:, 2]
    out["normal_from"] = np.where(use_branch, "branch", "pca")
    return out[keep].reset_index(drop=True)
