"""Flexible membrane of the YADE triaxial deck: GridNodes + GridConnections + PFacets
(yade.gridpfacet) around the sample, loaded by a follow-the-surface pressure as nodal forces.

Nodes (CohFrictMat, cohesive connections) carry the sheet's stiffness E_m t; the facets (CpmMat,
so that Ip2_FrictMat_CpmMat_FrictPhys gives grain-facet contacts linear FrictPhys with kn =
``k_contact`` while grain-grain contacts stay Hertz-Mindlin: no "Ambiguous dispatch"). The
pressure p A_f/3 along each facet's current inward normal is refreshed every ``update_every``
steps (:func:`.mesh.pressure_forces`). All numbers come from ``orchestrator.scenes.triaxial``
(``params["scene"]["membrane"]``, passed as ``cfg``)."""
from __future__ import annotations

import math

import numpy as np
from yade import O, Vector3
from yade.gridpfacet import gridConnection, gridNode, pfacet
from yade.wrapper import CohFrictMat, CohFrictPhys, CpmMat

from . import mesh
from .series import save_npz_atomic


class Membrane:
    """``cfg``: the derived membrane numbers (n_theta, n_z, node_radius, E_conn, E_facet, density,
    friction, node_mass, damping [N s/m], contact_damping [fraction of critical],
    contact_damping_lagged); ``radius0``: the sample's radius [m]; ``z_bot``, ``z_top``: the
    platens [m]."""

    def __init__(self, cfg: dict, radius0: float, z_bot: float, z_top: float):
        self.cfg = cfg
        nt, nz = cfg["n_theta"], cfg["n_z"]
        rn = self.rn = cfg["node_radius"]
        # node centres: the facets' inner faces (chords, offset rn inwards) clear the outermost grain
        R = (radius0 + rn) / math.cos(math.pi / nt)
        node_mat = O.materials.append(CohFrictMat(
            young=cfg["E_conn"], poisson=1.0, density=cfg["density"], frictionAngle=0.0,
            normalCohesion=1e300, shearCohesion=1e300, momentRotationLaw=True, alphaKr=0.1, alphaKtw=0.1,
            label="membrane_nodes"))
        # grain-membrane friction: Ip2_FrictMat_CpmMat_FrictPhys gave tan(phi) of the facet material
        # (checked: phys.tangensOfFrictionAngle), so this is the grain-membrane coefficient
        facet_mat = O.materials.append(CpmMat(
            young=cfg["E_facet"], poisson=1.0, density=cfg["density"],
            frictionAngle=math.atan(cfg["friction"]), label="membrane_facets"))
        # rows from one row below the bottom platen to one row above the top platen: the ends are
        # free (no node is tied to a platen) and the overhang carries no pressure
        dz = (z_top - z_bot) / nz
        nz = nz + 2
        self.nt, self.nz = nt, nz
        self.nodes = []
        for xyz in mesh.node_positions(nt, nz, R, z_bot - dz, dz).tolist():
            b = gridNode(tuple(xyz), rn, wire=False, fixed=False, material=node_mat)
            b.groupMask = 0b100
            self.nodes.append(O.bodies.append(b))
        self.bottom_ring = self.nodes[:nt]
        self.top_ring = self.nodes[nz * nt:]
        tris = [tuple(self.nodes[i] for i in t) for t in mesh.triangles(nt, nz).tolist()]
        # yade.gridpfacet's gridConnection/pfacet return Bodies to append (and add the
        # connections' mass to the nodes: the nodes' mass is set afterwards)
        for a, b in self._edges(tris):
            O.bodies.append(gridConnection(a, b, rn, material=node_mat, mask=0b100))
        self.facets = []
        for a, b, c in tris:
            # mask 0b110: meets grains (0b011) through bit 0b010; facets never meet each other
            # (collider avoidSelfInteractionMask = 0b100); nodes/connections are unbounded
            self.facets.append(O.bodies.append(pfacet(a, b, c, wire=False, material=facet_mat, mask=0b110)))
        for nid in self.nodes:
            st = O.bodies[nid].state
            st.mass = cfg["node_mass"]
            st.inertia = Vector3(1, 1, 1) * (0.4 * st.mass * rn * rn)
        self._index(tris)

    @staticmethod
    def _edges(tris):
        out = set()
        for t in tris:
            for a, b in ((t[0], t[1]), (t[1], t[2]), (t[0], t[2])):
                out.add((min(a, b), max(a, b)))
        return sorted(out)

    def _index(self, tris):
        """Lookups over the built mesh (node states, neighbours, local triangles) and constants;
        shared by the constructor and restore()."""
        cfg = self.cfg
        # the nodes' State objects, read in bulk (faster than O.bodies[i].state per call)
        self.states = [O.bodies[nid].state for nid in self.nodes]
        self.tri = np.array(tris, dtype=int)
        self.index = {nid: k for k, nid in enumerate(self.nodes)}
        self.tri_local = np.vectorize(self.index.get)(self.tri)
        local_edges = [(self.index[a], self.index[b]) for a, b in self._edges(tris)]
        self.avg = mesh.neighbour_mean_matrix(len(self.nodes), local_edges)
        self.c_damp = cfg["damping"]
        self.c_contact = cfg["contact_damping"]
        self.lagged_dashpot = bool(cfg.get("contact_damping_lagged", False))
        self.damped_grains = getattr(self, "damped_grains", set())
        self.node_mass = cfg["node_mass"]

    # -- resume: O.save keeps the bodies (with their ids) but not this Python object -------------
    def get_state(self):
        """JSON-able state: body ids, the mesh's triangles (node ids), the permanent forces in
        effect (O.save does not keep them), the lagged dashpots' grains and the recorded frames."""
        perm = {}
        for i in list(self.nodes) + sorted(self.damped_grains):
            perm[str(i)] = list(O.forces.permF(i))
        fr = getattr(self, "frames", {"iter": [], "time": [], "position": []})
        return {"nodes": list(self.nodes), "facets": list(self.facets), "nt": self.nt, "nz": self.nz,
                "rn": self.rn, "tri": self.tri.tolist(), "bottom_ring": list(self.bottom_ring),
                "top_ring": list(self.top_ring), "damped_grains": sorted(self.damped_grains), "perm": perm,
                "frames": {"iter": list(fr["iter"]), "time": list(fr["time"]),
                           "position": [np.asarray(x).tolist() for x in fr["position"]]}}

    @classmethod
    def restore(cls, cfg: dict, state: dict):
        """The Membrane of a loaded checkpoint (O.load): re-attached to its bodies by id, lookups
        rebuilt from the saved triangles exactly as the constructor builds them, permanent nodal
        and dashpot forces re-applied, recorded frames reloaded."""
        self = cls.__new__(cls)
        self.cfg = cfg
        self.nodes, self.facets = list(state["nodes"]), list(state["facets"])
        self.nt, self.nz, self.rn = state["nt"], state["nz"], state["rn"]
        self.bottom_ring, self.top_ring = list(state["bottom_ring"]), list(state["top_ring"])
        self.damped_grains = set(state["damped_grains"])
        self._index([tuple(t) for t in state["tri"]])
        for i, f in state["perm"].items():
            O.forces.setPermF(int(i), Vector3(*f))
        fr = state["frames"]
        self.frames = {"iter": list(fr["iter"]), "time": list(fr["time"]),
                       "position": [np.asarray(x, dtype=float).reshape(-1, 3) for x in fr["position"]]}
        return self

    def _contacts(self):
        """Real grain-facet contacts: (grain id, grain state, facet's node ids, node states, normal, c)."""
        if not hasattr(self, "fcache"):
            B = O.bodies
            self.fcache = []
            for f in self.facets:
                sh = B[f].shape
                nodes = (sh.node1.id, sh.node2.id, sh.node3.id)
                self.fcache.append((f, B[f], nodes, tuple(B[n].state for n in nodes)))
            self.ccache = {}
        mn = 3 * self.node_mass
        withBody = O.interactions.withBody       # real interactions only (Body.intrs() lists the
        for f, fb, nodes, nst in self.fcache:    # ~10x more potential ones, each a Python object)
            for I in withBody(f):
                g = I.id1 if I.id2 == f else I.id2
                gs = O.bodies[g].state
                key = (g, I.phys.kn)
                c = self.ccache.get(key)
                if c is None:
                    mg = gs.mass
                    c = self.ccache[key] = self.c_contact * 2 * math.sqrt(I.phys.kn * mg * mn / (mg + mn))
                yield g, gs, nodes, nst, I.geom.normal, c

    def contact_damping_forces(self):
        """{body id: force} of the grain-membrane dashpots (see contact_damping)."""
        out = {}
        for g, gs, nodes, nst, n, c in self._contacts():
            vf = (nst[0].vel + nst[1].vel + nst[2].vel) / 3.0
            F = n * (-c * (gs.vel - vf).dot(n))
            out[g] = out.get(g, Vector3.Zero) + F
            for nid in nodes:
                out[nid] = out.get(nid, Vector3.Zero) - F / 3.0
        return out

    def contact_damping(self):
        """A normal dashpot on every grain-membrane contact (YADE's linear FrictPhys/CundallStrack
        law has none): F = -c (v_grain - v_facet).n n on the grain, the opposite shared by the
        facet's three nodes; c is ``contact_damping`` of critical for the grain and the three nodes
        on the contact stiffness. Without it the grain-membrane contacts, whose force jumps when a
        contact passes from one facet to the next, pumped energy into the sample as soon as the
        stage-1 drag was removed."""
        addF = O.forces.addF
        for g, gs, nodes, nst, n, c in self._contacts():
            vf = (nst[0].vel + nst[1].vel + nst[2].vel) / 3.0
            F = n * (-c * (gs.vel - vf).dot(n))
            addF(g, F)
            F3 = F / -3.0
            for nid in nodes:
                addF(nid, F3)

    def relax(self):
        """Make the membrane's current shape stress-free (the sheet is fitted on the sample as it
        is): the cohesive node-node links forget their elastic normal, shear and moment state.
        Called at the end of every stage-1 chunk, so that the compaction of the loose packing does
        not leave hoop compression in the membrane."""
        for nid in self.nodes:
            for I in O.bodies[nid].intrs():
                if I.isReal and isinstance(I.phys, CohFrictPhys):
                    I.phys.unp = I.geom.penetrationDepth
                    I.phys.shearForce = Vector3.Zero
                    I.phys.moment_twist = Vector3.Zero
                    I.phys.moment_bending = Vector3.Zero

    def positions(self):
        """(n_nodes, 3) node positions [m]. Indexing a minieigen Vector3 is ~8x faster than iterating
        it (iteration ends on an IndexError per vector): 0.33 vs 2.6 ms for 84 nodes."""
        out = []
        for st in self.states:
            x = st.pos
            out.append((x[0], x[1], x[2]))
        return np.array(out)

    def velocities(self):
        """(n_nodes, 3) node velocities [m/s] (as :meth:`positions`)."""
        out = []
        for st in self.states:
            v = st.vel
            out.append((v[0], v[1], v[2]))
        return np.array(out)

    def apply_pressure(self, p, zb, zt):
        """Permanent nodal forces until the next call: the pressure (:func:`.mesh.pressure_forces`),
        plus the membrane's internal viscosity F_k = -c (v_k - <v_j>_neighbours), which leaves a
        uniform motion of the membrane (the sample bulging) unresisted and damps node oscillations
        on the grain contacts."""
        f = mesh.pressure_forces(self.positions(), self.tri_local, self.nt, self.rn, p, zb, zt)
        if self.c_damp > 0:
            v = self.velocities()
            f -= self.c_damp * (v - self.avg @ v)
        if self.lagged_dashpot:
            # the grain-membrane dashpots as permanent forces, held until the next update
            dd = self.contact_damping_forces()
            for k, nid in enumerate(self.nodes):
                if nid in dd:
                    f[k] += np.array(tuple(dd.pop(nid)))
            for g in self.damped_grains - set(dd):
                O.forces.setPermF(g, Vector3.Zero)
            for g, F in dd.items():
                O.forces.setPermF(g, F)
            self.damped_grains = set(dd)
        for nid, fk in zip(self.nodes, f.tolist()):
            O.forces.setPermF(nid, Vector3(*fk))

    def geometry(self, zb, zt):
        """Volume [m^3] and lateral area [m^2] inside the membrane between the platens
        (:func:`.mesh.inner_geometry`)."""
        return mesh.inner_geometry(self.positions(), self.nt, self.rn, zb, zt)

    def lateral_force(self):
        """Total radial force the membrane exerts on the grains, inward positive [N]."""
        tot = 0.0
        for f in self.facets:
            for I in O.interactions.withBody(f):
                cp = I.geom.contactPoint
                er = Vector3(cp[0], cp[1], 0)
                n = er.norm()
                if n == 0:
                    continue
                F = I.phys.normalForce + I.phys.shearForce      # force on the facet side (id2)
                tot += F.dot(er) / n if I.id2 == f else -F.dot(er) / n
        return tot

    def record(self, final=False):
        """Node positions at the frame times (the same iterations as the Recorder)."""
        if not hasattr(self, "frames"):
            self.frames = {"iter": [], "time": [], "position": []}
        it = O.iter if final else O.iter + 1
        if it in self.frames["iter"]:
            return
        self.frames["iter"].append(it)
        self.frames["time"].append(O.time if final else O.time + O.dt)
        self.frames["position"].append(self.positions())

    def save(self, name):
        save_npz_atomic(name, iter=np.array(self.frames["iter"]), time=np.array(self.frames["time"]),
                        position=np.array(self.frames["position"]), triangles=self.tri_local, node_radius=self.rn)
