"""The two registries that join scenes and engines: Python entry points (``importlib.metadata``).

- group ``orchestrator.engines``: name -> an :class:`engines.base.Engine` subclass;
- group ``orchestrator.scenes``: kind -> an :class:`orchestrator.scenes.base.Scene` subclass.

A package adds an engine or a scene by declaring an entry point in its ``pyproject.toml``
(``[project.entry-points."orchestrator.engines"]``); no module here or elsewhere lists them. The
lists are read from the installed distributions' metadata, so the package must be installed
(``pip install -e .`` in a checkout). This module imports neither layer: entry points are loaded
only when asked for.
"""
from __future__ import annotations

import functools
from importlib.metadata import entry_points

ENGINE_GROUP = "orchestrator.engines"
SCENE_GROUP = "orchestrator.scenes"


class RegistryError(KeyError):
    """A name no installed package registers."""

    def __str__(self):
        return str(self.args[0])


@functools.lru_cache(maxsize=None)
def _points(group: str) -> dict:
    pts = {ep.name: ep for ep in entry_points(group=group)}
    if not pts:
        raise RegistryError(f"no entry points in group {group!r}: the orchestrator package is not installed "
                            "(run `pip install -e .` in the checkout, or `bash .ci/setup`)")
    return dict(sorted(pts.items()))


def engine_names() -> tuple[str, ...]:
    """Names of the installed engine adapters, sorted."""
    return tuple(_points(ENGINE_GROUP))


def scene_kinds() -> tuple[str, ...]:
    """Kinds of the installed scenes, sorted."""
    return tuple(_points(SCENE_GROUP))


@functools.lru_cache(maxsize=None)
def engine_class(name: str):
    pts = _points(ENGINE_GROUP)
    if name not in pts:
        raise RegistryError(f"unknown engine {name!r}; installed engines: {', '.join(pts)}")
    return pts[name].load()


def get_engine(name: str):
    """A new adapter for the engine ``name``."""
    return engine_class(name)()


@functools.lru_cache(maxsize=None)
def get_scene(kind: str):
    """The scene ``kind`` (one instance per process: scenes hold no state)."""
    pts = _points(SCENE_GROUP)
    if kind not in pts:
        raise RegistryError(f"unknown scene kind {kind!r}; installed scenes: {', '.join(pts)}")
    return pts[kind].load()()
