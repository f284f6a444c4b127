"""The issue #14 triaxial figures of one or more run directories (docs/triaxial.md, docs/crossval.md).

    python benchmarks/triaxial_report.py RUN_DIR [RUN_DIR ...]

For each run: the end of stage 1 (scene_summary.json, or the engine log of a run still going), the
drag removal (ramp start and drag-off step from the engine log), the fastest grain and the number of
grains above 1 m/s in every frame from the drag-off frame on (frames.h5; for a YADE run still going,
its dump/chunk.*.npz; a clump sample's grain is its clump, at its fastest member's speed), and once the run is complete the loading figures: σ3 stray (largest |σ3/p - 1|
of 10-row means), the largest |ε_v(boundary) - ε_v(hull)| for the convex hull and the stacked-slab hull, K'/U (non-affine kinetic over Hertz
elastic energy, median over the loading frames, analysis ``energy``) and σ1/σ3, ε_v at
ε_a = 1, 2, 5, 10, 15 % (orchestrator.stability.observables, the source of the crossval numbers).
``stage1_speeds``: per stage-1 frame the median, rms and largest grain speed and the boundary
volume change, by phase (full drag, ramp, drag-free): whether the drag-supported sample comes to
rest or creeps. ``stage1_solid_fraction``: (step, height [mm], solid fraction, σ1/p) at 12 rows of
stage 1 from ``triax.txt`` (a drag-held sample reads σ1 ≈ p while it still compacts).
``attempts_pace``: each attempt's steps per CPU second; ``pace_against_estimate`` (a run still
going): the dry run's steps and time against the total its pace projects. ``latest_frame`` (a run still going): the
void ratios and the solid fraction in 10 rings about the axis of its last frame.
"""
from __future__ import annotations

import csv
import glob
import json
import re
import sys
from pathlib import Path

import h5py
import numpy as np
import pandas as pd

from engines.lammps_dump import read_binary_dump
from engines.liggghts.segments import dump_segments
from orchestrator.analysis.triaxial import triaxial_curves
from orchestrator.case import load_case
from orchestrator.derive import derive
from orchestrator.frames import Frames
from orchestrator.grains import frames_for_analysis
from orchestrator.attempts import read_attempts
from orchestrator.scenes.triaxial import (SLAB_HULL_D50, _solid_volume, _void_ratios_at, analyse, hull_volume, read_series,
                                          slab_hull_volume, solid_fraction_profile, void_ratios_at_loading)
from orchestrator.sizing import estimate
from orchestrator.stability.observables import observables

FLOOR = 1.0          # m/s, issue #14: no grain above 1 m/s in the frame after the drag goes off


def _log_steps(log: str, pattern: str) -> list[int]:
    return [int(m) for m in re.findall(pattern, log, re.M)]


def _frames(run: Path):
    """(steps, speeds (frames, grains), stage or None) from frames.h5, else from YADE's dump chunks or
    LIGGGHTS' binary dump segments (a run still going).
    A clump sample's grain is its clump: its speed is that of its fastest member (``clumps.txt``)."""
    if (run / "frames.h5").exists():
        with h5py.File(run / "frames.h5") as h:
            v = h["frames/velocity"][:]
            st = h["frames/step"][:]
            stage = h["frames/stage"][:] if "frames/stage" in h["frames"] else None
            ids = h["particles/id"][:]
        return st, _per_grain(run, ids, np.linalg.norm(v, axis=2)), stage
    files = sorted(glob.glob(str(run / "dump" / "chunk.*.npz")))
    if not files and (run / "dump" / "columns.json").exists():       # LIGGGHTS, still going: its binary dumps
        cols = json.loads((run / "dump" / "columns.json").read_text())
        st, sp, seen = [], [], set()
        for step, a in read_binary_dump(dump_segments(run), len(cols)):
            if step in seen:                                           # a segment's first frame, written twice
                continue
            seen.add(step)
            a = a[np.argsort(a[:, cols.index("id")])]
            st.append(step)
            sp.append(np.linalg.norm(a[:, [cols.index(c) for c in ("vx", "vy", "vz")]], axis=1))
            # a clump's members carry its body id in "mol" (fix multisphere); clumps.txt maps the
            # orchestrator's placed ids until the run's end rewrites it from the frames
            body = a[:, cols.index("mol")].astype(int) if "mol" in cols else None
        if not st:
            return np.zeros(0), np.zeros((0, 0)), None
        speeds = np.array(sp)
        return np.array(st), (speeds if body is None else _max_per_group(body, speeds)), None
    if not files:
        return np.zeros(0), np.zeros((0, 0)), None
    st, sp = [], []
    for f in files:
        z = np.load(f)
        st.append(z["iter"])
        sp.append(np.linalg.norm(z["velocity"], axis=2))
    ids = np.loadtxt(run / "particles.txt", ndmin=2, comments="#")[:, 0].astype(int)   # YADE's dump order
    return np.concatenate(st), _per_grain(run, ids, np.concatenate(sp)), None


