"""Engine adapters behind one interface (:class:`engines.base.Engine`), one package per engine
(``engines/<name>/``), registered under the entry-point group ``orchestrator.engines``
(pyproject.toml) and found through :mod:`orchestrator.registry`. Shared here: the interface
(:mod:`engines.base`), Jinja rendering (:mod:`engines.render`) and the LAMMPS-dump-family readers
(:mod:`engines.lammps_dump`).
"""
from __future__ import annotations

from orchestrator.registry import engine_names, get_engine

from .base import Engine, EngineError, Substitution, UnsupportedFeature

__all__ = ["Engine", "EngineError", "Substitution", "UnsupportedFeature", "get_engine", "engine_names"]
