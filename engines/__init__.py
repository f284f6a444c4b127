"""Engine adapters behind one interface (:class:`engines.base.Engine`)."""
from __future__ import annotations

from .base import Engine, EngineError, Substitution, UnsupportedFeature


def get_engine(name: str) -> Engine:
    """The adapter for ``name`` ('liggghts' or 'yade')."""
    if name == "liggghts":
        from .liggghts import Liggghts
        return Liggghts()
    if name == "yade":
        from .yade import Yade
        return Yade()
    raise KeyError(f"unknown engine {name!r}; known: liggghts, yade")


ENGINE_NAMES = ("liggghts", "yade")
__all__ = ["Engine", "EngineError", "Substitution", "UnsupportedFeature", "get_engine", "ENGINE_NAMES"]
