"""Segmentation of a tomogram into grains (seed 000 §2.2, seed 001 §2.2).

Pipeline of :func:`segment`:

1. Gaussian filter (``sigma`` [voxels]) to suppress noise;
2. IsoData threshold (:func:`skimage.filters.threshold_isodata`) -> binary solid phase;
3. filling of small enclosed pores (hollow grains), at most ``max_pore_volume`` [m^3] each,
   and removal of solid specks smaller than ``min_volume`` [m^3];
4. Euclidean distance transform (EDT) of the solid, and of the solid thresholded tighter
   (``marker_level``) for the markers;
5. marker-based watershed (:func:`skimage.segmentation.watershed`) on the negative distance map,
   restricted to the solid, seeded by every regional maximum of the tight EDT; the basins whose peak
   rises at most ``h`` [m] above the saddle to a higher basin are then merged (union-find over the
   basin adjacency graph). This is the partition seeded by the h-maxima, without a morphological
   reconstruction of the whole volume (which took half the time of the pipeline);
6. a grain table (:attr:`Segmentation.grains`), flags of likely over- and under-segmentation,
   and the contacts between grains with normals from a principal-component analysis of the contact
   voxels (:meth:`Segmentation.contacts`).

Centroids and volumes use the partial-volume information of the grey values: every voxel of a
grain and every pore voxel within 1.5 voxels of it contributes its solid fraction (normalised grey
value). This is what makes centroids accurate to a small fraction of a voxel. Every per-grain
quantity is computed for all grains at once (bincount-style label sums, face-pair lists); the only
per-grain loop calls Qhull for the convex-hull flag on a few candidate voxels per grain.
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy import ndimage
from scipy.special import ndtr

from .io import Scan
from ._kernels import (basin_saddles, edt, extreme_candidates, grow_kernel, label_sizes, label_stats, region_sums,
                       table_mask)

__all__ = ["segment", "Segmentation", "contacts_from_labels", "gap_fraction", "branch_profile_min", "CONTACT_GAP", "face_pairs", "grow_labels", "distance_map", "SegmentationError"]


class SegmentationError(RuntimeError):
    pass


#: Gap [voxels] below which two grains are reported in contact (:meth:`Segmentation.contacts`):
#: inside the 0-0.5 voxel band that the contact tests on rendered packings leave empty (0.25-0.35 tried;
#: 0.3 balances precision and recall over PSF 0.5-1.2 voxel and grains 8-27 voxels across)
#: (tests/ct/test_contacts.py; benchmarks/bench_ct.py --contacts prints the figures).
CONTACT_GAP = 0.3


def gap_fraction(gap, ri, rj, sigma):
    """Solid fraction at the middle of the gap between two spheres, seen through a Gaussian blur.

    gap : surface-to-surface distance [voxels] (0 = touching); ri, rj : radii [voxels]; sigma : blur
    standard deviation [voxels]. The surfaces near the gap are taken as paraboloids (gap width
    ``gap + rho^2 (1/ri + 1/rj) / 2`` at lateral distance rho, valid for rho << r): the blurred
    pore fraction at the middle is the radial Gaussian average of the pore slab's 1-D coverage,
    ``1 - int rho/s^2 exp(-rho^2/2s^2) [Phi(b/s) - Phi(-a/s)] drho`` (64-node quadrature).
    Broadcasts over arrays."""
    gap, ri, rj = (np.asarray(v, float)[..., None] for v in (gap, ri, rj))
    x = np.linspace(0.0, 5.0, 64)
    w = x * np.exp(-0.5 * x * x)
    w /= w.sum()
    rho = x * sigma
    pore = ndtr((0.5 * gap + rho ** 2 / (2 * rj)) / sigma) - ndtr((-0.5 * gap - rho ** 2 / (2 * ri)) / sigma)
    return 1.0 - (pore * w).sum(-1)


def branch_profile_min(fraction, ci, cj, ri, rj, samples: int = 41):
    """Lowest value of ``fraction`` (trilinear) on the branch segment between two grains, from 0.6 of
    grain i's radius beyond its centre to 0.6 of grain j's radius before its centre (away from the
    centres, where hollow grains have their cavity). ci, cj : centres (N, 3) in voxel coordinates
    (z, y, x), as :meth:`Scan.to_voxel` gives them; ri, rj : radii [voxels]. Returns (N,)."""
    ci, cj = np.asarray(ci, float), np.asarray(cj, float)
    L = np.linalg.norm(cj - ci, axis=1)
    u = (cj - ci) / np.maximum(L, 1e-12)[:, None]
    a, b = 0.6 * np.asarray(ri), L - 0.6 * np.asarray(rj)
    b = np.maximum(a, b)
    t = a[:, None] + np.linspace(0.0, 1.0, samples)[None, :] * (b - a)[:, None]
    p = ci[:, None, :] + t[..., None] * u[:, None, :]
    v = ndimage.map_coordinates(fraction, [p[..., 0].ravel(), p[..., 1].ravel(), p[..., 2].ravel()],
                                order=1, mode="nearest")
    return v.reshape(len(ci), samples).min(axis=1)


@dataclass
class Segmentation:
    """Result of :func:`segment`. ``labels`` (int32, 0 = pore) has the scan's shape; ``grains`` is
    the grain table (one row per label, SI units); ``timings`` [s] per step (wall), ``cpu_timings``
    the same in process CPU time."""
    scan: Scan
    labels: np.ndarray
    grains: pd.DataFrame
    threshold: float
    pore_level: float
    solid_level: float
    smoothed: np.ndarray
    params: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    cpu_timings: dict = field(default_factory=dict)     # process CPU time [s] per step (one thread: robust to load)
    _regions: np.ndarray | None = None
    _levels: tuple | None = None

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
            self._regions = grow_labels(self.labels, distance)
        return self._regions

    def local_fraction(self) -> np.ndarray:
        """Smoothed grey values mapped to [0, 1] with the pore and solid grey levels of each slice
        (z): the local greyscale calibration that the contact test uses, so that a drift of the
        contrast along the scan does not move the contact threshold. float32, not clipped."""
        pore, solid = self.slice_levels()
        f = self.smoothed - pore[:, None, None].astype(np.float32)
        f /= (solid - pore)[:, None, None].astype(np.float32)
        return f

    def slice_levels(self) -> tuple[np.ndarray, np.ndarray]:
        """Pore and solid grey levels per slice (z) of the smoothed scan: the mean grey value of the
        voxels at least 2 voxels inside the pore space and 3 inside the solid (labelled grains above the
        threshold: the filled cavities of hollow grains do not count). Slices without such voxels
        take the global levels."""
        if self._levels is None:
            sm, lab = self.smoothed, self.labels
            solid_core = ndimage.binary_erosion(lab > 0, iterations=3) & (sm > self.threshold)
            pore_core = ndimage.binary_erosion(lab == 0, iterations=2, border_value=1)
            nz = sm.shape[0]

            def per_slice(mask, default):
                cnt = mask.sum(axis=(1, 2))
                tot = np.where(mask, sm, 0).sum(axis=(1, 2), dtype=np.float64)
                return np.where(cnt > 100, tot / np.maximum(cnt, 1), default)

            self._levels = (per_slice(pore_core, self.pore_level), per_slice(solid_core, self.solid_level))
            assert len(self._levels[0]) == nz
        return self._levels

    def blur_sigma(self, fraction=None) -> float:
        """Standard deviation [voxels] of the total Gaussian blur of the smoothed scan (PSF and filter),
        from the steepest grey-level slope across grain surfaces: a blurred planar edge of unit contrast
        has slope 1/(sqrt(2 pi) sigma) at its middle. The upper quartile of the slope over voxels at
        solid fraction 0.4-0.6 (curvature and noise lower the median). Checked on rendered scans:
        within 10 % of sqrt(psf^2 + sigma_filter^2) for PSF 0.5-1.2 voxel."""
        f = self.local_fraction() if fraction is None else fraction
        nz, ny, nx = f.shape
        flat = f.ravel()
        idx = np.flatnonzero((flat > 0.4) & (flat < 0.6))
        z, y, x = np.unravel_index(idx, f.shape)
        idx = idx[(z > 0) & (z < nz - 1) & (y > 0) & (y < ny - 1) & (x > 0) & (x < nx - 1)]
        if idx.size == 0:
            return float(np.hypot(self.params.get("sigma", 1.0), 0.8))
        g2 = sum(((flat[idx + k] - flat[idx - k]) / 2) ** 2 for k in (ny * nx, nx, 1))
        return float(1.0 / (np.sqrt(2 * np.pi) * np.sqrt(np.percentile(g2, 75))))

    def contacts(self, min_voxels: int = 1, refine: bool = True, resolution: float = CONTACT_GAP) -> pd.DataFrame:
        """Contacts between grains (see :func:`contacts_from_labels`), with grain labels i < j.

        Face-adjacent labels alone include every pair closer than about 1.5 voxels (the blur bridges
        the gap). Each candidate is therefore refined by a local greyscale test (after the
        local-threshold contact detection of Wiebicke et al. 2017, Acta Geotech. 12:1): the lowest
        local solid fraction (:meth:`local_fraction`) along the branch vector between the two grains'
        surfaces (column ``profile_fraction``) is compared with the value that a gap of ``resolution``
        [voxels] between two spheres of the grains' equivalent radii would give under the scan's blur
        (:meth:`blur_sigma`, :func:`gap_fraction`; column ``touch_fraction``: the value for a gap of 0,
        ``threshold_fraction``: for ``resolution``). ``refine=False`` returns every candidate with
        these columns and ``touching``.
        """
        f = self.local_fraction()             # one float32 copy of the volume, used three times
        c = contacts_from_labels(self.labels, self.scan, min_voxels, self.grains, fraction=f)
        if len(c):
            g = self.grains.set_index("label")
            vs = self.scan.voxel_size
            ci = self.scan.to_voxel(g.loc[c["i"], ["x", "y", "z"]].to_numpy())
            cj = self.scan.to_voxel(g.loc[c["j"], ["x", "y", "z"]].to_numpy())
            ri = g.loc[c["i"], "radius"].to_numpy() / vs
            rj = g.loc[c["j"], "radius"].to_numpy() / vs
            c["profile_fraction"] = branch_profile_min(f, ci, cj, ri, rj)
            s = self.blur_sigma(f)
            c["touch_fraction"] = gap_fraction(0.0, ri, rj, s)
            c["threshold_fraction"] = gap_fraction(resolution, ri, rj, s)
            c["touching"] = c["profile_fraction"].to_numpy() >= c["threshold_fraction"].to_numpy()
        else:
            for k in ("profile_fraction", "touch_fraction", "threshold_fraction", "touching"):
                c[k] = []
        if refine:
            c = c[c["touching"].to_numpy(bool)].reset_index(drop=True)
        return c

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
    h : minimum height [m] of a distance-map maximum to seed a grain. Default: 1 voxel, or 0.15 x
        the typical peak (upper quartile of the basins' peaks) when that is lower, i.e. for grains
        under ~13 voxels across: two touching 8-voxel grains have a saddle less than 1 voxel below
        their peaks at a sharp PSF and were merged (7 of 918 pairs, the contact recall 0.972 of
        docs/ct.md); 0.15 x peak keeps them apart and changes nothing for larger grains.
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
    h_vox = None if h is None else h / vs           # None: scale-aware default, see _merge_shallow_basins
    max_pore = 1000 if max_pore_volume is None else max_pore_volume / v3
    min_vox = 30 if min_volume is None else min_volume / v3
    timings = {}
    steps = ["gaussian filter", "threshold", "pores", "distance map", "markers", "watershed", "merge",
             "grain table"]
    prog = None
    if progress:
        from rich.progress import Progress
        prog = Progress(transient=True)
        prog.start()
        task = prog.add_task("segmenting", total=len(steps))

    cpu_timings = {}
    c0 = [_time.process_time()]

    def tick(name, t0):
        timings[name] = _time.perf_counter() - t0
        c = _time.process_time()
        cpu_timings[name] = c - c0[0]
        c0[0] = c
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
                                    "nothing to segment: check that the file holds the reconstructed scan (an empty or "
                                    "failed reconstruction is all one value) and, for a raw file, its --shape and --dtype")
        with np.errstate(divide="ignore", invalid="ignore"):      # empty histogram bins, harmless
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
        size = label_sizes(lab0, n0)
        keep = size >= min_vox
        keep[0] = False
        binary = table_mask(lab0, keep, np.empty(0, np.bool_))
        del lab0
        t0 = tick("pores", t0)
        dist = distance_map(binary)
        t0 = tick("distance map", t0)
        if marker_level is not None and marker_level > 0.5:
            tight = sm > np.float32(pore_level + marker_level * (solid_level - pore_level))
            tight = _fill_small_pores(tight, max_pore) & binary
            mdist = distance_map(tight)
            del tight
        else:
            mdist = dist
        peaks, npk = _peak_markers(mdist)
        t0 = tick("markers", t0)
        basins = watershed(-dist, peaks, mask=binary, compactness=compactness)
        t0 = tick("watershed", t0)
        if h_vox is None:
            h_vox = default_h(mdist, peaks, npk)
        labels = _merge_shallow_basins(basins, mdist, h_vox, peaks)
        del basins, mdist, peaks
        t0 = tick("merge", t0)
        seg = Segmentation(scan, labels, pd.DataFrame(), thr, pore_level, solid_level, sm,
                           dict(sigma=sigma, threshold=threshold, h=h_vox * vs, max_pore_volume=max_pore * v3,
                                min_volume=min_vox * v3, over_ratio=over_ratio, under_ratio=under_ratio),
                           timings, cpu_timings)
        seg.grains = _grain_table(seg, dist, over_ratio, under_ratio)
        tick("grain table", t0)
    finally:
        if prog is not None:
            prog.stop()
    return seg


def _fill_small_pores(binary, max_voxels):
    """Fill enclosed pores (background components, 6-connected, not touching the volume border) of
    at most ``max_voxels`` voxels. One labelling of the background (the same holes as
    :func:`scipy.ndimage.binary_fill_holes`, without its iterated dilation from the border)."""
    lab, n = ndimage.label(~binary)
    if n == 0:
        return binary
    size = label_sizes(lab, n)
    fill = size <= max_voxels
    fill[0] = False
    for ax in range(3):
        for end in (0, -1):
            fill[np.take(lab, end, axis=ax)] = False
    if not fill.any():
        return binary
    return table_mask(lab, fill, np.ascontiguousarray(binary))


def distance_map(binary) -> np.ndarray:
    """Euclidean distance [voxels] of every non-zero voxel to the nearest zero voxel, float32.

    The exact separable transform of :mod:`orchestrator.ct._kernels` (Felzenszwalb-Huttenlocher, numba):
    the same values as :func:`scipy.ndimage.distance_transform_edt` (tests/ct/test_edt.py), ~6x
    faster than scipy's feature transform on a 512^3 scan (benchmarks/bench_ct.py)."""
    return edt(binary)


