"""Alignment of two frame sets (runs or CT series, any mix): which states correspond, in which
coordinate frame, and which grain is which.

* **States** are matched by a control both sets carry: ``axial_strain`` (triaxial), ``angle``
  (shear cell), else ``time``. Frames sharing one control value (e.g. the shear cell's loose,
  relaxed and compressed frames, all at angle 0) collapse to the *last* of them: the state the
  loading starts from. A state of A is paired with the nearest state of B within ``tolerance``
  (absolute, in the control's SI unit; default: a quarter of the smallest spacing of A's states).
* **Coordinates**: ``frame="none"`` (default: both sets are in the cell's world frame, as
  simulations and scans rendered from them are), ``"centroid"`` (B translated so that its
  reference-state centroid lands on A's), ``"rigid"`` (B rotated and translated onto A by the
  least-squares fit of Kabsch over grains identified in the reference state; needs identity).
* **Identity**: when both sets hold the same ids (≥ 90 % in common) and either every common id has
  the same radius in both (runs started from one particle table: engine vs engine, a run vs
  itself, a run started from a CT frame) or the grains sit within half a median diameter of each
  other in the reference state, ids are used as they are (``method="ids"``). Otherwise grains
  are matched by position in the reference state (``method="position"``): the exact minimum of the
  summed squared distances with a cut-off (:func:`orchestrator.ct.track.link`, default cut-off
  half a median diameter); grains without a partner are left out of grain-level comparisons.
  A run started from a frame of the other side (``initial_packing``) uses the ids it inherited
  (``method="ids (initial packing)"``, with the recorded id shift).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..frames import Frames
from ..ct.track import link

__all__ = ["Source", "open_source", "choose_control", "states", "match_states", "Identity", "match_identity",
           "Alignment", "align", "kabsch"]

#: controls tried in this order when matching states
CONTROL_ORDER = ("axial_strain", "angle", "shear_strain")


@dataclass
class Source:
    """A frame set and what is known about where it came from.

    path : the frames.h5 file; run_dir : the run directory (None for a bare CT frame set);
    label : short name for tables and plots; kind : "simulation" or "ct"; engine : engine name
    ("ct" for CT); summary : the run's summary.json (empty for CT); substitutions : list of
    ``{"feature", "mechanism", "note"}``.
    """
    frames: Frames
    path: Path
    run_dir: Path | None
    label: str
    kind: str
    engine: str
    summary: dict = field(default_factory=dict)
    substitutions: list = field(default_factory=list)

    @property
    def case(self) -> dict:
        c = self.frames.meta.get("case")
        return c if isinstance(c, dict) else {}


def open_source(x, label: str | None = None) -> Source:
    """Open a run directory, a ``frames.h5`` file (simulation or CT), or wrap a :class:`Frames`."""
    if isinstance(x, Source):
        return x
    fr = x if isinstance(x, Frames) else Frames(x)
    path = Path(fr.path)
    run_dir = path.parent if (path.parent / "summary.json").exists() else None
    summary = json.loads((run_dir / "summary.json").read_text()) if run_dir else {}
    meta = fr.meta
    kind = "ct" if str(meta.get("source", "simulation")).startswith("ct") else "simulation"
    engine = str(meta.get("engine", summary.get("engine", kind)))
    subs = summary.get("substitutions", meta.get("substitutions", [])) or []
    if isinstance(subs, str):
        subs = json.loads(subs)
    if label is None:
        if run_dir is not None:
            label = f"{engine}:{run_dir.parent.name}"
        else:
            label = f"{kind}:{path.parent.name}/{path.name}" if kind == "ct" else f"{engine}:{path.name}"
    return Source(fr, path, run_dir, label, kind, engine, summary, list(subs))


def choose_control(a: Frames, b: Frames, control: str | None = None) -> str:
    """The control both sets carry (finite somewhere in each), first of :data:`CONTROL_ORDER`,
    else ``time``. A ``control`` given that either set lacks is a ValueError naming the controls
    it has."""
    if control is not None:
        for fr in (a, b):
            if control != "time" and control not in fr.controls:
                raise ValueError(f"--control {control!r}: {fr.path} has no such control; give one of "
                                 f"{sorted(fr.controls)} or 'time', or leave --control out to choose one")
        return control
    for c in CONTROL_ORDER:
        if all(c in fr.controls and np.isfinite(fr.controls[c]).any() for fr in (a, b)):
            return c
    return "time"


def _values(fr: Frames, control: str) -> np.ndarray:
    return np.asarray(fr.time if control == "time" else fr.controls[control], float)


def states(fr: Frames, control: str) -> pd.DataFrame:
    """Distinct states of a frame set: one row per distinct finite control value (the last frame
    holding it), sorted by frame. Columns ``frame``, ``value``."""
    v = _values(fr, control)
    rows = {}
    for k, x in enumerate(v):
        if np.isfinite(x):
            rows[round(float(x), 12)] = k         # later frames overwrite: the last one wins
    ks = sorted(rows.values())
    return pd.DataFrame({"frame": ks, "value": v[ks]})


def match_states(a: Frames, b: Frames, control: str | None = None, tolerance: float | None = None,
                 at=None) -> tuple[str, pd.DataFrame]:
    """Pair states of A and B by control value.

    Returns ``(control, table)`` with columns ``state`` (0, 1, ...), ``frame_a``, ``frame_b``,
    ``value_a``, ``value_b``, ``value`` (A's). ``at``: restrict to these control values of A (nearest).
    """
    control = choose_control(a, b, control)
    sa, sb = states(a, control), states(b, control)
    if len(sa) == 0 or len(sb) == 0:
        raise ValueError(f"no finite '{control}' values in {a.path if len(sa) == 0 else b.path}")
    if at is not None:
        keep = sorted({int(np.argmin(np.abs(sa.value.to_numpy() - float(x)))) for x in np.atleast_1d(at)})
        sa = sa.iloc[keep].reset_index(drop=True)
    if tolerance is None:
        va = np.sort(sa.value.to_numpy())
        gaps = np.diff(va)
        gaps = gaps[gaps > 0]
        tolerance = 0.25 * float(gaps.min()) if len(gaps) else np.inf
        if control == "time" and not np.isfinite(tolerance):
            tolerance = np.inf
    rows = []
    vb = sb.value.to_numpy()
    used = set()
    for _, r in sa.iterrows():
        j = int(np.argmin(np.abs(vb - r.value)))
        if abs(vb[j] - r.value) <= tolerance * (1 + 1e-9) + 1e-15 and j not in used:
            used.add(j)
            rows.append((int(r.frame), int(sb.frame[j]), float(r.value), float(vb[j])))
    if not rows:
        raise ValueError(f"no state of {b.path} matches a state of {a.path} in '{control}' within {tolerance:g} "
                         f"(A: {sa.value.min():g}..{sa.value.max():g}, B: {vb.min():g}..{vb.max():g})")
    t = pd.DataFrame(rows, columns=["frame_a", "frame_b", "value_a", "value_b"])
    t.insert(0, "state", np.arange(len(t)))
    t["value"] = t["value_a"]
    return control, t


def kabsch(p: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R and translation t minimising Σ|R q + t − p|² (rows are points)."""
    pc, qc = p.mean(0), q.mean(0)
    H = (q - qc).T @ (p - pc)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    D = np.diag([1.0, 1.0, d])
    R = Vt.T @ D @ U.T
    return R, pc - R @ qc


@dataclass
class Identity:
    """Grain correspondence: ``rows_a[k]`` in A is ``rows_b[k]`` in B."""
    rows_a: np.ndarray
    rows_b: np.ndarray
    method: str                    # "ids" or "position"
    reference: tuple[int, int]     # frames (A, B) the matching was done in
    max_distance: float            # cut-off [m] (position matching)
    unmatched_a: int
    unmatched_b: int

    @property
    def n(self) -> int:
        return len(self.rows_a)

    def summary(self) -> dict:
        return {"method": self.method, "matched": int(self.n), "unmatched_a": int(self.unmatched_a),
                "unmatched_b": int(self.unmatched_b), "reference_frames": list(self.reference),
                "max_distance_m": float(self.max_distance)}


def _d50(fr: Frames) -> float:
    r = fr.radius[np.isfinite(fr.radius)]
    return 2 * float(np.median(r))


def match_identity(a: Frames, b: Frames, ka: int, kb: int, max_distance: float | None = None,
                   transform=None, use_ids: bool | None = None) -> Identity:
    """Which grain of B is which grain of A, from frames ``ka`` / ``kb`` (see the module doc).

    ``transform`` (R, t) maps B's coordinates to A's before position matching. ``use_ids``: force
    (True) or forbid (False) id matching; default automatic.
    """
    d50 = _d50(a)
    max_distance = 0.5 * d50 if max_distance is None else float(max_distance)
    pa, pb = a.position[ka], b.position[kb]
    if transform is not None:
        R, t = transform
        pb = pb @ np.asarray(R).T + np.asarray(t)
    ok_a, ok_b = np.isfinite(pa).all(1), np.isfinite(pb).all(1)
    common, ia, ib = np.intersect1d(a.ids, b.ids, return_indices=True)
    if use_ids is not False and len(common):
        sel = ok_a[ia] & ok_b[ib]
        ia, ib = ia[sel], ib[sel]
        dist = np.linalg.norm(pa[ia] - pb[ib], axis=1) if len(ia) else np.array([np.inf])
        enough = len(ia) >= 0.9 * min(ok_a.sum(), ok_b.sum())
        same_radii = len(ia) > 0 and np.allclose(a.radius[ia], b.radius[ib], rtol=1e-6, atol=0)
        if use_ids or (enough and (same_radii or np.median(dist) <= max_distance)):
            return Identity(ia, ib, "ids", (ka, kb), max_distance, int(ok_a.sum() - len(ia)), int(ok_b.sum() - len(ib)))
    ra, rb = np.nonzero(ok_a)[0], np.nonzero(ok_b)[0]
    L = link(pa[ra], pb[rb], max_distance)
    la = np.nonzero(L.a_to_b >= 0)[0]
    rows_a, rows_b = ra[la], rb[L.a_to_b[la]]
    return Identity(rows_a, rows_b, "position", (ka, kb), max_distance, int(len(ra) - len(la)),
                    int(len(rb) - len(la)))


def _packing_origin(src: Source):
    """(frames file, id shift) when ``src`` is a run started from a frame of another frame set."""
    if src.run_dir is None or not (src.run_dir / "params.json").exists():
        return None
    ip = json.loads((src.run_dir / "params.json").read_text()).get("initial_packing")
    if not isinstance(ip, dict) or "source" not in ip:
        return None
    return Path(ip["source"]).resolve(), int(ip.get("id_shift", 0))


def _identity_from_packing(A: Source, B: Source, ka: int, kb: int) -> Identity | None:
    """Ids of a run started from the other side's packing (``initial_packing``) name the same grains
    (shifted by the recorded offset), whatever happened to the positions since."""
    for run, other, flip in ((B, A, False), (A, B, True)):
        o = _packing_origin(run)
        if o is None or o[0] != Path(other.path).resolve():
            continue
        shift = o[1]
        ids_other = other.frames.ids + shift
        common, io, ir = np.intersect1d(ids_other, run.frames.ids, return_indices=True)
        ra, rb = (ir, io) if flip else (io, ir)
        return Identity(ra, rb, "ids (initial packing)", (ka, kb), 0.0, int(A.frames.n_particles - len(ra)),
                        int(B.frames.n_particles - len(rb)))
    return None


@dataclass
class Alignment:
    """Everything :func:`align` decided, for the comparison and the report."""
    a: Source
    b: Source
    control: str
    states: pd.DataFrame
    transform: tuple | None        # (R, t) applied to B, or None
    frame: str
    identity: Identity | None

    def transform_b(self, pos: np.ndarray) -> np.ndarray:
        """B's positions (…, 3) in A's coordinate frame."""
        if self.transform is None:
            return pos
        R, t = self.transform
        return pos @ np.asarray(R).T + np.asarray(t)

    def summary(self) -> dict:
        out = {"a": self.a.label, "b": self.b.label, "control": self.control, "states": int(len(self.states)),
               "coordinate_frame": self.frame,
               "identity": self.identity.summary() if self.identity is not None else None}
        if self.transform is not None:
            R, t = self.transform
            out["rotation"] = np.asarray(R).tolist()
            out["translation_m"] = np.asarray(t).tolist()
        return out


def align(a, b, control: str | None = None, tolerance: float | None = None, frame: str = "none",
          identity: bool = True, max_distance: float | None = None, at=None) -> Alignment:
    """Align B to A: matched states, coordinate transform, grain identity (see the module doc)."""
    A, B = open_source(a), open_source(b)
    control, st = match_states(A.frames, B.frames, control, tolerance, at)
    ka, kb = int(st.frame_a.iloc[0]), int(st.frame_b.iloc[0])
    transform = None
    if frame == "centroid":
        pa, pb = A.frames.position[ka], B.frames.position[kb]
        transform = (np.eye(3), np.nanmean(pa, 0) - np.nanmean(pb, 0))
    elif frame not in ("none", "rigid"):
        raise ValueError(f"frame must be 'none', 'centroid' or 'rigid', got {frame!r}")
    ident = None
    if identity or frame == "rigid":
        ident = _identity_from_packing(A, B, ka, kb)
        if ident is None:
            ident = match_identity(A.frames, B.frames, ka, kb, max_distance, transform)
        if frame == "rigid":
            if ident.n < 3:
                raise ValueError("frame='rigid' needs at least 3 identified grains in the reference state")
            pa = A.frames.position[ka][ident.rows_a]
            pb = B.frames.position[kb][ident.rows_b]
            transform = kabsch(pa, pb)
            ident = match_identity(A.frames, B.frames, ka, kb, max_distance, transform)
    return Alignment(A, B, control, st, transform, frame, ident)
