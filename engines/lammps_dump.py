"""Readers of the LAMMPS dump family (LIGGGHTS-PUBLIC 3.8 and LAMMPS 2025): ``dump custom``
text snapshots and binary ``dump custom`` files, per-atom column names, and ``compute stress/atom``.

Shared by every engine package whose engine writes LAMMPS dumps; nothing here knows a scene.
Layout of a binary snapshot (LAMMPS ``dump custom`` with a ``.bin`` file name, src/dump_custom.cpp
``header_binary`` / ``write_binary``; modern LAMMPS adds a magic header, :func:`_header`): int64 step, int64 natoms, int32 triclinic, 6 int32
boundary flags, 6 float64 box bounds (+3 tilt factors if triclinic), int32 values per atom,
int32 chunk count, then per chunk an int32 length and that many float64.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .base import EngineError


class DumpError(EngineError):
    """A dump file that cannot be read (wrong layout, truncated text snapshot)."""


def stress_tensors(a: np.ndarray, cols: list[str]) -> np.ndarray:
    """(n, 3, 3) particle stress [Pa] from ``compute stress/atom`` (stress x volume, components
    xx yy zz xy xz yz, tension positive) divided by the sphere's volume."""
    s = a[..., [cols.index(f"c_pstress[{k}]") for k in range(1, 7)]]
    v = 4.0 / 3.0 * np.pi * a[..., cols.index("radius")] ** 3
    s = s / v[..., None]
    out = np.empty(a.shape[:-1] + (3, 3))
    for k, (i, j) in enumerate(((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))):
        out[..., i, j] = out[..., j, i] = s[..., k]
    return out



#: the magic strings modern LAMMPS (since 2021) writes before each binary snapshot
MAGIC = (b"DUMPCUSTOM", b"DUMPATOM")


def _header(raw: bytes, pos: int, end: int):
    """One snapshot header at ``pos``: (step, natoms, values per atom, column names or None,
    offset of the chunk count), or None when it runs past ``end`` (a file cut by a kill).

    Modern LAMMPS (``tools/binary2txt.cpp``) puts before the legacy header an int64
    ``-len(magic)``, the magic string, an int32 endian flag (1) and an int32 format revision,
    and, for revision > 1, after the values per atom: int32 length + unit style, a byte "time
    follows" (+ float64 time), int32 length + the column names. LIGGGHTS 3.8 writes the legacy
    header only (its first int64, the step, is never negative)."""
    if pos + 8 > end:
        return None
    first = int(np.frombuffer(raw, np.int64, 1, pos)[0])
    revision, columns, q = 0, None, pos
    if first < 0:
        n = -first
        if q + 8 + n + 8 > end:
            return None
        magic = raw[q + 8:q + 8 + n]
        if magic not in MAGIC:
            raise DumpError(f"binary dump: unknown magic string {magic!r} at byte {pos}")
        endian, revision = (int(x) for x in np.frombuffer(raw, np.int32, 2, q + 8 + n))
        if endian != 1:
            raise DumpError(f"binary dump: written with another byte order (endian flag {endian:#x})")
        q += 8 + n + 8
    if q + 16 + 4 + 24 + 48 + 4 > end:
        return None
    step, natoms = (int(x) for x in np.frombuffer(raw, np.int64, 2, q))
    tri = int(np.frombuffer(raw, np.int32, 1, q + 16)[0])
    if tri not in (0, 1):
        raise DumpError(f"binary dump: general triclinic boxes (flag {tri}) are not read")
    q += 16 + 4 + 24 + 48 + (24 if tri else 0)
    if q + 4 > end:
        return None
    size_one = int(np.frombuffer(raw, np.int32, 1, q)[0])
    q += 4
    if revision > 1:
        if q + 4 > end:
            return None
        q += 4 + max(int(np.frombuffer(raw, np.int32, 1, q)[0]), 0)        # unit style
        if q + 1 > end:
            return None
        q += 1 + (8 if raw[q] else 0)                                       # time flag (+ time)
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


def scan_binary_dump(raw: bytes, ncols: int | None):
    """Yield (step, natoms, start, end, chunks) for each *complete* snapshot of a LIGGGHTS/LAMMPS
    binary ``dump custom`` in file order (either header, :func:`_header`), stopping at a snapshot
    cut short by a kill; ``chunks`` are (byte offset, number of float64). ``ncols``: the values
    per atom expected (checked; None: any)."""
    pos, end = 0, len(raw)
    while True:
        h = _header(raw, pos, end)
        if h is None:
            return
        step, natoms, size_one, _, q = h
        if ncols is not None and size_one != ncols:
            raise DumpError(f"binary dump: snapshot at byte {pos} has {size_one} values per atom, expected {ncols}")
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
        yield step, natoms, pos, q, chunks
        pos = q


def dump_columns_in(path) -> list[str] | None:
    """The column names a modern binary dump declares in its first snapshot (None: legacy)."""
    raw = Path(path).read_bytes()
    h = _header(raw, 0, len(raw))
    return h[3] if h else None


