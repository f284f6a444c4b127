"""Frame recorder of the YADE decks: buffers frames of the recorded grains and writes them as
chunks ``dump/chunk.<first iter>.npz`` (atomic), read by ``engines/yade.py`` ``parse``."""
from __future__ import annotations

import json
import os

import numpy as np
from yade import O, utils

from .series import WindowSeries, chunk_arrays, save_npz_atomic, stop_steps  # noqa: F401 (the decks import it from here)

CONTACT_KEYS = ["c_count", "c_i", "c_j", "c_point", "c_normal", "c_fn", "c_ft"]


class Recorder:
    """``fields``: the output fields of the case (position, velocity, ...); ``contacts``: record the
    grain-grain contacts too; ``chunk_frames``: frames per chunk file; ``pids``: the particle-table
    ids of the recorded bodies (for contact lists; default: read from particles.txt)."""

    def __init__(self, ids, fields, contacts=False, chunk_frames=256, pids=None):
        self.ids = [int(i) for i in ids]
        if pids is None:
            t = np.loadtxt("particles.txt", ndmin=2)
            pids = t[:, 0].astype(int) if len(t) == len(self.ids) else self.ids
        self.pids = [int(i) for i in pids]
        self.fields = list(fields)
        self.contacts = bool(contacts)
        self.chunk_frames = chunk_frames
        self.buf = self._empty()

    def _empty(self):
        return {k: [] for k in ["iter", "time"] + self.fields + (CONTACT_KEYS if self.contacts else [])}

    def grab(self, final=False):
        """A frame from a PyRunner placed after NewtonIntegrator (it sees the state at the *end* of
        iteration O.iter + 1), or, with ``final``, after O.run() has returned (state of O.iter)."""
        self._grab(O.iter if final else O.iter + 1, O.time if final else O.time + O.dt)

    def grab_now(self):
        """A frame of the state at the end of step O.iter, taken between O.run segments, then flushed."""
        self._grab(O.iter, O.time)
        self.flush()

    def _grab(self, it, t):
        b = self.buf
        if it in b["iter"]:
            return
        b["iter"].append(it)
        b["time"].append(t)
        bodies = [O.bodies[i] for i in self.ids]
        if "position" in self.fields:
            b["position"].append([tuple(x.state.pos) for x in bodies])
        if "velocity" in self.fields:
            b["velocity"].append([tuple(x.state.vel) for x in bodies])
        if "angular_velocity" in self.fields:
            b["angular_velocity"].append([tuple(x.state.angVel) for x in bodies])
        if "orientation" in self.fields:
            b["orientation"].append([(x.state.ori.w(), x.state.ori.x(), x.state.ori.y(), x.state.ori.z())
                                     if hasattr(x.state.ori, "w") else tuple(x.state.ori) for x in bodies])
        if "force" in self.fields:
            b["force"].append([tuple(O.forces.f(i)) for i in self.ids])
        if "torque" in self.fields:
            b["torque"].append([tuple(O.forces.t(i)) for i in self.ids])
        if "stress" in self.fields:
            # utils.bodyStressTensors: sigma = 1/V sum_c f_c (x) (x_c - x), tension positive
            st = utils.bodyStressTensors()
            b["stress"].append([[tuple(st[i].row(k)) for k in range(3)] for i in self.ids])
        if self.contacts:
            self._grab_contacts()
        if len(b["iter"]) >= self.chunk_frames:
            self.flush()

    def _grab_contacts(self):
        """Grain-grain contacts: ids, point, unit normal from i to j, normal and tangential force on
        i (both laws apply -(normalForce + shearForce) to id1). A pair that carries no normal force is left
        out: YADE keeps a separated pair real (zero force) until the collider erases it, LIGGGHTS'
        pair/gran/local lists touching pairs only (an adhesive pair pulled apart still carries a force: kept)."""
        b = self.buf
        pid = getattr(self, "_pid", None)
        if pid is None:
            pid = self._pid = dict(zip(self.ids, self.pids))
        rows = []
        for I in O.interactions:
            if not I.isReal or I.id1 not in pid or I.id2 not in pid:
                continue
            g, ph = I.geom, I.phys
            if ph.normalForce.squaredNorm() == 0:
                continue
            rows.append((pid[I.id1], pid[I.id2]) + tuple(g.contactPoint) + tuple(g.normal)
                        + tuple(-ph.normalForce) + tuple(-ph.shearForce))
        a = np.asarray(rows, dtype=float).reshape(-1, 14)
        b["c_count"].append(len(a))
        b["c_i"].append(a[:, 0].astype(np.int64))
        b["c_j"].append(a[:, 1].astype(np.int64))
        b["c_point"].append(a[:, 2:5])
        b["c_normal"].append(a[:, 5:8])
        b["c_fn"].append(a[:, 8:11])
        b["c_ft"].append(a[:, 11:14])

    def flush(self):
        if not self.buf["iter"]:
            return
        save_npz_atomic("dump/chunk.%012d.npz" % self.buf["iter"][0], **chunk_arrays(self.buf))
        self.buf = self._empty()


def progress():
    """The progress line the adapter reads (``PROGRESS <iter>``)."""
    print("PROGRESS %d" % O.iter, flush=True)


def save_checkpoint():
    """O.save to checkpoint.yade.gz (atomic rename). Call it from a PyRunner placed FIRST in
    O.engines, after flushing the Python buffers: only there do positions, O.iter and O.time
    describe one instant (after NewtonIntegrator the positions are one step ahead, and a resume
    would repeat a step)."""
    O.save("checkpoint.partial.yade.gz")
    os.replace("checkpoint.partial.yade.gz", "checkpoint.yade.gz")


#: O.tags key of the wall series' open window (the samples since its last row) at a checkpoint
WINDOW_TAG = "orch_wall_window"


def checkpoint_and_reload(rec, walls) -> None:
    """A checkpoint of a scene script, taken between ``O.run`` calls (an iteration boundary: positions,
    O.iter and O.time describe one instant): flush the frames and wall rows, keep the wall series'
    open window in ``O.tags``, save, and **load the saved file back**. An uninterrupted run thus passes
    through the very state a resumed run starts from: what ``O.save`` does not keep (the collider's
    sort arrays, the order interactions are visited and forces summed in, Python objects) is rebuilt
    at the same step in both (docs/engines.md, Resume). The caller sets its Python side up again."""
    rec.flush()
    walls.flush()
    O.tags[WINDOW_TAG] = json.dumps(walls.acc)
    save_checkpoint()
    O.load("checkpoint.yade.gz")


def series_after_load(name: str, n_values: int, window: int = 10):
    """A :class:`WindowSeries` for the run from here on, holding the open window a checkpoint kept
    (none on a fresh scene): the rows after a resume average the same samples as an uninterrupted
    run's."""
    s = WindowSeries(name, n_values, window)
    s.acc = [list(map(float, a)) for a in json.loads(O.tags[WINDOW_TAG])] if WINDOW_TAG in O.tags.keys() else []
    return s
