"""Scenes: each module defines one experiment (its case section, its derived numbers, the
physics features it needs, and the files it prepares for the engines).

A scene module provides:

- ``Scene``: a pydantic model with ``kind: Literal["<name>"]`` (the case's ``scene:`` section);
- ``required_features(case) -> list[str]``: physics features the engines must offer
  (vocabulary in :mod:`engines.base`);
- ``derive(case, common) -> dict``: scene numbers for the templates (SI), from the case and the
  common derived parameters;
- ``max_velocity(case) -> float``: largest expected relative velocity [m/s] (for the Hertz
  time-step limit);
- optional ``prepare(case, params, run_dir) -> dict``: write shared input files (meshes,
  particle lists) and return their paths for the templates;
- ``CONTROLS``: names of per-frame control values written to frames.h5.
"""
from __future__ import annotations

import importlib

#: scene kind -> module name. Add a scene here.
SCENES = {
    "impact": "orchestrator.scenes.impact",
    "triaxial": "orchestrator.scenes.triaxial",
    "shear_cell": "orchestrator.scenes.shear_cell",
    "plane_shear": "orchestrator.scenes.plane_shear",
}


def scene_module(kind: str):
    if kind not in SCENES:
        raise KeyError(f"unknown scene kind {kind!r}; known: {', '.join(SCENES)}")
    return importlib.import_module(SCENES[kind])


def scene_models():
    return [scene_module(k).Scene for k in SCENES]


def scene_kinds():
    return list(SCENES)
