"""YADE: seed 000 §3.3 asks for adhesion between particles but none at particle-wall contacts.
YADE's DMT ``gamma`` is one value for all pairs, so the shear-cell script zeroes the adhesion of
wall contacts every step (templates/yade/partials/adhesion.py.j2 ``wall_adhesion_off``). Before
this, the small shear cell's sample hung on the sidewall (178 adhesive wall contacts, no contact
with the upper piston) while LIGGGHTS' sample reached the upper piston.

The run: a sphere just touching a facet and a pair of spheres just touching each other (overlap
1e-5 R), no
gravity, at rest. DMT pulls a touching pair in to the overlap where the Hertz force balances the
adhesion, δ_eq = (F_adh/k)^(2/3) with F = k δ^(3/2) (YADE Mindlin's kno); without adhesion the
wall contact carries no force and the sphere stays put."""
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

SCRIPT = """
import json, math
mat = O.materials.append(FrictMat(young={{ E }}, poisson={{ NU }}, density={{ RHO }}, frictionAngle=0.5))
ip2 = Ip2_FrictMat_FrictMat_MindlinPhys()
law2 = Law2_ScGeom_MindlinPhys_Mindlin()
{% include "yade/partials/adhesion.py.j2" %}
a = O.bodies.append(sphere((0, 0, {{ R }} * (1 - 1e-5)), {{ R }}, material=mat))   # touching (overlap 1e-5 R)
b = O.bodies.append(sphere((1e-3, 0, 2e-4), {{ R }}, material=mat))
c = O.bodies.append(sphere((1e-3 + 2 * {{ R }} * (1 - 1e-5), 0, 2e-4), {{ R }}, material=mat))
w = O.bodies.append(facet([(-1e-4, -1e-4, 0), (1e-4, -1e-4, 0), (0, 1e-4, 0)], material=mat, fixed=True))
FIRST_WALL_ID = w
engines = [ForceResetter(), InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Facet_Aabb()]),
           InteractionLoop([Ig2_Sphere_Sphere_ScGeom(), Ig2_Facet_Sphere_ScGeom()], [ip2], [law2])]
if {{ off }}:
    engines.append(PyRunner(command="wall_adhesion_off(FIRST_WALL_ID)", iterPeriod=1))
O.engines = engines + [NewtonIntegrator(damping=0.0, gravity=(0, 0, 0))]
O.dt = 0.05 * PWaveTimeStep()
wall_max, pair_max, kno = 0.0, 0.0, None
for k in range(4000):
    O.step()
    if kno is None and O.interactions.has(b, c) and O.interactions[b, c].isReal:
        kno = O.interactions[b, c].phys.kno
    wall_max = max(wall_max, {{ R }} - O.bodies[a].state.pos[2])
    pair_max = max(pair_max, 2 * {{ R }} - (O.bodies[c].state.pos - O.bodies[b].state.pos).norm())
print("RESULT " + json.dumps({"wall_max": wall_max, "pair_max": pair_max, "kno": kno}))
"""


def run(tmp_path, off: bool) -> dict:
    gamma = F_ADH / (4 * math.pi * R / 2)       # DMT F = 4 pi gamma r_eff, r_eff = R/2 for the pair
    text = environment().from_string(SCRIPT).render(
        R=R, E=E, NU=NU, RHO=RHO, off=off, p={"scene": {"contact": {"yade_gamma": gamma}}})
    script = tmp_path / f"wall_adhesion_{off}.py"
    script.write_text(text)
    proc = subprocess.run(["yade", "-n", "-x", str(script)], capture_output=True, text=True, timeout=300)
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    assert line, proc.stdout[-2000:] + proc.stderr[-2000:]
    return json.loads(line[0][7:])


@pytest.mark.usefixtures("engines_installed")
def test_wall_contacts_lose_adhesion_particle_pairs_keep_it(tmp_path):
    on, off = run(tmp_path, False), run(tmp_path, True)
    delta_eq = (F_ADH / on["kno"]) ** (2 / 3)
    # particle pairs: DMT pulls the touching pair in past its equilibrium overlap (undamped: ~2x)
    for r in (on, off):
        assert r["pair_max"] > 0.9 * delta_eq, (r, delta_eq)
    # without the switch the wall contact is adhesive too (the behaviour the switch removes) ...
    assert on["wall_max"] > 0.5 * delta_eq, (on, delta_eq)
    # ... with it the wall contact is adhesive for its first step only: no pull-in
    assert off["wall_max"] < 0.05 * delta_eq, (off, delta_eq)
