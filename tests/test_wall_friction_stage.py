"""``scene.wall_friction: shear``: frictionless walls while the shear cell's sample is compressed,
the particles' Coulomb μ at the walls from the start of the shear stage (docs/validation.md: with
friction from the start, the sidewall carried part of the medium case's load and the servo settled
22 % short of it).

- engine-free: the derived first step and the three engines' decks (frictionless before the shear
  stage, frictional from it on, in every segment a resumed run can start from);
- LIGGGHTS (and LAMMPS, slow tier: the deck test covers its text): the smoke cell run both ways; up to the shear stage the wall series are
  those of the frictionless run, bit for bit, and in the shear stage the turning sidewall carries a
  torque it cannot carry without friction (only its facets' or regions' non-radial normals would);
- YADE: a sphere sliding on a frictionless facet under gravity keeps its speed; once the walls are
  made frictional (the deck's ``walls_frictional``) it decelerates at μ g (Coulomb sliding), and a
  contact made afterwards gets μ too.
"""
from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

from engines import get_engine
from engines.render import environment
from orchestrator.case import CaseError, load_case
from orchestrator.derive import derive
from orchestrator.runner import prepare, run_case

REPO = Path(__file__).resolve().parents[1]
SMOKE = REPO / "cases" / "shear_cell_smoke.yaml"
MU = 0.58                                   # the smoke case's contact.friction


def _case(mode, **scene):
    return load_case(SMOKE, overrides={"scene": {"wall_friction": mode, **scene}})


def test_wall_friction_from_is_the_shear_stage_start():
    for mode, mu, first in ((False, 0.0, 0), (True, MU, 0), ("shear", MU, None)):
        sc = derive(_case(mode))["scene"]
        assert sc["wall_mu"] == mu
        assert sc["wall_friction_from"] == (sc["stages"]["shear"][0] if first is None else first)


def test_bad_wall_friction_is_refused():
    with pytest.raises(CaseError, match="wall_friction"):
        _case("compress")


def _deck(case, engine, tmp_path) -> str:
    params, _ = prepare(case, engine, tmp_path / engine)
    return get_engine(engine).render(case, params, tmp_path / engine, resume=None).read_text()


def test_liggghts_deck_redefines_the_friction_matrix_at_the_shear_stage(tmp_path):
    case = _case("shear", final_angle="20 deg")          # a shear stage several restart segments long
    s2 = derive(case)["scene"]["stages"]["shear"][0]
    deck = _deck(case, "liggghts", tmp_path)
    lines = deck.splitlines()
    mu_lines = [i for i, ln in enumerate(lines) if ln.startswith("fix m_mu")]
    shear = next(i for i, ln in enumerate(lines) if ln.startswith("# --- stage shear"))
    for i in mu_lines:
        walls = lines[i].split()[-3:]
        # segment heads before the shear stage: frictionless; the redefinition after its start
        want = str(MU) if i > shear else "0.0"
        assert walls == [want] * 3, (i, lines[i])
    assert any(i > shear for i in mu_lines)
    # a segment that starts inside the shear stage (a resumed run) has frictional walls in its head
    segs = [int(m) for m in re.findall(r"read_restart +restart/state\.(\d+)\.restart", deck)]
    assert any(s > s2 for s in segs)


def test_lammps_deck_replaces_the_wall_fixes_at_the_shear_stage(tmp_path):
    deck = _deck(_case("shear"), "lammps", tmp_path)
    head, _, tail = deck.partition("# --- stage shear")
    wall_fixes = [ln for ln in head.splitlines() if ln.startswith("fix") and "wall/gran/region" in ln]
    assert wall_fixes and all("linear_nohistory" in ln for ln in wall_fixes)
    after = [ln for ln in tail.splitlines() if ln.startswith("fix") and "wall/gran/region" in ln]
    assert after and all("mindlin" in ln and f" {MU} damping" in ln for ln in after)


def test_yade_script_switches_the_walls_once(tmp_path):
    script = _deck(_case("shear"), "yade", tmp_path)
    assert "frictionAngle=math.atan(0.0), label=\"walls\"" in script
    assert script.count("walls_frictional(LOWER + UPPER + CYL, 0.58)") == 1
    assert "walls_frictional" not in _deck(_case(True), "yade", tmp_path / "true")


def _wall_series(run_dir) -> np.ndarray:
    from engines.liggghts.segments import wall_rows
    return wall_rows(run_dir)


@pytest.mark.engine
@pytest.mark.usefixtures("engines_installed")
@pytest.mark.parametrize("engine", ["liggghts", pytest.param("lammps", marks=pytest.mark.slow)])
def test_sidewall_torque_appears_with_the_shear_stage(engine, tmp_path):
    """``wall_friction: shear``: the walls are frictionless until the shear stage and frictional
    from it on. The sidewall (a mesh here: LIGGGHTS takes a sidewall that is frictionless throughout
    as its analytic cylinder, whose torque column is 0, so a frictionless run is no reference for
    this mesh) carries before the shear stage only the leak of its flat facets' normal forces about
    the axis, and in it a friction torque over 10x that (3.9e-11 N m after 2°, 3 % of the upper
    piston's, on LIGGGHTS, 29 Nov 2026)."""
    # 2 degrees of shear are enough to load the sidewall (the smoke case turns 4)
    short = {"final_angle": "2 deg", "frame_angles": ["1 deg", "2 deg"]}
    run = run_case(_case("shear", **short), engine, runs_root=tmp_path, analyze=False, progress=False)
    s2 = derive(_case("shear", **short))["scene"]["stages"]["shear"][0]
    on = _wall_series(run.run_dir)
    # columns: step z_lower Fx Fy Fz Tz_lower Tz_upper Tz_cylinder
    before = (on[:, 0] <= s2) & (on[:, 0] > 0.8 * s2)          # the end of compression, at rest
    t_before, t_shear = abs(on[before, 7].mean()), abs(on[on[:, 0] > s2, 7].mean())
    assert t_shear > 10 * t_before, (t_shear, t_before)


