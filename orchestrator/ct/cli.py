"""Command line of the CT side: ``orchestrator ct synth|segment|track``.

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
  ``frames.h5`` in the common frame format.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

__all__ = ["add_ct_parser", "synth_main", "segment_main", "track_main"]


def _length(s):
    if s is None:
        return None
    from ..units import to_si
    return to_si(s, "length")


def add_ct_parser(subparsers) -> argparse.ArgumentParser:
    """Add ``ct`` with sub-commands ``synth``, ``segment``, ``track`` to an argparse subparsers object."""
    ct = subparsers.add_parser("ct", help="X-ray CT: synthetic scans, segmentation, tracking")
    sub = ct.add_subparsers(dest="ct_command", required=True)

    p = sub.add_parser("synth", help="render frames (a frames.h5 or a demo packing) as synthetic scans")
    p.add_argument("--frames", help="frames.h5 (or run directory) to render")
    p.add_argument("--demo", choices=["shear"], help="instead of --frames: a sheared cylinder of spheres, 2 scans")
    p.add_argument("--voxel-size", required=True, help='voxel edge, e.g. "2.2 um"')
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--frame", type=int, action="append", help="frame index to render (repeatable; default all)")
    p.add_argument("--psf", type=float, default=0.8, help="Gaussian PSF sigma [voxels]")
    p.add_argument("--noise", type=float, default=0.05, help="noise std, fraction of contrast")
    p.add_argument("--drift", type=float, default=0.0, help="relative contrast drift bottom->top")
    p.add_argument("--hollow", type=float, default=0.0, help="fraction of grains made hollow")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=synth_main)

    p = sub.add_parser("segment", help="segment scans into grains (grain tables, contacts, SH invariants)")
    p.add_argument("scans", nargs="+", help="scan files (TIFF, directory of slices, .npy, raw)")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--voxel-size", help='voxel edge if the files lack it, e.g. "2.2 um"')
    p.add_argument("--shape", nargs=3, type=int, metavar=("NZ", "NY", "NX"), help="raw volumes: shape")
    p.add_argument("--dtype", help="raw volumes: dtype (uint8, uint16, float32 ...)")
    p.add_argument("--sigma", type=float, default=1.0, help="Gaussian filter sigma [voxels]")
    p.add_argument("--h", help='marker height, e.g. "2 um" (default 1 voxel)')
    p.add_argument("--no-shape", action="store_true", help="skip the SH expansion")
    p.add_argument("--degree", type=int, default=15, help="SH degree")
    p.add_argument("--labels", action="store_true", help="also write the label volume")
    p.set_defaults(func=segment_main)

    p = sub.add_parser("track", help="track grains across scans and write frames.h5")
    p.add_argument("segdir", help="output directory of `ct segment`")
    p.add_argument("--out", required=True, help="frames.h5 to write")
    p.add_argument("--method", choices=["displacement", "rotation", "invariants"], default="displacement")
    p.add_argument("--max-disp", help='largest displacement, e.g. "15 um" (default d50/2)')
    p.add_argument("--scans", nargs="*", help="the scans (needed by --method rotation), same order")
    p.add_argument("--voxel-size", help="voxel edge for scans that lack it")
    p.add_argument("--rings", type=int, default=4, help="rings of equal area (rotation method)")
    p.set_defaults(func=track_main)

    p = sub.add_parser("run", help="segment and track the scan series of a case's ct: section")
    p.add_argument("case", help="case YAML with a ct: section")
    p.add_argument("--runs", default="runs", help="runs directory (default ./runs)")
    p.add_argument("--force", action="store_true", help="process the series again")
    p.set_defaults(func=run_main)
    return ct


def run_main(args) -> int:
    from ..case import load_case
    from .case_run import run_ct_case
    case = load_case(args.case)
    out = run_ct_case(case, args.runs, force=args.force)
    print(f"ct frames: {out}")
    return 0


def synth_main(args) -> int:
    from rich.console import Console
    from . import synth
    from .io import write_scan
    from ..frames import write_frames
    con = Console(stderr=True)
    vs = _length(args.voxel_size)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(args.seed)
    kw = dict(psf_sigma=args.psf, noise=args.noise, drift=args.drift)
    if args.frames:
        from ..frames import Frames
        fr = Frames(args.frames)
        hollow = np.where(rng.random(fr.n_particles) < args.hollow, 0.5, 0.0)
        scans, ids = synth.scans_from_frames(fr, vs, frame_indices=args.frame, hollow=hollow, seed=args.seed, **kw)
        idx = list(range(fr.n_frames)) if args.frame is None else args.frame
        pos, radius, times = fr.position[idx], fr.radius, fr.time[idx]
    elif args.demo == "shear":
        n_vox, H = 96, 72
        R = 0.45 * n_vox * vs
        centre = np.array([(n_vox - 1) / 2, (n_vox - 1) / 2]) * vs
        r = rng.uniform(5, 6.5, int(0.45 * np.pi * (R / vs) ** 2 * (H - 4) / (4 / 3 * np.pi * 5.8 ** 3))) * vs
        cyl = (centre[0], centre[1], R, 2 * vs, H * vs)
        a = synth.pack_spheres(r, cylinder=cyl, seed=args.seed)
        ang = np.deg2rad(5) / (1 + np.exp(-(a[:, 2] - H * vs / 2) / (5 * vs)))
        b = synth.pack_spheres(r, cylinder=cyl, initial=synth.twist(a, centre, ang))
        pos, radius, times, ids = np.stack([a, b]), r, np.array([0.0, 1.0]), np.arange(len(r))
        hollow = np.where(rng.random(len(r)) < args.hollow, 0.5, 0.0)
        scans = synth.render_sequence((H + 3, n_vox, n_vox), vs, pos, r, times=times, progress=True,
                                      hollow=hollow, seed=args.seed, **kw)
    else:
        con.print("[red]ct synth: give --frames FILE or --demo shear[/red]")
        return 2
    for k, s in enumerate(scans):
        write_scan(s, out / f"scan_{k:03d}.tif")
    write_frames(out / "truth.h5", ids, radius, times, pos, meta={"source": "ct-synthetic-truth", "voxel_size": vs})
    con.print(f"wrote {len(scans)} scans of shape {scans[0].shape} to {out} (ground truth: truth.h5)")
    return 0


def segment_main(args) -> int:
    from rich.console import Console
    from rich.progress import Progress
    from . import segment, shape
    from .io import ScanError, read_scan, write_scan, check_series
    con = Console(stderr=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    kw = {}
    if args.voxel_size:
        kw["voxel_size"] = _length(args.voxel_size)
    if args.shape:
        kw["shape"], kw["dtype"] = tuple(args.shape), args.dtype
    try:
        scans = [read_scan(p, **kw) for p in args.scans]
        check_series(scans)
    except ScanError as e:
        con.print(f"[red]error:[/red] {e}")
        return 2
    summary = []
    with Progress(console=con) as prog:
        task = prog.add_task("segmenting scans", total=len(scans))
        for p, sc in zip(args.scans, scans):
            stem = Path(p).stem if not Path(p).is_dir() else Path(p).name
            seg = segment.segment(sc, sigma=args.sigma, h=_length(args.h))
            g = seg.grains
            if not args.no_shape:
                tab, _ = shape.grain_shapes(seg, degree=args.degree)
                g = g.merge(tab, on="label")
            g.to_csv(out / f"{stem}_grains.csv", index=False)
            seg.contacts().to_csv(out / f"{stem}_contacts.csv", index=False)
            if args.labels:
                from .io import Scan
                write_scan(Scan(seg.labels.astype(np.uint16 if seg.labels.max() < 65535 else np.float32),
                                sc.voxel_size, sc.origin), out / f"{stem}_labels.tif")
            info = {"scan": str(p), "time": sc.time, "controls": sc.controls, "voxel_size": sc.voxel_size,
                    **seg.summary()}
            summary.append(info)
            prog.advance(task)
            con.print(f"{p}: {info['grains']} grains, {info['flagged_over']} flagged over-, "
                      f"{info['flagged_under']} under-segmented")
    (out / "segment.json").write_text(json.dumps(summary, indent=1, default=str))
    return 0


def track_main(args) -> int:
    from rich.console import Console
    from . import track
    from .export import write_ct_frames
    from .io import ScanError, read_scan, check_series
    con = Console(stderr=True)
    segdir = Path(args.segdir)
    meta_path = segdir / "segment.json"
    if not meta_path.exists():
        con.print(f"[red]error:[/red] {meta_path}: not found; run `orchestrator ct segment` first")
        return 2
    info = json.loads(meta_path.read_text())
    tables = []
    for s in info:
        p = Path(s["scan"])
        stem = p.stem if not p.is_dir() else p.name
        tables.append(pd.read_csv(segdir / f"{stem}_grains.csv"))
    scans = None
    if args.method == "rotation":
        paths = args.scans or [s["scan"] for s in info]
        kw = {"voxel_size": _length(args.voxel_size)} if args.voxel_size else {}
        try:
            scans = [read_scan(p, **kw) for p in paths]
            check_series(scans)
        except ScanError as e:
            con.print(f"[red]error:[/red] {e}")
            return 2
    links = track.track_sequence(tables, args.method, max_disp=_length(args.max_disp), scans=scans,
                                 rotation_kw={"n_rings": args.rings}, progress=True)
    contacts = []
    for s in info:
        p = Path(s["scan"])
        f = segdir / f"{(p.stem if not p.is_dir() else p.name)}_contacts.csv"
        contacts.append(pd.read_csv(f) if f.exists() and f.stat().st_size > 1 else None)
    times = [s.get("time") if s.get("time") is not None else np.nan for s in info]
    ctrl_names = sorted({k for s in info for k in (s.get("controls") or {})})
    controls = {k: [float((s.get("controls") or {}).get(k, np.nan)) for s in info] for k in ctrl_names}
    write_ct_frames(args.out, tables, links, times=times, controls=controls, contacts=contacts,
                    voxel_size=info[0]["voxel_size"], meta={"scans": [s["scan"] for s in info],
                                                            "tracking_method": args.method})
    for k, L in enumerate(links):
        s = L.summary()
        con.print(f"scan {k}->{k + 1}: {s['linked']} linked, {s['lost']} lost, {s['new']} new")
    con.print(f"wrote {args.out}")
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
