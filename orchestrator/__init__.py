"""orchestrator: drive LIGGGHTS and YADE on granular scenes and compare them with X-ray CT.

Notebook entry points::

    import orchestrator as orc
    fr = orc.load("runs/shear_cell_smoke/liggghts-1a2b3c")   # frames as NumPy arrays
    fr[-1].to_dataframe()                                      # one frame as a table
    orc.status("runs")                                         # every run: status, steps, time so far and left
"""
__all__ = ["Frame", "Frames", "FrameWriter", "load", "write_frames", "load_case", "status"]
__version__ = "0.1.0"

#: names served from orchestrator.frames on first use: importing it (h5py) costs ~0.4 s, which every
#: command paid, `validate` included (issue #16: validate within 2 s)
_FRAMES = ("Frame", "Frames", "FrameWriter", "load", "write_frames")


def __getattr__(name):
    if name in _FRAMES:
        from . import frames
        return getattr(frames, name)
    raise AttributeError(f"module 'orchestrator' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_FRAMES))


def load_case(path, overrides=None):
    """Load and validate a case file (see :mod:`orchestrator.case`)."""
    from .case import load_case as _lc
    return _lc(path, overrides)


def status(paths="runs"):
    """Every run under ``paths`` (run directories or runs trees): status, steps reached, engine time
    so far and left, a row each in a DataFrame (:func:`orchestrator.run_status.status_table`)."""
    from .run_status import status_table
    return status_table(paths)
