"""Engine adapters behind one interface (:class:`engines.base.Engine`)."""
from __future__ import annotations

from .base import Engine, EngineError, Substitution, UnsupportedFeature


def get_engine(name: str) -> Engine:
    """The adapter for ``name`` (one of :data:`ENGINE_NAMES`)."""
    if name == "liggghts":
        from .liggghts import Liggghts
        return Liggghts()
    if name == "yade":
        from .yade import Yade
        return Yade()
    if name == "lammps":
        from .lammps import Lammps
        return Lammps()
    raise KeyError(f"unknown engine {name!r}; known: {', '.join(ENGINE_NAMES)}")


ENGINE_NAMES = ("liggghts", "yade", "lammps")
__all__ = ["Engine", "EngineError", "Substitution", "UnsupportedFeature", "get_engine", "ENGINE_NAMES"]
