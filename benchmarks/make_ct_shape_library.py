"""Regenerate the clump shape library measured by the CT side on synthetic sand-like grains.

    OMP_NUM_THREADS=1 python benchmarks/make_ct_shape_library.py [--out cases/shapes/ct_synthetic.yaml]
                                                                 [--grains 36] [--spheres 8] [--seed 0]

A scan of irregular grains (random spherical-harmonic shapes of degree 15, ``synth.random_sh_grains``,
rougher than the CT tests' grains) is rendered with partial volume, PSF blur and noise as the CT
tests do, segmented with ``orchestrator.ct.segment.segment``, and every grain that is not cut by the
scan border (nor flagged, nor under ``--min-voxels``) is fitted by overlapping spheres
(``orchestrator.ct.clumpfit.fit_clump``). The library is written with its provenance (seed, scan
and segmentation parameters, counts, per-shape quality) under ``meta:`` and ``quality:``, checked by
``orchestrator.clumps.load_library``, and the quality table quoted in docs/ct.md ("Clump shape
libraries from CT") is printed. About 25 s of CPU on one core.

The file name starts with "_": every other YAML under cases/ is loaded as a case by the tests.
"""
import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
from scipy.spatial import cKDTree

from orchestrator.clumps import load_library
from orchestrator.ct import clumpfit, segment, synth

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "cases" / "shapes" / "ct_synthetic.yaml"

# the scan: voxel edge [m], grains (mean radius [voxels], roughness, degree), acquisition as the CT tests
VOXEL = 1e-5
R0, ROUGHNESS, DEGREE = 12.0, 0.15, 15
PSF, NOISE, SUPERSAMPLE = 0.8, 0.08, 3
PACKING = 0.3            # solid fraction of the grains' bounding spheres (grains do not touch)
# marker height of the segmentation [voxels]: the grains do not touch, so a height above the default
# 1 voxel costs nothing; at 1 voxel one of the 36 grains (seed 0) was cut in two at a neck, unflagged
H_VOXELS = 2.0


def render(n_grains, seed):
    """Scan of ``n_grains`` irregular grains placed without contact in a cube; a few stick out of it
    (cut by the field of view, as in a real scan). Returns the scan, true centres [m], scan edge [voxels]."""
    coefs = synth.random_sh_grains(n_grains, R0 * VOXEL, degree=DEGREE, roughness=ROUGHNESS, seed=seed)
    radials = [synth._GridRadial(c, DEGREE) for c in coefs]
    rmax = np.array([r.rmax for r in radials])
    edge = int(np.ceil(np.cbrt(np.sum(4 / 3 * np.pi * (rmax / VOXEL + 1) ** 3) / PACKING)))
    box = ((-3 * VOXEL,) * 3, ((edge + 2) * VOXEL,) * 3)           # a little wider than the scan
    centres = synth.pack_spheres(rmax + VOXEL, box=box, seed=seed + 1)
    rng = np.random.default_rng(seed + 2)
    grains = [synth.Grain(c, r.rmax, r, synth._random_rotation(rng)) for c, r in zip(centres, radials)]
    scan = synth.render_scan((edge,) * 3, VOXEL, None, grains=grains, supersample=SUPERSAMPLE,
                             psf_sigma=PSF, noise=NOISE, seed=seed + 3)
    return scan, centres, edge


