"""Why a finished frames.h5 is read without HDF5's file lock (docs/frames.md).

    .venv/bin/python benchmarks/bench_h5_lock.py [--loops 400]

A thread starts processes in a loop (`true`, as a threaded sweep starts engines) while the main thread
writes a small frames file (``orchestrator.frames.write_frames``: ``.partial``, then renamed) and opens
the finished file for reading, once with HDF5's lock and once without it (what
``orchestrator.frames.Frames`` does). Prints how many of the loops failed to open the file each way.
"""
from __future__ import annotations

import argparse
import subprocess
import tempfile
import threading
from pathlib import Path

import h5py
import numpy as np

from orchestrator.frames import write_frames


def failures(loops: int, locking: bool, root: Path) -> int:
    """Loops [-] (of ``loops``) whose finished file did not open for reading."""
    stop = threading.Event()

    def start_processes():
        while not stop.is_set():
            subprocess.run(["true"])

    starter = threading.Thread(target=start_processes)
    starter.start()
    failed = 0
    try:
        for k in range(loops):
            path = root / f"{'on' if locking else 'off'}-{k}" / "frames.h5"
            write_frames(path, ids=np.arange(3), radius=np.full(3, 1e-5), time=np.arange(2) * 0.1,
                         position=np.zeros((2, 3, 3)))
            try:
                with h5py.File(path, "r", locking=locking) as h:
                    h["frames/position"][()]
            except OSError:
                failed += 1
    finally:
        stop.set()
        starter.join()
    return failed


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--loops", type=int, default=400)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for locking in (True, False):
            n = failures(args.loops, locking, Path(tmp))
            print(f"HDF5 file lock {'on ' if locking else 'off'}: {n} of {args.loops} finished files failed to open")


if __name__ == "__main__":
    main()
