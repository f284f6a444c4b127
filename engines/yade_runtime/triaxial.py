"""Controller of the YADE triaxial deck: stage 1 isotropic compression (pressure ramp, axial force
servo, membrane correction, convergence on chunk means), stage 2 strain-controlled axial loading;
one ``triax.txt`` row per call; checkpoints with the Python state. All numbers come from
``orchestrator.scenes.triaxial`` (passed as ``cfg``); the laws are in :mod:`.control`."""
from __future__ import annotations

import json
import math
import os
import time

from yade import O, Vector3

from . import control as law
from .recorder import save_checkpoint
from .series import reopen_series


class Controller:
    """Servo in stage 1 (a C++ ServoPIDController labelled "servo", set here), constant platen speed
    in stage 2; writes one triax.txt row per call.

    ``cfg`` keys: pressure [Pa], ramp_steps, chunk, max_chunks, tolerance, v_max [m/s], gain,
    strain_rate [1/s], shear_steps, platen_radius [m] (the platens are fixed spheres of that
    radius), radius0 [m], series_columns, correction_rows, correction_gain, correction_limit,
    drag_free_end, drag_viscosity [Pa s], drag_ramp_steps (0: the drag goes off at once), node_drag, friction,
    iso_friction, particle_mat (material id), restore_friction_early (optional: contact.friction once stage 1
    has converged with the drag, before its ramp), creep_tolerance (optional: the drag stage also needs the
    chunk-mean boundary volume to change by less than this fraction from the last chunk's).
    ``bodies``: bot, top (platen ids), ids, pids (grains), clump_ids (or None).
    ``membrane``: a :class:`.membrane.Membrane`; ``rec``: the :class:`.recorder.Recorder`;
    ``drag``: the stage-1 LinearDragEngine; ``state``: a checkpoint's saved state (resume)."""

    #: what a checkpoint keeps of a Controller (get_state / the constructor's ``state``)
    STATE = ("stage", "v", "chunk_rows", "chunks", "shear_end", "area", "corr", "s3_avg", "ramp_start", "v_prev")

    def __init__(self, cfg, bodies, membrane, rec, drag, state=None):
        self.cfg, self.membrane, self.rec, self.drag = cfg, membrane, rec, drag
        self.bot, self.top = bodies["bot"], bodies["top"]
        self.ids, self.pids = [int(i) for i in bodies["ids"]], [int(i) for i in bodies["pids"]]
        self.clump_ids = bodies.get("clump_ids")
        self.grain_set = set(self.ids)
        self.rows = []
        if state is not None:               # resumed: the state saved with the checkpoint
            for k in self.STATE:
                setattr(self, k, state.get(k))
            self.chunk_rows = [tuple(r) for r in self.chunk_rows]
            self.out = reopen_series("triax.txt", O.iter)
            return
        self.stage = 1
        self.v = 0.0
        self.v_prev = 0.0              # the last stage-1 chunk's mean boundary volume [m^3] (creep test)
        self.chunk_rows = []
        self.chunks = 0
        self.out = open("triax.txt", "w")
        self.out.write("# " + " ".join(cfg["series_columns"]) + "\n")
        self.shear_end = None
        self.area = math.pi * cfg["radius0"] ** 2
        # membrane correction: the nodal pressure is P * corr, corr in [1 - limit, 1 + limit],
        # adjusted slowly so that the lateral stress measured on the grains (sigma3 from the
        # grain-membrane contacts, averaged over ~correction_rows rows) equals P
        self.corr = 1.0
        self.s3_avg = None
        self.ramp_start = None               # iteration at which the drag's linear ramp to zero began

    # -- the loads ------------------------------------------------------------------------------
    def platens(self):
        """Inner faces of the bottom and top platens [m]."""
        rb = self.cfg["platen_radius"]
        return O.bodies[self.bot].state.pos[2] + rb, O.bodies[self.top].state.pos[2] - rb

    def pressure_now(self):
        """Nodal pressure [Pa]: p ramped, times the membrane correction."""
        return self.cfg["pressure"] * law.ramp(O.iter, self.cfg["ramp_steps"]) * self.corr

    def apply_pressure(self):
        """The boundary's forces for the next ``update_every`` steps, the servo's settings and the
        drag coefficient during its ramp."""
        self.membrane.apply_pressure(self.pressure_now(), *self.platens())
        self.update_servo()
        self.update_drag()

    def update_drag(self):
        """During the drag's ramp (stage 1 has converged with it): nu = nu0 (1 - (it - start)/ramp_steps),
        refreshed with the boundary forces; the drag goes off at the chunk test that ends the ramp."""
        if self.ramp_start is None or not self.grain_drag_on():
            return
        self.drag.nu = self.cfg["drag_viscosity"] * law.drag_ramp(O.iter, self.ramp_start, self.cfg["drag_ramp_steps"])

    def set_velocity(self, v):
        O.bodies[self.top].state.vel = Vector3(0, 0, v)

    def servo_engine(self):
        """The stage-1 servo, a ServoPIDController on the top platen (label "servo"; after O.load too)."""
        return next(e for e in O.engines if e.label == "servo")

    def update_servo(self):
        """Stage 1: the servo's target force and gains from the ramped pressure and the current
        cross-section (:func:`.control.servo_pid_settings`): v = -v_max clip(g e + g_i S, -1, 1) with
        e = 1 - F_top/(p A) and S the sum of e (ServoPIDController's iTerm), run in C++ every
        ``servo_every`` steps. The sum takes only errors below ``integral_window`` (conditional
        integration, decided here at each refresh: kI = 0 while |e| is larger)."""
        if self.stage != 1:
            return
        c = self.cfg
        s = self.servo_engine()
        p_now = c["pressure"] * law.ramp(O.iter, c["ramp_steps"])
        s.target, s.kP, s.kI = law.servo_pid_settings(p_now, self.area, c["gain"], c["v_max"], c["pressure"],
                                                      c["gain_integral"] * c["servo_every"])
        if abs(law.force_error(O.forces.f(self.top)[2], s.target)) >= c["integral_window"]:
            s.kI = 0.0

    # -- stage switches -------------------------------------------------------------------------
    def grain_drag_on(self):
        """Whether the stage-1 Stokes drag still acts on the grains (LinearDragEngine state, saved with O.save)."""
        d = self.drag
        return not d.dead and len(d.ids) > 0 and d.ids[0] in self.grain_set

    def drop_grain_drag(self):
        """The grains' drag ends (idempotent). With ``node_drag`` the membrane nodes keep it:
        numerical damping of the sheet's own motion only."""
        if self.cfg["node_drag"]:
            self.drag.ids = list(self.membrane.nodes)
            self.drag.nu = self.cfg["drag_viscosity"]
            self.drag.dead = False
        else:
            self.drag.dead = True

    def restore_friction(self):
        """End of stage 1: the grains' material and every existing grain-grain contact get
        contact.friction (MindlinPhys.tangensOfFrictionAngle; grain-platen and grain-membrane
        contacts keep theirs). Nothing to do when stage 1 used the same friction."""
        mu = self.cfg["friction"]
        if self.cfg["iso_friction"] == mu:
            return
        O.materials[self.cfg["particle_mat"]].frictionAngle = math.atan(mu)
        n = 0
        gs = self.grain_set
        for I in O.interactions:
            if I.isReal and I.id1 in gs and I.id2 in gs:
                I.phys.tangensOfFrictionAngle = mu
                n += 1
        print("FRICTION restored to %g on %d grain-grain contacts" % (mu, n), flush=True)

    # -- the series row and the stage logic (every series_every steps) ---------------------------
    def __call__(self, final=False):
        c = self.cfg
        P = c["pressure"]
        it, t = (O.iter, O.time) if final else (O.iter + 1, O.time + O.dt)
        zb, zt = self.platens()
        f_top = O.forces.f(self.top)[2]          # grains push the top platen up: > 0 in compression
        f_bot = -O.forces.f(self.bot)[2]
        geo = self.membrane.geometry(zb, zt)
        f_lat = self.membrane.lateral_force()
        H = zt - zb
        s1 = f_top / (geo["volume"] / H)
        s3 = f_lat / geo["area"]
        p_now = self.pressure_now()
        if O.iter >= c["ramp_steps"] and s3 > 0:
            self.corr, self.s3_avg = law.membrane_correction(self.corr, self.s3_avg, s3, P, c["correction_rows"],
                                                             c["correction_gain"], c["correction_limit"])
        # the row describes the state at the end of this iteration
        self.out.write("%d %.17g %d %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g\n" % (
            it, t, self.stage, zb, zt, f_bot, f_top, f_lat, geo["area"], geo["volume"], p_now))
        if self.stage == 1:
            self.chunk_rows.append((s1, s3, geo["volume"]))
            self.area = geo["volume"] / H
            # this runner fires at O.iter = 0 mod series_every, and the chunk is a multiple of it
            if O.iter % c["chunk"] == 0 and O.iter >= c["ramp_steps"]:
                self._end_chunk(H)
            elif O.iter % c["chunk"] == 0:
                self.chunk_rows = []
                self.membrane.relax()
        if self.stage == 1:
            self.v = self.servo_engine().curVel          # the servo moves the platen in stage 1
            self.update_servo()
        else:
            self.set_velocity(self.v)
        self.out.flush()

    def _end_chunk(self, H):
        c = self.cfg
        P = c["pressure"]
        rows = self.chunk_rows
        m1 = sum(r[0] for r in rows) / len(rows)
        m3 = sum(r[1] for r in rows) / len(rows)
        self.chunk_rows = []
        self.membrane.relax()
        if self.ramp_start is not None and self.grain_drag_on():
            # the drag's ramp (as LIGGGHTS' dragramp run: no chunk test, not counted in max_chunks)
            if O.iter - self.ramp_start >= c["drag_ramp_steps"]:
                self.drop_grain_drag()
                print("ISO drag off at step %d, continuing" % O.iter, flush=True)
            else:
                print("ISO drag ramp: sigma1/p = %.4f sigma3/p = %.4f nu/nu0 = %.3f" % (
                    m1 / P, m3 / P, self.drag.nu / c["drag_viscosity"]), flush=True)
            return
        self.chunks += 1
        print("ISO chunk %d: sigma1/p = %.4f sigma3/p = %.4f" % (self.chunks, m1 / P, m3 / P), flush=True)
        conv = law.iso_converged(m1, m3, P, c["tolerance"])
        if c.get("creep_tolerance"):
            # the volume-creep test of the drag stage (scene.isotropic.creep_tolerance; as LIGGGHTS' deck)
            mv = sum(r[2] for r in rows) / len(rows)
            v_prev = self.v_prev or 0.0
            still = law.creep_settled(mv, v_prev, c["creep_tolerance"])
            print("ISO creep: chunk-mean volume change %.15g (tolerance %g)" % ((mv - v_prev) / v_prev, c["creep_tolerance"])
                  if v_prev > 0 else "ISO creep: chunk-mean volume change n/a (first chunk)", flush=True)
            self.v_prev = mv
            if conv and self.grain_drag_on() and not still:
                print("ISO converged with drag, still creeping: the drag stays on", flush=True)
                conv = False
        if c["drag_free_end"] and conv and self.grain_drag_on():
            # converged with the drag: switch it off (or ramp it to zero) and converge again without it
            conv = False
            if c.get("restore_friction_early"):
                # isotropic.restore_friction: before_drag_ramp (the ramp then acts on a frictional packing)
                self.restore_friction()
            if c["drag_ramp_steps"] > 0:
                self.ramp_start = O.iter
                print("ISO converged with drag: drag ramped to zero over %d steps from step %d"
                      % (c["drag_ramp_steps"], O.iter), flush=True)
            else:
                self.drop_grain_drag()
                print("ISO converged with drag: drag off, continuing", flush=True)
        if conv or self.chunks >= c["max_chunks"]:
            if self.chunks >= c["max_chunks"]:
                print("ISO did not converge within %d chunks" % c["max_chunks"], flush=True)
            self.stage = 2
            self.servo_engine().dead = True
            self.restore_friction()
            self.drop_grain_drag()
            self.v = -c["strain_rate"] * H
            self.shear_end = O.iter + 1 + c["shear_steps"]
            O.stopAtIter = min(O.stopAtIter, self.shear_end)   # a checkpoint's stop may come first
            print("SHEAR start at iter %d, H0 = %.9g m, v = %.6g m/s" % (O.iter + 1, H, self.v), flush=True)
            self.announce_end()

    def announce_end(self):
        """Print the step the run ends at once it is known (in stage 2: the loading's last step), the
        deck line the progress lines count toward (engines.base.RUN_ENDS); at the stage switch and
        on each resume in stage 2."""
        if self.stage == 2:
            print("RUN ENDS at step %d" % self.shear_end, flush=True)

    def stop_iter(self):
        """The run ends after the loading steps (set at the stage switch), or after the longest stage 1."""
        c = self.cfg
        if self.stage == 2:
            return self.shear_end
        return c["ramp_steps"] + c["chunk"] * (c["max_chunks"] + 1) + c["drag_ramp_steps"] + c["shear_steps"]

    # -- resume ---------------------------------------------------------------------------------
    def get_state(self):
        return {k: getattr(self, k) for k in self.STATE}

    def checkpoint(self):
        """Flush frames, then save the simulation for resume with the Python state (controller,
        membrane with its recorded frames and permanent forces, body ids) as JSON in O.tags: one
        file, one atomic rename, so the state always belongs to the checkpoint it is in
        (docs/triaxial.md, Resume). Called between O.run calls (an iteration boundary: positions,
        O.iter and O.time describe one instant); the script then loads the file back."""
        self.rec.flush()
        t0 = time.time()
        state = {"iter": O.iter, "bot": self.bot, "top": self.top, "ids": self.ids, "pids": self.pids,
                 "membrane": self.membrane.get_state(), "control": self.get_state()}
        if self.clump_ids is not None:
            state["clump_ids"] = [int(i) for i in self.clump_ids]
        O.tags["orch_triaxial"] = json.dumps(state)
        save_checkpoint()
        print("CHECKPOINT iter %d %.3f s" % (O.iter, time.time() - t0), flush=True)


def load_state():
    """The Python state saved in a loaded checkpoint (O.load), checked against O.iter."""
    state = json.loads(O.tags["orch_triaxial"])
    if state["iter"] != O.iter:
        raise SystemExit("checkpoint.yade.gz: its saved state is for iteration %d, the simulation is at %d"
                         % (state["iter"], O.iter))
    return state


def clump_report(name, clump_ids, pid_of):
    """Clump body id, mass [kg], principal inertia [kg m^2] and its members' particle ids, one row per clump."""
    with open(name + ".partial", "w") as f:
        for c in clump_ids:
            st = O.bodies[c].state
            mem = sorted(pid_of[m] for m in O.bodies[c].shape.members.keys())
            f.write("%d %.17g %.17g %.17g %.17g %s\n" % (c, st.mass, st.inertia[0], st.inertia[1], st.inertia[2],
                                                        " ".join(str(m) for m in mem)))
    os.replace(name + ".partial", name)
