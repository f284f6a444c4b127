"""The shell-pressure boundary in a YADE triaxial deck (:mod:`.shell` law): permanent forces on
the shell grains, refreshed every ``update_every`` steps by a PyRunner. It offers the members of
:class:`.membrane.Membrane` that :class:`.triaxial.Controller` uses."""
from __future__ import annotations

import numpy as np
from yade import O, Vector3

from .shell import shell_forces


class ShellBoundary:
    """``cfg``: bands, sectors, shell (thickness w [m]); ``grains``: body ids of the grains."""

    nodes: list = []        # no sheet: nothing for node_drag to hold

    def __init__(self, cfg: dict, grains):
        self.cfg = cfg
        self.grains = [int(i) for i in grains]
        self.states = [O.bodies[i].state for i in self.grains]
        self.radius = np.array([O.bodies[i].shape.radius for i in self.grains])
        self.loaded = set()              # grains carrying a permanent force
        self.last = {"force": 0.0, "area": 0.0, "volume": 0.0}

    def positions(self):
        out = []
        for st in self.states:
            x = st.pos
            out.append((x[0], x[1], x[2]))
        return np.array(out)

    def _evaluate(self, p, zb, zt):
        c = self.cfg
        return shell_forces(self.positions(), self.radius, zb, zt, p, c["bands"], c["sectors"], c["shell"])

    def apply_pressure(self, p, zb, zt):
        """Permanent radial forces on the shell grains until the next call; the boundary's force,
        area and volume of this update are kept for the time series (as LIGGGHTS stores them)."""
        f, flat, area, volume = self._evaluate(p, zb, zt)
        self.last = {"force": flat, "area": area, "volume": volume}
        now = set()
        setPermF = O.forces.setPermF
        for k in np.nonzero(np.any(f != 0.0, axis=1))[0].tolist():
            gid = self.grains[k]
            setPermF(gid, Vector3(f[k, 0], f[k, 1], 0.0))
            now.add(gid)
        for gid in self.loaded - now:
            setPermF(gid, Vector3.Zero)
        self.loaded = now

    def geometry(self, zb, zt):
        """Volume [m^3] and lateral area [m^2] of the boundary at the last update."""
        return {"volume": self.last["volume"], "area": self.last["area"]}

    def lateral_force(self):
        """Total radial force [N] the boundary exerts on the grains (last update)."""
        return self.last["force"]

    def relax(self):
        """Nothing to relax: the shell has no elastic state."""

    # -- resume: O.save keeps no permanent force ---------------------------------------------------
    def get_state(self):
        return {"loaded": {str(g): list(O.forces.permF(g)) for g in sorted(self.loaded)}, "last": self.last}

    @classmethod
    def restore(cls, cfg, grains, state):
        self = cls(cfg, grains)
        for g, f in state["loaded"].items():
            O.forces.setPermF(int(g), Vector3(*f))
        self.loaded = {int(g) for g in state["loaded"]}
        self.last = dict(state["last"])
        return self
