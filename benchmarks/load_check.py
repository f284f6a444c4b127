"""Load check (issue #16): 8 runs started at once in one runs directory -- the same case four
times and four other cases -- must all end complete, with frames identical to solo runs.

    .venv/bin/python benchmarks/load_check.py [--runs DIR] [--engine liggghts]

The four runs of one case share a run directory: one drives it, the others wait for its lock and
reuse its result (orchestrator.runner: _RunLock(wait=True)). Then every case is run again alone in
a fresh runs directory and the frames are compared bit for bit. Prints, per run: exit status,
status, whether it was reused, wall time, and the largest position difference to the solo run.
Starts up to five engines at once: run it on a machine nobody else is using.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
VER = REPO / "cases" / "verification"
SAME = VER / "chung_ooi_4_oblique.yaml"
OTHERS = [VER / "chung_ooi_1_sphere_sphere_glass.yaml", VER / "chung_ooi_2_sphere_plane_alumina.yaml",
          VER / "chung_ooi_3_restitution_e06.yaml", REPO / "cases" / "plane_shear_smoke.yaml"]


def _cmd(case: Path, runs: Path, engine: str) -> list[str]:
    return [sys.executable, "-m", "orchestrator", "run", str(case), "--engine", engine, "--runs", str(runs), "--quiet"]


def _run_dir(out: str) -> Path:
    """The run directory named on the orchestrator's result line."""
    for line in out.splitlines():
        for word in line.split():
            if "-" in word and Path(word).is_dir() and (Path(word) / "summary.json").exists():
                return Path(word)
    raise RuntimeError(f"no run directory in output:\n{out}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", default="/tmp/load_check")
    ap.add_argument("--engine", default="liggghts", choices=["liggghts", "yade"])
    a = ap.parse_args()
    root = Path(a.runs)
    cases = [SAME] * 4 + OTHERS
    t0 = time.perf_counter()
    procs = [(c, subprocess.Popen(_cmd(c, root / "together", a.engine), stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True)) for c in cases]
    together = []
    for c, p in procs:
        out, err = p.communicate(timeout=7200)
        together.append((c, p.returncode, out, err, time.perf_counter() - t0))
    from orchestrator.frames import Frames
    bad = 0
    solo_dirs = {}
    for c in dict.fromkeys(cases):
        s = subprocess.run(_cmd(c, root / "solo", a.engine), capture_output=True, text=True, timeout=7200)
        assert s.returncode == 0, s.stderr
        solo_dirs[c] = _run_dir(s.stdout)
    print(f"{'case':40s} {'exit':>4s} {'status':9s} {'reused':6s} {'wall [s]':>9s} {'max |dx| vs solo [m]':>21s}")
    for c, code, out, err, wall in together:
        if code != 0:
            bad += 1
            print(f"{c.stem:40s} {code:4d} {'-':9s} {'-':6s} {wall:9.1f}  {err.strip().splitlines()[-1]}")
            continue
        d = _run_dir(out)
        s = json.loads((d / "summary.json").read_text())
        fa, fb = Frames(d), Frames(solo_dirs[c])
        same = fa.position.shape == fb.position.shape
        dx = float(np.nanmax(np.abs(fa.position - fb.position))) if same else float("inf")
        bad += (s["status"] != "complete") or dx != 0.0
        print(f"{c.stem:40s} {code:4d} {s['status']:9s} {str('reused' in out):6s} {wall:9.1f} {dx:21.3g}")
    print("all complete and identical to solo runs" if not bad else f"{bad} run(s) failed or differ")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
