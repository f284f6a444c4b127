"""How exactly does a LIGGGHTS run resume? (docs/engines.md, Resume; issue #16)

Runs a case's deck uninterrupted, keeping its restart files, then resumes it from one restart in a
copy of the run directory and prints, against the uninterrupted run:

1. the largest grain-position difference at every frame after the restart step;
2. per-step state at the restart step S and S+1: grain positions, velocities, forces, and the
   servo wall's z and force (thermo every step around S);
3. the wall series rows on both sides of S.

    .venv/bin/python benchmarks/resume_exactness.py [CASE] [--step S] [--root DIR]

Each run is a full smoke run (a few minutes on a loaded 2-core machine).
"""
from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np

from engines import get_engine
from engines.liggghts import dump_segments, read_binary_dump
from orchestrator.case import load_case
from orchestrator.runner import run_case

REPO = Path(__file__).resolve().parents[1]
DBG_COLS = "id x y z vx vy vz fx fy fz omegax omegay omegaz"


def _debug_deck(deck: Path, S: int, stop: int | None) -> None:
    """Add text dumps at S and S+1, per-step thermo with the servo's z and force, and stop at ``stop``."""
    fmt = "%d" + " %.17g" * 12
    extra = "".join(f"dump dbg{k} all custom {S + k} dump/dbg{k}.*.txt {DBG_COLS}\n"
                    f"dump_modify dbg{k} sort id format \"{fmt}\"\n" for k in (0, 1))
    extra += ("thermo_style custom step atoms ke f_lower[9] f_lower[3]\nthermo_modify format float %.17g\n"
              f"thermo 1\n")
    text = deck.read_text()
    k = text.index("\ndump            fr ")
    text = text[:k + 1] + extra + text[k + 1:]
    if stop is not None:
        text = re.sub(r"^run\s+(\d+) upto", lambda m: f"run {min(int(m.group(1)), stop)} upto", text, flags=re.M)
    deck.write_text(text)


def _run(eng, case, deck: Path) -> None:
    with open(deck.parent / "engine.log", "w") as log:
        subprocess.run(eng.command(deck, case), cwd=deck.parent, stdout=log, stderr=subprocess.STDOUT, check=True)


def _thermo(run_dir: Path) -> dict:
    log = (run_dir / "engine.log").read_text()
    return {int(m.group(1)): (float(m.group(2)), float(m.group(3)))
            for m in re.finditer(r"^\s*(\d+)\s+\d+\s+\S+\s+(\S+)\s+(\S+)\s*$", log, re.M)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("case", nargs="?", default=str(REPO / "cases" / "shear_cell_smoke.yaml"))
    ap.add_argument("--step", type=int, help="restart step to resume from (default: the second restart)")
    ap.add_argument("--root", default="/tmp/resume_exactness")
    a = ap.parse_args()
    root = Path(a.root)
    case = load_case(a.case)
    eng = get_engine("liggghts")
    ref = run_case(case, "liggghts", runs_root=root, dry_run=True, progress=False).run_dir
    params = json.loads((ref / "params.json").read_text())
    if not (ref / "ref.done").exists():
        _run(eng, case, ref / "deck.in")
        (ref / "ref.done").write_text("")
    cols = json.loads((ref / "dump" / "columns.json").read_text())
    restarts = sorted(int(p.name.split(".")[1]) for p in (ref / "restart").glob("state.*.restart"))
    S = a.step or restarts[1]
    print(f"case {case.name}: restart steps {restarts}; resuming from {S}")

    # 1. frames and wall series of a full resumed run
    d = root / f"resume_{S}"
    shutil.rmtree(d, ignore_errors=True)
    shutil.copytree(ref, d)
    resume = {"restart_file": f"restart/state.{S}.restart", "step": S}
    eng.prepare_resume(d, resume)
    _run(eng, case, eng.render(case, params, d, resume=resume))
    rfr = dict(read_binary_dump(dump_segments(ref), len(cols)))
    fr = dict(read_binary_dump(dump_segments(d), len(cols)))
    xi = [cols.index(c) for c in ("x", "y", "z")]
    print("frames: uninterrupted", sorted(rfr), "resumed", sorted(fr))
    for st in sorted(fr):
        print(f"  frame at step {st}: max |dx| = {np.abs(fr[st][:, xi] - rfr[st][:, xi]).max():.3e} m")
    w_ref = np.vstack([np.loadtxt(f, ndmin=2) for f in sorted(ref.glob("walls.*.txt"))])
    w_res = np.vstack([np.loadtxt(f, ndmin=2) for f in sorted(d.glob("walls.*.txt"))])
    print(f"wall rows: uninterrupted {len(w_ref)}, resumed {len(w_res)}; same steps: "
          f"{len(w_ref) == len(w_res) and np.array_equal(w_ref[:, 0], w_res[:, 0])}")
    rows = {int(r[0]): r for r in w_res}
    for r in w_ref:
        if S - 40 <= r[0] <= S + 100:
            q = rows.get(int(r[0]))
            print(f"  step {int(r[0])}: z_lower {r[1]:.6e} / {q[1] if q is not None else float('nan'):.6e}")

    # 2. the state at S and S+1, uninterrupted (from step 0) and resumed
    state = {}
    for start in (0, S):
        e = root / f"dbg_{start}"
        shutil.rmtree(e, ignore_errors=True)
        shutil.copytree(ref, e)
        for f in [*(e / "dump").glob("frames*.bin"), *e.glob("walls.*.txt")]:
            f.unlink()
        if start:
            eng.prepare_resume(e, dict(resume))
            deck = eng.render(case, params, e, resume=resume)
        else:
            deck = e / "deck.in"
        _debug_deck(deck, S, S + 2)
        _run(eng, case, deck)
        state[start] = {k: np.loadtxt(e / "dump" / f"dbg{k}.{S + k}.txt", skiprows=9) for k in (0, 1)}
        th = _thermo(e)
        print(f"{'uninterrupted' if not start else 'resumed'}: servo z, force at steps S..S+2: "
              + "; ".join(f"{s}: {th[s][0]!r}, {th[s][1]:.3e} N" for s in range(S, S + 3) if s in th))
    names = DBG_COLS.split()
    for k in (0, 1):
        u, r = state[0][k], state[S][k]
        diff = np.abs(u - r)
        print(f"step S+{k}: max |difference| " + ", ".join(f"{n} {diff[:, i].max():.2e}" for i, n in enumerate(names) if i))
        f_rel = diff[:, 7:10].max(1) / np.maximum(np.abs(u[:, 7:10]).max(1), 1e-300)
        for i in np.where(f_rel > 1e-12)[0]:
            print(f"  grain {int(u[i, 0])} at z = {u[i, 3]:.4e} m: force {u[i, 7:10]} N uninterrupted, {r[i, 7:10]} N resumed")


if __name__ == "__main__":
    main()
