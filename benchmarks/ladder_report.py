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

from orchestrator.analysis.neighbors import geometric_contacts
from orchestrator.case import load_case
from orchestrator.frames import Frames
from orchestrator.stability.observables import observables


def run_detail(run_dir: Path) -> dict:
    """The ladder's shear-cell observables of one run with their in-run spreads
    (:func:`orchestrator.stability.observables.observables`, as the ladder computes them), and the
    last frame's grain-grain contacts with their mean and median overlap over ξ_σ (SI units)."""
    run_dir = Path(run_dir)
    out = observables(load_case(run_dir / "case.yaml"), run_dir)
    fr = Frames(run_dir / "frames.h5")
    x, r = fr.position[-1], fr.radius
    i, j = geometric_contacts(x, r)
    ov = r[i] + r[j] - np.linalg.norm(x[j] - x[i], axis=1)
    xi_s = json.loads((run_dir / "params.json").read_text())["scene"]["contact"]["expected_overlap"]
    out.update(contacts=int(ov.size), xi_mean=float(ov.mean() / xi_s), xi_median=float(np.median(ov) / xi_s))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("ladder_runs", help="ladder_runs.csv written by `orchestrator crossval --ladder`")
    a = ap.parse_args(argv)
    if not Path(a.ladder_runs).is_file():
        raise SystemExit(f"{a.ladder_runs}: no such file; give the ladder_runs.csv that "
                         "`orchestrator crossval CASE --ladder` wrote (RUNS/<case>/ladder/ladder_runs.csv)")
    runs = pd.read_csv(a.ladder_runs)
    runs = runs[runs["status"] == "complete"].sort_values(["rung", "engine", "seed"])
    print("| rung | engine | seed | μ_macro ± std (± sem, 8 blocks) | z_sb ± std over r̃ [µm] | "
          "w_sb ± std over r̃ [µm] | piston [µm] | contacts | ⟨ξ⟩/ξ_σ (median) | engine time [s] |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for _, r in runs.iterrows():
        d = run_detail(Path(r["run_dir"]))
        um = 1e6
        print(f"| {r['rung']} | {r['engine']} | {r['seed']} | {d['mu_macro']:.3f} ± {d['mu_macro_std']:.3f} "
              f"(± {d['mu_macro_sem']:.3f}) | {d.get('shearband_z', np.nan) * um:.1f} ± "
              f"{d.get('shearband_z_spread', np.nan) * um:.1f} | {d.get('shearband_width', np.nan) * um:.1f} ± "
              f"{d.get('shearband_width_spread', np.nan) * um:.1f} | "
              f"{d['piston_z'] * um:.1f} | {d['contacts']} | {d['xi_mean']:.2f} ({d['xi_median']:.2f}) | "
              f"{r['engine_time']:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
