"""Reader for the LAMMPS binary ``dump custom`` family: LIGGGHTS' legacy header and the modern
LAMMPS header (since 2021) that starts each snapshot with a ``DUMPCUSTOM`` magic string.

Layout per snapshot (LAMMPS ``tools/binary2txt.cpp``; ``src/dump_custom.cpp`` header_binary):

- modern only: int64 ``-len(magic)``, the magic string (``DUMPCUSTOM``), int32 endian flag (1),
  int32 format revision;
- int64 step, int64 natoms, int32 triclinic, 6 int32 boundary flags, 6 float64 box bounds
  (+3 tilt factors if triclinic), int32 values per atom;
- modern with revision > 1 only: int32 length + unit-style string, one byte "time follows" flag
  (+ float64 time), int32 length + the column names (space separated);
- int32 chunk count, then per chunk an int32 length and that many float64.

One scanner serves both, so LIGGGHTS 3.8 dumps read here as they do in ``engines.liggghts``.
A snapshot cut short by a kill ends the scan (the complete ones before it are kept).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..base import EngineError

#: the magic strings LAMMPS writes before a binary dump's snapshots (dump custom / atom)
MAGIC = (b"DUMPCUSTOM", b"DUMPATOM")


def _header(raw: bytes, pos: int, end: int):
    """Parse one snapshot header at ``pos``: (step, natoms, size_one, columns or None, offset of
    the chunk count), or None when the header runs past ``end`` (a truncated file)."""
    if pos + 8 > end:
        return None
    first = int(np.frombuffer(raw, np.int64, 1, pos)[0])
    revision, columns = 0, None
    q = pos
    if first < 0:                                        # modern header: magic, endian, revision
        n = -first
        if q + 8 + n + 8 > end:
            return None
        magic = raw[q + 8:q + 8 + n]
        if magic not in MAGIC:
            raise EngineError(f"binary dump: unknown magic string {magic!r} at byte {pos}")
        endian, revision = (int(x) for x in np.frombuffer(raw, np.int32, 2, q + 8 + n))
        if endian != 1:
            raise EngineError(f"binary dump: written with another byte order (endian flag {endian:#x})")
        q += 8 + n + 8
    if q + 16 + 4 + 24 + 48 + 4 > end:
        return None
    step, natoms = (int(x) for x in np.frombuffer(raw, np.int64, 2, q))
    tri = int(np.frombuffer(raw, np.int32, 1, q + 16)[0])
    if tri not in (0, 1):
        raise EngineError(f"binary dump: general triclinic boxes (flag {tri}) are not read")
    q += 16 + 4 + 24 + 48 + (24 if tri else 0)
    if q + 4 > end:
        return None
    size_one = int(np.frombuffer(raw, np.int32, 1, q)[0])
    q += 4
    if revision > 1:
        if q + 4 > end:
            return None
        n = int(np.frombuffer(raw, np.int32, 1, q)[0])              # unit style
        q += 4 + max(n, 0)
        if q + 1 > end:
            return None
        q += 1 + (8 if raw[q] else 0)                                # time flag (+ time)
        if q + 4 > end:
            return None
        n = int(np.frombuffer(raw, np.int32, 1, q)[0])
        if q + 4 + n > end:
            return None
        columns = raw[q + 4:q + 4 + n].decode().split()
        q += 4 + n
    if q + 4 > end:
        return None
    return step, natoms, size_one, columns, q


def scan(raw: bytes, ncols: int | None = None):
    """Yield (step, natoms, start, stop, chunks, columns) for each complete snapshot in file
    order; ``chunks`` are (byte offset, number of float64). ``ncols``: values per atom expected
    (checked when given); ``columns``: the column names a modern header carries, else None."""
    pos, end = 0, len(raw)
    while True:
        h = _header(raw, pos, end)
        if h is None:
            return
        step, natoms, size_one, columns, q = h
        if ncols is not None and size_one != ncols:
            raise EngineError(f"binary dump: snapshot at byte {pos} has {size_one} values per atom, expected {ncols}")
        nchunk = int(np.frombuffer(raw, np.int32, 1, q)[0])
        q += 4
        chunks = []
        for _ in range(nchunk):
            if q + 4 > end:
                return
            n = int(np.frombuffer(raw, np.int32, 1, q)[0])
            q += 4
            if q + 8 * n > end:
                return
            chunks.append((q, n))
            q += 8 * n
        yield step, natoms, pos, q, chunks, columns
        pos = q


def read_binary_dump(paths, ncols: int | None = None):
    """Yield (step, (natoms, ncols) array) for every complete snapshot of one or more binary
    dumps (given in writing order), in step order; a step written twice (a resumed segment
    starts at its restart step) is taken from its last occurrence."""
    found = {}
    for path in ([paths] if isinstance(paths, (str, Path)) else paths):
        raw = Path(path).read_bytes()
        for step, natoms, _, _, chunks, columns in scan(raw, ncols):
            width = ncols if ncols is not None else (len(columns) if columns else None)
            parts = [np.frombuffer(raw, np.float64, n, q) for q, n in chunks]
            a = parts[0] if len(parts) == 1 else np.concatenate(parts) if parts else np.zeros(0)
            found[step] = a.reshape(natoms, width if width else (a.size // max(natoms, 1)))
    for step in sorted(found):
        yield step, found[step]


def dump_columns_in(path) -> list[str] | None:
    """The column names a modern binary dump declares in its first snapshot (None: legacy)."""
    raw = Path(path).read_bytes()
    for *_, columns in scan(raw):
        return columns
    return None


def truncate_binary_dump(path, max_step: int, ncols: int | None = None) -> int:
    """Cut a binary dump after its last complete snapshot with step <= ``max_step`` (before a
    resumed run writes on); returns the new size in bytes (0 for a missing file)."""
    path = Path(path)
    if not path.exists():
        return 0
    raw = path.read_bytes()
    keep = 0
    for step, _, _, stop, _, _ in scan(raw, ncols):
        if step <= max_step:
            keep = stop
    with open(path, "r+b") as fh:
        fh.truncate(keep)
    return keep
