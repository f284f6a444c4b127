"""YADE: seed 000 §3.3 gives particle-wall contacts "the visco-elastic part of the contact model
eq. (1)", Hertz + damping: no adhesion, no rolling or twisting resistance (and no Coulomb friction
unless ``scene.wall_friction``). YADE's Ip2_FrictMat_FrictMat_MindlinPhys gives every pair the same
DMT ``gamma``, ``krot`` and ``ktwist``, so the shear-cell script zeroes them on wall contacts every
step (templates/yade/partials/wall_contacts.py.j2). Before this, the small shear cell's sample
hung on the sidewall (178 adhesive wall contacts; no contact with the upper piston) while
LIGGGHTS' sample reached the upper piston.

Real YADE runs, no gravity unless stated, everything at rest at first:
- a sphere touching a facet and a pair of touching spheres (overlap 1e-5 R). DMT pulls a touching
  pair in past the overlap where Hertz balances adhesion, δ_eq = (F_adh/k)^(2/3), F = k δ^(3/2);
  the wall contact must not pull in;
- a sphere spinning on a frictionless facet under gravity: a rolling spring stops it within the
  run (limit eta R F_n); without one its spin is untouched (the normal force passes through the
  centre)."""
from __future__ import annotations

import json
import math
import subprocess

import pytest

from engines.render import environment

R = 15e-6          # sphere radius [m]
E = 5e6            # Young's modulus [Pa]
NU = 0.3
RHO = 2500.0
F_ADH = 5e-8       # DMT adhesion force at the sphere-sphere r_eff [N]
OMEGA0 = 100.0     # initial spin of the rolling sphere [rad/s]
G_ROLL = 100.0     # gravity of the rolling run [m/s^2]: weight 3.5e-9 N, rolling limit 5e-15 N m

SCRIPT = """
import json, math
mat = O.materials.append(FrictMat(young={{ E }}, poisson={{ NU }}, density={{ RHO }}, frictionAngle=0.5))
wall_mat = O.materials.append(FrictMat(young={{ E }}, poisson={{ NU }}, density={{ RHO }}, frictionAngle=0.0))
ip2 = Ip2_FrictMat_FrictMat_MindlinPhys()
law2 = Law2_ScGeom_MindlinPhys_Mindlin()
{% include "yade/partials/adhesion.py.j2" %}
{% include "yade/partials/rolling.py.j2" %}
{% include "yade/partials/torsion.py.j2" %}
{% include "yade/partials/wall_contacts.py.j2" %}
touch = {{ R }} * (1 - 1e-5)
a = O.bodies.append(sphere((0, 0, touch), {{ R }}, material=mat))
b = O.bodies.append(sphere((1e-3, 0, 2e-4), {{ R }}, material=mat))
c = O.bodies.append(sphere((1e-3 + 2 * touch, 0, 2e-4), {{ R }}, material=mat))
w = O.bodies.append(facet([(-1e-4, -1e-4, 0), (1e-4, -1e-4, 0), (0, 1e-4, 0)], material=wall_mat, fixed=True))
FIRST_WALL_ID = w
if {{ roll }}:
    O.bodies[a].state.angVel = Vector3({{ OMEGA0 }}, 0, 0)
engines = [ForceResetter(), InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Facet_Aabb()]),
           InteractionLoop([Ig2_Sphere_Sphere_ScGeom(), Ig2_Facet_Sphere_ScGeom()], [ip2], [law2])]
if {{ visco_elastic }}:
    engines.append(PyRunner(command="wall_contacts_visco_elastic(FIRST_WALL_ID)", iterPeriod=1))
O.engines = engines + [NewtonIntegrator(damping=0.0, gravity=(0, 0, -{{ g }}))]
O.dt = 0.05 * PWaveTimeStep()
wall_max, pair_max, kno = 0.0, 0.0, None
for k in range(4000):
    O.step()
    if kno is None and O.interactions.has(b, c) and O.interactions[b, c].isReal:
        kno = O.interactions[b, c].phys.kno
    wall_max = max(wall_max, {{ R }} - O.bodies[a].state.pos[2])
    pair_max = max(pair_max, 2 * {{ R }} - (O.bodies[c].state.pos - O.bodies[b].state.pos).norm())
print("RESULT " + json.dumps({"wall_max": wall_max, "pair_max": pair_max, "kno": kno,
                              "omega_end": O.bodies[a].state.angVel[0]}))
"""


def run(tmp_path, visco_elastic: bool, roll: bool = False) -> dict:
    gamma = F_ADH / (4 * math.pi * R / 2)       # DMT F = 4 pi gamma r_eff, r_eff = R/2 for the pair
    contact = {"yade_gamma": gamma, "yade_eta": 0.1, "yade_krot": 1e-9, "yade_ktwist": 1e-9}
    text = environment().from_string(SCRIPT).render(
        R=R, E=E, NU=NU, RHO=RHO, OMEGA0=OMEGA0, visco_elastic=visco_elastic, roll=roll,
        g=G_ROLL if roll else 0.0, p={"scene": {"contact": contact, "wall_adhesion": False}})
    script = tmp_path / f"wall_contacts_{visco_elastic}_{roll}.py"
    script.write_text(text)
    proc = subprocess.run(["yade", "-n", "-x", str(script)], capture_output=True, text=True, timeout=300)
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    assert line, proc.stdout[-2000:] + proc.stderr[-2000:]
    return json.loads(line[0][7:])


@pytest.mark.engine
@pytest.mark.usefixtures("engines_installed")
def test_wall_contacts_lose_adhesion_particle_pairs_keep_it(tmp_path):
    on, off = run(tmp_path, False), run(tmp_path, True)
    delta_eq = (F_ADH / on["kno"]) ** (2 / 3)
    # particle pairs: DMT pulls the touching pair in past its equilibrium overlap (undamped: ~2x)
    for r in (on, off):
        assert r["pair_max"] > 0.9 * delta_eq, (r, delta_eq)
    # YADE's own behaviour: the wall contact is adhesive too (what the switch removes) ...
    assert on["wall_max"] > 0.5 * delta_eq, (on, delta_eq)
    # ... with the switch the wall contact is adhesive for its first step only: no pull-in
    assert off["wall_max"] < 0.05 * delta_eq, (off, delta_eq)


@pytest.mark.engine
@pytest.mark.usefixtures("engines_installed")
def test_wall_contacts_have_no_rolling_resistance(tmp_path):
    on, off = run(tmp_path, False, roll=True), run(tmp_path, True, roll=True)
    # YADE's own behaviour: the rolling spring (limit eta R m g) stops the spin within the run
    assert abs(on["omega_end"]) < 0.5 * OMEGA0, on
    # visco-elastic wall contact: frictionless, no rolling spring, the spin stays
    assert off["omega_end"] == pytest.approx(OMEGA0, rel=1e-3), off
