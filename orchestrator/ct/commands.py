"""The CT commands (``orchestrator ct synth|segment|track|shapes``): each ``*_main(args)`` takes the parsed
:class:`argparse.Namespace` of :mod:`.cli` and returns an exit code; :mod:`.case_run` calls them for a
case's scan series. Lengths carry units ("2.2 um"), converted with :func:`orchestrator.units.to_si`.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
from rich.progress import Progress

from ..console import console
from ..frames import Frames, write_frames
from ..units import to_si
from . import clumpfit, segment, shape, synth, track
from .export import write_ct_frames
from .io import Scan, ScanError, check_series, read_scan, write_scan

__all__ = ["synth_main", "segment_main", "track_main", "shapes_main"]


def _length(s, option):
    """A length option ("2.2 um") in metres, or None; a ValueError naming ``option`` (exit 2) unless it
    is a positive length."""
    if s is None:
        return None
    try:
        v = to_si(s, "length")
    except ValueError as e:
        raise ValueError(f"{option}: {e}") from None
    if not 0 < v < np.inf:
        raise ValueError(f"{option}: {s!r} is not a positive length; write e.g. '30 um'")
    return v


def synth_main(args) -> int:
    con = console(stderr=True)
    vs = _length(args.voxel_size, "--voxel-size")
    out = Path(args.out)
    rng = np.random.default_rng(args.seed)
    kw = dict(psf_sigma=args.psf, noise=args.noise, drift=args.drift)
    if args.frames:
        fr = Frames(args.frames)
        n = fr.n_frames
        bad = [k for k in args.frame or [] if not -n <= k < n]
        if bad:
            con.print(f"[red]error:[/red] --frame {bad[0]}: {args.frames} holds {n} frames; give an index in "
                      f"0..{n - 1} (or -{n}..-1 counting from the end)")
            return 2
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
        con.print("[red]error:[/red] ct synth: give --frames FILE (a frames.h5 or run directory) or --demo shear")
        return 2
    out.mkdir(parents=True, exist_ok=True)
    for k, s in enumerate(scans):
        write_scan(s, out / f"scan_{k:03d}.tif")
    write_frames(out / "truth.h5", ids, radius, times, pos, meta={"source": "ct-synthetic-truth", "voxel_size": vs})
    con.print(f"wrote {len(scans)} scans of shape {scans[0].shape} to {out} (ground truth: truth.h5)")
    return 0


def _scan_options(args) -> dict:
    """read_scan's keywords from the command line: voxel size, and shape and dtype of a raw volume."""
    kw = {}
    if args.voxel_size:
        kw["voxel_size"] = _length(args.voxel_size, "--voxel-size")
    if args.shape:
        kw["shape"], kw["dtype"] = tuple(args.shape), args.dtype
    return kw


