#!/usr/bin/env python3
"""Probe the stage-1 servo of a YADE triaxial run from its checkpoint: the platen's contact stiffness
and damping against the derivation's estimates, and how the loop behaves at a given gain.

    .venv/bin/python benchmarks/servo_probe.py RUN_DIR [--gain G ...] [--steps N]

RUN_DIR is a YADE triaxial run directory with ``checkpoint.yade.gz`` (a run in stage 1; the run
itself is left alone: the checkpoint is copied). For the checkpoint's state it prints

- K: the platen contacts' tangent normal stiffness (1.5 kn for YADE's Mindlin law) [N/m], and C:
  their normal dashpots 2 betan sqrt(m kn) [N s/m], each against the estimate of
  ``orchestrator.scenes.servo_loop`` (one d50 grain per d50² of platen at F = p d50²);
- the linear loop's spectral radius at each gain with the measured K and C (above 1: unstable);
- per gain (the deck's own first, then ``--gain``; proportional only, the integral off), the run of
  ``--steps`` steps with every other engine of the deck off but the grains' drag: the mean platen
  force on even and on odd steps over the last half, relative to the target (an even/odd split is
  the chatter), and the platen's mean speed.

Session 18 (docs/triaxial.md, "Servo"): the 4 000-clump sample at step 295 200 of the old deck."""
from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from orchestrator.scenes import servo_loop  # noqa: E402

YADE_PART = r'''
import json, math, sys
from yade import *
O.load("checkpoint.yade.gz")
args = json.load(open("probe_args.json"))
st = json.loads(O.tags["orch_triaxial"])
top = st["top"]
for e in O.engines:
    if isinstance(e, PyRunner):
        e.dead = True
s = next(e for e in O.engines if e.label == "servo")
K = C = 0.0
ints = [i for i in O.interactions.withBody(top) if i.isReal]
for i in ints:
    g = i.id1 if i.id2 == top else i.id2
    m = O.bodies[g].state.mass
    K += 1.5 * i.phys.kn                     # Mindlin: F = kno uN^1.5, kn = kno uN^0.5
    C += 2.0 * i.phys.betan * math.sqrt(m * i.phys.kn)
out = {"iter": O.iter, "contacts": len(ints), "K": K, "C": C, "target": s.target, "kP": s.kP,
       "dt": O.dt, "runs": []}
for gs in args["gain_scales"]:
    O.load("checkpoint.yade.gz")
    for e in O.engines:
        if isinstance(e, PyRunner):
            e.dead = True
    s = next(e for e in O.engines if e.label == "servo")
    s.kP *= gs
    s.kI = 0.0
    f, v = [], []
    for k in range(args["steps"]):
        O.step()
        f.append(O.forces.f(top)[2])
        v.append(s.curVel)
    h = len(f) // 2
    tail, vt = f[h:], v[h:]
    out["runs"].append({"scale": gs, "even": sum(tail[0::2]) / len(tail[0::2]) / s.target,
                        "odd": sum(tail[1::2]) / len(tail[1::2]) / s.target,
                        "v_mean": sum(vt) / len(vt), "v_alt": sum(abs(vt[k] - vt[k - 1]) for k in range(1, len(vt))) / (len(vt) - 1)})
json.dump(out, open("probe_out.json", "w"))
'''


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--gain", type=float, action="append", default=[], help="a gain to try (repeat)")
    ap.add_argument("--steps", type=int, default=2000)
    a = ap.parse_args(argv)
    run = a.run_dir.resolve()
    params = json.loads((run / "params.json").read_text())
    sc, iso = params["scene"], params["scene"]["iso"]
    p, d50, dt = sc["pressure"], sc["d50"], params["dt"]
    k_est = servo_loop.platen_stiffness(p, d50, params["E_eff_pw"])
    c_est = servo_loop.platen_damping(p, d50, params["E_eff_pw"], params["material"]["rho"],
                                      params["restitution"].get("damping_ratio") or 0.0)
    g0 = iso["gain"]
    gains = [g0] + a.gain
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        shutil.copy(run / "checkpoint.yade.gz", tmp)
        (tmp / "probe.py").write_text(YADE_PART)
        (tmp / "probe_args.json").write_text(json.dumps({"gain_scales": [g / g0 for g in gains], "steps": a.steps}))
        r = subprocess.run(["yade", "-n", "-j", "1", "-x", "probe.py"], cwd=tmp, capture_output=True, text=True)
        if r.returncode != 0 or not (tmp / "probe_out.json").exists():
            sys.exit(f"servo_probe: yade failed:\n{r.stdout[-2000:]}\n{r.stderr[-2000:]}")
        out = json.loads((tmp / "probe_out.json").read_text())
    area = out["target"] / p                     # the servo's target is p A (stage 1 after the ramp)
    n_est = area / d50 ** 2
    K, C = out["K"], out["C"]
    print(f"{run.name}: step {out['iter']}, {out['contacts']} platen contacts (estimate {n_est:.0f} grains)")
    print(f"  K = {K:.3g} N/m = {K / (n_est * k_est):.2f} x estimate;  C = {C:.3g} N s/m = {C / (n_est * c_est):.2f} x estimate")
    v_max = iso["v_max"]
    print(f"  {'gain':>8} {'a':>6} {'b':>6} {'radius':>7} {'F even/T':>9} {'F odd/T':>8} {'v mean':>8} {'|dv| per step':>13}")
    for g, run_ in zip(gains, out["runs"]):
        a_, b_ = g * v_max * dt * K / (p * area), g * v_max * C / (p * area)
        rad = servo_loop.spectral_radius(a_, b_)
        print(f"  {g:8.3g} {a_:6.2f} {b_:6.2f} {rad:7.2f} {run_['even']:9.3f} {run_['odd']:8.3f} "
              f"{run_['v_mean']:8.3f} {run_['v_alt']:13.3f}")


if __name__ == "__main__":
    main()
