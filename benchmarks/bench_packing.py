"""CPU time of the dense packer (orchestrator.psd.relax_overlaps through the triaxial scene's
pack_cylinder) on the shipped triaxial cases' grains, with its sweep count and packing fraction.

    .venv/bin/python benchmarks/bench_packing.py [CASE ...]      # default: smoke, small, seed

To compare with another version of the packer, run the same file with that checkout first on the
path: ``git worktree add /tmp/old REV && PYTHONPATH=/tmp/old .venv/bin/python
benchmarks/bench_packing.py`` (26 Nov 2026, quiet machine: the seed case 78 s at bd0de3c, a
neighbour search every sweep; 15 s with the Verlet list; 1409 sweeps both).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from orchestrator.case import load_case
from orchestrator.derive import derive
from orchestrator.scenes.triaxial import pack_cylinder

CASES = Path(__file__).resolve().parents[1] / "cases"


def main(names: list[str]) -> None:
    for name in names or ["triaxial_smoke", "triaxial_small", "triaxial_seed"]:
        case = load_case(CASES / f"{name}.yaml")
        sc = derive(case).scene
        r = np.asarray(sc["diameters"]) / 2
        t0 = time.process_time()
        _, geo = pack_cylinder(r, sc["diameter"] / 2, sc["height"], np.random.default_rng(case.seed + 2))
        cpu = time.process_time() - t0
        print(f"{name}: {len(r)} grains, {cpu:.2f} s CPU, {geo['packing_iterations']} sweeps, "
              f"packing fraction {geo['packing_fraction0']:.4f}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