def grow_labels(labels, distance=1.5):
    """Grow labels by ``distance`` [voxels] into the background (0): each background voxel within
    ``distance`` of a labelled voxel takes the label of the nearest one (ties: the larger label).
    Same result as :func:`skimage.segmentation.expand_labels` up to ties, without a feature
    transform of the whole volume: one compiled pass (:func:`._kernels.grow_kernel`) that looks at
    the shells of equal distance in turn (two shells, 6 face and 12 edge neighbours, for the
    default 1.5)."""
    k = int(np.floor(distance))
    g = np.mgrid[-k:k + 1, -k:k + 1, -k:k + 1].reshape(3, -1)
    d2 = (g ** 2).sum(0)
    sel = np.flatnonzero((d2 > 0) & (d2 <= distance ** 2))
    sel = sel[np.argsort(d2[sel], kind="stable")]
    r2 = d2[sel]
    start = np.r_[0, np.flatnonzero(np.diff(r2)) + 1, len(sel)].astype(np.int64)
    lab = np.ascontiguousarray(labels)
    out = lab.copy()
    if len(sel):
        grow_kernel(lab, out, start, *(np.ascontiguousarray(g[a, sel]).astype(np.int64) for a in range(3)))
    return out


def _peak_markers(dist):
    """Regional maxima of a distance map (plateau-exact, 26-connected), each labelled: the seeds of
    an over-segmentation that :func:`_merge_shallow_basins` reduces to the h-maxima partition.
    (Seeding at every voxel equal to its 3x3x3 maximum is 2x faster but adds non-maximal plateau
    pieces whose basins go whole to one neighbour: 99.4 % instead of 99.8 % of voxels as the
    reference, centroid error 0.083 instead of 0.078 voxel on the test packing.)
    Returns (markers int32, count)."""
    from skimage.morphology import local_maxima
    peaks = local_maxima(dist, connectivity=3, allow_borders=True)
    peaks &= dist > 0
    lab, n = ndimage.label(peaks, structure=np.ones((3, 3, 3)))
    return lab.astype(np.int32, copy=False), n


