"""The shear cell's piston servo: its force against the target, its loop gain, a per-step probe
(docs/shear_cell.md, docs/validation.md: the medium case's servo).

    python benchmarks/shear_cell_servo.py gains                  # G per shipped case (I_c speed, capped)
    python benchmarks/shear_cell_servo.py series RUN_DIR         # F/F_target from the wall series
    python benchmarks/shear_cell_servo.py probe RUN_DIR STEP [S] # LIGGGHTS: 400 steps from restart STEP,
                                                                 # the force printed every step (servo
                                                                 # speed limit x S)

``gains``: the loop gain G = v_max kp γ_w/F_c of the servo against the dashpots of the grains it
pushes (scenes/shear_cell.py ``servo_dashpot_gain``; plane shear: scenes/plane_shear.py), at the
speed the compression inertial number gives and at the speed derive() uses (capped at G = 0.7).
``series``: on a parsed run of any engine (frames.h5's wall series), and on a LIGGGHTS or LAMMPS run
still going (its walls.*.txt): the step the piston arrives (force first
above 0.98 of the target), the mean and std of F/F_target over the last 10 000 steps of compression
that were written, and over the shear stage. ``probe``: a LIGGGHTS run directory with its restart
files; the deck's segment that starts at STEP, run for 400 steps on one rank with the piston's
force and position printed every step (in a temporary directory; the run is not touched).
"""
from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from engines.liggghts.segments import wall_rows
from orchestrator.case import load_case
from orchestrator.derive import derive
from orchestrator.frames import Frames
from orchestrator.scenes import plane_shear, shear_cell

REPO = Path(__file__).resolve().parents[1]


def gains() -> None:
    print("| case | v_max from I_c [m/s] | G there | v_max used [m/s] | G used | frictional walls: gain factor, "
          "v_max in shear [m/s] |")
    print("|---|---|---|---|---|---|")
    for path in sorted((REPO / "cases").glob("shear_cell_*.yaml")) + sorted((REPO / "cases").glob("plane_shear_*.yaml")):
        case = load_case(path)
        s = case.scene
        sv = derive(case).scene.servo
        if s.kind == "shear_cell":
            mod = shear_cell
            v_ic = (s.compression_inertial_number / (s.psd.median * math.sqrt(case.material.density / s.normal_stress))
                    * shear_cell.geometry_numbers(case)["h_dense_estimate"])
        else:
            mod = plane_shear
            v_ic = s.compression_inertial_number * plane_shear.geometry(case)["H_dense"] / plane_shear._time_scale(case)
        fw = (f"{shear_cell.frictional_wall_gain_factor(case):.2f}, {sv['v_max_shear']:.4g}"
              if s.kind == "shear_cell" and s.wall_friction else "")
        print(f"| {path.stem} | {v_ic:.4g} | {mod.servo_dashpot_gain(case, v_ic, sv['kp']):.2f} | {sv['v_max']:.4g} | "
              f"{mod.servo_dashpot_gain(case, sv['v_max'], sv['kp']):.2f} | {fw} |")


def piston_force(run: Path, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(steps, the lower piston's axial force [N]) of a run: from frames.h5's wall series once the
    run is parsed (any engine), else from the LIGGGHTS or LAMMPS deck's sampler files of a run
    still going (the adapter's reader, every segment's file)."""
    if (run / "frames.h5").is_file():
        w = Frames(run / "frames.h5").wall("lower_piston")
        return np.rint(w["time"].to_numpy() / dt), w["force_z"].to_numpy()
    w = wall_rows(run)
    if w is None:
        raise SystemExit(f"{run}: no frames.h5 and no walls.*.txt: no piston series to read")
    w = w[np.argsort(w[:, 0], kind="stable")]
    return w[:, 0], w[:, 4]


def series(run: Path) -> None:
    p = json.loads((run / "params.json").read_text())
    sc = p["scene"]
    Ft = sc["servo"]["target_force"]
    a, b = sc["stages"]["compress"]
    step, force = piston_force(run, p["dt"])
    ratio = np.abs(force) / Ft
    print(f"{run.name}: compression steps {a}-{b}, wall series to step {int(step[-1])}")
    arrived = np.flatnonzero((step > a) & (ratio > 0.98))
    if arrived.size:
        print(f"  piston arrives (F > 0.98 F_target) at step {int(step[arrived[0]])}")
    end = min(b, step[-1])
    sel = (step > end - 10000) & (step <= end) & (step > a)
    print(f"  compression, steps {int(end) - 10000}-{int(end)}: F/F_target mean {ratio[sel].mean():.4f} "
          f"std {ratio[sel].std():.4f}, range {ratio[sel].min():.3f}-{ratio[sel].max():.3f}")
    sh = step > b
    if sh.any():
        print(f"  shear ({sh.sum()} samples): F/F_target mean {ratio[sh].mean():.3f}, "
              f"range {ratio[sh].min():.3f}-{ratio[sh].max():.3f}")


def probe(run: Path, start: int, steps: int = 400, vmax_scale: float = 1.0) -> None:
    deck = (run / "deck.in").read_text().splitlines()
    if vmax_scale != 1.0:       # the servo's speed limit scaled: where does the limit cycle stop?
        deck = [_scaled_vmax(l, vmax_scale) if l.startswith("fix lower") else l for l in deck]
    first = next(i for i, l in enumerate(deck) if l.startswith(f"read_restart    restart/state.{start}.restart"))
    begin = max(i for i in range(first) if deck[i].startswith("atom_style"))
    end = next(i for i in range(first, len(deck)) if deck[i].startswith("fix_modify lower integrate start"))
    F_t = json.loads((run / "params.json").read_text())["scene"]["servo"]["target_force"]
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        (t / "restart").mkdir()
        shutil.copy(run / "restart" / f"state.{start}.restart", t / "restart")
        for stl in run.glob("*.stl"):
            shutil.copy(stl, t)
        (t / "deck.in").write_text("\n".join(deck[begin:end + 1] + [
            "variable s equal step", "variable fz equal f_lower[3]", "variable z equal f_lower[9]",
            'fix pr all print 1 "${s} ${z} ${fz}" file probe.txt screen no', f"run {steps}", ""]))
        subprocess.run(["liggghts", "-in", "deck.in", "-log", "none", "-echo", "none"], cwd=t, check=True,
                       stdout=subprocess.DEVNULL)
        p = np.loadtxt(t / "probe.txt", comments="#", ndmin=2)
    f = -p[:, 2] / F_t
    print(f"{run.name}: {len(p)} steps from {start} (v_max x {vmax_scale:g}): F/F_target every step, first 10: "
          + " ".join(f"{x:.2f}" for x in f[:10]))
    print(f"  mean {f.mean():.3f}, min {f.min():.3f}, max {f.max():.3f}; piston z range {np.ptp(p[:, 1]) * 1e9:.1f} nm; "
          f"sign changes of the step-to-step force change: {int(np.sum(np.diff(np.sign(np.diff(f))) != 0))}")


def _scaled_vmax(line: str, scale: float) -> str:
    words = line.split()
    i = words.index("vel_max")
    words[i + 1] = repr(float(words[i + 1]) * scale)
    return " ".join(words)


def main(argv=None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if args[:1] == ["gains"]:
        gains()
    elif args[:1] == ["series"] and len(args) >= 2:
        for r in args[1:]:
            series(Path(r))
    elif args[:1] == ["probe"] and len(args) in (3, 4):
        probe(Path(args[1]), int(args[2]), vmax_scale=float(args[3]) if len(args) == 4 else 1.0)
    else:
        print(__doc__, file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