def segment_main(args) -> int:
    con = console(stderr=True)
    out = Path(args.out)
    kw, h = _scan_options(args), _length(args.h, "--h")
    try:
        scans = [read_scan(p, **kw) for p in args.scans]
        check_series(scans)
    except ScanError as e:
        con.print(f"[red]error:[/red] {e}")
        return 2
    out.mkdir(parents=True, exist_ok=True)
    summary = []
    with Progress(console=con) as prog:
        task = prog.add_task("segmenting scans", total=len(scans))
        for p, sc in zip(args.scans, scans):
            stem = Path(p).stem if not Path(p).is_dir() else Path(p).name
            seg = segment.segment(sc, sigma=args.sigma, h=h)
            g = seg.grains
            if not args.no_shape:
                tab, _ = shape.grain_shapes(seg, degree=args.degree)
                g = g.merge(tab, on="label")
            g.to_csv(out / f"{stem}_grains.csv", index=False)
            seg.contacts().to_csv(out / f"{stem}_contacts.csv", index=False)
            if args.labels:
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
    con = console(stderr=True)
    segdir = Path(args.segdir)
    meta_path = segdir / "segment.json"
    if not meta_path.exists():
        con.print(f"[red]error:[/red] {meta_path}: not found; run `orchestrator ct segment` first")
        return 2
    max_disp = _length(args.max_disp, "--max-disp")
    vs = _length(args.voxel_size, "--voxel-size")
    try:
        info = json.loads(meta_path.read_text())
    except ValueError as e:
        info = f"not JSON ({e})"
    scans_ok = isinstance(info, list) and all(isinstance(s, dict) and {"scan", "voxel_size"} <= s.keys() for s in info)
    if not (scans_ok and info):
        what = info if isinstance(info, str) else "empty" if info == [] else "not a list of scans"
        con.print(f"[red]error:[/red] {meta_path}: {what}; run `orchestrator ct segment SCANS --out {segdir}` "
                  "first (it writes segment.json with one entry a scan)")
        return 2
    tables = []
    for s in info:
        p = Path(s["scan"])
        stem = p.stem if not p.is_dir() else p.name
        tables.append(pd.read_csv(segdir / f"{stem}_grains.csv"))
    scans = None
    if args.method == "rotation":
        paths = args.scans or [s["scan"] for s in info]
        kw = {"voxel_size": vs} if vs else {}
        try:
            scans = [read_scan(p, **kw) for p in paths]
            check_series(scans)
        except ScanError as e:
            con.print(f"[red]error:[/red] {e}")
            return 2
    links = track.track_sequence(tables, args.method, max_disp=max_disp, scans=scans,
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


def shapes_main(args) -> int:
    """A clump shape library (YAML for ``scene.particles.library``) from one scan, which is segmented
    first, or from a label volume ``<scan>_labels.tif`` of ``ct segment --labels`` with its
    ``<scan>_grains.csv`` beside it."""
    con = console(stderr=True)
    src, out = Path(args.input), Path(args.out)
    if out.suffix.lower() not in (".yaml", ".yml"):
        con.print(f"[red]error:[/red] {out}: a shape library is written as YAML; give -o/--out ending in .yaml")
        return 2
    if args.spheres < 1 or not 0 < args.coverage <= 1:
        con.print(f"[red]error:[/red] --spheres {args.spheres} --coverage {args.coverage}: give at least 1 sphere "
                  "and a coverage in (0, 1], e.g. --spheres 6 --coverage 0.97")
        return 2
    kw, h = _scan_options(args), _length(args.h, "--h")
    try:
        sc = read_scan(args.input, **kw)
    except ScanError as e:
        con.print(f"[red]error:[/red] {e}")
        return 2
    meta = {"source": str(src), "voxel_size": sc.voxel_size, "n_spheres": args.spheres, "coverage": args.coverage,
            "min_voxels": args.min_voxels, "skip_flagged": not args.keep_flagged}
    if src.stem.endswith("_labels"):
        table = src.with_name(src.stem[: -len("_labels")] + "_grains.csv")
        if not table.exists():
            con.print(f"[red]error:[/red] {src}: a label volume needs its grain table {table} (written beside it by "
                      "`orchestrator ct segment --labels`); or give the scan itself")
            return 2
        grains = pd.read_csv(table)
        missing = {"label", "n_voxels", "at_border", "flag", "z0", "y0", "x0", "z1", "y1", "x1"} - set(grains.columns)
        if missing:
            con.print(f"[red]error:[/red] {table}: columns {sorted(missing)} missing; write it again with "
                      "`orchestrator ct segment --labels`")
            return 2
        labels = sc.volume.astype(np.int32)
        meta["grain_table"] = str(table)
    else:
        try:
            seg = segment.segment(sc, sigma=args.sigma, h=h, progress=True)
        except segment.SegmentationError as e:
            con.print(f"[red]error:[/red] {e}")
            return 2
        grains, labels = seg.grains, seg.labels
        meta["segment"] = {k: v for k, v in seg.params.items() if v is not None}
    keep = clumpfit.library_grains(grains, args.min_voxels, not args.keep_flagged)
    if not keep.any():
        n_border = int(grains["at_border"].astype(bool).sum())
        n_small = int((grains["n_voxels"] < args.min_voxels).sum())
        con.print(f"[red]error:[/red] {src}: no grain for the library among {len(grains)} ({n_border} at the scan "
                  f"border, {n_small} under --min-voxels {args.min_voxels}, the rest flagged over/under-segmented); "
                  "lower --min-voxels or add --keep-flagged")
        return 2
    shapes, quality = clumpfit.shape_library_from_labels(labels, sc.voxel_size, grains[keep], n_spheres=args.spheres,
                                                         coverage=args.coverage)
    clumpfit.write_shape_library(out, shapes, quality["name"], meta=meta, quality=quality,
                                 comment=f"clump shape library from {src} (orchestrator ct shapes)")
    med = quality[["volume_ratio", "coverage", "outside"]].median()
    con.print(f"wrote {out}: {len(shapes)} shapes of {len(grains)} grains; median volume ratio "
              f"{med['volume_ratio']:.3f}, coverage {med['coverage']:.3f}, outside {med['outside']:.3f}")
    return 0
