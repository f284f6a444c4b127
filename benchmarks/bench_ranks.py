"""Benchmark (not a test) for issue #17 item 6: one case on 1 and on 2 MPI ranks (LIGGGHTS), whole runs.

    .venv/bin/python benchmarks/bench_ranks.py CASE [--set JSON] [--runs DIR]

Runs the case (fresh: a new runs directory unless ``--runs`` names one) with
``engine_options.mpi_ranks`` 1 and 2, one after the other, and prints for each the engine wall time,
LIGGGHTS' own loop time and its breakdown summed over every ``run`` of the deck (Pair, Neigh, Comm,
Output, Other: "Other" is the fixes: mesh walls, servo, shell pressure, monitors), then the speed-up
2 ranks / 1 rank of the loop time (floor 1.7) and of each part. Run it on a quiet machine: with more
runnable processes than cores the two ranks wait on each other at every exchange.

Examples (docs/speed.md)::

    python benchmarks/bench_ranks.py cases/shear_cell_default.yaml
    python benchmarks/bench_ranks.py cases/triaxial_small.yaml \\
        --set '{"scene": {"axial_strain": 0.005, "frames": 2, "isotropic": {"max_chunks": 2, "drag_ramp": 0}}}'
"""
from __future__ import annotations

import argparse
import json
import re
import tempfile
from pathlib import Path

from orchestrator.case import load_case
from orchestrator.runner import run_case

PARTS = ("Pair", "Neigh", "Comm", "Outpt", "Other")


def loop_breakdown(log: Path) -> dict:
    """LIGGGHTS' loop time and its parts [s], summed over every run of an engine log."""
    out = dict.fromkeys(("loop",) + PARTS, 0.0)
    for line in log.read_text(errors="replace").splitlines():
        m = re.match(r"Loop time of ([\d.eE+-]+) on \d+ procs", line)
        if m:
            out["loop"] += float(m.group(1))
            continue
        m = re.match(r"(Pair|Neigh|Comm|Outpt|Other)\s+time \(%\) = ([\d.eE+-]+)", line)
        if m:
            out[m.group(1)] += float(m.group(2))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("case")
    ap.add_argument("--set", default="{}", help="case overrides as JSON")
    ap.add_argument("--runs", type=Path, help="runs directory (default: a fresh temporary one)")
    a = ap.parse_args(argv)
    over = json.loads(a.set)
    root = a.runs or Path(tempfile.mkdtemp(prefix="bench_ranks_"))
    res = {}
    for ranks in (1, 2):
        eo = {**over.get("engine_options", {}), "mpi_ranks": ranks}
        case = load_case(a.case, overrides={**over, "engine_options": eo, "name": f"{Path(a.case).stem}_np{ranks}"})
        out = run_case(case, "liggghts", runs_root=root, progress=False, analyze=False)
        res[ranks] = {"engine": out.summary["wall_time"]["engine"], "steps": out.summary["steps_run"],
                      **loop_breakdown(out.run_dir / "engine.log")}
        r = res[ranks]
        print(f"{ranks} rank(s): {r['steps']} steps, engine {r['engine']:.1f} s, loop {r['loop']:.1f} s = "
              + ", ".join(f"{k} {r[k]:.1f}" for k in PARTS), flush=True)
    one, two = res[1], res[2]
    print(f"speed-up 2/1: loop {one['loop'] / two['loop']:.2f} (floor 1.7), engine {one['engine'] / two['engine']:.2f}; "
          + ", ".join(f"{k} {one[k] / two[k]:.2f}" for k in ("Pair", "Other") if two[k] > 0))
    print(f"share of one rank's loop outside Pair: {1 - one['Pair'] / one['loop']:.0%}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
