"""Data files shipped with the package (templates, measured throughput), found through
:mod:`importlib.resources`, so that a non-editable ``pip install .`` can run a case.

The files stay where the project keeps them (top-level ``templates/<engine>/``,
``benchmarks/throughput.json``); ``orchestrator/_data/`` holds symbolic links to them, which
setuptools follows when it builds a wheel (``[tool.setuptools.package-data]`` in pyproject.toml)
and which an editable install or a checkout reads in place.
"""
from __future__ import annotations

from importlib.resources import as_file, files
from pathlib import Path


def data_file(relative: str) -> Path:
    """Path of a shipped data file, e.g. ``benchmarks/throughput.json`` (it may not exist: a
    benchmark result is written by its script)."""
    with as_file(files("orchestrator") / "_data" / relative) as p:    # a real directory in both installs
        return Path(p)


def templates_dir() -> Path:
    """The directory holding ``<engine>/<scene>.<ext>.j2`` (top-level ``templates/``)."""
    return data_file("templates")
