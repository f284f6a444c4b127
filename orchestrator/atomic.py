"""Atomic file writes: write to ``<name>.partial`` then rename, so no half-written file ever
carries a final name."""
from __future__ import annotations

import contextlib
import errno
import json
import os
import re
from pathlib import Path

#: the name :func:`temp_file` gives (``tempfile.mkstemp``: the prefix ``.<name>.``, eight random
#: characters, the suffix)
_TEMP_NAME = re.compile(r"^\..+\.[A-Za-z0-9_]{8}(\.[A-Za-z0-9]+)?$")


def cache_dir(kind: str) -> Path:
    """``$ORCHESTRATOR_CACHE/<kind>`` (default ``~/.cache/orchestrator/<kind>``): where results that
    a pure computation can always make again are kept between processes (packings, clump mass
    properties). Not created here."""
    return Path(os.environ.get("ORCHESTRATOR_CACHE", Path.home() / ".cache" / "orchestrator")) / kind


def umask() -> int:
    """The process's file-creation mask (read by setting and restoring it)."""
    m = os.umask(0o022)
    os.umask(m)
    return m


def temp_file(path, suffix: str = "") -> Path:
    """A new empty temporary file beside ``path`` whose mode follows the user's umask (as a file
    opened normally would): :func:`tempfile.mkstemp` makes it 0600 and a rename keeps that mode,
    so a colleague on a shared filesystem could not read the result."""
    import tempfile
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix="." + path.name + ".", suffix=suffix, dir=path.parent)
    try:
        os.fchmod(fd, 0o666 & ~umask())
    finally:
        os.close(fd)
    return Path(tmp)


def remove_stale_temp_files(folder) -> list[Path]:
    """Delete the temporary files :func:`temp_file` made under ``folder`` (recursively) that a killed
    process left behind, and return them. Only for a folder no other process writes to (a run
    directory whose lock the caller holds): a write under way there would lose its file. A run
    killed while its analyses wrote left ``analysis/.profiles_axial.csv.zu2ysuqa.csv`` beside the
    tables of the resumed run (session 37)."""
    gone = []
    for f in Path(folder).rglob(".*"):
        if f.is_file() and _TEMP_NAME.match(f.name):
            f.unlink(missing_ok=True)
            gone.append(f)
    return gone


def write_text(path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` through ``<name>.partial``. A ``path`` that is a directory is
    an IsADirectoryError naming it, before anything is written; the temporary file is removed when
    the write fails."""
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR), str(path))
    tmp = path.with_name(path.name + ".partial")
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):      # never created, or not ours (a directory of that name)
            tmp.unlink()
        raise
    return path


def write_json(path, data) -> Path:
    return write_text(path, json.dumps(data, indent=2, sort_keys=True, default=_default) + "\n")


def _default(o):
    try:
        import numpy as np
        if isinstance(o, np.generic):
            return o.item()
        if isinstance(o, np.ndarray):
            return o.tolist()
    except ImportError:  # pragma: no cover
        pass
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
