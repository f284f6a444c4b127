"""The common particle-frame format (``frames.h5``) shared by simulations and CT scans.

Layout (after H5MD's ideas; readable with plain h5py, see docs/frames.md):

``/particles/id`` (N,) int64, ``/particles/radius`` (N,) float64 [m], optional ``mass`` (N,) [kg],
``shape`` (N, K) (e.g. spherical-harmonic invariants ‖R_n‖ [m]).

``/frames/time`` (T,) [s], ``/frames/step`` (T,) int64, and per-scene control values
``/frames/<name>`` (T,) such as ``angle`` [rad] or ``axial_strain`` [-].

``/frames/position`` (T, N, 3) [m]; optional ``velocity`` [m/s], ``angular_velocity`` [rad/s],
``orientation`` (T, N, 4) unit quaternion (w, x, y, z), ``force`` [N], ``torque`` [N m],
``stress`` (T, N, 3, 3) [Pa]. A particle absent from a frame is a NaN row; row k always means
particle ``id[k]``.

``/contacts/<frame index>/``: ``i``, ``j`` (ids), ``point`` (M, 3) [m], ``normal`` (M, 3) unit
vector from i to j, ``fn`` (M, 3) normal force on i [N], ``ft`` (M, 3) tangential force on i [N].
A contact with a wall has a negative ``j``: ``-1 - k`` for the k-th wall, whose name is in the
``/meta`` attribute ``wall_ids`` (JSON ``{"-1": "bottom_piston", ...}``).

``/walls/<name>/``: ``time`` (S,) [s] and any of ``position`` (S, 3) [m], ``angle`` (S,) [rad],
``force`` (S, 3) [N], ``torque`` (S, 3) [N m].

``/meta``: attributes ``engine``, ``engine_version``, ``case`` (resolved case as JSON),
``deck_hash``, ``template_hash``, ``units`` (JSON), ``created``, ``software_version``,
``source`` ("simulation" or "ct").

Writers write to ``<name>.partial`` and rename on :meth:`FrameWriter.close`, so a file named
``frames.h5`` is always complete.
"""
from __future__ import annotations

import datetime as _dt
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np

__all__ = [
    "FrameWriter", "write_frames", "Frames", "Frame", "load", "UNITS", "PER_PARTICLE_FIELDS",
    "CONTACT_FIELDS",
]

#: SI unit of every dataset, stored in ``/meta`` as JSON.
UNITS = {
    "time": "s", "position": "m", "velocity": "m/s", "angular_velocity": "rad/s",
    "orientation": "1", "force": "N", "torque": "N m", "stress": "Pa", "radius": "m",
    "mass": "kg", "angle": "rad", "axial_strain": "1", "point": "m", "fn": "N", "ft": "N",
}

#: Per-particle datasets under ``/frames`` and the trailing shape of one particle's row.
PER_PARTICLE_FIELDS = {
    "position": (3,), "velocity": (3,), "angular_velocity": (3,), "orientation": (4,),
    "force": (3,), "torque": (3,), "stress": (3, 3),
}
CONTACT_FIELDS = ("i", "j", "point", "normal", "fn", "ft")


def _software_version() -> str:
    try:
        from importlib.metadata import version
        return version("orchestrator")
    except Exception:  # pragma: no cover - running from a source tree
        return "0+unknown"


