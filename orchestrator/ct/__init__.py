"""X-ray CT side of the orchestrator: read and synthesise tomograms, segment grains, describe their
shape by spherical harmonics, track them across scans and write CT frames (``frames.h5``).

Modules: :mod:`.io` (scans), :mod:`.synth` (synthetic scans with ground truth), :mod:`.segment`
(grains and contacts), :mod:`.shape` (SH expansion and invariants), :mod:`.track` (linking,
image-based rotation, SH matching), :mod:`.export` (tracked grains -> frames), :mod:`.cli`.
All lengths are in metres; see docs/ct.md.
"""
from .io import Scan, ScanError, read_scan, read_series, write_scan, check_series  # noqa: F401
