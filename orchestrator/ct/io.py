"""Reading and writing tomograms: TIFF stacks, multi-page TIFF, raw volumes, NumPy arrays.

Conventions (used by every module of :mod:`orchestrator.ct`):

* a volume is a 3-D array indexed ``[z, y, x]`` (slice, row, column);
* voxels are cubic with edge ``voxel_size`` [m];
* the centre of voxel ``[k, j, i]`` lies at world position
  ``origin + voxel_size * (i, j, k)`` [m], i.e. world coordinates are ``(x, y, z)``.

A :class:`Scan` carries the grey values together with ``voxel_size``, ``origin`` and an optional
acquisition ``time`` [s] and control values (e.g. the shear ``angle`` [rad]).
"""
from __future__ import annotations

import glob as _glob
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

__all__ = ["Scan", "ScanError", "read_scan", "read_series", "write_scan", "check_series"]

TIFF_SUFFIXES = (".tif", ".tiff")


class ScanError(ValueError):
    """An unreadable scan or an inconsistent scan series (message names the file and the problem)."""


@dataclass
class Scan:
    """A tomogram in SI units.

    volume : (nz, ny, nx) grey values (any real dtype).
    voxel_size : edge of a cubic voxel [m].
    origin : world position (x, y, z) of the centre of voxel [0, 0, 0] [m].
    time : acquisition time [s] (or any monotonic scan coordinate); NaN if unknown.
    controls : per-scan control values in SI (e.g. ``{"angle": 0.0873}`` [rad]).
    source : where the scan came from (file name), used in error messages.
    """
    volume: np.ndarray
    voxel_size: float
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))
    time: float = float("nan")
    controls: dict = field(default_factory=dict)
    source: str = "<array>"

    def __post_init__(self):
        self.volume = np.asarray(self.volume)
        if self.volume.ndim != 3:
            raise ScanError(f"{self.source}: a scan must be a 3-D volume, got shape {self.volume.shape}")
        if 0 in self.volume.shape:
            raise ScanError(f"{self.source}: empty volume (shape {self.volume.shape})")
        if not np.issubdtype(self.volume.dtype, np.number) or np.iscomplexobj(self.volume):
            raise ScanError(f"{self.source}: grey values must be real numbers, got dtype {self.volume.dtype}")
        try:
            self.voxel_size = float(self.voxel_size)
        except (TypeError, ValueError):
            raise ScanError(f"{self.source}: voxel_size must be one number in metres (cubic voxels), "
                            f"got {self.voxel_size!r}") from None
        if not np.isfinite(self.voxel_size) or self.voxel_size <= 0:
            raise ScanError(f"{self.source}: voxel_size must be a positive length in metres, got {self.voxel_size}")
        if self.voxel_size > 1e-1:
            raise ScanError(f"{self.source}: voxel_size {self.voxel_size} m is larger than 10 cm; "
                            "voxel sizes are in metres (e.g. 2.2e-6 for 2.2 um)")
        self.origin = np.asarray(self.origin, dtype=float).reshape(3)

    @property
    def shape(self) -> tuple:
        return self.volume.shape

    def to_world(self, zyx) -> np.ndarray:
        """Voxel coordinates (..., 3) in (z, y, x) order -> world (x, y, z) [m]."""
        zyx = np.asarray(zyx, dtype=float)
        return self.origin + self.voxel_size * zyx[..., ::-1]

    def to_voxel(self, xyz) -> np.ndarray:
        """World (..., 3) (x, y, z) [m] -> fractional voxel coordinates (z, y, x)."""
        xyz = np.asarray(xyz, dtype=float)
        return ((xyz - self.origin) / self.voxel_size)[..., ::-1]

    @property
    def extent(self) -> np.ndarray:
        """World (x, y, z) of the last voxel centre [m]."""
        return self.to_world(np.array(self.shape) - 1)

    def __repr__(self):
        return (f"Scan({self.source!r}, shape={self.shape}, dtype={self.volume.dtype}, "
                f"voxel_size={self.voxel_size:.4g} m, origin={self.origin.tolist()})")


# --------------------------------------------------------------------------------------- reading

def _tiff_meta(tif) -> dict:
    """Voxel size [m], origin [m], time and controls stored in a TIFF (ours or ImageJ's)."""
    meta: dict = {}
    ij = tif.imagej_metadata or {}
    desc = ij.get("orchestrator")
    if desc:
        try:
            meta.update(json.loads(desc))
        except ValueError:
            pass
    if "voxel_size" not in meta and ij.get("spacing"):
        unit = str(ij.get("unit", "")).replace("\\u00B5", "u").replace("µ", "u").replace("micron", "um")
        scale = {"um": 1e-6, "nm": 1e-9, "mm": 1e-3, "m": 1.0, "cm": 1e-2}.get(unit.strip())
        if scale is not None:
            meta["voxel_size"] = float(ij["spacing"]) * scale
    if "voxel_size" not in meta:
        try:
            sm = tif.shaped_metadata
            if sm and "voxel_size" in sm[0]:
                meta.update({k: sm[0][k] for k in ("voxel_size", "origin", "time", "controls") if k in sm[0]})
        except Exception:
            pass
    return meta


