"""Sweep benchmark (not a test): 8 plane-shear smoke runs (LIGGGHTS, μ = 0.1 … 0.8) through the
executor on 2 workers against 1 worker; prints both times and the ratio (target ≤ 0.55). The
process start-up (imports, engine version probe) is paid once before both timings.

    .venv/bin/python benchmarks/bench_sweep.py [--dask] [--engine liggghts|yade]

Local processes by default; ``--dask`` uses a dask.distributed LocalCluster (processes, one thread
each). Every run starts from a fresh runs directory (nothing reused). The machine must have 2
idle cores for a meaningful ratio: `uptime` is printed before and after.
"""
from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from orchestrator.stability.executor import DaskExecutor, LocalExecutor, warm_worker  # noqa: E402
from orchestrator.stability.sweep import sweep  # noqa: E402

CASE = REPO / "cases" / "plane_shear_smoke.yaml"
MUS = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8]


def timed(make_executor, engine) -> float:
    """Wall time of the whole sweep, the executor's creation and shut-down included (both sides)."""
    root = Path(tempfile.mkdtemp(prefix="bench_sweep_"))
    try:
        t0 = time.perf_counter()
        with make_executor() as executor:
            df = sweep(CASE, {"contact.friction": MUS}, engines=[engine], runs_root=root, executor=executor)
        dt = time.perf_counter() - t0
        bad = df[df["status"] != "complete"]
        if len(bad):
            raise SystemExit(f"{len(bad)} run(s) did not complete:\n{bad}")
        return dt
    finally:
        shutil.rmtree(root, ignore_errors=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--dask", action="store_true")
    ap.add_argument("--engine", default="liggghts")
    a = ap.parse_args()
    print("load before:", subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip())
    os.environ["OMP_NUM_THREADS"] = "1"
    # the one-off start-up of this process (imports ~2.5 s, the engine's version probe ~0.5 s, the
    # restitution inversion) is paid here, outside both timings: otherwise the 1-worker side, timed
    # first, would carry it alone. Each side then times the same sweep; the 2-worker side also pays
    # its pool (fork + worker warm-up) inside its timing.
    t0 = time.perf_counter()
    import pandas  # noqa: F401  (the sweep's result table)
    warm_worker(CASE, (a.engine,))
    print(f"process start-up (excluded from both sides): {time.perf_counter() - t0:.1f} s")
    if a.dask:
        from distributed import Client, LocalCluster
        times = {}
        for n in (1, 2):
            with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None) as cl, \
                    Client(cl) as client:
                times[n] = timed(lambda: DaskExecutor(client=client), a.engine)
    else:
        times = {1: timed(lambda: LocalExecutor(1), a.engine), 2: timed(lambda: LocalExecutor(2), a.engine)}
    print("load after: ", subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip())
    print(f"8 smoke runs ({a.engine}, {'dask LocalCluster' if a.dask else 'local processes'}): "
          f"1 worker {times[1]:.1f} s, 2 workers {times[2]:.1f} s")
    ratio = times[2] / times[1]
    print(f"ratio 2 workers / 1 worker = {ratio:.3f} (target <= 0.55: {'met' if ratio <= 0.55 else 'NOT met'})")


if __name__ == "__main__":
    main()