class FrameWriter:
    """Write frames one at a time into ``frames.h5`` (atomic: ``.partial`` then rename).

    Parameters
    ----------
    path : path of the final file.
    ids : (N,) particle ids; row k of every per-particle array belongs to ``ids[k]``.
    radius : (N,) radii [m].
    fields : per-particle fields that frames will carry (keys of :data:`PER_PARTICLE_FIELDS`).
    controls : names of per-frame scalar control values (e.g. ``("angle",)``).
    mass, shape : optional per-particle mass [kg] and shape descriptors (N, K).
    meta : attributes for ``/meta`` (dicts are stored as JSON).
    """

    def __init__(self, path, ids, radius, fields: Iterable[str] = ("position",),
                 controls: Iterable[str] = (), mass=None, shape=None, meta: Mapping | None = None):
        self.path = Path(path)
        self.partial = self.path.with_name(self.path.name + ".partial")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        ids = np.asarray(ids, dtype=np.int64)
        radius = np.asarray(radius, dtype=np.float64)
        if ids.ndim != 1 or radius.shape != ids.shape:
            raise ValueError(f"ids and radius must be 1-D of equal length, got {ids.shape} and {radius.shape}")
        srt = np.sort(ids)
        if len(srt) > 1 and not (srt[1:] != srt[:-1]).all():
            raise ValueError("particle ids must be unique")
        self.n = len(ids)
        self.fields = tuple(fields)
        for f in self.fields:
            if f not in PER_PARTICLE_FIELDS:
                raise ValueError(f"unknown per-particle field {f!r}; known: {sorted(PER_PARTICLE_FIELDS)}")
        if "position" not in self.fields:
            self.fields = ("position",) + self.fields
        self.controls = tuple(controls)
        import h5py                 # here: h5py costs ~0.4 s to import, which validate does not need (#16)
        self.h5 = h5py.File(self.partial, "w")
        p = self.h5.create_group("particles")
        p["id"] = ids
        p["radius"] = radius
        if mass is not None:
            p["mass"] = np.asarray(mass, dtype=np.float64)
        if shape is not None:
            p["shape"] = np.asarray(shape, dtype=np.float64)
        fr = self.h5.create_group("frames")
        fr.create_dataset("time", shape=(0,), maxshape=(None,), dtype="f8", chunks=(1024,))
        fr.create_dataset("step", shape=(0,), maxshape=(None,), dtype="i8", chunks=(1024,))
        for c in self.controls:
            fr.create_dataset(c, shape=(0,), maxshape=(None,), dtype="f8", chunks=(1024,))
        # chunks of ~64 K values: one frame for large systems, many frames for small ones (a chunk
        # per tiny frame makes HDF5's per-chunk overhead dominate)
        t_chunk = int(max(1, min(1024, 65536 // max(self.n * 3, 1))))
        for f in self.fields:
            tail = PER_PARTICLE_FIELDS[f]
            fr.create_dataset(f, shape=(0, self.n) + tail, maxshape=(None, self.n) + tail,
                              dtype="f8", chunks=(t_chunk, max(self.n, 1)) + tail, fillvalue=np.nan)
        self.h5.create_group("contacts")
        self.h5.create_group("walls")
        m = self.h5.create_group("meta")
        base = {"units": UNITS, "created": _dt.datetime.now(_dt.timezone.utc).isoformat(),
                "software_version": _software_version(), "source": "simulation"}
        base.update(meta or {})
        for k, v in base.items():
            m.attrs[k] = v if isinstance(v, (str, int, float, np.number)) else json.dumps(v, default=str)
        self.t = 0

    #: frames are buffered in memory and written in blocks of about this many bytes
    BUFFER_BYTES = 64 * 2 ** 20

    def append(self, time: float, step: int = 0, controls: Mapping[str, float] | None = None,
               contacts: Mapping[str, np.ndarray] | None = None, **per_particle) -> int:
        """Append one frame and return its index. ``per_particle`` arrays are (N, ...) in id order."""
        k = self.t
        controls = dict(controls or {})
        row = {"time": float(time), "step": int(step)}
        for c in self.controls:
            row[c] = controls.pop(c, np.nan)
        if controls:
            raise ValueError(f"controls {sorted(controls)} were not declared in FrameWriter(controls=...)")
        if per_particle.get("position") is None:
            raise ValueError("every frame needs a position array")
        for f in self.fields:
            a = per_particle.pop(f, None)
            shape = (self.n,) + PER_PARTICLE_FIELDS[f]
            if a is None:
                a = np.full(shape, np.nan)
            else:
                a = np.asarray(a, dtype=np.float64)
                if a.shape != shape:
                    raise ValueError(f"{f}: expected shape {shape}, got {a.shape}")
            row[f] = a
        extra = {k2 for k2, v in per_particle.items() if v is not None}
        if extra:
            raise ValueError(f"fields {sorted(extra)} were not declared in FrameWriter(fields=...)")
        if not hasattr(self, "_buf"):
            self._buf, self._buf_bytes = [], 0
        self._buf.append(row)
        self._buf_bytes += sum(v.nbytes for v in row.values() if isinstance(v, np.ndarray))
        if contacts is not None:
            self.write_contacts(k, contacts)
        self.t += 1
        if self._buf_bytes >= self.BUFFER_BYTES:
            self._flush()
        return k

    def append_block(self, time, step=None, controls: Mapping[str, np.ndarray] | None = None,
                     **per_particle) -> range:
        """Append B frames at once: ``time`` (B,), ``step`` (B,), each field (B, N, ...) in id
        order. Much faster than B calls of :meth:`append` for many small frames."""
        time = np.atleast_1d(np.asarray(time, dtype=np.float64))
        B = len(time)
        step = np.zeros(B, np.int64) if step is None else np.asarray(step, np.int64)
        controls = dict(controls or {})
        unknown = set(controls) - set(self.controls)
        if unknown:
            raise ValueError(f"controls {sorted(unknown)} were not declared in FrameWriter(controls=...)")
        if per_particle.get("position") is None:
            raise ValueError("every frame needs a position array")
        extra = {k for k, v in per_particle.items() if v is not None and k not in self.fields}
        if extra:
            raise ValueError(f"fields {sorted(extra)} were not declared in FrameWriter(fields=...)")
        self._flush()
        fr = self.h5["frames"]
        k0 = fr["time"].shape[0]
        k1 = k0 + B
        cols = {"time": time, "step": step}
        for c in self.controls:
            cols[c] = np.broadcast_to(np.asarray(controls.get(c, np.nan), dtype=np.float64), (B,))
        for name, v in cols.items():
            fr[name].resize((k1,))
            fr[name][k0:k1] = v
        for f in self.fields:
            ds = fr[f]
            shape = (B, self.n) + PER_PARTICLE_FIELDS[f]
            a = per_particle.get(f)
            ds.resize((k1,) + ds.shape[1:])
            if a is not None:
                a = np.asarray(a, dtype=np.float64)
                if a.shape != shape:
                    raise ValueError(f"{f}: expected shape {shape}, got {a.shape}")
                ds[k0:k1] = a
        self.t = k1
        return range(k0, k1)

    def _flush(self):
        buf = getattr(self, "_buf", None)
        if not buf:
            return
        fr = self.h5["frames"]
        k0 = fr["time"].shape[0]
        k1 = k0 + len(buf)
        for name in ("time", "step") + self.controls:
            fr[name].resize((k1,))
            fr[name][k0:k1] = [r[name] for r in buf]
        for f in self.fields:
            ds = fr[f]
            ds.resize((k1,) + ds.shape[1:])
            ds[k0:k1] = np.stack([r[f] for r in buf])
        self._buf, self._buf_bytes = [], 0

    def write_contacts(self, frame_index: int, contacts: Mapping[str, np.ndarray]):
        """Store the contact list of one frame under ``/contacts/<frame_index>``."""
        g = self.h5["contacts"].require_group(str(frame_index))
        for key in CONTACT_FIELDS:
            if key in contacts and contacts[key] is not None:
                dtype = "i8" if key in ("i", "j") else "f8"
                g.create_dataset(key, data=np.asarray(contacts[key], dtype=dtype))

    def write_wall(self, name: str, time, **series):
        """Store a wall's time series (``position``, ``angle``, ``force``, ``torque`` …)."""
        g = self.h5["walls"].require_group(name)
        g.create_dataset("time", data=np.asarray(time, dtype="f8"))
        for k, v in series.items():
            g.create_dataset(k, data=np.asarray(v, dtype="f8"))

    def set_meta(self, **attrs):
        for k, v in attrs.items():
            self.h5["meta"].attrs[k] = v if isinstance(v, (str, int, float, np.number)) else json.dumps(v, default=str)

    def close(self):
        """Flush and atomically rename ``<path>.partial`` to ``<path>``."""
        if self.h5 is None:
            return
        self._flush()
        self.h5.flush()
        self.h5.close()
        self.h5 = None
        os.replace(self.partial, self.path)

    def abort(self):
        if self.h5 is not None:
            self.h5.close()
            self.h5 = None
        self.partial.unlink(missing_ok=True)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        else:
            self.abort()


def write_frames(path, ids, radius, time, position, step=None, controls: Mapping | None = None,
                 contacts: Mapping[int, Mapping] | None = None, walls: Mapping[str, Mapping] | None = None,
                 mass=None, shape=None, meta: Mapping | None = None, **per_particle) -> Path:
    """Write a whole frame set at once. ``position`` is (T, N, 3); other fields (T, N, ...).

    ``controls`` maps a name to a (T,) array, ``contacts`` a frame index to a contact dict,
    ``walls`` a wall name to ``{"time": ..., "force": ...}``.
    """
    time = np.asarray(time, dtype=float)
    position = np.asarray(position, dtype=float)
    T = len(time)
    step = np.zeros(T, dtype=np.int64) if step is None else np.asarray(step)
    controls = {k: np.asarray(v, dtype=float) for k, v in (controls or {}).items()}
    fields = [f for f, v in per_particle.items() if v is not None]
    with FrameWriter(path, ids, radius, fields=fields, controls=controls.keys(), mass=mass,
                     shape=shape, meta=meta) as w:
        for k in range(T):
            w.append(time[k], int(step[k]), controls={c: v[k] for c, v in controls.items()},
                     contacts=(contacts or {}).get(k), position=position[k],
                     **{f: np.asarray(per_particle[f])[k] for f in fields})
        for name, series in (walls or {}).items():
            series = dict(series)
            w.write_wall(name, series.pop("time"), **series)
    return Path(path)


@dataclass
class Frame:
    """One frame: a view of :class:`Frames` at index ``index``, with arrays in id order."""
    index: int
    time: float
    step: int
    ids: np.ndarray
    radius: np.ndarray
    data: dict = field(default_factory=dict)
    controls: dict = field(default_factory=dict)

    @property
    def position(self) -> np.ndarray:
        return self.data["position"]

    def __getattr__(self, name):
        data = self.__dict__.get("data", {})
        if name in data:
            return data[name]
        raise AttributeError(name)

    def present(self) -> np.ndarray:
        """Boolean mask of particles present in this frame (position not NaN)."""
        return ~np.isnan(self.position).any(axis=1)

    def to_dataframe(self, dropna: bool = True):
        """One row per particle: id, radius, x, y, z and any other field flattened (vx, …)."""
        import pandas as pd
        cols = {"id": self.ids, "radius": self.radius}
        names = {"position": ("x", "y", "z"), "velocity": ("vx", "vy", "vz"),
                 "angular_velocity": ("wx", "wy", "wz"), "force": ("fx", "fy", "fz"),
                 "torque": ("tx", "ty", "tz"), "orientation": ("qw", "qx", "qy", "qz")}
        for f, a in self.data.items():
            if f == "stress":
                for a_, ax in enumerate("xyz"):
                    for b_, bx in enumerate("xyz"):
                        cols[f"s{ax}{bx}"] = a[:, a_, b_]
            else:
                for c, col in enumerate(names.get(f, [f"{f}{q}" for q in range(a.shape[1])])):
                    cols[col] = a[:, c]
        df = pd.DataFrame(cols)
        if dropna:
            df = df[self.present()].reset_index(drop=True)
        return df

    def to_vtk(self, path):
        """Write this frame as VTK point data (spheres as points with a ``radius`` array)."""
        return _frame_to_vtk(self, path)


class Frames:
    """Read a ``frames.h5`` file (or a run directory holding one); arrays are NumPy, in SI.

    >>> fr = Frames("runs/x/liggghts-abc/frames.h5")   # doctest: +SKIP
    >>> fr.position.shape                                # (T, N, 3)
    >>> fr[-1].to_dataframe()                            # last frame as a table
    """

    def __init__(self, path):
        path = Path(path)
        if path.is_dir():
            path = path / "frames.h5"
        elif not path.exists():
            raise FileNotFoundError(f"{path}: no such run directory or frames.h5 file; check the path")
        if not path.exists():
            raise FileNotFoundError(f"{path}: no frames.h5 here (is the run complete? `orchestrator status "
                                    f"{path.parent}` says how far it got)")
        self.path = path
        with _open_h5(path) as h:
            self.ids = h["particles/id"][()]
            self.radius = h["particles/radius"][()]
            self.mass = h["particles/mass"][()] if "mass" in h["particles"] else None
            self.shape = h["particles/shape"][()] if "shape" in h["particles"] else None
            self.time = h["frames/time"][()]
            self.step = h["frames/step"][()]
            self.fields = tuple(f for f in PER_PARTICLE_FIELDS if f in h["frames"])
            self.controls = {k: h["frames"][k][()] for k in h["frames"]
                             if k not in PER_PARTICLE_FIELDS and k not in ("time", "step")}
            self.meta = {k: _maybe_json(v) for k, v in h["meta"].attrs.items()}
            self.contact_frames = sorted(int(k) for k in h["contacts"])
            self.wall_names = sorted(h["walls"])
        self._cache: dict = {}
        self._index = {int(i): k for k, i in enumerate(self.ids)}

    @classmethod
    def from_arrays(cls, position, radius, time=None, ids=None, controls: Mapping | None = None,
                    meta: Mapping | None = None, mass=None, step=None, contacts: Mapping | None = None,
                    walls: Mapping | None = None, **fields) -> "Frames":
        """Frames held in memory, built from arrays without writing a file (e.g. for the array-level
        analyses in a notebook, or a clump sample's grains, :mod:`orchestrator.grains`). ``position``
        (T, N, 3) [m] (or (N, 3) for one frame; NaN rows = absent), ``radius`` (N,) [m], ``time``
        (T,) [s] (default 0, 1, ...), ``ids`` (N,) (default 1..N), ``controls`` name -> (T,) arrays,
        ``mass`` (N,) [kg], ``step`` (T,), ``contacts`` frame index -> dict of contact arrays (the
        file's ``/contacts/<k>`` layout, :data:`CONTACT_FIELDS`, plus any other per-contact array),
        ``walls`` name -> DataFrame (as :meth:`wall` returns), other per-particle fields (T, N, ...)
        by name."""
        pos = np.asarray(position, dtype=float)
        if pos.ndim == 2:
            pos = pos[None]
        if pos.ndim != 3 or pos.shape[2] != 3:
            raise ValueError(f"Frames.from_arrays: position must be (T, N, 3) or (N, 3) [m], got {pos.shape}")
        T, N = pos.shape[:2]
        self = cls.__new__(cls)
        self.path = "<arrays>"
        self.ids = np.arange(1, N + 1, dtype=np.int64) if ids is None else np.asarray(ids, dtype=np.int64)
        self.radius = np.broadcast_to(np.asarray(radius, dtype=float), (N,)).copy()
        self.mass = None if mass is None else np.asarray(mass, dtype=float)
        self.shape = None
        self.time = np.arange(T, dtype=float) if time is None else np.asarray(time, dtype=float)
        self.step = np.arange(T, dtype=np.int64) if step is None else np.asarray(step, dtype=np.int64)
        self._cache = {"position": pos, **{k: np.asarray(v) for k, v in fields.items() if v is not None}}
        unknown = [k for k in self._cache if k not in PER_PARTICLE_FIELDS]
        if unknown:
            raise ValueError(f"Frames.from_arrays: unknown per-particle fields {unknown}; known: {list(PER_PARTICLE_FIELDS)}")
        for k, v in self._cache.items():
            if v.shape[:2] != (T, N):
                raise ValueError(f"Frames.from_arrays: field {k!r} has shape {v.shape}, expected ({T}, {N}, ...)")
        if len(self.ids) != N or len(self.time) != T:
            raise ValueError(f"Frames.from_arrays: {len(self.ids)} ids and {len(self.time)} times for "
                             f"{T} frames x {N} particles")
        self.fields = tuple(f for f in PER_PARTICLE_FIELDS if f in self._cache)
        self.controls = {k: np.asarray(v, dtype=float) for k, v in (controls or {}).items()}
        self.meta = dict(meta or {})
        if self.mass is not None and self.mass.shape != (N,):
            raise ValueError(f"Frames.from_arrays: mass has shape {self.mass.shape}, expected ({N},) [kg]")
        self._contacts = {int(k): {n: np.asarray(a) for n, a in c.items()} for k, c in (contacts or {}).items()}
        self._walls = dict(walls or {})
        self.contact_frames = sorted(self._contacts)
        self.wall_names = sorted(self._walls)
        self._index = {int(i): k for k, i in enumerate(self.ids)}
        return self

    @property
    def in_memory(self) -> bool:
        """True for frames built by :meth:`from_arrays` (no file behind them)."""
        return "_contacts" in self.__dict__

    def __repr__(self):
        return (f"Frames({str(self.path)!r}: {self.n_frames} frames x {self.n_particles} particles, "
                f"fields={list(self.fields)}, controls={list(self.controls)}, walls={self.wall_names})")

    @property
    def n_frames(self) -> int:
        return len(self.time)

    def __len__(self):
        return self.n_frames

    @property
    def n_particles(self) -> int:
        return len(self.ids)

    def field(self, name: str) -> np.ndarray:
        """A per-particle field for all frames, (T, N, ...) [SI]."""
        if name not in self.fields:
            raise KeyError(f"{self.path}: no field {name!r}; this file has {list(self.fields)}")
        if name not in self._cache:
            with _open_h5(self.path) as h:
                self._cache[name] = h["frames"][name][()]
        return self._cache[name]

    def __getattr__(self, name):
        if name in PER_PARTICLE_FIELDS:
            return self.field(name)
        controls = self.__dict__.get("controls", {})
        if name in controls:
            return controls[name]
        raise AttributeError(name)

    def row(self, particle_id: int) -> int:
        """Row index of a particle id."""
        return self._index[int(particle_id)]

    def __getitem__(self, k: int) -> Frame:
        k = range(self.n_frames)[k]
        if self.in_memory:
            data = {f: self._cache[f][k] for f in self.fields}
        else:
            with _open_h5(self.path) as h:
                data = {f: h["frames"][f][k] for f in self.fields}
        return Frame(k, float(self.time[k]), int(self.step[k]), self.ids, self.radius, data,
                     {c: float(v[k]) for c, v in self.controls.items()})

    def __iter__(self):
        for k in range(self.n_frames):
            yield self[k]

    def contacts(self, k: int):
        """Contacts of frame k as a DataFrame (i, j, point, normal, fn, ft split into x/y/z)."""
        k = range(self.n_frames)[k]
        if self.in_memory:
            return _group_table(self.contact_arrays(k), CONTACT_FIELDS)
        with _open_h5(self.path) as h:
            if str(k) not in h["contacts"]:
                raise KeyError(f"{self.path}: frame {k} has no contacts; frames with contacts: {self.contact_frames}")
            return _group_table(h["contacts"][str(k)], CONTACT_FIELDS)

    def contact_arrays(self, k: int) -> dict:
        """Contacts of frame k as a dict of arrays (``i``, ``j``, ``point``, ``normal``, ``fn``, ``ft``)."""
        k = range(self.n_frames)[k]
        if self.in_memory:
            if k not in self._contacts:
                raise KeyError(f"{self.path}: frame {k} has no contacts; frames with contacts: {self.contact_frames}")
            return {key: a.copy() for key, a in self._contacts[k].items()}
        with _open_h5(self.path) as h:
            g = h["contacts"][str(k)]
            return {key: g[key][()] for key in g}

    def wall(self, name: str):
        """Time series of one wall as a DataFrame (time, position_x, …, force_z, torque_z …)."""
        if self.in_memory:
            if name not in self._walls:
                raise KeyError(f"{self.path}: no wall {name!r}; walls: {self.wall_names}")
            return self._walls[name].copy()
        with _open_h5(self.path) as h:
            return _group_table(h["walls"][name])

    @property
    def walls(self) -> dict:
        return {n: self.wall(n) for n in self.wall_names}

    def to_vtk(self, k: int, path):
        """Write frame k as a VTK file for ParaView."""
        return self[k].to_vtk(path)


class FramesError(ValueError):
    """A frames.h5 that cannot be read (truncated, damaged, not HDF5, not in this format)."""


class _open_h5:
    """``h5py.File(path, "r")`` whose read errors (a truncated or damaged file, a missing group)
    become a :class:`FramesError` naming the file and the fix."""

    def __init__(self, path):
        self.path = Path(path)

    def __enter__(self):
        try:
            import h5py
            # locking=False: a frames.h5 is written as .partial and renamed once complete, so no
            # reader ever meets a file being written and HDF5's advisory lock protects nothing here.
            # It did harm: a process started from another thread (an engine of a threaded sweep)
            # inherits, until its exec, the descriptor of a frames file being written, with its
            # exclusive flock, and opening the renamed file for reading then fails with errno 11
            # (tests/test_frames.py::test_a_finished_file_opens_while_a_process_holds_its_writers_descriptor)
            self.h = h5py.File(self.path, "r", locking=False)
        except OSError as exc:
            raise FramesError(self._msg(exc)) from None
        return self.h

    def __exit__(self, typ, exc, tb):
        self.h.close()
        # h5py's read errors: OSError/RuntimeError for damaged data, KeyError "Unable to ..." for a
        # group or dataset a truncated file lacks (a KeyError of this module's own API passes)
        damaged = isinstance(exc, (OSError, RuntimeError)) and not isinstance(exc, FileNotFoundError) or \
            isinstance(exc, KeyError) and "Unable to" in str(exc)
        if damaged:
            raise FramesError(self._msg(exc)) from None
        return False

    def _msg(self, exc) -> str:
        size = self.path.stat().st_size if self.path.exists() else 0
        return (f"{self.path}: not a readable frames file ({size} bytes; {str(exc).splitlines()[0][:160]}): it is "
                f"truncated or damaged. Run the case again (`orchestrator run CASE` checks a run's files and "
                f"resumes or redoes a damaged one) or write it again from its source")


def load(path) -> Frames:
    """Open the frames of a run directory, a ``frames.h5`` file, or a CT frame set."""
    return Frames(path)


def _group_table(g, keys=None):
    """The datasets of an HDF5 group (or the arrays of a dict) as a DataFrame, one row per sample (the length of its ``time``
    dataset when it has one); (M, 3) arrays become <name>_x/_y/_z columns. Datasets that are not
    one value or one vector per row (a YADE membrane's node positions per frame, its triangles, a
    node radius) go to ``DataFrame.attrs`` under their names, as arrays."""
    import pandas as pd
    keys = [k for k in (keys if keys is not None else list(g)) if k in g]
    arrays = {k: g[k][()] for k in keys}
    rows = len(arrays["time"]) if "time" in arrays else next((len(a) for a in arrays.values() if a.ndim), 0)
    cols, other = {}, {}
    for key, a in arrays.items():
        if a.ndim == 1 and len(a) == rows:
            cols[key] = a
        elif a.ndim == 2 and len(a) == rows and a.shape[1] == 3:
            for c, ax in enumerate("xyz"):
                cols[f"{key}_{ax}"] = a[:, c]
        else:
            other[key] = a
    df = pd.DataFrame(cols)
    df.attrs.update(other)
    return df


def _maybe_json(v):
    if isinstance(v, bytes):
        v = v.decode()
    if isinstance(v, str) and v[:1] in "{[":
        try:
            return json.loads(v)
        except ValueError:
            return v
    return v


def _frame_to_vtk(frame: Frame, path):
    import meshio
    mask = frame.present()
    pts = frame.position[mask]
    point_data = {"id": frame.ids[mask].astype(np.int64), "radius": frame.radius[mask]}
    for f, a in frame.data.items():
        if f == "position":
            continue
        a = a[mask]
        point_data[f] = a.reshape(len(a), -1) if f == "stress" else a
    cells = [("vertex", np.arange(len(pts)).reshape(-1, 1))]
    path = Path(path)
    tmp = path.with_name(path.stem + ".partial" + path.suffix)
    meshio.write(tmp, meshio.Mesh(pts, cells, point_data=point_data))
    os.replace(tmp, path)
    return path
