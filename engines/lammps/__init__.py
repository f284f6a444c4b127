"""LAMMPS (``pair_style granular``) behind the :class:`engines.base.Engine` interface."""
from .adapter import Lammps

__all__ = ["Lammps"]
