"""CT benchmark (not a test): linking speed vs trackpy, contact detection on packings with known contacts,
and segmentation of a 512^3 scan on one core.

    OMP_NUM_THREADS=1 python3 benchmarks/bench_ct.py [--size 512] [--skip-segment] [--skip-link]
                                                      [--skip-contacts] [--cache scan512.npy]

Prints the figures quoted in docs/ct.md.
"""
import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from orchestrator.ct import segment, synth, track
from orchestrator.ct.io import Scan


def bench_link(n=16000, seed=0, repeat=7):
    """Linking of n touching grains after a shear step (largest 0.3 d), ours and trackpy.link
    alternating ``repeat`` times in the same process, best time of each (issue 17: >= 10x)."""
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.8, 1.2, n) * 5e-5
    L = (np.sum(4 / 3 * np.pi * r ** 3) / 0.5) ** (1 / 3)
    a = synth.pack_spheres(r, box=((0, 0, 0), (L, L, L)), seed=seed)
    d = 2 * np.median(r)
    b = a.copy()
    b[:, 0] += 0.3 * d * a[:, 2] / L
    b += rng.normal(0, 0.05 * d, b.shape)
    perm = rng.permutation(n)
    b = b[perm]
    try:
        import trackpy as tp
        tp.quiet()
    except ImportError:
        tp = None
    df = pd.DataFrame({"x": np.r_[a[:, 0], b[:, 0]], "y": np.r_[a[:, 1], b[:, 1]], "z": np.r_[a[:, 2], b[:, 2]],
                       "frame": np.r_[np.zeros(n, int), np.ones(n, int)], "true": np.r_[np.arange(n), perm]})
    t_ours, t_tp, lk, out = [], [], None, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        lk = track.link(a, b, 0.5 * d)
        t_ours.append(time.perf_counter() - t0)
        if tp is not None:
            t0 = time.perf_counter()
            out = tp.link(df, search_range=0.5 * d, memory=0, pos_columns=["x", "y", "z"])
            t_tp.append(time.perf_counter() - t0)
    acc = np.mean(perm[lk.a_to_b] == np.arange(n))
    print(f"link: {n} grains, largest step 0.3 d: {min(t_ours) * 1e3:.1f} ms (best of {repeat}), {acc:.4%} correct")
    if tp is None:
        print("trackpy not installed: no comparison (pip install trackpy)")
        return
    g = out.groupby("particle")["true"].agg(["count", "nunique"])
    acc_tp = ((g["count"] == 2) & (g["nunique"] == 1)).sum() / n
    print(f"link: trackpy {tp.__version__} link {min(t_tp) * 1e3:.1f} ms (best of {repeat}, alternating), "
          f"{acc_tp:.4%} correct -> ours is {min(t_tp) / min(t_ours):.1f}x faster")


def bench_contacts(seed=0):
    """Contact detection on rendered packings with known contacts (issue 17 item 1): precision and
    recall of face-adjacent labels alone and after the local greyscale test, coordination numbers
    and normal errors, over PSF, noise and grain size."""
    vs = 1e-5
    print("contacts: packing with known contacts (synth.contact_packing: DEM overlaps <= 1 % of the radii sum, "
          "other pairs >= 0.5 voxel apart), 96^3 voxels")
    print(f"{'grains [vox]':>12} {'PSF':>4} {'noise':>5} {'true':>5} {'cand':>5} {'P cand':>6} {'P':>6} {'R':>6} "
          f"{'Z true':>6} {'Z cand':>6} {'Z ref':>6} {'normal err med/p90 [deg]':>24}")
    for rr, psf, noise in [((4.0, 5.0), 0.5, 0.03), ((5.0, 6.0), 0.8, 0.06), ((5.0, 7.5), 0.8, 0.10),
                           ((6.0, 8.0), 0.8, 0.06), ((6.0, 8.0), 1.2, 0.10), ((8.0, 10.0), 1.2, 0.10),
                           ((12.0, 13.4), 0.8, 0.06)]:
        c, r, con = synth.contact_packing((96,) * 3, vs, rr, seed=seed)
        scan = synth.render_scan((96,) * 3, vs, c, r, noise=noise, psf_sigma=psf, drift=0.05, seed=seed + 2,
                                 supersample=3)
        s = synth.score_contacts(segment.segment(scan), c, r, con)
        p_cand = s["recall_candidates"] * s["true"] / max(s["candidates"], 1)
        print(f"{2 * rr[0]:5.0f}-{2 * rr[1]:<6.0f} {psf:4.1f} {noise:5.2f} {s['true']:5d} {s['candidates']:5d} "
              f"{p_cand:6.3f} {s['precision']:6.3f} {s['recall']:6.3f} {s['z_true']:6.2f} {s['z_candidates']:6.2f} "
              f"{s['z_refined']:6.2f} {s['normal_err_median_deg']:11.1f} / {s['normal_err_p90_deg']:.1f}")


def bench_segment(size=512, seed=1, cache=None):
    vs = 1e-5
    rng = np.random.default_rng(seed)
    rr = (8.0, 12.0)
    n = int(0.45 * (size - 4) ** 3 / (4 / 3 * np.pi * np.mean(rr) ** 3))
    r = rng.uniform(*rr, n) * vs
    t0 = time.perf_counter()
    c = synth.pack_spheres(r, box=((2 * vs,) * 3, ((size - 2) * vs,) * 3), seed=seed)
    t1 = time.perf_counter()
    if cache and os.path.exists(cache):
        scan = Scan(np.load(cache), vs)
    else:
        scan = synth.render_scan((size,) * 3, vs, c, r, noise=0.1, psf_sigma=0.8, supersample=3)
        if cache:
            np.save(cache, scan.volume)
    t2 = time.perf_counter()
    print(f"segment: {size}^3 scan, {n} spheres {2 * rr[0]:.0f}-{2 * rr[1]:.0f} voxels across "
          f"(packing {t1 - t0:.0f} s, rendering {t2 - t1:.0f} s)")
    t0, c0 = time.perf_counter(), time.process_time()
    seg = segment.segment(scan)
    tot, cpu = time.perf_counter() - t0, time.process_time() - c0
    ws, ws_cpu = seg.timings["watershed"], seg.cpu_timings["watershed"]
    d, k = cKDTree(c).query(seg.grains[["x", "y", "z"]].to_numpy())
    ok = d < 0.5 * r[k]
    print(f"segment: {tot:.1f} s wall, {cpu:.1f} s CPU on one core; steps (CPU): "
          + ", ".join(f"{k} {v:.1f} s" for k, v in seg.cpu_timings.items()))
    print(f"segment: scikit-image watershed alone {ws_cpu:.1f} s CPU ({ws:.1f} s wall) -> whole pipeline = "
          f"{cpu / ws_cpu:.2f}x the watershed in CPU time ({tot / ws:.2f}x in wall time; floor <= 2x)")
    print(f"segment: found {len(np.unique(k[ok])) / n:.3%} of grains, median centroid error "
          f"{np.median(d[ok]) / vs:.3f} voxel")


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--skip-segment", action="store_true")
    ap.add_argument("--skip-link", action="store_true")
    ap.add_argument("--skip-contacts", action="store_true")
    ap.add_argument("--cache", help="scan .npy to reuse (written on the first run)")
    a = ap.parse_args()
    if not a.skip_link:
        bench_link()
    if not a.skip_contacts:
        bench_contacts()
    if not a.skip_segment:
        bench_segment(a.size, cache=a.cache)