def _per_grain(run: Path, ids: np.ndarray, speeds: np.ndarray) -> np.ndarray:
    """``speeds`` (frames, particles with ``ids``) per grain: unchanged for spheres; for a clump sample
    (``clumps.txt``: member id, clump) the largest member speed of each clump, so that "grains above
    1 m/s" counts clumps, not their member spheres."""
    if not (run / "clumps.txt").exists():
        return speeds
    owner = dict(np.loadtxt(run / "clumps.txt", ndmin=2, comments="#").astype(int).tolist())
    return _max_per_group(np.array([owner[int(i)] for i in ids]), speeds)


def _max_per_group(group: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(frames, particles) ``values`` reduced to their largest per ``group`` label (particles,)."""
    order = np.argsort(group, kind="stable")
    starts = np.flatnonzero(np.r_[True, np.diff(group[order]) != 0])
    return np.maximum.reduceat(values[:, order], starts, axis=1)


def volume_methods(run: Path, strains=(0.01, 0.02, 0.05, 0.10, 0.15, 0.20), floor: float = 0.01,
                   up_to: float = 0.15, slabs=(1.0, 2.0, 4.0)) -> dict:
    """The volumetric strain while loading three ways: the boundary's, the grains' convex hull's
    and the grains' stacked-slab hull's (``slab_hull_volume``, slabs of SLAB_HULL_D50 d50, from
    the frames' positions, so older runs without that control get it too): at the strains reached
    [boundary, hull, slab hull], each hull's largest difference from the boundary up to ``up_to``
    and over the whole loading, and the first strain where it passes ``floor`` (issue #14 item 4:
    within 0.01); the slab hull's largest difference for slabs of ``slabs`` d50 (how much the
    choice matters); the sample's radial extent (largest and 95th-percentile grain distance from
    the axis through the grains' mean x, y [mm]) at a third of the loading frames and at the last;
    and, at the reference frame and the last, its outline (:func:`outline`) and the depth of its
    deepest waist (:func:`neck_depth`), which the global hull bridges and the slab hull follows."""
    if not (run / "frames.h5").exists():
        return {}
    f = Frames(run)
    c = f.controls
    if "volumetric_strain_hull" not in c:
        return {}
    ld = np.flatnonzero(c["stage"] >= 2)
    if not len(ld):
        return {}
    r = f.radius
    d50 = 2 * float(np.median(r))       # the frames keep radii: the median diameter stands in for d50
    ref = max(0, int(ld[0]) - 1)        # the last stage-1 frame: the controls' reference

    def slab_strain(m):
        vol = []
        for k in [ref, *ld]:
            x = f.position[k]
            vol.append(slab_hull_volume(x, r, float(np.nanmin(x[:, 2] - r)), float(np.nanmax(x[:, 2] + r)), m * d50))
        vol = np.asarray(vol)
        return (vol[0] - vol[1:]) / vol[0]

    ea, eb, eh = c["axial_strain"][ld], c["volumetric_strain"][ld], c["volumetric_strain_hull"][ld]
    es = slab_strain(SLAB_HULL_D50)
    upto = ea <= up_to + 1e-4
    out = {"at": {f"{e:g}": [round(float(eb[i]), 4), round(float(eh[i]), 4), round(float(es[i]), 4)]
                  for e in strains if ea.max() >= e - 1e-4 for i in [int(np.argmin(np.abs(ea - e)))]}}
    for name, ev in (("hull", eh), ("slab_hull", es)):
        d = np.abs(eb - ev)
        out[name] = {f"max_diff_to_{up_to:g}": float(d[upto].max()) if upto.any() else None,
                     "max_diff": float(d.max()),
                     f"first_strain_above_{floor:g}": float(ea[d > floor][0]) if (d > floor).any() else None}
    out["slab_hull"]["max_diff_by_slab_d50"] = {f"{m:g}": round(float(np.abs(eb - (es if m == SLAB_HULL_D50 else
                                                                                    slab_strain(m))).max()), 4)
                                                for m in slabs}
    extent = {}
    for k in (ld[len(ld) // 3], ld[-1]):
        x = f.position[k]
        rr = np.hypot(x[:, 0] - np.nanmean(x[:, 0]), x[:, 1] - np.nanmean(x[:, 1]))
        extent[f"frame {int(k)} (ε_a {float(c['axial_strain'][k]):.3f})"] = [round(float(np.nanmax(rr)) * 1e3, 3),
                                                                              round(float(np.nanpercentile(rr, 95)) * 1e3, 3)]
    out["radial_extent_max_p95_mm"] = extent
    shapes = {f"ε_a {float(c['axial_strain'][k]):.3f}": outline(f.position[k], r, d50) for k in (ref, ld[-1])}
    out["neck_d50"] = {k: neck_depth(R) for k, R in shapes.items()}
    out["outline_d50_foot_to_top"] = {k: [round(float(v), 2) for v in R] for k, R in shapes.items()}
    return out


def outline(pos: np.ndarray, r: np.ndarray, d50: float, tenths: int = 10, sectors: int = 8) -> np.ndarray:
    """The sample's outline [d50], foot to top: per tenth of the height, the mean over ``sectors``
    of the farthest grain surface from the axis through the grains' mean x, y."""
    ok = ~np.isnan(pos).any(axis=1)
    x, rr = pos[ok], r[ok]
    cx, cy = x[:, 0].mean(), x[:, 1].mean()
    zb, zt = (x[:, 2] - rr).min(), (x[:, 2] + rr).max()
    band = np.clip(((x[:, 2] - zb) / (zt - zb) * tenths).astype(int), 0, tenths - 1)
    sector = ((np.arctan2(x[:, 1] - cy, x[:, 0] - cx) + np.pi) / (2 * np.pi) * sectors).astype(int) % sectors
    reach = np.zeros((tenths, sectors))
    np.maximum.at(reach, (band, sector), np.hypot(x[:, 0] - cx, x[:, 1] - cy) + rr)
    return reach.mean(axis=1) / d50


def neck_depth(R: np.ndarray) -> float:
    """Depth [the outline's unit] of the deepest waist of an :func:`outline` ``R``: how far a tenth
    lies inside the lesser of the widest tenth below it and the widest above it; 0 for a barrel or
    a cylinder."""
    depth = [min(R[:i].max(), R[i + 1:].max()) - R[i] for i in range(1, len(R) - 1)]
    return round(max(0.0, float(max(depth))), 3)


def series_figures(run: Path, strains=(0.01, 0.02, 0.05, 0.10, 0.15), rows: int = 10) -> dict:
    """σ1/σ3 (10-row running means of σ1 and σ3) and the boundary's ε_v at the strains reached, from
    ``triax.txt`` alone (a run still going: no frames.h5 yet), with the definitions of
    ``TriaxialScene.post``: σ1 = F_top/(V/H), σ3 = F_lat/A_lat, ε_a and ε_v from the last stage-1 row."""
    a = np.loadtxt(run / "triax.txt", comments="#", ndmin=2)
    stage, zb, zt, ftop, flat, area, vol = a[:, 2], a[:, 3], a[:, 4], a[:, 6], a[:, 7], a[:, 8], a[:, 9]
    if not (stage >= 2).any():
        return {}
    i0 = int(np.flatnonzero(stage >= 2)[0]) - 1
    H = zt - zb
    s1, s3 = ftop / (vol / H), flat / area
    sl = slice(i0 + 1, None)
    ea = (H[i0] - H[sl]) / H[i0]
    ev = (vol[i0] - vol[sl]) / vol[i0]
    c = triaxial_curves(ea, s1[sl], s3[sl], ev, smoothing_rows=rows)
    m1, m3 = c["sigma1_smoothed"].to_numpy(), c["sigma3_smoothed"].to_numpy()
    out = {"axial_strain_reached": float(ea.max())}
    for e in strains:
        if ea.max() >= e * (1 - 1e-3):
            out[f"stress_ratio@{e:g}"] = float(np.interp(e, ea, m1 / m3))
            out[f"volumetric_strain@{e:g}"] = float(np.interp(e, ea, ev))
    return out


def stage1_speeds(run: Path, log: str, steps: np.ndarray, sp: np.ndarray) -> list:
    """Per stage-1 frame: (step, phase, median and rms grain speed [m/s], fastest [m/s], grains above
    1 m/s, boundary volume change since the previous frame [-], fraction of grains exactly at rest: a
    clump that nothing has touched yet, with no gravity). phase: "drag" (full drag), "ramp",
    "free" (drag off, stage 1 going on). Whether the drag-supported sample comes to rest (a static
    packing the drag's removal would not disturb) or creeps at a steady rate."""
    ramp = _log_steps(log, r"^ISO converged with drag: drag ramped to zero over \d+ steps from step (\d+)")
    off = _log_steps(log, r"^ISO drag off at step (\d+)")
    start = _log_steps(log, r"^SHEAR (?:start at iter|from step) (\d+)")
    vol = None
    if (run / "triax.txt").exists():
        a = np.loadtxt(run / "triax.txt", comments="#", ndmin=2)
        vol = (a[:, 0], a[:, 9])
    rows, v_prev = [], None
    for k, st in enumerate(steps):
        if start and st > start[0]:
            break
        phase = "free" if off and st > off[0] else "ramp" if ramp and st > ramp[0] else "drag"
        v = float(np.interp(st, *vol)) if vol is not None else float("nan")
        dv = (v - v_prev) / v_prev if v_prev else float("nan")
        v_prev = v
        s = sp[k]
        rows.append((int(st), phase, round(float(np.median(s)), 4), round(float(np.sqrt(np.mean(s ** 2))), 4),
                     round(float(s.max()), 2), int((s > FLOOR).sum()), float(f"{dv:.2e}"),
                     round(float(np.mean(s == 0)), 3)))
    return rows


def stage1_solid_fraction(run: Path, points: int = 12) -> list:
    """Stage 1's compaction from ``triax.txt`` (works on a run still going): at ``points`` rows evenly
    spread over stage 1, (step, sample height [mm], solid fraction = the grains' solid volume over the
    boundary volume, σ1/p_now). A drag-held sample reads σ1 ≈ p while its solid fraction still rises."""
    params = json.loads((run / "params.json").read_text())
    r = np.loadtxt(run / "particles.txt", ndmin=2, comments="#")[:, 1]
    vs = _solid_volume(params["scene"], r)
    s = read_series(run)
    iso = np.flatnonzero((s["stage"] == 1) & (s["pressure"] > 0))
    if vs is None or not len(iso):
        return []
    sigma1 = analyse(s, params["scene"]["pressure"])["sigma1"]
    H = s["z_top"] - s["z_bottom"]
    return [(int(s["step"][k]), round(float(H[k]) * 1e3, 3), round(float(vs / s["volume"][k]), 3),
             round(float(sigma1[k] / s["pressure"][k]), 3))
            for k in iso[np.linspace(0, len(iso) - 1, min(points, len(iso))).astype(int)]]


def _latest_frame(run: Path):
    """(step, positions, radii) of the last frame of a run still going (LIGGGHTS' binary dumps, with
    their own radius column: during a clump run particles.txt holds the placed packing's ids, not the
    engine's; YADE's dump chunks, in particles.txt's order); None for a complete run or none yet."""
    if (run / "frames.h5").exists():
        return None
    if (run / "dump" / "columns.json").exists():
        cols = json.loads((run / "dump" / "columns.json").read_text())
        last = None
        for last in read_binary_dump(dump_segments(run)[-2:], len(cols)):
            pass
        if last is None:
            return None
        step, a = last
        return int(step), a[:, [cols.index(c) for c in "xyz"]], a[:, cols.index("radius")]
    files = sorted(glob.glob(str(run / "dump" / "chunk.*.npz")))
    if not files:
        return None
    z = np.load(files[-1])
    return int(z["iter"][-1]), z["position"][-1], np.loadtxt(run / "particles.txt", ndmin=2, comments="#")[:, 1]


def latest_frame(run: Path) -> dict:
    """For a run still going, its last frame: the void ratios (``void_ratios``: boundary, hull and
    the CT-like interior) and the solid fraction in 10 rings about the axis (``solid_fraction_profile``)."""
    lf = _latest_frame(run)
    if lf is None:
        return {}
    step, pos, r = lf
    sc = json.loads((run / "params.json").read_text())["scene"]
    s = read_series(run)
    j = int(np.argmin(np.abs(s["step"] - step)))
    zb, zt = float(s["z_bottom"][j]), float(s["z_top"][j])
    e = _void_ratios_at(sc, s, j, pos, r, hull_volume(pos, r, zb, zt)) or {}
    edges, phi = solid_fraction_profile(pos, r, zb, zt, float(sc["d50"]))
    return {"step": step, "void_ratio": {k: float(f"{v:.4g}") for k, v in e.items() if v is not None},
            "solid_fraction_by_ring": [round(float(x), 3) for x in phi], "ring_width_mm": round(float(edges[1]) * 1e3, 3)}


def attempts_pace(run: Path) -> list:
    """Each attempt of the run (attempts.json): (first step, last step, CPU s, steps per CPU second,
    load): the pace a run still going has kept, which its estimate is checked against."""
    rows = []
    for a in read_attempts(run):
        first, last, cpu = a.get("first_step"), a.get("last_step"), a.get("cpu_s")
        if isinstance(first, int) and isinstance(last, int) and cpu:
            rows.append((first, last, round(cpu), round((last - first) / cpu, 1), a.get("load")))
    return rows


def pace_against_estimate(run: Path, engine: str) -> dict | None:
    """A run still going against its dry-run estimate: the steps and engine time the clock expects
    for the run's case on ``engine`` (``orchestrator.sizing.estimate``, what ``run --dry-run``
    prints), the CPU time so far, and the total projected from it at the pace of the attempts after
    the first pooled (their resumes' start-ups included) and at the fastest one's (a sample starts
    loose, with few contacts: the first attempt is left out; attempts that made no steps count in
    the CPU time, not in the pace), with the estimate over each projection. None without a case or
    an attempt that made steps."""
    rows = attempts_pace(run)
    if not rows or not (run / "case.yaml").exists():
        return None
    case = load_case(run / "case.yaml")
    size = estimate(case, derive(case), engine)
    total = int(size["steps_expected"] or size["steps"])
    cpu = sum(r[2] for r in rows)
    last = max(r[1] for r in rows)
    moved = [r for r in rows if r[1] > r[0]]      # an attempt stopped before its first checkpoint made no steps
    if not moved:
        return None
    later = moved[1:] or moved
    pooled = sum(r[1] - r[0] for r in later) / sum(r[2] for r in later)   # start-ups of the resumes included
    paces = [round(pooled, 1), max(r[3] for r in later)]
    proj = [cpu + max(total - last, 0) / p for p in (paces[1], paces[0])]
    est = size["engine_time_s"]
    return {"steps_expected": total, "estimate_h": round(est / 3600, 1), "cpu_h_so_far": round(cpu / 3600, 2),
            "last_step": last, "pace_steps_per_cpu_s": paces,
            "projected_h": [round(x / 3600, 1) for x in proj], "estimate_over_projected": [round(est / x, 2) for x in proj]}


def _iso_chunks(log: str) -> tuple[list, list]:
    """The stage-1 chunks of an engine log: (chunk, σ1/p, σ3/p) per chunk, and the chunk-mean
    volume change each ``ISO creep`` line gives after its chunk (None for "n/a"). A resumed run
    prints its checkpoint's chunk again: a chunk repeating the one before it is counted once."""
    chunks, creep, repeat = [], [], False
    for m in re.finditer(r"^ISO chunk (\d+): sigma1/p = ([\d.eE+-]+) sigma3/p = ([\d.eE+-]+)"
                         r"|^ISO creep: chunk-mean volume change (\S+)", log, re.M):
        if m.group(1) is not None:
            row = (int(m.group(1)), round(float(m.group(2)), 4), round(float(m.group(3)), 4))
            repeat = bool(chunks) and chunks[-1][0] == row[0]
            if not repeat:
                chunks.append(row)
        elif not repeat:
            creep.append(None if m.group(4) == "n/a" else float(f"{float(m.group(4)):.3g}"))
    return chunks, creep


def report(run: Path) -> dict:
    run = Path(run)
    log = (run / "engine.log").read_text(errors="replace") if (run / "engine.log").exists() else ""
    out: dict = {"run": str(run)}
    chunks, creep = _iso_chunks(log)
    out["iso_chunks"] = chunks
    if creep:        # isotropic.creep_tolerance: the chunk-mean volume change after every tested chunk
        out["iso_creep_per_chunk"] = creep
    out["ramp_start"] = _log_steps(log, r"^ISO converged with drag: drag ramped to zero over \d+ steps from step (\d+)")
    off = _log_steps(log, r"^ISO drag off at step (\d+)")
    if not off and re.search(r"^ISO converged with drag: drag off", log, re.M):
        out["drag_off_note"] = "drag switched off at once (no ramp)"
    out["drag_off"] = off
    out["stage1_solid_fraction"] = stage1_solid_fraction(run)      # (step, H [mm], solid fraction, σ1/p)
    out["attempts_pace"] = attempts_pace(run)          # (first step, last step, CPU s, steps/CPU s, load)
    if not (run / "frames.h5").exists():               # still going: its pace against its estimate
        out["pace_against_estimate"] = pace_against_estimate(run, run.name.split("-")[0])
    out["latest_frame"] = latest_frame(run)            # a run still going: void ratios, rings' solid fraction
    steps, sp, _ = _frames(run)
    if off and len(steps):
        k0 = int(np.searchsorted(steps, off[0] - 1))      # the frame at (or just after) the drag-off step
        rows = []
        for k in range(max(0, k0 - 2), min(len(steps), k0 + 8)):
            rows.append((int(steps[k]), round(float(sp[k].max()), 2), int((sp[k] > FLOOR).sum())))
        out["fastest_grain_around_drag_off"] = rows           # (step, fastest [m/s], grains above 1 m/s)
        after = [r for r in rows if r[0] > off[0]]
        if after:
            out["frame_after_drag_off"] = after[0]
        if (run / "clumps.txt").exists() and (run / "frames.h5").exists():
            # a clump's fastest member includes its spin; its centre of mass is the grain's own speed
            # (orchestrator.grains: the rigid-body fit of the members)
            g = frames_for_analysis(run)
            cs = np.linalg.norm(g.velocity, axis=2)
            out["fastest_grain_centre_around_drag_off"] = [
                (int(g.step[k]), round(float(np.nanmax(cs[k])), 2), int((cs[k] > FLOOR).sum()))
                for k in range(max(0, k0 - 2), min(len(g.step), k0 + 8))]
    if len(steps):
        out["stage1_speeds"] = stage1_speeds(run, log, steps, sp)
    summ = run / "scene_summary.json"
    if summ.exists():
        s = json.loads(summ.read_text())
        out["isotropic_end"] = {k: s["isotropic_end"].get(k) for k in ("converged", "sigma1_error", "sigma3_error",
                                                                       "void_ratio", "steps")}
        if (out["isotropic_end"].get("void_ratio") or {}).get("interior") is None:
            # a clump run post-processed before the interior figure counted clumps: from its frames
            out["isotropic_end"]["void_ratio"] = void_ratios_at_loading(run) or out["isotropic_end"].get("void_ratio")
        sh = s.get("shear", {})
        out["sigma3_stray_smoothed"] = sh.get("sigma3_error_max_abs_smoothed")
        out["peak_stress_ratio"] = sh.get("peak_stress_ratio")
        out["final_axial_strain"] = sh.get("final_axial_strain")
        out["dev_volumetric_strain_max"] = s.get("volume_methods", {}).get("volumetric_strain_max_abs_diff")
    en = run / "analysis" / "energy_summary.csv"
    if en.exists() and (run / "frames.h5").exists():
        with h5py.File(run / "frames.h5") as h:
            stage = h["frames/stage"][:]
        with open(en) as f:
            r = [row for row in csv.DictReader(f)]
        kn = np.array([float(x["ratio_nonaffine"] or "nan") for x in r])
        load = (stage[:len(kn)] >= 2) & np.isfinite(kn)
        if load.any():
            out["K_nonaffine_over_U_loading_median"] = float(np.median(kn[load]))
            out["K_nonaffine_over_U_loading_max"] = float(np.max(kn[load]))
    out["series_figures"] = series_figures(run)
    # ε_v of the boundary, the hull and the slab hull at each strain; each hull's difference
    out["volume_methods"] = volume_methods(run)
    curves = run / "analysis" / "triaxial_curves.csv"
    if curves.exists():
        # the 10-row mean of σ1/σ3 over the plateau ε_a = 5-15 % (mean and std in time: how much one run
        # wanders, the scale a one-seed engine difference is judged on) and where it peaks
        d = pd.read_csv(curves)
        m = (d["axial_strain"] >= 0.05) & (d["axial_strain"] <= 0.15)
        if m.any():
            out["plateau_stress_ratio_5_15"] = [float(d.loc[m, "stress_ratio_smoothed"].mean()),
                                                float(d.loc[m, "stress_ratio_smoothed"].std())]
        i = d["stress_ratio_smoothed"].idxmax()
        out["peak_stress_ratio_smoothed_at"] = [float(d["stress_ratio_smoothed"][i]), float(d["axial_strain"][i])]
    if (run / "frames.h5").exists() and (run / "case.yaml").exists():
        out["observables"] = observables(load_case(run / "case.yaml"), run)
    return out


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit("usage: python benchmarks/triaxial_report.py RUN_DIR [RUN_DIR ...]")
    for d in sys.argv[1:]:
        r = report(Path(d))
        for k, v in r.items():
            print(f"{k}: {json.dumps(v, default=float)}")
        print()