def read_binary_dump(paths, ncols: int):
    """Yield (step, (n, ncols) array) for every complete snapshot of one or more binary dumps
    (given in writing order), in step order; a step written twice (a resumed segment starts at
    its restart step) is taken from its last occurrence."""
    found = {}
    for path in ([paths] if isinstance(paths, (str, Path)) else paths):
        raw = Path(path).read_bytes()
        for step, natoms, _, _, chunks in scan_binary_dump(raw, ncols):
            parts = [np.frombuffer(raw, np.float64, n, q) for q, n in chunks]
            a = parts[0] if len(parts) == 1 else np.concatenate(parts)
            found[step] = a.reshape(natoms, ncols)
    for step in sorted(found):
        yield step, found[step]



def truncate_binary_dump(path, ncols: int, max_step: int) -> int:
    """Cut a binary dump after its last complete snapshot with step <= ``max_step`` (before a
    resumed run appends to it); returns the new size in bytes."""
    path = Path(path)
    if not path.exists():
        return 0
    raw = path.read_bytes()
    keep = 0
    for step, _, _, stop, _ in scan_binary_dump(raw, ncols):
        if step <= max_step:
            keep = stop
    with open(path, "r+b") as fh:
        fh.truncate(keep)
    return keep



def _parse_numbers(body: bytes, ncols: int) -> np.ndarray:
    """Whitespace-separated numbers -> (rows, ncols) float64, exactly (round trip)."""
    if len(body) < 200_000:                         # small: a plain split is fastest
        a = np.array(body.split(), dtype=np.float64)
    else:                                            # pandas' C parser: ~10x faster, exact
        import io
        import pandas as pd       # only for large text dumps: pandas costs ~0.3 s to import
        # usecols drops the empty column a trailing space would add, while parsing
        a = pd.read_csv(io.BytesIO(body), sep=" ", header=None, usecols=range(ncols), dtype=np.float64,
                        engine="c", skipinitialspace=True).to_numpy()
    return a.reshape(-1, ncols)



def read_dump(path) -> tuple[int, list[str], np.ndarray]:
    """Read one LAMMPS/LIGGGHTS ``dump custom`` snapshot: (step, column names, (n, k) array)."""
    with open(path, "rb") as fh:
        raw = fh.read()
    # the nine header lines; the body is left in place (a view, not a 7 MB copy, for large dumps)
    header_end = 0
    for _ in range(9):
        header_end = raw.find(b"\n", header_end) + 1
        if header_end == 0:
            header_end = len(raw)
            break
    lines = raw[:header_end].split(b"\n")
    if not lines[0].startswith(b"ITEM: TIMESTEP"):
        raise DumpError(f"{path}: not a dump custom file")
    if len(lines) < 9:
        raise DumpError(f"{path}: truncated dump (header of {len(lines)} lines, 9 expected)")
    step = int(lines[1])
    n = int(lines[3])
    cols = lines[8].decode().split()[2:]
    body = memoryview(raw)[header_end:]
    if n == 0:
        return step, cols, np.empty((0, len(cols)))
    a = None
    if n * len(cols) < 20000:                     # tiny: a plain split is fastest
        a = np.array(bytes(body).split(), dtype=np.float64)
    else:
        # compiled exact parser (engines/_textparse.py), ~4x pandas; the general parser for the
        # tokens outside its fast path (17 significant digits, nan, inf)
        from . import _textparse
        got = _textparse.parse(body, n * len(cols))
        if isinstance(got, int):
            raise DumpError(f"{path}: truncated dump ({got} numbers for {n} atoms x {len(cols)} columns)")
        a = got if got is not None else _parse_numbers(bytes(body), len(cols)).ravel()
    if a.size != n * len(cols):
        raise DumpError(f"{path}: truncated dump ({a.size} numbers for {n} atoms x {len(cols)} columns)")
    return step, cols, a.reshape(n, len(cols))



COLUMNS = {"position": ("x", "y", "z"), "velocity": ("vx", "vy", "vz"),
            "angular_velocity": ("omegax", "omegay", "omegaz"), "force": ("fx", "fy", "fz"),
            "torque": ("tqx", "tqy", "tqz")}


def per_atom_arrays(a: np.ndarray, cols: list[str], ids: np.ndarray, order: np.ndarray, fields) -> tuple:
    """One snapshot ``a`` (atoms × ``cols``) as per-particle (N, 3) arrays of the frame fields in
    ``fields`` (see :data:`COLUMNS`), rows placed by atom id into the run's particle order (``ids``,
    with ``order = argsort(ids)``); a particle absent from the snapshot is a NaN row. Returns
    ``(rows, arrays)``: the row of each atom of ``a`` and ``{field: array}``."""
    rows = order[np.searchsorted(ids[order], a[:, cols.index("id")].astype(np.int64))]
    arrays = {}
    for field, names in COLUMNS.items():
        if field in fields and names[0] in cols:
            out = np.full((len(ids), 3), np.nan)
            out[rows] = a[:, [cols.index(c) for c in names]]
            arrays[field] = out
    return rows, arrays
