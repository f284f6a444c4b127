"""Command line of the CT side: ``orchestrator ct synth|segment|track|shapes``.

The lead's CLI wires :func:`add_ct_parser` into its sub-commands; each ``*_main(args)`` takes the
parsed :class:`argparse.Namespace` and returns an exit code. Lengths on the command line carry
units ("2.2 um") and are converted to SI with :func:`orchestrator.units.to_si`.

File layout:

* ``ct synth`` writes ``<out>/scan_000.tif`` ... (ImageJ TIFF with voxel size and origin) and
  ``<out>/truth.h5`` (the frames rendered, ground truth ids and positions);
* ``ct segment`` writes for every scan ``<out>/<scan>_grains.csv`` (grain table, SI units, with
  SH invariants R0..R15 unless ``--no-shape``), ``<out>/<scan>_contacts.csv`` and, with
  ``--labels``, ``<out>/<scan>_labels.tif``;
* ``ct track`` reads those grain tables (and the scans for ``--method rotation``) and writes
  ``frames.h5`` in the common frame format;
* ``ct shapes`` writes a clump shape library (YAML of :func:`orchestrator.clumps.load_library`) from
  one scan or one ``<scan>_labels.tif`` (with its ``<scan>_grains.csv``).
"""
from __future__ import annotations

import argparse
import math
import sys

__all__ = ["add_ct_parser", "run_main", "main"]   # the *_main handlers: orchestrator.ct.commands


def _checked(conv, ok, rule):
    """An argparse ``type``: ``conv`` of the option's text, refused unless ``ok`` (argparse then names
    the option and exits 2, before any work)."""
    def check(s):
        try:
            v = conv(s)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{s!r} is not a number; give {rule}") from None
        if not (ok(v) and math.isfinite(v)):
            raise argparse.ArgumentTypeError(f"{s!r} is out of range; give {rule}")
        return v
    return check


_voxels = _checked(float, lambda v: v >= 0, "a number of voxels >= 0 (0 = none), e.g. 0.8")
_noise = _checked(float, lambda v: v >= 0, "a fraction of the solid-pore contrast >= 0, e.g. 0.05")
_fraction = _checked(float, lambda v: 0 <= v <= 1, "a fraction of the grains in [0, 1], e.g. 0.1")
_degree = _checked(int, lambda v: 0 <= v <= 30, "an SH degree in 0..30, e.g. 15")
_count = _checked(int, lambda v: v >= 1, "a whole number >= 1")


def _dtype(s):
    """An argparse ``type``: a NumPy numeric data type name."""
    import numpy as np
    try:
        ok = np.dtype(s).kind in "biuf"
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise argparse.ArgumentTypeError(f"{s!r} is not a numeric data type; give e.g. uint8, uint16 or float32")
    return s


def _deferred(name):
    """The handler ``name`` of :mod:`.commands`, imported when the sub-command runs: the parser alone,
    built for ``orchestrator --help``, then loads no imaging stack."""
    def handler(args):
        from . import commands
        return getattr(commands, name)(args)
    handler.__name__ = name
    return handler


