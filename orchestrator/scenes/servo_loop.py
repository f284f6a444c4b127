"""The triaxial's stage-1 force servo as a discrete loop: its stability and its gains.

Both engines run the same law on the top platen, every ``n`` steps (docs/triaxial.md, Servo):

    v_{k+1} = -v_max clip(g e_k + g_i S_k, -1, 1),   e_k = 1 - F_k / (p A),   S_k = e_0 + ... + e_k

(relative force error ``e``, its sum ``S`` from the end of the pressure ramp on; ``g_i`` per update).
The velocity the servo sets after step k moves the platen from step k+1 on, and the force of a
step is computed before the platen moves in it. Linearised about F = pA, the platen contacts act
as a spring K (the force's change per platen displacement) and a dashpot C (its change per platen
speed, the contacts' viscous damping, felt in the same step):

    e_{k+1} = (1 - b - b_i) e_k + (b - a) e_{k-1} - a_i S_{k-1}

with a = g α, b = g β, a_i = g_i α, b_i = g_i β, α = v_max n dt K / (pA) and β = v_max C / (pA).
With the spring alone (β = 0) the loop is stable for a < 1 (λ² - λ + a = 0: the one-update delay
halves the undelayed limit a < 2); the dashpot's same-step feedback makes the error flip sign every
update (an even/odd oscillation) once b > 1 + a/2 (Jury's test). That
oscillation is what the 4 000-clump YADE sample at the old default g = 0.8/α showed (docs/triaxial.md):
there a = 1.06 and b = 1.66, from K = 1.33x and C = 0.58x this module's estimates as measured at the
platen (``benchmarks/servo_probe.py``).

The integral term removes the steady error a creeping sample leaves under a proportional law
(e = v_creep / (v_max g)): a sample that compacts at the platen's pace otherwise reads σ1 < p for
as long as it creeps, and the convergence test waits for the creep to stop.

Arrays and numbers in, numbers out; no engine here."""
from __future__ import annotations

import math

import numpy as np

#: corners of the (K, C) range the default gain must be stable over, as multiples of the estimates
#: of :func:`platen_stiffness` and :func:`platen_damping`: measured 1.33 and 0.58 on the 4 000-clump
#: sample (289 member contacts on the platen, benchmarks/servo_probe.py), sphere samples touch it with fewer grains
ENVELOPE = ((0.5, 0.3), (0.5, 1.5), (2.0, 0.3), (2.0, 1.5), (1.0, 1.0))
#: the default gain is this fraction of the envelope's stability limit (a gain margin of 2)
GAIN_MARGIN = 0.5
#: the integral's time constant, as a fraction of the stage-1 chunk whose mean the convergence test reads
INTEGRAL_FRACTION_OF_CHUNK = 0.1


def wall_contact(p: float, d50: float, E_pw: float) -> tuple[float, float]:
    """(overlap δ [m], tangent stiffness k [N/m]) of one d50 grain on a flat wall carrying
    F = p d50² (Hertz): δ = (3F / (4 E* sqrt R))^(2/3), k = 2 E* sqrt(R δ), E* grain-wall. The
    platen carries about one such grain per d50² of its area; the membrane's contact stiffness is
    set from the same k (orchestrator.scenes.triaxial.derive)."""
    F = p * d50 ** 2
    R = d50 / 2
    delta = (3 * F / (4 * E_pw * math.sqrt(R))) ** (2 / 3)
    return delta, 2 * E_pw * math.sqrt(R * delta)


def platen_stiffness(p: float, d50: float, E_pw: float) -> float:
    """Tangent Hertz stiffness [N/m] of one d50 grain on the platen at F = p d50² (:func:`wall_contact`)."""
    return wall_contact(p, d50, E_pw)[1]


def platen_damping(p: float, d50: float, E_pw: float, rho: float, zeta: float) -> float:
    """Normal dashpot [N s/m] of that grain-wall contact: c = 2 sqrt(5/6) ζ sqrt(m k) with the grain's
    mass m = ρ π d50³/6 and the tangent stiffness k (LIGGGHTS' hertz model, Tsuji's form; YADE's
    Mindlin law takes 2 ζ sqrt(m k/1.5), 0.89 of it)."""
    m = rho * math.pi * d50 ** 3 / 6
    return 2 * math.sqrt(5 / 6) * zeta * math.sqrt(m * platen_stiffness(p, d50, E_pw))


def loop_matrix(a: float, b: float, a_i: float = 0.0, b_i: float = 0.0) -> np.ndarray:
    """The linearised loop's update matrix on the state (e_k, e_{k-1}, S_{k-1}) (module docstring)."""
    return np.array([[1 - b - b_i, b - a, -a_i],
                     [1.0, 0.0, 0.0],
                     [1.0, 0.0, 1.0]])


def spectral_radius(a: float, b: float, a_i: float = 0.0, b_i: float = 0.0) -> float:
    """Largest |eigenvalue| of :func:`loop_matrix`; below 1 the loop is stable. With no integral
    (a_i = b_i = 0) the sum S is a bystander (eigenvalue 1): the radius is then that of the
    (e_k, e_{k-1}) block."""
    if a_i == 0.0 and b_i == 0.0:
        return float(max(abs(np.roots([1.0, -(1 - b), a - b]))))
    return float(max(abs(np.linalg.eigvals(loop_matrix(a, b, a_i, b_i)))))


def stable_everywhere(g: float, alpha: float, beta: float, integral_ratio: float = 0.0,
                      envelope=ENVELOPE) -> bool:
    """Whether gain ``g`` (and ``g_i = g * integral_ratio`` per update) is stable at every (K, C)
    corner of ``envelope`` around the estimates ``alpha``, ``beta`` (per unit gain)."""
    g_i = g * integral_ratio
    for km, cm in envelope:
        a, b = g * alpha * km, g * beta * cm
        if spectral_radius(a, b, g_i * alpha * km, g_i * beta * cm) >= 1.0:
            return False
    return True


def stability_limit(alpha: float, beta: float, envelope=ENVELOPE) -> float:
    """The largest proportional gain stable at every corner of ``envelope`` (bisection; the loop is
    stable for small g and loses stability once as g grows)."""
    lo, hi = 0.0, 4.0 / alpha          # a = 4 at the estimate: unstable for any beta
    while stable_everywhere(hi, alpha, beta, envelope=envelope):
        hi *= 2.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if mid > 0 and stable_everywhere(mid, alpha, beta, envelope=envelope):
            lo = mid
        else:
            hi = mid
    return lo
#: the integral sums only errors |e| below this (conditional integration): while the platen closes the
#: gap to the grains, or the ramped target is still near zero, e is near 1 and summing it would wind
#: the integral up into an overshoot at contact
INTEGRAL_WINDOW = 0.5
