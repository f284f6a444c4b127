"""YADE: seed 000 §3.3 gives particle-wall contacts "the visco-elastic part of the contact model
eq. (1)", Hertz + damping: no adhesion, no rolling or twisting resistance (and no Coulomb friction
unless ``scene.wall_friction``). YADE's Ip2_FrictMat_FrictMat_MindlinPhys gives every pair the same
DMT ``gamma``, ``krot`` and ``ktwist``, so the shear-cell deck gives grain-wall pairs their own
functor by material class, from birth (templates/yade/partials/contact_walls.py.j2: grains
PartialSatMat with Ip2_PartialSatMat_PartialSatMat_MindlinPhys, walls FrictMat with
Ip2_FrictMat_FrictMat_MindlinPhys); until then a Python callback zeroed them every step. Before this, the small shear cell's sample
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
{% include "yade/partials/contact_walls.py.j2" %}
mat = particle_mat
if not {{ visco_elastic }}:
    # YADE's own behaviour with one functor for every pair: the walls get the grains' terms
    ip2_wall.gamma, ip2_wall.krot, ip2_wall.ktwist, ip2_wall.eta = ip2.gamma, ip2.krot, ip2.ktwist, ip2.eta
touch = {{ R }} * (1 - 1e-5)
a = O.bodies.append(sphere((0, 0, touch), {{ R }}, material=mat))
b = O.bodies.append(sphere((1e-3, 0, 2e-4), {{ R }}, material=mat))
c = O.bodies.append(sphere((1e-3 + 2 * touch, 0, 2e-4), {{ R }}, material=mat))
w = O.bodies.append(facet([(-1e-4, -1e-4, 0), (1e-4, -1e-4, 0), (0, 1e-4, 0)], material=wall_mat, fixed=True))
if {{ roll }}:
    O.bodies[a].state.angVel = Vector3({{ OMEGA0 }}, 0, 0)
engines = [ForceResetter(), InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Facet_Aabb()]),
           InteractionLoop([Ig2_Sphere_Sphere_ScGeom(), Ig2_Facet_Sphere_ScGeom()], [ip2, ip2_wall], [law2])]
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
    contact = {"restitution": {"target": 1.0, "from": "elastic"}}
    p = {"material": {"E": E, "nu": NU, "rho": RHO}, "friction": math.tan(0.5), "wall": {"nu": NU},
         "scene": {"contact": contact, "wall_adhesion": False, "wall_mu": 0.0, "wall_friction_from": 0}}
    engine = {"contact_restitution_input": 1.0, "wall_young": E, "gamma": gamma, "eta": 0.1, "krot": 1e-9,
              "ktwist": 1e-9}
    text = environment().from_string(SCRIPT).render(
        R=R, E=E, NU=NU, RHO=RHO, OMEGA0=OMEGA0, visco_elastic=visco_elastic, roll=roll,
        g=G_ROLL if roll else 0.0, p=p, engine=engine)
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
    # ... with its own functor the wall contact is never adhesive: no pull-in
    assert off["wall_max"] < 0.05 * delta_eq, (off, delta_eq)


@pytest.mark.engine
@pytest.mark.usefixtures("engines_installed")
def test_wall_contacts_have_no_rolling_resistance(tmp_path):
    on, off = run(tmp_path, False, roll=True), run(tmp_path, True, roll=True)
    # YADE's own behaviour: the rolling spring (limit eta R m g) stops the spin within the run
    assert abs(on["omega_end"]) < 0.5 * OMEGA0, on
    # visco-elastic wall contact: frictionless, no rolling spring, the spin stays
    assert off["omega_end"] == pytest.approx(OMEGA0, rel=1e-3), off


PAIR = """
import json
mats = {}
for cls in (FrictMat, PartialSatMat):
    mats[cls.__name__] = O.materials.append(cls(young={{ E }}, poisson={{ NU }}, density={{ RHO }}, frictionAngle=0.5))
kw = dict(en=MatchMaker(algo="val", val=0.4), es=MatchMaker(algo="val", val=0.4), gamma=1e-3, eta=0.1, krot=1e-9,
          ktwist=1e-9)
law2 = Law2_ScGeom_MindlinPhys_Mindlin(includeAdhesion=True, includeMoment=True)
pairs = {}
for k, name in enumerate(mats):
    # both pairs at the same place, each in its own collision group (they never meet each other)
    a = O.bodies.append(sphere((0, 0, 0), {{ R }}, material=mats[name], mask=1 << k))
    b = O.bodies.append(sphere((2 * {{ R }} + 1e-7, 0, 1e-6), {{ R }}, material=mats[name], mask=1 << k))
    O.bodies[a].state.vel = Vector3(0.05, 0, 0.01)
    O.bodies[a].state.angVel = Vector3(0, 50, 30)
    pairs[name] = (a, b)
O.engines = [ForceResetter(), InsertionSortCollider([Bo1_Sphere_Aabb()]),
             InteractionLoop([Ig2_Sphere_Sphere_ScGeom()],
                             [Ip2_FrictMat_FrictMat_MindlinPhys(**kw), Ip2_PartialSatMat_PartialSatMat_MindlinPhys(**kw)],
                             [law2]),
             NewtonIntegrator(damping=0.0)]
O.dt = 0.02 * PWaveTimeStep()
out = {name: [] for name in pairs}
phys = {}
for k in range(3000):
    O.step()
    for name, (a, b) in pairs.items():
        out[name].append(list(O.bodies[b].state.pos - O.bodies[a].state.pos) + list(O.bodies[b].state.angVel))
        if name not in phys and O.interactions.has(a, b) and O.interactions[a, b].isReal:
            ph = O.interactions[a, b].phys
            phys[name] = {"type": type(ph).__name__, **{key: getattr(ph, key) for key in (
                "kno", "kso", "betan", "betas", "adhesionForce", "kr", "ktw", "maxBendPl", "tangensOfFrictionAngle")}}
print("RESULT " + json.dumps({"out": out, "phys": phys}))
"""


@pytest.mark.engine
@pytest.mark.usefixtures("engines_installed")
def test_grain_functor_is_the_frictmat_hertz_mindlin(tmp_path):
    """The deck's grain-grain functor (Ip2_PartialSatMat_PartialSatMat_MindlinPhys, chosen so that
    grain-wall pairs can get their own) builds exactly the contact of Ip2_FrictMat_FrictMat_MindlinPhys:
    same MindlinPhys numbers, same trajectory of an oblique, spinning, damped, adhesive collision."""
    script = tmp_path / "pair.py"
    script.write_text(environment().from_string(PAIR).render(R=R, E=E, NU=NU, RHO=RHO))
    proc = subprocess.run(["yade", "-n", "-x", str(script)], capture_output=True, text=True, timeout=300)
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    assert line, proc.stdout[-2000:] + proc.stderr[-2000:]
    r = json.loads(line[0][7:])
    assert r["phys"]["FrictMat"]["type"] == "MindlinPhys"
    assert r["phys"]["PartialSatMat"] == r["phys"]["FrictMat"]
    assert r["phys"]["FrictMat"]["betan"] > 0 and r["phys"]["FrictMat"]["adhesionForce"] > 0
    assert r["out"]["PartialSatMat"] == r["out"]["FrictMat"]
