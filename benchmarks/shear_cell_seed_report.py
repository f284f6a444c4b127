"""Seed 000's statements against one shear-cell run (docs/validation.md, issue #15 item 2).

    python benchmarks/shear_cell_seed_report.py RUN_DIR [RUN_DIR ...]

For each complete shear-cell run it prints, with heights measured from the lower vanes' top edge
at the frame's time (seed 000 measures from there: lower plate face + vane height + the lower
piston's travel, from the run's wall series):

- the steady shear band (the run's ``shearband`` analysis, eq. 2 of seed 000: erf fit of the
  angular velocity): position z_sb above the lower vane tips and width w_sb, in µm and in x50,
  mean ± std over radii of the steady window; the seed finds w_sb ≈ 8 x50 with the band just above
  the lower vanes;
- φ(z) in the compressed state (the first shear-stage frame) and at the end of shear, averaged in
  the seed's two zones, 0 ≤ z ≤ 0.2 mm above the vane tips (seed: dilation) and 0.2 mm up to the
  upper vane tips (seed: compaction), each cut at the upper vane tips: Δφ < 0 is dilation;
- layering near the cylinder wall: the number density n(r) of the final frame in 0.25 x50 shells,
  the standard deviation of n over the outer 2 x50 against that over the interior (> 1: layers);
- the number density inside the band (|z − z_sb| ≤ w_sb/2) against the rest of the packing.

Every figure is computed from the run directory (frames.h5, params.json, analysis/*.csv).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from orchestrator.analysis import density_profile
from orchestrator.frames import Frames
from orchestrator.units import to_si

SEED_BAND_WIDTH_X50 = 8.0          # seed 000, §4: steady band width ≈ 8 x50
SEED_DILATION_ZONE = 0.2e-3        # seed 000, Fig. 2: dilation within 0.2 mm above the lower vanes [m]


def vane_top(frames: Frames, params: dict, time: float) -> float:
    """Height [m] of the lower vanes' top edge at ``time`` [s]: plate face + vane height + the
    lower piston's travel (its wall series, linearly interpolated)."""
    g = params["scene"]["geometry"]
    w = frames.wall("lower_piston")
    travel = float(np.interp(time, w["time"].to_numpy(), w["position_z"].to_numpy()))
    return g["z_lower_face"] + params["case_scene"]["vane_height"] + travel