def summary_lines(q, n_seg, n_used, counts):
    """The quality table of docs/ct.md: median and extremes over the shapes."""
    lines = [f"grains segmented {n_seg}: {counts['at_border']} at the scan border, {counts['small']} under "
             f"min_voxels, {counts['flagged']} flagged; {n_used} shapes",
             f"{'figure':<24}{'median':>9}{'min':>9}{'max':>9}"]
    for k in ("volume_ratio", "coverage", "outside", "n_spheres", "radius_ratio"):
        v = q[k].to_numpy()
        lines.append(f"{k:<24}{np.median(v):>9.3f}{v.min():>9.3f}{v.max():>9.3f}")
    lines.append(f"{'grain vs clump':<24}{'grain':>9}{'clump':>9}{'|diff| med':>11}{'max':>8}")
    for k in ("sphericity", "elongation", "flatness", "hull_ratio"):
        g, c = q[f"{k}_grain"].to_numpy(), q[f"{k}_clump"].to_numpy()
        lines.append(f"{k + ' (median)':<24}{np.median(g):>9.3f}{np.median(c):>9.3f}"
                     f"{np.median(np.abs(c - g)):>11.3f}{np.abs(c - g).max():>8.3f}")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--grains", type=int, default=36, help="grains rendered (some are cut by the scan border)")
    ap.add_argument("--spheres", type=int, default=8, help="most spheres per clump")
    ap.add_argument("--coverage", type=float, default=0.97, help="covered fraction at which a fit stops")
    ap.add_argument("--min-voxels", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)

    t0 = time.perf_counter()
    scan, centres, edge = render(a.grains, a.seed)
    t1 = time.perf_counter()
    seg = segment.segment(scan, h=H_VOXELS * VOXEL)
    t2 = time.perf_counter()
    g = seg.grains
    keep = clumpfit.library_grains(g, a.min_voxels)
    shapes, q = clumpfit.shape_library_from_labels(seg.labels, VOXEL, g[keep], n_spheres=a.spheres, coverage=a.coverage)
    t3 = time.perf_counter()
    # each shape's true grain: the nearest rendered centre (a check of the segmentation, not of the fit)
    dist, true = cKDTree(centres).query(g.loc[keep, ["x", "y", "z"]].to_numpy())
    q.insert(2, "true_grain", true)
    split = int((np.bincount(true) > 1).sum())           # a true grain in two labels: halves in the library
    counts = {"at_border": int(g["at_border"].sum()),
              "small": int((~g["at_border"] & (g["n_voxels"] < a.min_voxels)).sum()),
              "flagged": int((~g["at_border"] & (g["n_voxels"] >= a.min_voxels) & (g["flag"] != "")).sum())}
    lines = summary_lines(q, len(g), len(shapes), counts)
    meta = {"generator": "benchmarks/make_ct_shape_library.py",
            "regenerate": f"python benchmarks/make_ct_shape_library.py --grains {a.grains} --spheres {a.spheres} "
                          f"--seed {a.seed}",
            "method": "orchestrator.ct.clumpfit.fit_clump: greedy cover by maximal inscribed spheres of the EDT "
                      "(Euclidean map, Angelidakis et al. 2021, SoftwareX 15:100735) + refinement of the union",
            "seed": a.seed,
            "scan": {"shape_voxels": [edge] * 3, "voxel_size": VOXEL, "grains_rendered": a.grains,
                     "grain_radius_voxels": R0, "sh_degree": DEGREE, "roughness": ROUGHNESS, "psf_sigma_voxels": PSF,
                     "noise_of_contrast": NOISE, "supersample": SUPERSAMPLE},
            "segment": {k: v for k, v in seg.params.items() if v is not None},
            "fit": {"n_spheres": a.spheres, "coverage": a.coverage, "min_voxels": a.min_voxels, "skip_flagged": True},
            "counts": {"segmented": len(g), **counts, "shapes": len(shapes), "true_grains_split": split,
                       "largest_centroid_offset_voxels": float(dist.max() / VOXEL)},
            "quality_median": {k: float(q[k].median()) for k in ("volume_ratio", "coverage", "outside")},
            "quality_min": {k: float(q[k].min()) for k in ("volume_ratio", "coverage")}}
    comment = ("Clump shape library measured by the CT side on synthetic sand-like grains (issue #15 item 2).\n"
               "Regenerate: python benchmarks/make_ct_shape_library.py (docs/ct.md, 'Clump shape libraries from CT').\n"
               "Spheres [x, y, z, r] in metres about each grain's centroid; scene.particles.library rescales them.\n"
               "Per shape, 'quality' compares the union of the spheres with the segmented grain voxel for voxel.\n\n"
               + "\n".join(lines))
    clumpfit.write_shape_library(a.out, shapes, q["name"], meta=meta, quality=q, comment=comment)
    lib = load_library(a.out)               # validates every shape (orchestrator.clumps.check_shape)
    assert len(lib) == len(shapes)
    print("\n".join(lines))
    print(f"against the rendered grains: {split} split into several labels, largest centroid offset "
          f"{dist.max() / VOXEL:.2f} voxel")
    print(f"times [s]: render {t1 - t0:.1f}, segment {t2 - t1:.1f}, fit {t3 - t2:.1f} ({len(shapes)} grains); "
          f"total {time.perf_counter() - t0:.1f}")
    print(f"wrote {a.out} ({len(lib)} shapes; loads with orchestrator.clumps.load_library)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
