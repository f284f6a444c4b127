"""Atomic writers for frame chunks and wall series, the windowed mean of wall samples and the
resume of a text time series. numpy only (no YADE): unit-tested without the engine."""
from __future__ import annotations

import os

import numpy as np


def save_npz_atomic(name: str, **arrays) -> None:
    """``np.savez`` to ``name`` through a ``.partial.npz`` file and an atomic rename: a reader (or a
    run killed mid-write) never sees half a file."""
    tmp = name + ".partial.npz"
    np.savez(tmp, **arrays)
    os.replace(tmp, name)


def save_npy_atomic(name: str, array) -> None:
    """``np.save`` through a ``.partial.npy`` file and an atomic rename."""
    tmp = name + ".partial.npy"
    np.save(tmp, array)
    os.replace(tmp, name)


def chunk_arrays(buf: dict) -> dict:
    """A frame buffer (lists per key, one entry per frame) as the arrays of one chunk file: frame
    fields stacked along a first frame axis; contact lists (keys ``c_*`` except ``c_count``)
    concatenated over the frames, ``c_count`` giving each frame's number of contacts."""
    out = {}
    for k, v in buf.items():
        if k.startswith("c_") and k != "c_count":
            out[k] = np.concatenate(v) if v else np.zeros((0,))
        else:
            out[k] = np.asarray(v)
    return out


class WindowSeries:
    """A series whose rows are means over ``window`` samples: ``add(step, values)`` buffers a
    sample; every ``window``-th sample appends ``[step] + mean(values)`` (``step`` is that of the
    last sample). ``flush()`` writes all rows to ``name`` (``.npy``, atomic) as a (rows, 1 + n)
    float array."""

    def __init__(self, name: str, n_values: int, window: int = 10):
        self.name, self.n_values, self.window = name, n_values, window
        self.rows, self.acc = [], []

    def add(self, step: int, values) -> None:
        values = list(values)
        if len(values) != self.n_values:
            raise ValueError("%s: a sample has %d values, expected %d" % (self.name, len(values), self.n_values))
        self.acc.append(values)
        if len(self.acc) >= self.window:
            self.rows.append([step] + list(np.mean(np.asarray(self.acc, dtype=float), axis=0)))
            self.acc = []

    def flush(self) -> None:
        save_npy_atomic(self.name, np.asarray(self.rows, dtype=float).reshape(-1, 1 + self.n_values))


def reopen_series(name: str, it: int):
    """Resume a text series at a checkpoint: keep the header (``#`` lines) and the rows stamped with
    an iteration <= ``it`` (the rows after the checkpoint are written again), drop a last line cut
    by the kill; rewrite atomically and return the file opened for appending."""
    keep = []
    with open(name) as fh:
        for line in fh:
            if not line.endswith("\n"):
                break
            if line.startswith("#"):
                keep.append(line)
                continue
            try:
                if int(line.split()[0]) <= it:
                    keep.append(line)
            except (ValueError, IndexError):
                break
    with open(name + ".partial", "w") as fh:
        fh.writelines(keep)
    os.replace(name + ".partial", name)
    return open(name, "a")


def stop_steps(events, restart_every: int) -> list:
    """The steps a scene script stops at: every event step and every multiple of ``restart_every``
    before the last event (yade_runtime.recorder.checkpoint_and_reload there)."""
    last = events[-1]["step"]
    return sorted({e["step"] for e in events} | set(range(restart_every, last, restart_every)))
