"""YADE 2023.02 (Debian ``yade``, its own python3.11): adapter and the files its scripts write.
Registered as the ``yade`` engine (pyproject.toml entry points)."""
from __future__ import annotations

from .adapter import Yade
from .output import chunk_files

__all__ = ["Yade", "chunk_files"]