def report(run_dir: Path) -> dict:
    """The seed-000 figures of one run (see the module docstring); lengths in m."""
    fr = Frames(run_dir)
    params = json.loads((run_dir / "params.json").read_text())
    case = json.loads((run_dir / "summary.json").read_text())
    scene = yaml.safe_load((run_dir / "case.yaml").read_text())["scene"]       # the resolved case, SI with units
    params["case_scene"] = {"vane_height": to_si(scene["vane_height"], "length")}
    x50 = params["scene"]["psd"]["median"]
    g = params["scene"]["geometry"]
    steady = pd.read_csv(run_dir / "analysis" / "shearband_steady.csv")
    stage = fr.stage
    times = fr.time
    first = int(np.argmax(stage >= 3)) if (stage >= 3).any() else 0
    last = fr.n_frames - 1
    z0_first, z0_last = vane_top(fr, params, times[first]), vane_top(fr, params, times[last])
    z_upper_tips = g["z_upper_face"] - params["case_scene"]["vane_height"]
    out = {"run": run_dir.name, "engine": case["engine"], "case": case["case"], "n": fr.n_particles, "x50": x50,
           "engine_s": case["wall_time"]["engine"], "engine_cpu_s": case["wall_time"].get("engine_cpu")}
    if len(steady):
        z_sb = steady["z_sb"].to_numpy() - z0_last
        w_sb = steady["w_sb"].to_numpy()
        out.update(z_sb=float(z_sb.mean()), z_sb_std=float(z_sb.std()), w_sb=float(w_sb.mean()),
                   w_sb_std=float(w_sb.std()), band_radii=len(steady))
    R = g["R_cyl"]
    center = (0.0, 0.0)
    gap = z_upper_tips - z0_last                      # powder between the vane tips at the end [m]
    out["tips_gap"] = float(gap)
    zones = {"dilation": (0.0, min(SEED_DILATION_ZONE, gap)), "above": (SEED_DILATION_ZONE, gap)}
    for name, k, zref in (("compressed", first, z0_first), ("sheared", last, z0_last)):
        for zone, (lo, hi) in zones.items():
            if hi <= lo:
                continue
            prof = density_profile(fr.position[k], fr.radius, np.array([0.0, R]), np.array([lo, hi]), center,
                                   zref, samples=128)
            out[f"phi_{zone}_{name}"] = float(prof["phi"][0, 0])
    # layering: n(r) of the final frame between the vane tips, 0.25 x50 shells
    edges = np.arange(0.0, R + 1e-12, 0.25 * x50)
    prof = density_profile(fr.position[last], fr.radius, edges, np.array([0.0, z_upper_tips - z0_last]), center,
                           z0_last, samples=0)
    n_r = prof["n"][:, 0]
    rc = 0.5 * (edges[1:] + edges[:-1])
    outer = rc > R - 2 * x50
    inner = (rc > 2 * x50) & (rc < R - 3 * x50)
    out["layering"] = float(n_r[outer].std() / max(n_r[inner].std(), 1e-30)) if inner.sum() > 2 else float("nan")
    if "z_sb" in out:
        zc = fr.position[last][:, 2] - z0_last
        ok = np.isfinite(zc)
        band = ok & (np.abs(zc - out["z_sb"]) <= 0.5 * out["w_sb"])
        rest = ok & ~band & (zc >= 0) & (zc <= z_upper_tips - z0_last)
        hb = out["w_sb"]
        hr = (z_upper_tips - z0_last) - hb
        out["n_band_over_rest"] = float((band.sum() / hb) / max(rest.sum() / hr, 1e-30)) if hr > 0 else float("nan")
    return out


def main(argv=None) -> int:
    runs = [Path(a) for a in (argv if argv is not None else sys.argv[1:])]
    if not runs:
        print(__doc__)
        return 2
    for run in runs:
        r = report(run)
        x50 = r["x50"]
        um = 1e6
        print(f"\n{r['case']} on {r['engine']} ({r['run']}), {r['n']} grains, x50 = {x50 * um:.0f} µm, engine "
              f"{r['engine_s']:.0f} s" + (f" (CPU {r['engine_cpu_s']:.0f} s)" if r.get("engine_cpu_s") else ""))
        print("| seed 000 | this run |\n|---|---|")
        print(f"| (geometry) | {r['tips_gap'] * um:.0f} µm = {r['tips_gap'] / x50:.1f} x50 of powder between the vane tips "
              "at the end |")
        if "z_sb" in r:
            print(f"| band just above the lower vanes | z_sb = {r['z_sb'] * um:.0f} ± {r['z_sb_std'] * um:.0f} µm "
                  f"= {r['z_sb'] / x50:.1f} x50 above the lower vane tips ({r['band_radii']} radii) |")
            print(f"| w_sb ≈ {SEED_BAND_WIDTH_X50:.0f} x50 | w_sb = {r['w_sb'] * um:.0f} ± {r['w_sb_std'] * um:.0f} µm "
                  f"= {r['w_sb'] / x50:.1f} ± {r['w_sb_std'] / x50:.1f} x50 |")
        else:
            print("| band | no steady band fitted |")
        for zone, words in (("dilation", "dilation at 0-0.2 mm"), ("above", "compaction above 0.2 mm")):
            a, b = r.get(f"phi_{zone}_compressed"), r.get(f"phi_{zone}_sheared")
            if a is not None and b is not None:
                print(f"| {words} | φ {a:.3f} → {b:.3f} (Δφ = {b - a:+.3f}) |")
        print(f"| layering near the walls | std of n(r) in the outer 2 x50 / interior: {r['layering']:.2f} |")
        if "n_band_over_rest" in r:
            print(f"| similar number density inside the band | n(band) / n(rest) = {r['n_band_over_rest']:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
