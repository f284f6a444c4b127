"""LIGGGHTS-PUBLIC 3.8 (Debian ``liggghts``): adapter, its dump and resume files, its side of
the scenes' decks. Registered as the ``liggghts`` engine (pyproject.toml entry points)."""
from __future__ import annotations

from .adapter import Liggghts, dump_columns, read_contacts, write_data_file
from .segments import dump_segments, wall_rows

__all__ = ["Liggghts", "dump_columns", "read_contacts", "write_data_file", "dump_segments", "wall_rows"]
