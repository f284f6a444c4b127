"""The initial packing's digest (orchestrator.initial_packing.packing_digest, part of the run hash)
covers the grains a run starts from, not the frames file's bytes: a file written again with the same
grains (its meta.created differs) gives the same digest, so the run made from it is reused; another
grain position or another frame gives another."""
from __future__ import annotations

import time

import numpy as np

from orchestrator.case import InitialPacking
from orchestrator.frames import write_frames
from orchestrator.initial_packing import packing_digest


def _write(path, position):
    ids, radius = np.arange(1, 5), np.full(4, 1e-5)
    return write_frames(path, ids, radius, time=[0.0, 1.0], position=position)


def test_digest_follows_the_grains_not_the_file_bytes(tmp_path):
    rng = np.random.default_rng(0)
    pos = rng.uniform(0, 1e-4, (2, 4, 3))
    a = _write(tmp_path / "a.h5", pos)
    time.sleep(0.01)                         # meta.created differs
    b = _write(tmp_path / "b.h5", pos)
    assert a.read_bytes() != b.read_bytes()
    assert packing_digest(InitialPacking(frames=str(a))) == packing_digest(InitialPacking(frames=str(b)))
    moved = pos.copy()
    moved[0, 2, 1] += 1e-9
    c = _write(tmp_path / "c.h5", moved)
    assert packing_digest(InitialPacking(frames=str(c))) != packing_digest(InitialPacking(frames=str(a)))
    assert packing_digest(InitialPacking(frames=str(a), frame=1)) != packing_digest(InitialPacking(frames=str(a)))
