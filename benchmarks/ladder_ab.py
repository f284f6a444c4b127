"""Two ladders of the same scene that differ in one case field, packing by packing (docs/crossval.md):
what switching the field does on each engine, and how far apart the engines are in each ladder.

    .venv/bin/python benchmarks/ladder_ab.py A/ladder/ladder_runs.csv B/ladder/ladder_runs.csv [--rung L0]

e.g. A = ``shear_cell_small`` (the tangential dashpot on), B = ``shear_cell_small_no_tangential_damping``.
For each observable and engine it prints the mean of B − A over the packings both ladders ran on
that engine, relative to A's mean, with twice its standard error (paired: 2 s_d/√n); then each
packing's μ_macro in both. A change smaller than its 2 sem is not resolved by these packings.
"""
from __future__ import annotations

import argparse
import math

import pandas as pd

OBSERVABLES = ("mu_macro", "shearband_z", "shearband_width", "piston_z")


def paired_change(a: pd.DataFrame, b: pd.DataFrame, engine: str, obs: str) -> tuple[int, float, float]:
    """(packings, mean relative change (B − A)/mean(A), 2 sem of it) of ``obs`` on ``engine``."""
    va = a[a["engine"] == engine].set_index("seed")[obs].dropna()
    vb = b[b["engine"] == engine].set_index("seed")[obs].dropna()
    seeds = sorted(set(va.index) & set(vb.index))
    if not seeds:
        return 0, math.nan, math.nan
    d = (vb.loc[seeds] - va.loc[seeds]) / va.loc[seeds].mean()
    sem2 = 2 * d.std(ddof=1) / math.sqrt(len(d)) if len(d) > 1 else math.nan
    return len(seeds), float(d.mean()), float(sem2)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("a")
    ap.add_argument("b")
    ap.add_argument("--rung", default="L0")
    args = ap.parse_args(argv)
    a, b = (pd.read_csv(p) for p in (args.a, args.b))
    a, b = (t[(t["rung"] == args.rung) & (t["status"] == "complete")] for t in (a, b))
    engines = sorted(set(a["engine"]) & set(b["engine"]))
    print(f"B − A, packing by packing, relative to A's mean (A = {args.a}, B = {args.b}, rung {args.rung})\n")
    print("| observable | " + " | ".join(engines) + " |")
    print("|---|" + "---|" * len(engines))
    for obs in OBSERVABLES:
        cells = []
        for eng in engines:
            n, m, s = paired_change(a, b, eng, obs)
            cells.append(f"{100 * m:+.1f} % ± {100 * s:.1f} % ({n})" if n else "–")
        print(f"| {obs} | " + " | ".join(cells) + " |")
    print("\n| packing | " + " | ".join(f"μ_macro {e} A / B" for e in engines) + " |")
    print("|---|" + "---|" * len(engines))
    for seed in sorted(set(a["seed"]) & set(b["seed"])):
        cells = []
        for eng in engines:
            va = a[(a["engine"] == eng) & (a["seed"] == seed)]["mu_macro"]
            vb = b[(b["engine"] == eng) & (b["seed"] == seed)]["mu_macro"]
            cells.append(f"{va.iloc[0]:.3f} / {vb.iloc[0]:.3f}" if len(va) and len(vb) else "–")
        print(f"| {seed} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
