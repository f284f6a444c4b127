"""Stability monitors of the YADE decks (orchestrator.stability): every ``cfg["every"]`` steps a
PyRunner checks the kinetic energy, the largest overlap / r_min, grains outside the box, NaN and
(when a wall force is given) the wall force and its swing between checks; the first that trips
prints ``ORCH_UNSTABLE:<figure>:<value>:<limit>:<step>`` and ends the process (exit 3; the runner
marks the run unstable)."""
from __future__ import annotations

import os
import sys

from yade import O, PyRunner


def monitor_engine(cfg: dict, name: str = "monitor"):
    """The PyRunner to append to O.engines (after NewtonIntegrator). It calls ``name()`` in the
    script's namespace (where PyRunner commands run): the script binds ``name`` to a
    :class:`Monitor` once the grains exist (and again after O.load on resume)."""
    return PyRunner(command="%s()" % name, iterPeriod=cfg["every"], dead=not cfg["enabled"], label="orch_monitor")


class Monitor:
    """``cfg``: the derived monitor settings (``params["monitors"]``); ``ids``: the case's grains
    (body ids); ``wall_force``: a callable giving the watched wall force [N], or None."""

    def __init__(self, cfg: dict, ids, wall_force=None):
        self.cfg = cfg
        self.ids = list(ids)
        self.mine = set(self.ids)
        self.wall_force = wall_force
        self.prev = 0.0

    @staticmethod
    def trip(fig, value, limit):
        print("ORCH_UNSTABLE:%s:%r:%r:%d" % (fig, value, limit, O.iter + 1), flush=True)
        sys.stdout.flush()
        os._exit(3)

    def __call__(self):
        m = self.cfg
        ke = 0.0
        lo, hi, per = m.get("box_lo"), m.get("box_hi"), m.get("periodic") or [False, False, False]
        out = 0
        for i in self.ids:
            s = O.bodies[i].state
            v = s.vel
            ke += 0.5 * s.mass * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
            p = s.pos
            if lo is not None:
                for k in range(3):
                    if not per[k] and not (lo[k] <= p[k] <= hi[k]):
                        out += 1
                        break
        if ke != ke:
            self.trip("nan", ke, 0)
        if ke > m["ke_limit"]:
            self.trip("kinetic_energy", ke, m["ke_limit"])
        dmax = 0.0
        mine = self.mine
        for I in O.interactions:
            # contacts of the case's grains only (fixed helper bodies, e.g. overlapping plane spheres, do
            # not count); a duplicate grain-PFacet contact (ScGridCoGeom.isDuplicate) carries no force and
            # its geometry is not computed: after O.load its penetrationDepth stays NaN (not saved), which
            # is no instability
            if I.isReal and (I.id1 in mine or I.id2 in mine) and not getattr(I.geom, "isDuplicate", 0):
                d = I.geom.penetrationDepth
                if d != d:
                    self.trip("nan", d, 0)
                if d > dmax:
                    dmax = d
        ov = dmax / m["r_min"]
        if m.get("print_figures"):         # orchestrator.stability.history: the figures at every check
            print("ORCH_OV %d %r %r" % (O.iter + 1, ov, ke), flush=True)
        if ov > m["overlap_limit"]:
            self.trip("overlap", ov, m["overlap_limit"])
        n_in = len(self.ids) - out
        if n_in < m["n_particles"]:
            self.trip("grains_outside", n_in, m["n_particles"])
        if self.wall_force is not None and m.get("wall_force_limit"):
            w = self.wall_force()
            if abs(w) > m["wall_force_limit"]:
                self.trip("wall_force", w, m["wall_force_limit"])
            if abs(w - self.prev) > m["wall_force_limit"]:
                self.trip("wall_force_swing", w, m["wall_force_limit"])
            self.prev = w
