"""CT benchmark (not a test): linking speed vs trackpy, and segmentation of a 512^3 scan on one core.

    OMP_NUM_THREADS=1 python3 benchmarks/bench_ct.py [--size 512] [--skip-segment] [--skip-link] [--cache scan512.npy]

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


def bench_link(n=16000, seed=0):
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
    t = []
    for _ in range(5):
        t0 = time.perf_counter()
        lk = track.link(a, b, 0.5 * d)
        t.append(time.perf_counter() - t0)
    ours = min(t)
    acc = np.mean(perm[lk.a_to_b] == np.arange(n))
    print(f"link: {n} grains, largest step 0.3 d: {ours * 1e3:.1f} ms (best of 5), {acc:.4%} correct")
    try:
        import trackpy as tp
        tp.quiet()
        df = pd.DataFrame({"x": np.r_[a[:, 0], b[:, 0]], "y": np.r_[a[:, 1], b[:, 1]], "z": np.r_[a[:, 2], b[:, 2]],
                           "frame": np.r_[np.zeros(n, int), np.ones(n, int)], "true": np.r_[np.arange(n), perm]})
        t0 = time.perf_counter()
        out = tp.link(df, search_range=0.5 * d, memory=0, pos_columns=["x", "y", "z"])
        ttp = time.perf_counter() - t0
        g = out.groupby("particle")["true"].agg(["count", "nunique"])
        linked = g[g["count"] == 2]
        acc_tp = (linked["nunique"] == 1).sum() / n
        print(f"trackpy.link: {ttp * 1e3:.1f} ms, {acc_tp:.4%} correct -> ours is {ttp / ours:.1f}x faster")
    except ImportError:
        print("trackpy not installed: no comparison")


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
    t0 = time.perf_counter()
    seg = segment.segment(scan)
    tot = time.perf_counter() - t0
    ws = seg.timings["watershed"]
    d, k = cKDTree(c).query(seg.grains[["x", "y", "z"]].to_numpy())
    ok = d < 0.5 * r[k]
    print(f"segment: {tot:.1f} s on one core ({tot / 60:.1f} min); steps: "
          + ", ".join(f"{k} {v:.1f} s" for k, v in seg.timings.items()))
    print(f"segment: scikit-image watershed alone {ws:.1f} s -> whole pipeline = {tot / ws:.1f}x the watershed")
    print(f"segment: found {len(np.unique(k[ok])) / n:.3%} of grains, median centroid error "
          f"{np.median(d[ok]) / vs:.3f} voxel")


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--skip-segment", action="store_true")
    ap.add_argument("--skip-link", action="store_true")
    ap.add_argument("--cache", help="scan .npy to reuse (written on the first run)")
    a = ap.parse_args()
    if not a.skip_link:
        bench_link()
    if not a.skip_segment:
        bench_segment(a.size, cache=a.cache)