def add_ct_parser(subparsers) -> argparse.ArgumentParser:
    """Add ``ct`` with sub-commands ``synth``, ``segment``, ``track``, ``run``, ``shapes`` to an argparse
    subparsers object."""
    ct = subparsers.add_parser("ct", help="X-ray CT: synthetic scans, segmentation, tracking")
    sub = ct.add_subparsers(dest="ct_command", required=True)

    p = sub.add_parser("synth", help="render frames (a frames.h5 or a demo packing) as synthetic scans")
    p.add_argument("--frames", help="frames.h5 (or run directory) to render")
    p.add_argument("--demo", choices=["shear"], help="instead of --frames: a sheared cylinder of spheres, 2 scans")
    p.add_argument("--voxel-size", required=True, help='voxel edge, e.g. "2.2 um"')
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--frame", type=int, action="append", help="frame index to render (repeatable; default all)")
    p.add_argument("--psf", type=_voxels, default=0.8, help="Gaussian PSF sigma [voxels]")
    p.add_argument("--noise", type=_noise, default=0.05, help="noise std, fraction of contrast")
    p.add_argument("--drift", type=float, default=0.0, help="relative contrast drift bottom->top")
    p.add_argument("--hollow", type=_fraction, default=0.0, help="fraction of grains made hollow")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=_deferred("synth_main"))

    p = sub.add_parser("segment", help="segment scans into grains (grain tables, contacts, SH invariants)")
    p.add_argument("scans", nargs="+", help="scan files (TIFF, directory of slices, .npy, raw)")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--voxel-size", help='voxel edge if the files lack it, e.g. "2.2 um"')
    p.add_argument("--shape", nargs=3, type=_count, metavar=("NZ", "NY", "NX"), help="raw volumes: shape")
    p.add_argument("--dtype", type=_dtype, help="raw volumes: dtype (uint8, uint16, float32 ...)")
    p.add_argument("--sigma", type=_voxels, default=1.0, help="Gaussian filter sigma [voxels]")
    p.add_argument("--h", help='marker height, e.g. "2 um" (default 1 voxel)')
    p.add_argument("--no-shape", action="store_true", help="skip the SH expansion")
    p.add_argument("--degree", type=_degree, default=15, help="SH degree")
    p.add_argument("--labels", action="store_true", help="also write the label volume")
    p.set_defaults(func=_deferred("segment_main"))

    p = sub.add_parser("track", help="track grains across scans and write frames.h5")
    p.add_argument("segdir", help="output directory of `ct segment`")
    p.add_argument("--out", required=True, help="frames.h5 to write")
    p.add_argument("--method", choices=["displacement", "rotation", "invariants"], default="displacement")
    p.add_argument("--max-disp", help='largest displacement, e.g. "15 um" (default d50/2)')
    p.add_argument("--scans", nargs="*", help="the scans (needed by --method rotation), same order")
    p.add_argument("--voxel-size", help="voxel edge for scans that lack it")
    p.add_argument("--rings", type=_count, default=4, help="rings of equal area (rotation method)")
    p.set_defaults(func=_deferred("track_main"))

    p = sub.add_parser("run", help="segment and track the scan series of a case's ct: section")
    p.add_argument("case", help="case YAML with a ct: section")
    p.add_argument("--runs", default="runs", help="runs directory (default ./runs)")
    p.add_argument("--force", action="store_true", help="process the series again")
    p.set_defaults(func=run_main)

    p = sub.add_parser("shapes", help="clump shape library (YAML for particles.library) from a scan's grains")
    p.add_argument("input", help="a scan (TIFF, directory of slices, .npy, raw), or <scan>_labels.tif of "
                   "`ct segment --labels` with <scan>_grains.csv beside it")
    p.add_argument("-o", "--out", required=True, help="library to write (.yaml)")
    p.add_argument("--spheres", type=int, default=6, help="most spheres per clump (default 6)")
    p.add_argument("--coverage", type=float, default=0.97, help="stop adding spheres at this covered fraction of a grain")
    p.add_argument("--min-voxels", type=int, default=1000, help="smallest grain [voxels] to use (default 1000)")
    p.add_argument("--keep-flagged", action="store_true", help="also use grains flagged over/under-segmented")
    p.add_argument("--voxel-size", help='voxel edge if the file lacks it, e.g. "2.2 um"')
    p.add_argument("--shape", nargs=3, type=_count, metavar=("NZ", "NY", "NX"), help="raw volume: shape")
    p.add_argument("--dtype", type=_dtype, help="raw volume: dtype (uint8, uint16, float32 ...)")
    p.add_argument("--sigma", type=_voxels, default=1.0, help="Gaussian filter sigma [voxels] of the segmentation")
    p.add_argument("--h", help='marker height of the segmentation, e.g. "2 um" (default: segment\'s)')
    p.set_defaults(func=_deferred("shapes_main"))
    return ct


def run_main(args) -> int:
    from ..case import load_case
    from .case_run import run_ct_case
    case = load_case(args.case)
    out = run_ct_case(case, args.runs, force=args.force)
    print(f"ct frames: {out}")
    return 0


def main(argv=None) -> int:
    """Stand-alone entry (``python -m orchestrator.ct.cli ...``) until the lead wires ``orchestrator ct``."""
    ap = argparse.ArgumentParser(prog="orchestrator")
    sub = ap.add_subparsers(dest="command", required=True)
    add_ct_parser(sub)
    args = ap.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
