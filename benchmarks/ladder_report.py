"""Per-run detail behind a shear-cell ladder (docs/crossval.md): each observable with its own
in-run spread, for when there is one seed per engine and no seed-to-seed scatter.

    .venv/bin/python benchmarks/ladder_report.py RUNS/<case>/ladder/ladder_runs.csv

For every complete run of the ladder it prints, as a markdown table:

- μ_macro over the steady window (the case's ``friction`` analysis, as the ladder computes it),
  its standard deviation in time and the standard error of the mean from 8 block means (the
  samples are correlated; a block mean is nearly independent of the next);
- the steady band position z_sb and width w_sb (the r̃-averaged steady fits, as the ladder), with
  their spread over the radii r̃ (std);
- the final lower-piston height and the engine time;
- the grain-grain contacts of the last frame (overlap > 0 from positions and radii) and their mean
  and median overlap over the expected overlap ξ_σ the decks match substitutes at (LIGGGHTS' sjkr
  adhesion k·A(ξ), A ≈ 2π r_eff ξ, is matched to the seed's F_adh r_eff/⟨r_eff⟩ at ξ_σ, so its mean
  over the contacts is ⟨ξ⟩/ξ_σ times the seed's).

A difference between engines smaller than about twice the larger block standard error is not
resolved by one run per engine.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from orchestrator.analysis import parse_specs
from orchestrator.analysis.friction import analyze_friction
from orchestrator.analysis.shearband import analyze_shearband
from orchestrator.case import load_case
from orchestrator.frames import Frames


def block_sem(x: np.ndarray, blocks: int = 8) -> float:
    """Standard error of the mean of a correlated series from ``blocks`` contiguous block means."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if x.size < 2 * blocks:
        return float("nan")
    means = np.array([b.mean() for b in np.array_split(x, blocks)])
    return float(means.std(ddof=1) / np.sqrt(blocks))


def contact_overlaps(position: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Overlaps r_i + r_j − |x_i − x_j| > 0 [m] of every touching pair of spheres."""
    ok = ~np.isnan(position).any(1)
    x, r = position[ok], radius[ok]
    pairs = cKDTree(x).query_pairs(2 * r.max(), output_type="ndarray")
    ov = r[pairs[:, 0]] + r[pairs[:, 1]] - np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1)
    return ov[ov > 0]


def run_detail(run_dir: Path) -> dict:
    """The ladder's shear-cell observables of one run with their in-run spreads (SI units)."""
    case = load_case(run_dir / "case.yaml")
    fr = Frames(run_dir / "frames.h5")
    specs = dict(parse_specs(case.analysis))
    opts = {"torque_wall": "rotating", "force_wall": "lower_piston", "steady_control": "angle",
            "steady_from": 0.5 * case.scene.final_angle}
    opts.update(specs.get("friction", {}))
    fric = analyze_friction(fr, **opts)
    df = fric.tables["friction"]
    mu = df[df[opts["steady_control"]] >= opts["steady_from"]]["mu"].to_numpy()
    band = analyze_shearband(fr, **specs.get("shearband", {})).tables.get("steady")
    out = {"mu_macro": fric.scalars["mu_mean"], "mu_std": fric.scalars["mu_std"], "mu_sem_blocks": block_sem(mu)}
    if band is not None and len(band):
        out.update(z_sb=float(np.nanmean(band["z_sb"])), z_sb_std_r=float(np.nanstd(band["z_sb"], ddof=1)),
                   w_sb=float(np.nanmean(band["w_sb"])), w_sb_std_r=float(np.nanstd(band["w_sb"], ddof=1)))
    out["piston_z"] = float(fr.wall("lower_piston")["position_z"].iloc[-1])
    xi_s = json.loads((run_dir / "params.json").read_text())["scene"]["contact"]["expected_overlap"]
    ov = contact_overlaps(fr.position[-1], fr.radius)
    out.update(contacts=int(ov.size), xi_mean=float(ov.mean() / xi_s), xi_median=float(np.median(ov) / xi_s))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("ladder_runs", help="ladder_runs.csv written by `orchestrator crossval --ladder`")
    a = ap.parse_args(argv)
    runs = pd.read_csv(a.ladder_runs)
    runs = runs[runs["status"] == "complete"].sort_values(["rung", "engine", "seed"])
    print("| rung | engine | seed | μ_macro ± std (± sem, 8 blocks) | z_sb ± std over r̃ [µm] | "
          "w_sb ± std over r̃ [µm] | piston [µm] | contacts | ⟨ξ⟩/ξ_σ (median) | engine time [s] |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for _, r in runs.iterrows():
        d = run_detail(Path(r["run_dir"]))
        um = 1e6
        print(f"| {r['rung']} | {r['engine']} | {r['seed']} | {d['mu_macro']:.3f} ± {d['mu_std']:.3f} "
              f"(± {d['mu_sem_blocks']:.3f}) | {d.get('z_sb', np.nan) * um:.1f} ± {d.get('z_sb_std_r', np.nan) * um:.1f} | "
              f"{d.get('w_sb', np.nan) * um:.1f} ± {d.get('w_sb_std_r', np.nan) * um:.1f} | "
              f"{d['piston_z'] * um:.1f} | {d['contacts']} | {d['xi_mean']:.2f} ({d['xi_median']:.2f}) | "
              f"{r['engine_time']:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
