"""Binary impacts for contact-level verification (Chung & Ooi 2011, Granular Matter 13, 643-656).

``target: sphere`` — two identical spheres approach each other head-on with relative speed
``speed`` (tests 1 and 3 of Chung & Ooi). ``target: plane`` — one sphere per entry of ``angles``
hits a rigid plane z = 0 with speed ``speed`` at incidence ``angle`` measured from the plane's
normal (tests 2, 3 and 4). Spheres are spaced far enough apart never to touch each other, so
one engine run covers all angles.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field, field_validator

from ..case import Strict, positive
from ..derive import hertz_contact_time
from ..params import Params, ScenePart, StabilityInputs, opt
from ..units import Angle, Length, Velocity
from . import base



class Scene(Strict):
    kind: Literal["impact"]
    target: Literal["sphere", "plane"]
    radius: Length
    speed: Velocity
    angles: list[Angle] = Field(default_factory=lambda: [0.0])
    initial_gap: float = Field(0.02, gt=0, le=1, description="initial surface gap / radius")
    after_contact: float = Field(1.0, gt=0, description="simulated time after contact ends, in contact times")
    frames_per_contact: int = Field(400, ge=1, description="frames written per Hertz contact time")

    _pos = positive("radius", "speed")

    @field_validator("angles")
    @classmethod
    def _angles(cls, v):
        for a in v:
            if not 0 <= a < np.pi / 2:
                raise ValueError(f"incidence angle {np.degrees(a):g} deg must lie in [0, 90) deg")
        return v


def required_features(case) -> list[str]:
    feats = ["hertz", "restitution_damping"]
    if case.contact.friction > 0 and any(a > 0 for a in case.scene.angles):
        feats.append("sliding_friction")
    if case.scene.target == "plane":
        feats.append("plane_wall")
    return feats


def max_velocity(case) -> float:
    return case.scene.speed


@dataclass(frozen=True)
class ImpactParams(ScenePart):
    """The impact scene's numbers (SI)."""
    n: int                  #: spheres [-]
    ids: tuple              #: their ids, 1..n
    radius: float           #: sphere radius [m]
    mass: float             #: sphere mass [kg]
    position: tuple         #: (n, 3) initial centres [m]
    velocity: tuple         #: (n, 3) initial velocities [m/s]
    steps: int              #: steps of the run [-]
    dump_every: int         #: steps between frames [-]
    duration: float         #: simulated time [s]
    box_lo: tuple           #: simulation box, lower corner [m]
    box_hi: tuple           #: upper corner [m]
    angles: tuple           #: incidence angles from the plane's normal [rad]
    target: str             #: "sphere" or "plane"
    contact_points: tuple | None = opt("plane: (x, y) [m] where each sphere first touches z = 0")


def derive(case, common: Params) -> ImpactParams:
    """Initial positions and velocities [m, m/s], run length [s], output interval [steps]."""
    s = case.scene
    R = s.radius
    gap = s.initial_gap * R
    rho = case.material.density
    mass = rho * 4.0 / 3.0 * np.pi * R ** 3
    if s.target == "sphere":
        # particle 1 at -x, particle 2 at +x, each moving towards the other with speed/2
        pos = np.array([[-(R + gap / 2), 0.0, 0.0], [R + gap / 2, 0.0, 0.0]])
        vel = np.array([[s.speed / 2, 0.0, 0.0], [-s.speed / 2, 0.0, 0.0]])
        approach = gap / s.speed
        m_eff, R_eff, E_eff, v_n = mass / 2, R / 2, common.E_eff_pp, s.speed
    else:
        n = len(s.angles)
        # 20 R apart: an engine may stand a large sphere below each sphere in for the plane
        # (engines/yade/numbers.py), whose surface must stay far below the neighbours
        y = (np.arange(n) - (n - 1) / 2) * 20 * R
        # each sphere travels tangentially while approaching: spread along x too
        pos = np.stack([np.zeros(n), y, np.full(n, R + gap)], axis=1)
        vel = np.stack([s.speed * np.sin(s.angles), np.zeros(n), -s.speed * np.cos(s.angles)], axis=1)
        vn = s.speed * np.cos(np.asarray(s.angles))
        approach = gap / vn.min()
        m_eff, R_eff, E_eff, v_n = mass, R, common.E_eff_pw, float(vn.min())
    tc = hertz_contact_time(m_eff, R_eff, E_eff, v_n)
    duration = approach + tc * (1.0 + s.after_contact)
    dt = common.dt
    steps = int(np.ceil(duration / dt))
    every = max(1, int(tc / dt / s.frames_per_contact))
    contact_points = None
    if s.target == "plane":
        # where each sphere first touches the plane (it travels gap / v_n before contact)
        t_hit = gap / (s.speed * np.cos(np.asarray(s.angles)))
        cx = pos[:, 0] + vel[:, 0] * t_hit
        contact_points = [[float(x), float(y_)] for x, y_ in zip(cx, pos[:, 1])]
    # bounding box for the engines' domain (periodic nowhere)
    lo = pos.min(axis=0) - 3 * R - np.abs(vel).max(axis=0) * duration
    hi = pos.max(axis=0) + 3 * R + np.abs(vel).max(axis=0) * duration
    if s.target == "plane":
        lo[2] = -2 * R
    return ImpactParams(
        n=len(pos), ids=list(range(1, len(pos) + 1)), radius=R, mass=mass,
        position=pos.tolist(), velocity=vel.tolist(), steps=steps, dump_every=every,
        duration=duration, box_lo=lo.tolist(), box_hi=hi.tolist(),
        angles=list(map(float, s.angles)), target=s.target, contact_points=contact_points)


class ImpactScene(base.Scene):
    """Binary impacts (module docstring). Controls: none; no wall series."""
    kind = "impact"
    section = Scene
    honoured = frozenset({"output.contacts", "output.stress", "initial_packing"})
    controls = {}
    count_field = None          # one sphere per angle: no grain count to ladder

    required_features = staticmethod(required_features)
    derive = staticmethod(derive)
    max_velocity = staticmethod(max_velocity)

    def stability_inputs(self, case, params):
        sc = params.scene
        return StabilityInputs(n_particles=sc.n, total_steps=sc.steps, box_lo=sc.box_lo, box_hi=sc.box_hi,
                               height=sc.box_hi[2] - sc.box_lo[2])
