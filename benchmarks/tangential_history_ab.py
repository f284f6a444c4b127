"""The Mindlin spring's history, displacement against force, on several packings (issue #14 item 5).

    .venv/bin/python benchmarks/tangential_history_ab.py [--seeds 1 2 3 4 5] [--yade-seeds 1 2]
        [--runs benchmarks/runs-tangential] [--case cases/plane_shear_tangential.yaml]

The case (L0 physics) runs on LAMMPS with ``contact.tangential_history: displacement`` (its
``mindlin``, as LIGGGHTS) and ``force`` (its ``mindlin/force``, as YADE), on LIGGGHTS
(displacement) and on YADE (force), every engine on the same packings. Per run it prints the steady
μ_macro (strain ≥ the case's ``steady_from``) and the sample's height change Δh/h0 [%] from the start
of shear, at γ = 0.3 and as the mean over the steady window; then per arm the mean ± sem over the
packings, and LAMMPS' force − displacement difference seed by seed (paired: the same packing, the
same engine, only the history differs). Runs are reused when complete.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from orchestrator.case import load_case
from orchestrator.frames import Frames
from orchestrator.runner import run_case
from orchestrator.scenes.plane_shear import mu_macro_series, steady_mu

HERE = Path(__file__).resolve().parent
ARMS = (("lammps", "displacement"), ("lammps", "force"), ("liggghts", None), ("yade", None))


def height_change(run_dir, steady_from: float) -> dict:
    """Δh/h0 [%] of the sample from the start of shear: at γ = 0.3 and the mean over γ ≥ steady_from."""
    df = mu_macro_series(Frames(run_dir))
    sh = df[df.strain > 0]
    z0 = float(sh.z_top.iloc[0])
    dh = 100 * (sh.z_top.to_numpy() - z0) / z0
    k = int(np.argmin(np.abs(sh.strain.to_numpy() - 0.3)))
    return {"at_0.3": float(dh[k]), "steady_mean": float(dh[sh.strain.to_numpy() >= steady_from].mean())}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--case", default=str(HERE.parent / "cases" / "plane_shear_tangential.yaml"))
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5])
    ap.add_argument("--yade-seeds", type=int, nargs="*", default=[1, 2])
    ap.add_argument("--runs", default=str(HERE / "runs-tangential"))
    a = ap.parse_args(argv)
    rows = []
    for eng, hist in ARMS:
        for seed in (a.yade_seeds if eng == "yade" else a.seeds):
            ov = {"seed": seed, **({"contact": {"tangential_history": hist}} if hist else {})}
            case = load_case(a.case, overrides=ov)
            out = run_case(case, eng, runs_root=a.runs, progress=False, analyze=False)
            if out.status != "complete":
                print(f"{eng} {hist or ''} seed {seed}: {out.status}")
                continue
            st = steady_mu(Frames(out.run_dir))
            h = height_change(out.run_dir, case.scene.steady_from)
            arm = f"{eng}" + (f" ({hist})" if hist else "")
            rows.append({"arm": arm, "seed": seed, "mu": st["mu"], **h})
            print(f"{arm:24s} seed {seed}: mu {st['mu']:.4f}  dh/h0 at 0.3 {h['at_0.3']:+.2f} %  "
                  f"steady mean {h['steady_mean']:+.2f} %   {out.run_dir}")
    print()
    print(f"{'arm':24s} {'n':>2s} {'mu (± sem)':>18s} {'dh/h0 steady mean [%] (± sem)':>32s}")
    for arm in dict.fromkeys(r["arm"] for r in rows):
        g = [r for r in rows if r["arm"] == arm]
        for key in ("mu", "steady_mean"):
            v = np.array([r[key] for r in g])
            g[0][key + "_stat"] = (v.mean(), v.std(ddof=1) / math.sqrt(len(v)) if len(v) > 1 else math.nan)
        mu, dh = g[0]["mu_stat"], g[0]["steady_mean_stat"]
        print(f"{arm:24s} {len(g):2d} {mu[0]:10.4f} ± {mu[1]:.4f} {dh[0]:+22.2f} ± {dh[1]:.2f}")
    disp = {r["seed"]: r for r in rows if r["arm"] == "lammps (displacement)"}
    force = {r["seed"]: r for r in rows if r["arm"] == "lammps (force)"}
    common = sorted(set(disp) & set(force))
    if len(common) > 1:
        print("\nLAMMPS, force - displacement, seed by seed (the same packing):")
        for key, unit in (("mu", ""), ("steady_mean", " %")):
            d = np.array([force[s][key] - disp[s][key] for s in common])
            print(f"  {key:12s} {' '.join(f'{x:+.4f}' for x in d)}   mean {d.mean():+.4f}{unit} ± "
                  f"{d.std(ddof=1) / math.sqrt(len(d)):.4f} (sem, {len(d)} packings)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
