"""Benchmark (not a test) for the foundation, issue #2.

1. For every verification case on both engines: the share of wall time spent outside the engine.
   Two figures: the orchestrator's own work (render + parse) over the total, and the share
   outside the engine's time loop (adds process launch, engine start-up and its file writing).
   Target: <= 3 %.
2. Parse throughput (MB/s) of a 100 000-particle LIGGGHTS text dump (written by liggghts itself),
   as a ratio to OVITO's LAMMPS-dump reader on the same file (target >= 1, issue #17), and the
   same with the frames.h5 write added. Needs ``pip install ovito`` for the ratio; run with
   ``OVITO_THREAD_COUNT=1`` (benchmarks/docs_figures.sh sets it).

Run: ``.venv/bin/python benchmarks/bench_foundation.py [--skip-cases] [--repeat 7]``
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def overhead_table(runs_root: Path):
    from orchestrator.case import load_case
    from orchestrator.runner import run_case
    from orchestrator.verify import verification_cases
    rows = []
    for path in verification_cases():
        case = load_case(path)
        for eng in ("liggghts", "yade"):
            out = run_case(case, eng, runs_root=runs_root, force=True, progress=False)
            w = out.summary["wall_time"]
            total = w["total"]
            own = w["render"] + w["parse"]
            outside_loop = total - w["engine_loop"]
            rows.append((case.name.replace("chung_ooi_", ""), eng, total, w["engine"], w["engine_loop"],
                         w["render"], w["parse"], own / total, outside_loop / total))
    print(f"\n{'case':32s} {'engine':8s} {'total s':>8s} {'engine s':>9s} {'loop s':>7s} {'render s':>9s} "
          f"{'parse s':>8s} {'own %':>6s} {'outside loop %':>15s}")
    for r in rows:
        print(f"{r[0]:32s} {r[1]:8s} {r[2]:8.2f} {r[3]:9.2f} {r[4]:7.2f} {r[5]:9.3f} {r[6]:8.3f} "
              f"{100 * r[7]:6.1f} {100 * r[8]:15.1f}")
    for eng in ("liggghts", "yade"):
        sub = [r for r in rows if r[1] == eng]
        own = sum(r[5] + r[6] for r in sub) / sum(r[2] for r in sub)
        out = sum(r[2] - r[4] for r in sub) / sum(r[2] for r in sub)
        print(f"{eng}: orchestrator's own share {100 * own:.1f} % (target <= 3 %), "
              f"outside the engine's time loop {100 * out:.1f} %")


DECK = """units si
atom_style granular
atom_modify map array
communicate single vel yes
newton off
boundary f f f
region box block 0 {L} 0 {L} 0 {L} units box
create_box 1 box
lattice sc {a}
create_atoms 1 box
set atom * diameter {d} density 2500
velocity all set 0.013 -0.021 0.034 units box
fix m1 all property/global youngsModulus peratomtype 1e7
fix m2 all property/global poissonsRatio peratomtype 0.3
fix m3 all property/global coefficientRestitution peratomtypepair 1 0.9
fix m4 all property/global coefficientFriction peratomtypepair 1 0.5
pair_style gran model hertz tangential history
pair_coeff * *
timestep 1e-7
fix i all nve/sphere
dump d all custom 1 dump.100k.txt id type x y z vx vy vz fx fy fz radius
dump_modify d sort id
run 0
"""


def make_dump(workdir: Path) -> Path:
    """100 000 spheres on a 47^3 lattice (103 823), one dump written by liggghts."""
    a, n = 1e-3, 47
    (workdir / "in.dump").write_text(DECK.format(L=a * n, a=a, d=1.02 * a))   # overlapping: non-zero forces
    subprocess.run(["liggghts", "-in", "in.dump", "-echo", "none", "-log", "none"], cwd=workdir,
                   check=True, stdout=subprocess.DEVNULL)
    return workdir / "dump.100k.txt"


def parse_only(dump: Path) -> float:
    from engines.lammps_dump import read_dump
    t0 = time.perf_counter()
    _, _, a = read_dump(dump)
    assert a.shape[0] > 100000
    return time.perf_counter() - t0


def parse_into_frames(dump: Path, out: Path) -> float:
    from engines.lammps_dump import read_dump
    from orchestrator.frames import FrameWriter
    t0 = time.perf_counter()
    step, cols, a = read_dump(dump)
    ids = a[:, cols.index("id")].astype(np.int64)
    with FrameWriter(out, ids, a[:, cols.index("radius")], fields=("position", "velocity", "force")) as w:
        w.append(0.0, step, position=a[:, [cols.index(c) for c in "x y z".split()]],
                 velocity=a[:, [cols.index(c) for c in "vx vy vz".split()]],
                 force=a[:, [cols.index(c) for c in "fx fy fz".split()]])
    return time.perf_counter() - t0


def parse_throughput(workdir: Path, repeat: int = 7):
    """Best of ``repeat`` of each, interleaved (ours, OVITO, ours, ...), after one warm-up each
    (numba's cached kernel, pandas, OVITO's start-up). Two figures: the parse alone (text -> an
    in-memory (n, k) array, what OVITO's ``import_file(...).compute()`` does: the floor of #17) and
    parse + writing frames.h5 (the orchestrator's whole step; OVITO writes nothing)."""
    import pandas  # noqa: F401  (imported once per process, not part of a parse)
    dump = make_dump(workdir)
    mb = dump.stat().st_size / 1e6
    print(f"\nLIGGGHTS text dump: {mb:.1f} MB, 103 823 particles; best of {repeat}, one thread")
    try:
        from ovito.io import import_file
    except ImportError:
        import_file = None
    def ovito_once():
        t0 = time.perf_counter()
        data = import_file(str(dump)).compute()
        assert data.particles.count > 100000
        return time.perf_counter() - t0
    parse_only(dump)
    parse_into_frames(dump, workdir / "warm.h5")
    if import_file is not None:
        ovito_once()                                 # warm-up (OVITO's own start-up)
    ours, full, ov = [], [], []
    for k in range(repeat):
        ours.append(parse_only(dump))
        full.append(parse_into_frames(dump, workdir / f"f{k}.h5"))
        if import_file is not None:
            ov.append(ovito_once())
    ours, full = min(ours), min(full)
    print(f"orchestrator read_dump (parse):          {ours:.3f} s = {mb / ours:.0f} MB/s")
    print(f"orchestrator read_dump + frames.h5:      {full:.3f} s = {mb / full:.0f} MB/s")
    if import_file is None:
        print("OVITO not installed (pip install ovito): no ratio")
        return
    ov = min(ov)
    print(f"OVITO import_file + compute (parse):     {ov:.3f} s = {mb / ov:.0f} MB/s")
    print(f"parse throughput ratio orchestrator / OVITO = {ov / ours:.2f} (target >= 1)")
    print(f"parse + frames.h5 write / OVITO parse       = {ov / full:.2f}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--skip-cases", action="store_true")
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if not args.skip_cases:
            overhead_table(tmp / "runs")
        parse_throughput(tmp, args.repeat)


if __name__ == "__main__":
    main()