def _read_tiff(path: Path):
    import tifffile
    try:
        with tifffile.TiffFile(path) as tif:
            vol = tif.asarray()
            meta = _tiff_meta(tif)
    except Exception as e:  # tifffile raises many types
        raise ScanError(f"{path}: cannot read as TIFF ({type(e).__name__}: {e})") from None
    return vol, meta


def _read_tiff_stack(files: Sequence[Path], label: str):
    """A directory/glob of 2-D TIFF slices, in natural sort order, as one volume."""
    if not files:
        raise ScanError(f"{label}: no TIFF files found")
    slices, meta, shape0, dtype0 = [], {}, None, None
    for k, f in enumerate(files):
        im, m = _read_tiff(f)
        if im.ndim != 2:
            raise ScanError(f"{f}: a slice of the stack {label} must be a 2-D image, got shape {im.shape}")
        if shape0 is None:
            shape0, dtype0, meta = im.shape, im.dtype, m
        elif im.shape != shape0:
            raise ScanError(f"{f}: slice {k} of stack {label} has shape {im.shape}, "
                            f"but the first slice {files[0].name} has {shape0}")
        elif im.dtype != dtype0:
            raise ScanError(f"{f}: slice {k} of stack {label} has dtype {im.dtype}, "
                            f"but the first slice {files[0].name} has {dtype0}")
        slices.append(im)
    return np.stack(slices), meta


def _natural_key(p: Path):
    import re
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", p.name)]


def read_scan(path, voxel_size: float | None = None, origin=None, shape=None, dtype=None,
              byte_order: str = "<", header: int = 0, time: float | None = None,
              controls: dict | None = None) -> Scan:
    """Read one tomogram and return a :class:`Scan`.

    ``path`` may be

    * a multi-page TIFF (``.tif``/``.tiff``); voxel size and origin are taken from our metadata or
      ImageJ's ``spacing``/``unit`` when present;
    * a directory or glob pattern of 2-D TIFF slices (one slice per file, natural sort order);
    * a raw file (``.raw``, ``.bin``, ``.vol`` ...) with ``shape=(nz, ny, nx)`` and ``dtype`` given,
      optional ``header`` bytes to skip and ``byte_order`` ``"<"`` or ``">"``;
    * a ``.npy`` file, or a NumPy array.

    ``voxel_size`` [m] and ``origin`` (x, y, z) [m] override the file's metadata; one of the two
    must provide a voxel size.
    """
    meta: dict = {}
    if isinstance(path, np.ndarray):
        vol, label = path, "<array>"
    else:
        label = str(path)
        p = Path(path)
        if any(ch in label for ch in "*?["):
            files = sorted((Path(f) for f in _glob.glob(label)), key=_natural_key)
            vol, meta = _read_tiff_stack(files, label)
        elif p.is_dir():
            files = sorted((f for f in p.iterdir() if f.suffix.lower() in TIFF_SUFFIXES), key=_natural_key)
            if not files:
                raise ScanError(f"{p}: directory holds no .tif/.tiff slices")
            vol, meta = _read_tiff_stack(files, label)
        elif not p.exists():
            raise ScanError(f"{p}: no such file or directory")
        elif p.suffix.lower() in TIFF_SUFFIXES:
            vol, meta = _read_tiff(p)
            if vol.ndim == 4 and vol.shape[-1] in (3, 4):
                raise ScanError(f"{p}: colour (RGB) TIFF of shape {vol.shape}; a tomogram must be grey-valued")
            if vol.ndim == 2:
                raise ScanError(f"{p}: a single 2-D image of shape {vol.shape}, not a volume; give a multi-page "
                                "TIFF, a directory of slices or a glob such as 'scan/slice_*.tif'")
        elif p.suffix.lower() == ".npy":
            try:
                vol = np.load(p, allow_pickle=False)
            except Exception as e:
                raise ScanError(f"{p}: cannot read as .npy ({e})") from None
            side = p.with_suffix(".json")
            if side.exists():
                meta = json.loads(side.read_text())
        else:
            if shape is None or dtype is None:
                raise ScanError(f"{p}: a raw volume needs shape=(nz, ny, nx) and dtype (e.g. uint16); "
                                f"got shape={shape}, dtype={dtype}")
            try:
                np.dtype(dtype)
            except (TypeError, ValueError):
                raise ScanError(f"{p}: dtype {dtype!r} is not a data type; give e.g. uint8, uint16 or "
                                "float32") from None
            dt = np.dtype(dtype).newbyteorder(byte_order) if np.dtype(dtype).itemsize > 1 else np.dtype(dtype)
            n = int(np.prod(shape))
            size = p.stat().st_size
            need = header + n * dt.itemsize
            if size != need:
                raise ScanError(f"{p}: file has {size} bytes, but shape {tuple(shape)} of {np.dtype(dtype).name} "
                                f"with a {header}-byte header needs {need} bytes")
            vol = np.fromfile(p, dtype=dt, count=n, offset=header).reshape(shape).astype(np.dtype(dtype).newbyteorder("="))
    if voxel_size is None:
        voxel_size = meta.get("voxel_size")
    if voxel_size is None:
        raise ScanError(f"{label}: no voxel size in the file; give voxel_size in metres (e.g. 2.2e-6)")
    if origin is None:
        origin = meta.get("origin", (0.0, 0.0, 0.0))
    if time is None:
        time = meta.get("time", float("nan"))
    ctrl = dict(meta.get("controls", {}))
    ctrl.update(controls or {})
    vol = np.asarray(vol)
    if vol.ndim != 3:
        raise ScanError(f"{label}: expected a 3-D volume, got shape {vol.shape}")
    return Scan(vol, voxel_size, origin, float(time), ctrl, label)