def face_pairs(labels, connectivity=1):
    """Adjacent voxel pairs carrying two different non-zero labels.

    connectivity : 1 = face neighbours (3 offsets), 3 = face, edge and corner neighbours (13 offsets;
    each pair is listed once).
    Returns (la, lb, ia, ib, axis): the two labels, the flat (C-order) indices of the two voxels and,
    for face pairs, the axis (0, 1, 2 = z, y, x) along which ``ib`` follows ``ia`` (-1 otherwise).
    Vectorised: one comparison of the flat volume with itself shifted per offset; pairs that wrap
    around a row or a slice are dropped afterwards."""
    nz, ny, nx = labels.shape
    flat = np.ascontiguousarray(labels).ravel()
    offsets = [np.subtract(o, 1) for o in np.ndindex(3, 3, 3)]
    offsets = [o for o in offsets if 0 < np.abs(o).sum() <= connectivity and tuple(o) > (0, 0, 0)]
    la, lb, ia, ib, ax_ = [], [], [], [], []
    for dz, dy, dx in offsets:
        k = int(dz * ny * nx + dy * nx + dx)                      # > 0: one of each +-pair
        i = np.flatnonzero(flat[:-k] != flat[k:])
        a, b = flat[i], flat[i + k]
        ok = (a > 0) & (b > 0)
        i, a, b = i[ok], a[ok], b[ok]
        if dy or dx:
            y, x = (i // nx) % ny + dy, i % nx + dx
            ok = (y >= 0) & (y < ny) & (x >= 0) & (x < nx)
            i, a, b = i[ok], a[ok], b[ok]
        la.append(a)
        lb.append(b)
        ia.append(i)
        ib.append(i + k)
        face = abs(dz) + abs(dy) + abs(dx) == 1
        ax_.append(np.full(len(i), int(np.argmax((dz, dy, dx))) if face else -1, np.int8))
    return tuple(np.concatenate(v) for v in (la, lb, ia, ib, ax_))


def default_h(height, seeds, n) -> float:
    """The default merge height [voxels] of :func:`segment`: 1 voxel, or 0.15 x the upper quartile
    of the regional maxima's peaks of ``height`` (seeds labelled 1..n) when that is lower."""
    if n == 0:
        return 1.0
    at = np.flatnonzero(seeds)
    peak = np.zeros(n + 1, np.float64)
    np.maximum.at(peak, seeds.ravel()[at], height.ravel()[at])
    return float(min(1.0, 0.15 * np.percentile(peak[1:], 75)))


def _merge_shallow_basins(basins, height, h, seeds):
    """Merge the watershed basins of the regional maxima of ``height`` [voxels] that are not
    h-maxima: a basin whose peak is at most ``h`` above the highest saddle (26-connected, as in the
    reconstruction) joining it to a basin with a higher peak is merged into that basin (union-find
    over the basin adjacency graph, saddles in decreasing order). This gives the grains of a marker
    watershed seeded by the h-maxima of ``height`` without the morphological reconstruction of the
    whole volume; a basin that is not an h-maximum goes whole to the neighbour across its highest
    saddle (the seeded watershed would flood it from all its neighbours).

    basins : int labels (0 = background), consecutive from 1, grown from the labelled regional maxima
    ``seeds`` (same labels); height : float map of the same shape.
    Returns int32 labels, consecutive from 1 (in the order of the label of each group's highest basin).
    """
    n = int(basins.max())
    if n == 0:
        return basins.astype(np.int32)
    flat_h = height.ravel()
    at = np.flatnonzero(seeds)
    peak = np.zeros(n + 1, np.float64)
    np.maximum.at(peak, seeds.ravel()[at], flat_h[at])
    # every 26-connected pair of basins with its highest saddle (one compiled pass)
    keys, saddle, base = basin_saddles(np.ascontiguousarray(basins), np.ascontiguousarray(height))
    key, inv = np.unique(keys, return_inverse=True)
    s = np.full(len(key), -np.inf)
    np.maximum.at(s, inv, saddle)
    ki, kj = (key // base).tolist(), (key % base).tolist()
    parent = list(range(n + 1))
    top = peak.tolist()
    s = s.tolist()

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for e in np.argsort(-np.asarray(s), kind="stable").tolist():
        a, b = find(ki[e]), find(kj[e])
        if a != b and min(top[a], top[b]) - s[e] <= h:
            if top[a] < top[b]:
                a, b = b, a
            parent[b] = a
            top[a] = max(top[a], top[b])
    roots = np.array([find(x) for x in range(n + 1)], np.int64)
    roots[0] = 0
    _, lut = np.unique(roots, return_inverse=True)
    return lut.astype(np.int32)[basins]


def _hull_ratio(labels, n, nvox=None) -> np.ndarray:
    """Volume of the convex hull of each grain's voxel centres divided by its voxel count (labels
    1..n). Convex grains have nearly the same value (set by discretisation); two grains merged into
    one label have a larger one (the hull bridges the gap between them). Only voxels that are not the
    midpoint of two voxels of their grain along any of the 13 lattice directions can be hull
    vertices (:func:`._kernels.extreme_candidates`); they are found for all grains at once and Qhull
    gets those."""
    from scipy.spatial import ConvexHull, QhullError
    ends = extreme_candidates(np.ascontiguousarray(labels))
    pts = np.argwhere(ends).astype(np.float64)
    lab = labels[ends]
    del ends
    order = np.argsort(lab, kind="stable")
    pts, lab = pts[order], lab[order]
    start = np.searchsorted(lab, np.arange(1, n + 2))
    if nvox is None:
        nvox = np.bincount(labels.ravel(), minlength=n + 1)[1:]
    out = np.full(n, np.nan)
    for k in np.flatnonzero(nvox >= 20):
        try:
            # QJ: joggled input, no coplanar bookkeeping for lattice points (2x faster, same volume
            # to 1e-9)
            out[k] = ConvexHull(pts[start[k]:start[k + 1]], qhull_options="QJ").volume / nvox[k]
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
    # voxel count, bounding box, largest distance-map value: one compiled pass
    cnt, box, peak = label_stats(np.ascontiguousarray(labels), np.ascontiguousarray(dist, dtype=np.float32), n)
    nvox, bbox, inscribed = cnt[1:], box[1:], peak[1:]
    # partial-volume centroid and volume over each grain's region (grain + nearest pore voxels):
    # the solid fraction of Segmentation.raw_fraction summed on the fly (same sums as
    # ndimage.sum_labels and center_of_mass of that volume)
    reg = seg.grain_regions()
    sums = region_sums(np.ascontiguousarray(reg), np.ascontiguousarray(scan.volume), seg.pore_level,
                       seg.solid_level, n)[1:]
    vol = sums[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        cz, cy, cx = (sums[:, 1:] / vol[:, None]).T
    world = scan.to_world(np.column_stack([cz, cy, cx]))
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
    hull = _hull_ratio(labels, n, nvox)
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
                         normals: bool = True, dist=None, fraction=None) -> pd.DataFrame:
    """Contacts between labelled grains (seed 001 §2.2).

    Every pair of face-adjacent voxels carrying two different grain labels contributes one contact
    element at the midpoint of the shared face. A pair (i, j) with more than ``min_voxels`` elements
    is a contact. Its normal is the direction of least variance of its elements (principal-component
    analysis), oriented from grain i to grain j; with fewer than 3 elements, or a degenerate cloud, the
    branch vector (centroid j - centroid i) is used and ``normal_from`` says so.

    Returns a DataFrame: ``i``, ``j`` (labels, i < j), ``n_voxels``, ``area`` [m^2], contact point
    ``px, py, pz`` [m], normal ``nx, ny, nz``, ``normal_from`` ("pca" or "branch"); with a distance
    map ``dist`` [voxels] also ``saddle``, its largest value across the shared face [voxels]; with a
    solid-fraction volume ``fraction`` (e.g. :meth:`Segmentation.local_fraction`) also
    ``saddle_fraction``, the largest solid fraction at the shared face (mean of the two voxels of an
    element): the level of a local threshold at which the two grains are still connected.
    """
    vs = scan.voxel_size
    la, lb, ia, ib, ax = face_pairs(labels)
    i, j = np.minimum(la, lb).astype(np.int64), np.maximum(la, lb).astype(np.int64)
    del la, lb
    # contact element: the midpoint of the shared face, (z, y, x) voxel coordinates
    p = np.column_stack(np.unravel_index(ia, labels.shape)).astype(np.float64)
    p[np.arange(len(ia)), ax] += 0.5
    sad = None if dist is None else np.minimum(dist.ravel()[ia], dist.ravel()[ib])
    fsad = None if fraction is None else 0.5 * (fraction.ravel()[ia] + fraction.ravel()[ib])
    del ia, ib, ax
    cols = ["i", "j", "n_voxels", "area", "px", "py", "pz", "nx", "ny", "nz", "normal_from"]
    if not len(i):
        return pd.DataFrame(columns=cols)
    base = int(labels.max()) + 1
    uk, inv, cnt = np.unique(i * base + j, return_inverse=True, return_counts=True)
    i, j = uk // base, uk % base
    mean = np.stack([np.bincount(inv, p[:, k]) for k in range(3)], -1) / cnt[:, None]
    out = pd.DataFrame({"i": i, "j": j, "n_voxels": cnt, "area": cnt * vs ** 2})
    world = scan.to_world(mean)
    out["px"], out["py"], out["pz"] = world[:, 0], world[:, 1], world[:, 2]
    if dist is not None:
        saddle = np.zeros(len(uk))
        np.maximum.at(saddle, inv, sad)
        out["saddle"] = saddle
    if fsad is not None:
        fs = np.full(len(uk), -np.inf)
        np.maximum.at(fs, inv, fsad)
        out["saddle_fraction"] = fs
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
