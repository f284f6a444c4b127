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
- the number density inside the band (|z − z_sb| ≤ w_sb/2) against the rest of the packing;
- the steady angular-velocity profile itself (the shearband analysis' v_φ̃(z), pooled over radii and
  the steady window, in 2 x50 bins from the lower vane tips, at least six): where its gradient is steepest, the
  share of the velocity change from the lower to the upper vane tips that happens within the seed's
  8 x50 around that height (1 for a band of ≤ 8 x50, 8/gap for a uniform shear), and how far eq. 2
  with the fitted z_sb, w_sb misses it (rms): an erf fitted to a profile that is not an erf still
  returns a z_sb and a w_sb.

It first prints the run's compression check (the servo force against the target at the end of
compression, shear_cell_checks.json): outside 2 %, the run is not a valid comparison.

Every figure is computed from the run directory (frames.h5, params.json, analysis/*.csv).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.special import erf

from orchestrator.analysis import density_profile, parse_specs
from orchestrator.case import load_case
from orchestrator.frames import Frames
from orchestrator.results import key_results

SEED_BAND_WIDTH_X50 = 8.0          # seed 000, §4: steady band width ≈ 8 x50
SEED_DILATION_ZONE = 0.2e-3        # seed 000, Fig. 2: dilation within 0.2 mm above the lower vanes [m]


def vane_top(frames: Frames, geometry: dict, vane_height: float, time: float) -> float:
    """Height [m] of the lower vanes' top edge at ``time`` [s]: plate face + ``vane_height`` [m] +
    the lower piston's travel (its wall series, linearly interpolated)."""
    w = frames.wall("lower_piston")
    travel = float(np.interp(time, w["time"].to_numpy(), w["position_z"].to_numpy()))
    return geometry["z_lower_face"] + vane_height + travel


def engine_time_row(run_dir):
    """The results table's engine-time row (the whole run's, a resumed one from its attempts, and
    the estimate before it: orchestrator.results.key_results), or None."""
    return next((r for r in key_results(run_dir) if r.quantity == "engine time"), None)


def report(run_dir: Path) -> dict:
    """The seed-000 figures of one run (see the module docstring); lengths in m."""
    fr = Frames(run_dir)
    params = json.loads((run_dir / "params.json").read_text())
    case = json.loads((run_dir / "summary.json").read_text())
    run_case = load_case(run_dir / "case.yaml")                          # the run's resolved case
    vane_height = run_case.scene.vane_height                             # [m]
    x50 = params["scene"]["psd"]["median"]
    g = params["scene"]["geometry"]
    steady = pd.read_csv(run_dir / "analysis" / "shearband_steady.csv")
    stage = fr.stage
    times = fr.time
    first = int(np.argmax(stage >= 3)) if (stage >= 3).any() else 0
    last = fr.n_frames - 1
    z0_first, z0_last = vane_top(fr, g, vane_height, times[first]), vane_top(fr, g, vane_height, times[last])
    z_upper_tips = g["z_upper_face"] - vane_height
    out = {"run": run_dir.name, "engine": case["engine"], "case": case["case"], "n": fr.n_particles, "x50": x50,
           "engine_time": engine_time_row(run_dir)}
    if len(steady):
        z_sb = steady["z_sb"].to_numpy() - z0_last
        w_sb = steady["w_sb"].to_numpy()
        out.update(z_sb=float(z_sb.mean()), z_sb_std=float(z_sb.std()), w_sb=float(w_sb.mean()),
                   w_sb_std=float(w_sb.std()), band_radii=len(steady))
        last_pair = pd.read_csv(run_dir / "analysis" / "shearband_band.csv").iloc[-1]
        out["w_sb_last"] = float(last_pair["w_sb"])          # the last frame pair's band (radii pooled)
        out["angle_last"] = float(np.degrees(last_pair["control"]))
    chk = json.loads((run_dir / "shear_cell_checks.json").read_text())["compression"]
    out["compression_error"] = float(chk["relative_error"])   # servo force vs target at the end of compression
    # the normal load during shear: the lower piston's force over the shear stage, against the target
    w = fr.wall("lower_piston")
    in_shear = w["time"].to_numpy() >= times[first]
    load = -w["force_z"].to_numpy()[in_shear] / chk["target_force"]
    out["shear_load"] = (float(load.mean()), float(load.min()), float(load.max())) if in_shear.any() else None
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
    if "z_sb" in out:
        out.update(velocity_profile(run_dir, case_steady_from(run_case), z0_last, z_upper_tips, x50,
                                    out["z_sb"], out["w_sb"]))
    return out


def case_steady_from(case) -> float:
    """The steady window's start [rad] of the run's shearband analysis (seed 000: 10°)."""
    opts = next((o for n, o in parse_specs(case.analysis) if n == "shearband"), {})
    return float(opts.get("steady_from", np.radians(10.0)))


def velocity_profile(run_dir: Path, steady_from: float, z0: float, z_upper_tips: float, x50: float,
                     z_sb: float, w_sb: float) -> dict:
    """The steady v_φ̃(z) (module docstring): heights [m] above the lower vane tips ``z0``."""
    prof = pd.read_csv(run_dir / "analysis" / "shearband_profiles.csv")
    prof = prof[(prof["control"] >= steady_from) & np.isfinite(prof["v"]) & (prof["count"] > 0)]
    z = prof["z"].to_numpy() - z0
    v, wgt = prof["v"].to_numpy(), prof["count"].to_numpy(float)
    gap = z_upper_tips - z0
    dz = min(2 * x50, gap / 6)                    # 2 x50 bins; at least 6 in a thin cell
    edges = np.linspace(0.0, gap, max(int(round(gap / dz)), 1) + 1)
    idx = np.digitize(z, edges) - 1
    vb = np.array([np.average(v[idx == k], weights=wgt[idx == k]) if (idx == k).any() else np.nan
                   for k in range(len(edges) - 1)])
    zc = 0.5 * (edges[1:] + edges[:-1])
    grad = np.gradient(vb, zc)
    k = int(np.nanargmax(grad))
    dv_total = vb[-1] - vb[0]
    near = np.abs(zc - zc[k]) <= 4 * x50
    lo, hi = np.flatnonzero(near)[[0, -1]]
    share = float((vb[hi] - vb[max(lo - 1, 0)]) / dv_total) if dv_total > 0 else float("nan")
    inside = (z >= 0) & (z <= gap)
    model = 0.5 + 0.5 * erf((z[inside] - z_sb) / w_sb)
    rms = float(np.sqrt(np.average((v[inside] - model) ** 2, weights=wgt[inside])))
    return {"v_profile": (zc, vb), "z_steepest": float(zc[k]), "share_within_8x50": share, "erf_rms": rms,
            "v_lower_tips": float(vb[0]), "v_upper_tips": float(vb[-1])}


def main(argv=None) -> int:
    runs = [Path(a) for a in (argv if argv is not None else sys.argv[1:])]
    if not runs:
        print(__doc__)
        return 2
    for run in runs:
        if not (run / "frames.h5").is_file() or not (run / "analysis" / "shearband_steady.csv").is_file():
            inside = sorted(p.parent for p in run.glob("*/frames.h5")) if run.is_dir() else []
            print(f"error: {run}: not a complete shear-cell run with its shearband analysis"
                  + (f"; it holds the runs {', '.join(map(str, inside))}: give one of them" if inside else
                     "; give runs/<case>/<engine>-<hash>"), file=sys.stderr)
            return 2
        r = report(run)
        x50 = r["x50"]
        um = 1e6
        et = r["engine_time"]
        print(f"\n{r['case']} on {r['engine']} ({r['run']}), {r['n']} grains, x50 = {x50 * um:.0f} µm"
              + (f", engine time {et.text()}" + (f" ({et.seed})" if et.seed else "") if et else ""))
        print("| seed 000 | this run |\n|---|---|")
        ok = abs(r["compression_error"]) <= 0.02
        print(f"| (normal load 0.5 kPa) | servo force at the end of compression {100 * r['compression_error']:+.1f} % "
              f"from the target: {'within' if ok else 'OUTSIDE'} the 2 % check"
              + ("" if ok else ": the sample was sheared before it carried the seed's load, not a valid comparison")
              + " |")
        if r["shear_load"]:
            print("| (normal load during shear) | lower piston force / target: mean %.3f, range %.3f-%.3f |"
                  % r["shear_load"])
        print(f"| (geometry) | {r['tips_gap'] * um:.0f} µm = {r['tips_gap'] / x50:.1f} x50 of powder between the vane tips "
              "at the end |")
        if "z_sb" in r:
            print(f"| band just above the lower vanes | z_sb = {r['z_sb'] * um:.0f} ± {r['z_sb_std'] * um:.0f} µm "
                  f"= {r['z_sb'] / x50:.1f} x50 above the lower vane tips ({r['band_radii']} radii) |")
            print(f"| w_sb ≈ {SEED_BAND_WIDTH_X50:.0f} x50 | w_sb = {r['w_sb'] * um:.0f} ± {r['w_sb_std'] * um:.0f} µm "
                  f"= {r['w_sb'] / x50:.1f} ± {r['w_sb_std'] / x50:.1f} x50 over the steady window; "
                  f"{r['w_sb_last'] * um:.0f} µm = {r['w_sb_last'] / x50:.1f} x50 at {r['angle_last']:.1f}° |")
        else:
            print("| band | no steady band fitted |")
        for zone, words in (("dilation", "dilation at 0-0.2 mm"), ("above", "compaction above 0.2 mm")):
            a, b = r.get(f"phi_{zone}_compressed"), r.get(f"phi_{zone}_sheared")
            if a is not None and b is not None:
                print(f"| {words} | φ {a:.3f} → {b:.3f} (Δφ = {b - a:+.3f}) |")
        if "z_steepest" in r:
            zc, vb = r["v_profile"]
            print(f"| band just above the lower vanes (steady v_φ̃, radii pooled) | steepest at "
                  f"{r['z_steepest'] / x50:.1f} x50 above the lower vane tips ({(r['tips_gap'] - r['z_steepest']) / x50:.1f}"
                  f" x50 below the upper tips); {100 * r['share_within_8x50']:.0f} % of the change "
                  f"{r['v_lower_tips']:.2f} → {r['v_upper_tips']:.2f} between the tips lies within 8 x50 of it "
                  f"(uniform shear: {100 * min(1.0, 8 * x50 / r['tips_gap']):.0f} %); eq. 2 misses it by "
                  f"{r['erf_rms']:.3f} rms |")
            print("| (steady v_φ̃ at heights in x50 above the lower vane tips) | "
                  + ", ".join(f"{z / x50:.1f}: {v:.2f}" for z, v in zip(zc, vb) if np.isfinite(v)) + " |")
        print(f"| layering near the walls | std of n(r) in the outer 2 x50 / interior: {r['layering']:.2f} |")
        if "n_band_over_rest" in r:
            print(f"| similar number density inside the band | n(band) / n(rest) = {r['n_band_over_rest']:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
