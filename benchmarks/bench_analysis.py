"""Benchmark of the heavy analysis measures on 100 000 particles, one core (not a test).

    OMP_NUM_THREADS=1 OVITO_THREAD_COUNT=1 python benchmarks/bench_analysis.py [N]

Prints seconds per measure for orchestrator.analysis and, when ``ovito`` is importable, for the
equivalent OVITO modifier on the same data (in units of the particle diameter, as OVITO needs)
and the ratio ours/OVITO (target <= 1). Best of ``REPEAT`` runs each.
"""
from __future__ import annotations

import os
import sys
import time

os.environ.setdefault("OVITO_THREAD_COUNT", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")
sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import numpy as np  # noqa: E402

from orchestrator.analysis.clusters import cluster_properties, find_clusters, fractal_dimension, powerlaw_fit  # noqa: E402
from orchestrator.analysis.containers import infer_container  # noqa: E402
from orchestrator.analysis.coordination import coordination_from_pairs, neighbor_counts  # noqa: E402
from orchestrator.analysis.d2min import d2min  # noqa: E402
from orchestrator.analysis.neighbors import geometric_contacts  # noqa: E402
from orchestrator.analysis.rdf import rdf  # noqa: E402

D = 30e-6
REPEAT = 2


def packing(n: int, seed: int = 0):
    """Jittered fcc packing (volume fraction ~0.6) cut to an upright cylinder, radii 0.45..0.5 d."""
    rng = np.random.default_rng(seed)
    a = (4 * np.pi / 6 / 0.60) ** (1 / 3) * D            # fcc cell edge for phi = 0.60 with d = D
    m = int(np.ceil((n / 4 / (np.pi / 4)) ** (1 / 3))) + 2
    g = np.arange(m)
    cells = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    base = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]])
    p = ((cells[:, None, :] + base[None]).reshape(-1, 3)) * a
    c = 0.5 * m * a
    p = p[np.hypot(p[:, 0] - c, p[:, 1] - c) <= 0.5 * m * a]
    p = p[np.argsort(p[:, 2], kind="stable")][:n]
    p = p + rng.normal(scale=0.05 * D, size=p.shape)
    r = rng.uniform(0.45, 0.5, len(p)) * D
    return p, r


def best(f, repeat=REPEAT):
    t = []
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = f()
        t.append(time.perf_counter() - t0)
    return min(t), out


def main(n=100_000):
    p0, rad = packing(n)
    rng = np.random.default_rng(1)
    F = np.eye(3) + 0.01 * rng.normal(size=(3, 3))
    p1 = p0 @ F.T + 0.02 * D * rng.normal(size=p0.shape)
    n = len(p0)
    print(f"{n} particles, one core; best of {REPEAT}")
    ours = {}

    ours["d2min + local strain (1.5 d)"] = best(lambda: d2min(p0, p1, 1.5 * D))
    box = infer_container(p0)
    ours["g(r) to 5 d, 100 bins, edge-corrected"] = best(lambda: rdf(p0, 5 * D, 100, box))
    ours["coordination: neighbours within 1.05 d"] = best(lambda: neighbor_counts(p0, 1.05 * D))

    def contacts():
        i, j = geometric_contacts(p0, rad, tolerance=0.05)
        return coordination_from_pairs(n, i, j)
    ours["coordination: polydisperse contacts"] = best(contacts)
    dm = ours["d2min + local strain (1.5 d)"][1]["d2min"]
    thr = np.nanquantile(dm, 0.9)
    sel = np.isfinite(dm) & (dm >= thr)

    def clusters():
        lab = find_clusters(p0, sel, 1.5 * D)
        cp = cluster_properties(p0, 4 / 3 * np.pi * rad ** 3, lab)
        return cp, powerlaw_fit(cp["size"]), fractal_dimension(cp["size"], cp["rg"])
    ours["clusters top 10 % (1.5 d) + Rg + fits"] = best(clusters)

    ov = {}
    try:
        import ovito  # noqa: F401
        from ovito.data import DataCollection
        from ovito.modifiers import (AtomicStrainModifier, ClusterAnalysisModifier, CoordinationAnalysisModifier,
                                     ExpressionSelectionModifier)
        from ovito.pipeline import Pipeline, StaticSource
    except ImportError:
        ovito = None
    if ovito is not None:
        s0, s1 = p0 / D, p1 / D
        lo = s0.min(0) - 1
        hi = s0.max(0) + 1

        def dc(p, extra=None):
            d = DataCollection()
            m = np.zeros((3, 4))
            m[:, :3] = np.diag(hi - lo + 2)
            m[:, 3] = lo - 1
            d.create_cell(m, pbc=(False, False, False))
            pa = d.create_particles(count=len(p))
            pa.create_property("Position", data=p)
            if extra is not None:
                pa.create_property("Selection", data=extra.astype(np.int32))
            return d

        d0, d1 = dc(s0), dc(s1)

        def ov_strain():
            pipe = Pipeline(source=StaticSource(data=d1))
            mod = AtomicStrainModifier(cutoff=1.5, output_nonaffine_squared_displacements=True)
            mod.reference = StaticSource(data=d0)
            pipe.modifiers.append(mod)
            return pipe.compute()
        ov["d2min + local strain (1.5 d)"] = best(ov_strain)

        def ov_coord(cut, bins):
            pipe = Pipeline(source=StaticSource(data=d0))
            pipe.modifiers.append(CoordinationAnalysisModifier(cutoff=cut, number_of_bins=bins))
            return pipe.compute()
        ov["g(r) to 5 d, 100 bins, edge-corrected"] = best(lambda: ov_coord(5.0, 100))
        ov["coordination: neighbours within 1.05 d"] = best(lambda: ov_coord(1.05, 10))
        dsel = dc(s0, sel)

        def ov_clusters():
            pipe = Pipeline(source=StaticSource(data=dsel))
            pipe.modifiers.append(ClusterAnalysisModifier(cutoff=1.5, only_selected=True, compute_gyration=True,
                                                          compute_com=True, sort_by_size=True))
            return pipe.compute()
        ov["clusters top 10 % (1.5 d) + Rg + fits"] = best(ov_clusters)

    w = max(len(k) for k in ours)
    print(f"{'measure':<{w}}  {'ours [s]':>9}  {'OVITO [s]':>9}  {'ratio':>6}")
    for k, (t, _) in ours.items():
        if k in ov:
            to = ov[k][0]
            print(f"{k:<{w}}  {t:9.3f}  {to:9.3f}  {t / to:6.2f}")
        else:
            print(f"{k:<{w}}  {t:9.3f}  {'-':>9}  {'-':>6}")
    if ovito is None:
        print("(ovito not importable: no ratios)")
    else:
        print("notes: OVITO's g(r) has no edge correction; its coordination row counts neighbours within a fixed cutoff "
              "(the polydisperse contact row has no OVITO equivalent); OVITO's cluster row excludes the P(s)/d_f fits.")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 100_000)
