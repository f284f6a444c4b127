"""Shared helpers of the analysis package: result container, frame selection, sizes, geometry.

Nothing here is a measure; each measure lives in its own module.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd

__all__ = ["Result", "present", "d50", "control_values", "frame_pairs", "frame_indices", "loading_frames",
           "stage_frames",
           "atomic_write_csv", "atomic_savefig", "atomic_write_json", "sphere_volume"]


@dataclass
class Result:
    """What every analysis returns (trackpy-like tables plus scalars and a plot).

    Attributes
    ----------
    name : registry name of the measure.
    tables : name -> :class:`pandas.DataFrame` (written as ``<name>_<table>.csv``).
    scalars : name -> float/str summary values (JSON-serialisable), e.g. a fit parameter.
    arrays : name -> ndarray kept for notebooks (not written).
    options : the options the analysis ran with (after defaults were filled in).
    """
    name: str
    tables: dict = field(default_factory=dict)
    scalars: dict = field(default_factory=dict)
    arrays: dict = field(default_factory=dict)
    options: dict = field(default_factory=dict)
    plotter: Callable | None = field(default=None, repr=False)

    def plot(self, **kw):
        """Return a matplotlib Figure of this result (Agg backend; never shows a window)."""
        if self.plotter is None:
            raise NotImplementedError(f"{self.name}: no plot")
        return self.plotter(self, **kw)

    def __getitem__(self, key):
        if key in self.tables:
            return self.tables[key]
        if key in self.scalars:
            return self.scalars[key]
        return self.arrays[key]

    def __repr__(self):
        t = ", ".join(f"{k}[{len(v)}]" for k, v in self.tables.items())
        return f"Result({self.name!r}, tables: {t}, scalars: {self.scalars})"

    def _repr_html_(self) -> str:
        """In a notebook: the scalars as a table, the tables' names and sizes, and the plot inline
        (a PNG in the page: the notebook stays self-contained)."""
        import base64
        import html
        import io
        rows = "".join(f"<tr><td>{html.escape(str(k))}</td><td>{html.escape(_shown(v))}</td></tr>"
                       for k, v in self.scalars.items())
        tables = ", ".join(f"<code>{html.escape(k)}</code> ({len(v)} rows)" for k, v in self.tables.items())
        out = (f"<p><b>{html.escape(self.name)}</b>: tables {tables or 'none'} (<code>result[name]</code>)</p>"
               + (f"<table><tr><th>scalar</th><th>value</th></tr>{rows}</table>" if rows else ""))
        if self.plotter is not None:
            buf = io.BytesIO()
            try:
                self.plot().savefig(buf, format="png", dpi=80)
            except Exception as exc:          # noqa: BLE001 - a plot that fails must not hide the numbers
                return out + f"<p>(no plot: {html.escape(str(exc))})</p>"
            out += f'<img src="data:image/png;base64,{base64.b64encode(buf.getvalue()).decode()}"/>'
        return out


def _shown(v) -> str:
    """A scalar as a notebook shows it: floats to 4 significant figures."""
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def present(position: np.ndarray) -> np.ndarray:
    """Boolean mask of rows that are present (no NaN coordinate); works on (N,3) or (T,N,3)."""
    return ~np.isnan(position).any(axis=-1)


def sphere_volume(radius) -> np.ndarray:
    """Volume of spheres of the given radii [m^3]."""
    return 4.0 / 3.0 * np.pi * np.asarray(radius, dtype=float) ** 3


def d50(radius: np.ndarray, weighting: str = "number") -> float:
    """Median particle diameter [m] (``weighting="volume"`` gives x50,3 of seed 000)."""
    d = 2.0 * np.asarray(radius, dtype=float)
    d = d[np.isfinite(d)]
    if d.size == 0:
        raise ValueError("no particle radii")
    if weighting == "number":
        return float(np.median(d))
    if weighting == "volume":
        order = np.argsort(d)
        w = np.cumsum(d[order] ** 3)
        return float(d[order][np.searchsorted(w, 0.5 * w[-1])])
    raise ValueError(f"weighting must be 'number' or 'volume', got {weighting!r}")


def control_values(frames, control: str | None = None) -> tuple[str, np.ndarray]:
    """The per-frame control series used to label states: ``control`` if given, else the first
    of axial_strain, angle, shear_strain present in the frames, else time. A ``control`` the frames
    do not carry is a ValueError naming the ones they do."""
    if control is not None:
        if control == "time":
            return "time", np.asarray(frames.time, float)
        if control not in frames.controls:
            raise ValueError(f"control {control!r}: {frames.path} has no such control; give one of "
                             f"{sorted(frames.controls)} or 'time'")
        return control, np.asarray(frames.controls[control], float)
    for c in ("axial_strain", "angle", "shear_strain"):
        if c in frames.controls and np.isfinite(frames.controls[c]).any():
            return c, np.asarray(frames.controls[c], float)
    return "time", np.asarray(frames.time, float)


def _nearest(values: np.ndarray, target: float) -> int:
    d = np.abs(values - target)
    d[~np.isfinite(d)] = np.inf
    return int(np.argmin(d))


def frame_indices(frames, at=None, control=None, stride: int = 1) -> list[int]:
    """Frame indices to analyse. ``at``: list of frame indices (int) or of control values
    (float, nearest frame is taken, e.g. ``at=[0.01, 0.05]`` axial strain); default: every
    ``stride``-th frame."""
    T = frames.n_frames
    if at is None:
        return list(range(0, T, max(int(stride), 1)))
    _, vals = control_values(frames, control)
    out = []
    for a in np.atleast_1d(at):
        if isinstance(a, (int, np.integer)) and not isinstance(a, bool):
            out.append(range(T)[int(a)])
        else:
            out.append(_nearest(vals, float(a)))
    return out


def loading_frames(frames) -> list[int]:
    """Frame indices of the loading stage: its reference state (the last frame before the final
    stage begins: the end of isotropic compression in a triaxial run, the piston at rest before the
    rotation in a shear cell) and every frame after it.

    Both scenes write a ``stage`` control whose last value is the loading (triaxial: 1 isotropic,
    2 loading; shear cell: 0-2 filling and compression, 3 shearing). Frames without a ``stage``
    control, or with a single stage, are all loading frames.
    """
    T = frames.n_frames
    st = np.asarray(frames.controls["stage"], float) if "stage" in frames.controls else None
    if st is None or not np.isfinite(st).any():
        return list(range(T))
    first = int(np.flatnonzero(np.isfinite(st))[-1])
    while first > 0 and st[first - 1] == st[first]:    # back to the start of the final stage
        first -= 1
    return list(range(max(first - 1, 0), T))


def stage_frames(frames, stages: str = "loading") -> list[int]:
    """Frame indices of ``stages``: "loading" (:func:`loading_frames`) or "all"."""
    if stages == "loading":
        return loading_frames(frames)
    if stages == "all":
        return list(range(frames.n_frames))
    raise ValueError(f"stages must be 'loading' or 'all', got {stages!r}")


def frame_pairs(frames, pairs=None, interval=None, start=None, control=None, stride: int = 1,
                stages: str = "loading") -> list[tuple[int, int]]:
    """(reference, current) frame index pairs for incremental measures.

    - ``pairs``: explicit ``[[k0, k1], ...]``;
    - ``interval``: a control increment (e.g. 0.01 axial strain, seed 001 uses 1 %): for every
      start state (``start`` list of control values, default every ``stride``-th frame of the
      stages chosen) the current frame is the one nearest to control + interval;
    - default: consecutive frames ``(k, k + stride)`` of the stages chosen.

    ``stages``: "loading" (default; :func:`loading_frames`: seed 001 measures D²min while
    loading, not while the sample is prepared) or "all" (the preparation stages too). Explicit
    ``pairs`` and ``start`` are taken as given.
    """
    T = frames.n_frames
    if T < 2:
        raise ValueError(f"{frames.path}: an incremental measure needs at least 2 frames, got {T}")
    if pairs is not None:
        return [(range(T)[int(a)], range(T)[int(b)]) for a, b in pairs]
    usable = stage_frames(frames, stages)
    s = max(int(stride), 1)
    if interval is not None:
        _, vals = control_values(frames, control)
        starts = (frame_indices(frames, start, control) if start is not None else usable[::s])
        out = []
        for k0 in starts:
            target = vals[k0] + float(interval)
            k1 = _nearest(vals, target)
            if k1 != k0 and abs(vals[k1] - target) <= 0.5 * abs(float(interval)):
                out.append((k0, k1))
        if not out:
            raise ValueError(f"no frame pair spans a control interval of {interval} (control range "
                             f"{np.nanmin(vals[usable]):g} .. {np.nanmax(vals[usable]):g} in the "
                             f"{stages} frames)")
        return out
    out = [(usable[i], usable[i + s]) for i in range(0, len(usable) - s, s)]
    if not out:
        raise ValueError(f"{frames.path}: the {stages} stage has {len(usable)} frame(s); an incremental "
                         f"measure needs at least {s + 1} (stages='all' takes the preparation too)")
    return out


# ----------------------------------------------------------------------------- atomic output

def _tmp_in(path: Path, suffix: str):
    from ..atomic import temp_file          # its mode follows the umask (mkstemp's 0600 would not)
    return temp_file(path, suffix)


def atomic_write_csv(df: pd.DataFrame, path) -> Path:
    """Write a DataFrame as CSV via a temporary file and :func:`os.replace`."""
    path = Path(path)
    tmp = _tmp_in(path, ".csv")
    try:
        df.to_csv(tmp, index=False)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def atomic_savefig(fig, path, dpi: int = 120) -> Path:
    """Save a matplotlib Figure as PNG via a temporary file and :func:`os.replace`."""
    path = Path(path)
    tmp = _tmp_in(path, ".png")
    try:
        fig.savefig(tmp, dpi=dpi, format="png")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def save_figure(fig, path, dpi: int = 120) -> Path:
    """Save ``fig`` atomically as PNG (creating the folder) and close it; returns the path."""
    # pyplot here, not at module top: importing it there would fix matplotlib's backend before
    # plots.py selects Agg, for every user of the analysis package
    import matplotlib.pyplot as plt
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_savefig(fig, path, dpi=dpi)
    plt.close(fig)
    return path


def atomic_write_json(obj, path) -> Path:
    path = Path(path)
    tmp = _tmp_in(path, ".json")
    try:
        tmp.write_text(json.dumps(obj, indent=2, default=_json_default))
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def _json_default(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return None if not np.isfinite(o) else float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)