YADE_SLIDE = """
import json, math
{% include "yade/partials/contact_walls.py.j2" %}
{% include "yade/partials/wall_friction_on.py.j2" %}
R, G, V0 = {{ R }}, {{ G }}, {{ V0 }}
w = O.bodies.append(facet([(-1, -1e-3, 0), (1, -1e-3, 0), (0, 1e-3, 0)], material=wall_mat, fixed=True))
a = O.bodies.append(sphere((0, 0, R * (1 - 1e-4)), R, material=particle_mat))
O.bodies[a].state.vel = Vector3(V0, 0, 0)
O.engines = [ForceResetter(), InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Facet_Aabb()]),
             InteractionLoop([Ig2_Facet_Sphere_ScGeom()], [ip2, ip2_wall], [law2]),
             NewtonIntegrator(damping=0.0, gravity=(0, 0, -G))]
O.dt = 0.05 * PWaveTimeStep()
n = int({{ T }} / O.dt)
def speeds():
    out = []
    for k in range(n):
        O.step()
        out.append((O.time, O.bodies[a].state.vel[0]))
    return out
before = speeds()
walls_frictional([w], {{ MU }})
after = speeds()
b = O.bodies.append(sphere((0.5, 0, R * (1 - 1e-4)), R, material=particle_mat))
O.step()
new_mu = O.interactions[w, b].phys.tangensOfFrictionAngle
print("RESULT " + json.dumps({"before": before, "after": after, "new_mu": new_mu,
                              "wall_angle": O.materials[wall_mat].frictionAngle}))
"""


@pytest.mark.engine
@pytest.mark.usefixtures("engines_installed")
def test_yade_walls_frictional_gives_coulomb_sliding(tmp_path):
    R, E, G, V0, T = 15e-6, 5e6, 100.0, 0.1, 2e-4
    p = {"material": {"E": E, "nu": 0.3, "rho": 2500.0}, "friction": MU, "wall": {"nu": 0.3},
         "tangential_damping": True,
         "scene": {"contact": {"restitution": {"target": 0.5, "from": "test"}}, "wall_adhesion": False,
                   "wall_mu": MU, "wall_friction_from": 1}}
    engine = {"contact_restitution_input": 0.5, "wall_young": E, "gamma": None, "eta": None, "ktwist": None}
    text = environment().from_string(YADE_SLIDE).render(R=R, G=G, V0=V0, T=T, MU=MU, p=p, engine=engine)
    script = tmp_path / "slide.py"
    script.write_text(text)
    proc = subprocess.run(["yade", "-n", "-x", str(script)], capture_output=True, text=True, timeout=300)
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    assert line, proc.stdout[-2000:] + proc.stderr[-2000:]
    r = json.loads(line[0][7:])
    before, after = np.array(r["before"]), np.array(r["after"])
    # frictionless facet: the sliding speed is untouched
    assert np.allclose(before[:, 1], V0, rtol=1e-9, atol=0)
    # Coulomb sliding: dv/dt = -mu g while the sphere slides (it would roll at 5/7 V0, after 0.95 ms)
    slope = np.polyfit(after[:, 0], after[:, 1], 1)[0]
    assert slope == pytest.approx(-MU * G, rel=0.03)
    assert after[-1, 1] > 5 / 7 * V0
    assert r["new_mu"] == pytest.approx(MU, rel=1e-12)
    assert np.tan(r["wall_angle"]) == pytest.approx(MU, rel=1e-12)


def test_servo_slows_for_frictional_walls_in_shear(tmp_path):
    """With Coulomb friction at the walls the grains on the piston's axial faces add their tangential
    dashpots to the servo's loop (the medium case's shear stage swung every step at 1.48 x its target
    load, docs/validation.md): the shear stage's speed limit keeps the frictional gain at 0.7."""
    from orchestrator.contact_law import SERVO_DASHPOT_GAIN
    from orchestrator.scenes.shear_cell import frictional_wall_gain_factor, servo_dashpot_gain
    case = load_case(REPO / "cases" / "shear_cell_medium_wall_friction.yaml")
    sv = derive(case)["scene"]["servo"]
    frictionless = load_case(REPO / "cases" / "shear_cell_medium.yaml")
    assert sv["v_max"] == derive(frictionless)["scene"]["servo"]["v_max"]       # compression unchanged
    factor = frictional_wall_gain_factor(case)
    assert factor > 1
    gain = servo_dashpot_gain(case, sv["v_max_shear"], case.scene.servo_gain) * factor
    assert gain == pytest.approx(SERVO_DASHPOT_GAIN, rel=1e-9)
    assert sv["v_max_shear"] < sv["v_max"]
    smoke = _case("shear")
    assert "fix_modify lower vel_max" in _deck(smoke, "liggghts", tmp_path)
    assert "servo.maxVelocity = " in _deck(smoke, "yade", tmp_path / "y")
    assert "*(step>" in [ln for ln in _deck(smoke, "lammps", tmp_path / "m").splitlines()
                         if ln.startswith("variable        vz")][0]
