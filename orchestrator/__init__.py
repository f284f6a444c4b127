"""orchestrator: drive LIGGGHTS and YADE on granular scenes and compare them with X-ray CT.

Notebook entry points::

    import orchestrator as orc
    fr = orc.load("runs/shear_cell_smoke/liggghts-1a2b3c")   # frames as NumPy arrays
    fr[-1].to_dataframe()                                      # one frame as a table
"""
from .frames import Frame, Frames, FrameWriter, load, write_frames

__all__ = ["Frame", "Frames", "FrameWriter", "load", "write_frames", "load_case"]
__version__ = "0.1.0"


def load_case(path, overrides=None):
    """Load and validate a case file (see :mod:`orchestrator.case`)."""
    from .case import load_case as _lc
    return _lc(path, overrides)
