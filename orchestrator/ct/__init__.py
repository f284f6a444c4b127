"""X-ray CT side of the orchestrator: read and synthesise tomograms, segment grains, describe their
shape by spherical harmonics, track them across scans and write CT frames (``frames.h5``).

Modules: :mod:`.io` (scans), :mod:`.synth` (synthetic scans with ground truth), :mod:`.segment`
(grains and contacts), :mod:`.shape` (SH expansion and invariants), :mod:`.track` (linking,
image-based rotation, SH matching), :mod:`.export` (tracked grains -> frames), :mod:`.clumpfit`
(grains -> clump shape libraries), :mod:`.cli`.
All lengths are in metres; see docs/ct.md.
"""
from .io import Scan, ScanError, read_scan, read_series, write_scan, check_series  # noqa: F401

#: exported from :mod:`.clumpfit`, imported on first use (it pulls in scikit-image and the
#: segmentation kernels, which ``import orchestrator.ct`` alone does not need)
_CLUMPFIT = ("fit_clump", "clump_quality", "shape_library_from_segmentation", "shape_library_from_labels",
             "write_shape_library")


def __getattr__(name):
    if name in _CLUMPFIT:
        from . import clumpfit
        return getattr(clumpfit, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