def check_series(scans: Sequence[Scan], rtol: float = 1e-6) -> None:
    """Raise :class:`ScanError` unless all scans share shape, dtype, voxel size and origin."""
    if not scans:
        raise ScanError("empty scan series")
    ref = scans[0]
    for s in scans[1:]:
        if s.shape != ref.shape:
            raise ScanError(f"{s.source}: shape {s.shape} differs from {ref.shape} of the first scan {ref.source}")
        if not np.isclose(s.voxel_size, ref.voxel_size, rtol=rtol, atol=0):
            raise ScanError(f"{s.source}: voxel size {s.voxel_size:.6g} m differs from {ref.voxel_size:.6g} m "
                            f"of the first scan {ref.source}")
        if s.volume.dtype != ref.volume.dtype:
            raise ScanError(f"{s.source}: dtype {s.volume.dtype} differs from {ref.volume.dtype} "
                            f"of the first scan {ref.source}")
        if not np.allclose(s.origin, ref.origin, rtol=0, atol=1e-3 * ref.voxel_size):
            raise ScanError(f"{s.source}: origin {s.origin.tolist()} m differs from {ref.origin.tolist()} m "
                            f"of the first scan {ref.source}")
    t = np.array([s.time for s in scans])
    if np.all(np.isfinite(t)) and np.any(np.diff(t) <= 0):
        k = int(np.argmax(np.diff(t) <= 0)) + 1
        raise ScanError(f"{scans[k].source}: time {t[k]} s does not increase after {t[k-1]} s of {scans[k-1].source}")


def read_series(paths: Iterable, **kwargs) -> list[Scan]:
    """Read a scan series (one path per scan, or one glob matching several scan files) and check it."""
    if isinstance(paths, (str, os.PathLike)):
        paths = sorted((Path(f) for f in _glob.glob(str(paths))), key=_natural_key) or [paths]
    scans = [read_scan(p, **kwargs) for p in paths]
    check_series(scans)
    return scans


# --------------------------------------------------------------------------------------- writing

def write_scan(scan: Scan, path) -> Path:
    """Write a scan as a multi-page ImageJ TIFF (voxel size readable in Fiji) or ``.npy`` + ``.json``.

    The voxel size [m], origin [m], time [s] and controls are stored so that :func:`read_scan`
    restores them. The file is written to a temporary name and renamed.
    """
    import tifffile
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = {"voxel_size": scan.voxel_size, "origin": scan.origin.tolist(),
            "time": None if not np.isfinite(scan.time) else scan.time, "controls": scan.controls}
    tmp = path.with_name(path.name + ".partial")
    if path.suffix.lower() == ".npy":
        with open(tmp, "wb") as fh:
            np.save(fh, scan.volume)
        os.replace(tmp, path)
        path.with_suffix(".json").write_text(json.dumps({k: v for k, v in meta.items() if v is not None}))
        return path
    vol = scan.volume
    if vol.dtype not in (np.uint8, np.uint16, np.float32):
        vol = vol.astype(np.float32)
    um = scan.voxel_size * 1e6
    tifffile.imwrite(tmp, vol, imagej=True, resolution=(1.0 / um, 1.0 / um),
                     metadata={"spacing": um, "unit": "um", "axes": "ZYX",
                               "orchestrator": json.dumps({k: v for k, v in meta.items() if v is not None})})
    os.replace(tmp, path)
    return path
