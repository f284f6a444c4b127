"""Control laws of the YADE triaxial deck (numbers from ``orchestrator.scenes.triaxial.derive``).
Pure functions (no YADE): unit-tested without the engine."""
from __future__ import annotations


def servo_velocity(error: float, gain: float, v_max: float) -> float:
    """Platen velocity [m/s] of the stage-1 servo: ``v = -v_max clip(gain * error, -1, 1)`` with
    ``error = 1 - sigma_top / p`` (positive: too little stress, the top platen moves down, -z).
    The gain's stability limit g_c = p d50^2 / (v_max n dt k) is derived in the scene
    (docs/triaxial.md)."""
    return -v_max * max(-1.0, min(1.0, gain * error))


def servo_pid_settings(p_now: float, area: float, gain: float, v_max: float, p: float, gain_integral: float = 0.0):
    """``(target [N], kP [m/s/N], kI [m/s/N])`` for YADE's ServoPIDController on the top platen (axis +z) so
    that its law ``v = clip(kP (|F| - target) + iTerm, v_max)``, ``iTerm += kI (|F| - target)`` at each
    update, is v = -v_max clip(g e + g_i S) with ``e = 1 - F/(p_now area)`` and S the sum of e:
    target = p_now A, kP = v_max gain / (p_now A), kI = v_max gain_integral / (p_now A) (``gain_integral``
    per update). ``p_now`` is floored at 1e-9 p (the ramp starts at zero, where the Python law took
    error = 1)."""
    pa = max(p_now, 1e-9 * p) * area
    return pa, v_max * gain / pa, v_max * gain_integral / pa


def force_error(force: float, target: float) -> float:
    """The servo's relative error e = 1 - F/target [-] (1 when the target is zero)."""
    return 1.0 - force / target if target > 0 else 1.0


def ramp(it: int, ramp_steps: int) -> float:
    """Fraction of the confining pressure applied at iteration ``it`` (linear ramp)."""
    return min(1.0, it / float(ramp_steps)) if ramp_steps > 0 else 1.0


def drag_ramp(it: int, start: int, ramp_steps: int) -> float:
    """Fraction of the stage-1 drag left at iteration ``it`` of its linear ramp to zero that began at
    ``start`` and lasts ``ramp_steps`` (derived in the scene: the sample's rearrangement time under the
    initial drag, 18 nu/p)."""
    return max(0.0, 1.0 - (it - start) / float(ramp_steps)) if ramp_steps > 0 else 0.0


def membrane_correction(corr: float, s3_avg, s3: float, p: float, rows: int, gain: float, limit: float):
    """One update of the membrane correction (the nodal pressure is ``p * corr``): ``s3_avg`` is an
    exponential mean of the lateral stress measured on the grains over ~``rows`` samples; ``corr``
    moves by ``gain/rows * (p/s3_avg - 1)`` (relative) and stays in ``[1 - limit, 1 + limit]``.
    Returns ``(corr, s3_avg)``. The sheet's own stiffness and wrapping otherwise take a few per
    cent of the pressure."""
    a = 1.0 / rows
    s3_avg = s3 if s3_avg is None else (1 - a) * s3_avg + a * s3
    corr *= 1.0 + gain * a * (p / s3_avg - 1.0)
    return min(1.0 + limit, max(1.0 - limit, corr)), s3_avg


def creep_settled(v_mean: float, v_prev: float, tol: float) -> bool:
    """The drag stage's volume-creep test (scene.isotropic.creep_tolerance, as LIGGGHTS' deck): the
    chunk-mean boundary volume ``v_mean`` [m^3] differs from the last chunk's ``v_prev`` by less than
    ``tol`` of it (False before a last chunk exists: ``v_prev`` 0)."""
    return v_prev > 0 and abs(v_mean - v_prev) < tol * v_prev


def iso_converged(m1: float, m3: float, p: float, tol: float) -> bool:
    """Stage 1 has converged when the chunk means of sigma1 and sigma3 are both within ``tol`` of p."""
    return abs(m1 / p - 1) < tol and abs(m3 / p - 1) < tol
