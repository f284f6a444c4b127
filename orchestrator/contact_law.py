"""Contact-law formulas shared by the derivation and the stability checks: Hertz elasticity,
Tsuji damping (with and without tensile clipping), the Rayleigh time step. Pure functions of SI
numbers; the references are in :mod:`orchestrator.derive`'s docstring, which lists every formula.
Kept apart from :mod:`orchestrator.derive` so that :mod:`orchestrator.stability.checks` uses them
without importing the derivation that calls it (no import cycle).
"""
from __future__ import annotations

import functools
import json
import math
import os
from pathlib import Path
from .atomic import write_text

# scipy (integrate, optimize: ~0.8 s to import) is imported where an integration is done, and the
# integrations are remembered across processes (:func:`remembered`): `validate` within 2 s (#16)


class DerivationError(ValueError):
    """A case whose derived numbers are unsafe (time step above the critical one, …)."""


# ----------------------------------------------------------------------------------------------
# Remembered integrations
# ----------------------------------------------------------------------------------------------
#: bump when a remembered function's numerics change (the stored values are then ignored)
MEMO_VERSION = 1
#: the package's table (values for the shipped cases, written by benchmarks/bench_validate.py --memo)
PACKAGE_MEMO = Path(__file__).resolve().parent / "_data" / "contact_law_memo.json"


def memo_path() -> Path:
    """The user's table of remembered integrations (ORCHESTRATOR_MEMO overrides it)."""
    if os.environ.get("ORCHESTRATOR_MEMO"):
        return Path(os.environ["ORCHESTRATOR_MEMO"])
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "orchestrator" / "contact_law_memo.json"


@functools.lru_cache(maxsize=1)
def _memo_prefix() -> str:
    """Stored values are exact doubles of one scipy version and one MEMO_VERSION."""
    from importlib.metadata import version
    return f"v{MEMO_VERSION}/scipy-{version('scipy')}/"


def _read_memo(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


@functools.lru_cache(maxsize=1)
def _memo() -> dict:
    return {**_read_memo(PACKAGE_MEMO), **_read_memo(memo_path())}


def remembered(fn):
    """A pure function of floats whose result (an exact double: JSON keeps all 17 digits) is kept in
    the user's table, so a later process skips the integration and scipy's import. A table that
    cannot be written is no error (the value is computed again next time)."""
    @functools.wraps(fn)
    def wrapper(*xs: float) -> float:
        key = f"{_memo_prefix()}{fn.__module__}.{fn.__name__}({', '.join(repr(float(x)) for x in xs)})"
        memo = _memo()
        if key in memo:
            return float(memo[key])
        value = float(fn(*xs))
        memo[key] = value
        path = memo_path()
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            write_text(path, json.dumps({**_read_memo(path), key: value}, indent=0, sort_keys=True))
        except OSError:
            pass
        return value
    return wrapper


# ----------------------------------------------------------------------------------------------
# Elastic contact (Hertz)
# ----------------------------------------------------------------------------------------------
def effective_modulus(E1: float, nu1: float, E2: float, nu2: float) -> float:
    """E* [Pa] of two elastic bodies (Johnson 1985 eq. 4.22)."""
    return 1.0 / ((1 - nu1 ** 2) / E1 + (1 - nu2 ** 2) / E2)


def effective_shear_modulus(E1: float, nu1: float, E2: float, nu2: float) -> float:
    """G* [Pa] for the Mindlin tangential stiffness k_t = 8 G* a."""
    return 1.0 / (2 * (2 - nu1) * (1 + nu1) / E1 + 2 * (2 - nu2) * (1 + nu2) / E2)


def reduced(a: float, b: float) -> float:
    """a b / (a + b); b = inf gives a (a wall's radius or mass)."""
    if math.isinf(b):
        return a
    return a * b / (a + b)


def hertz_max_overlap(m_eff: float, R_eff: float, E_eff: float, v: float) -> float:
    """Largest overlap δ_max [m] of an elastic Hertz impact at normal speed v [m/s]."""
    return (15 * m_eff * v ** 2 / (16 * E_eff * math.sqrt(R_eff))) ** 0.4


def hertz_contact_time(m_eff: float, R_eff: float, E_eff: float, v: float) -> float:
    """Duration t_c [s] of an elastic Hertz impact: 2.868 (m*²/(R* E*² v))^(1/5)."""
    return 2.868 * (m_eff ** 2 / (R_eff * E_eff ** 2 * v)) ** 0.2


def hertz_peak_force(m_eff: float, R_eff: float, E_eff: float, v: float) -> float:
    """Peak normal force F_max [N] of an elastic Hertz impact."""
    d = hertz_max_overlap(m_eff, R_eff, E_eff, v)
    return 4.0 / 3.0 * E_eff * math.sqrt(R_eff) * d ** 1.5


def rayleigh_time_step(R_min: float, density: float, youngs: float, poisson: float) -> float:
    """Rayleigh-wave time step [s] for the smallest sphere (Li, Xu & Thornton 2005)."""
    G = youngs / (2 * (1 + poisson))
    return math.pi * R_min * math.sqrt(density / G) / (0.1631 * poisson + 0.8766)


def sliding_limit_tangential_restitution(angle: float, mu: float, e_n: float) -> float:
    """Rigid-body e_t = 1 - μ(1+e_n)/tan θ of the sphere centre in gross sliding (Chung & Ooi
    2011, test 4; valid for tan θ ≥ 7/2 μ (1+e_n))."""
    return 1.0 - mu * (1 + e_n) / math.tan(angle)


def sliding_threshold_angle(mu: float, e_n: float) -> float:
    """Incidence angle [rad] above which a sphere slides throughout the impact: tan θ = 7/2 μ (1+e)."""
    return math.atan(3.5 * mu * (1 + e_n))


# ----------------------------------------------------------------------------------------------
# Restitution under Tsuji damping with tensile clipping
# ----------------------------------------------------------------------------------------------
def wall_dashpot_coefficient(E_eff: float, R_eff: float, m_eff: float, force: float, damping: str,
                             restitution: float) -> float:
    """Normal dashpot coefficient γ [N s/m] of a Hertz contact carrying ``force`` [N] (overlap
    ξ = (3F/(4 E* √R))^(2/3)): seed 000's γ_n √ξ with γ_n = √(4/3 E* m*) for ``damping`` "seed000",
    else Tsuji's 2 √(5/6) |β(e)| √(S_n m*) with S_n = 2 E* √(R ξ) (Tsuji et al. 1992)."""
    xi = (3 * force / (4 * E_eff * math.sqrt(R_eff))) ** (2 / 3)
    if damping == "seed000":
        return math.sqrt(4 / 3 * E_eff * m_eff) * math.sqrt(xi)
    return 2 * math.sqrt(5 / 6) * abs(tsuji_beta(restitution)) * math.sqrt(2 * E_eff * math.sqrt(R_eff * xi) * m_eff)


#: largest loop gain G = v_max k_p γ/F_c of a proportional force servo against the dashpots of the
#: contacts it pushes (scenes/shear_cell.py servo_dashpot_gain: above 1 the error alternates every
#: step and never decays; the medium shear cell at G = 2.66 held 1.22 x its target force)
SERVO_DASHPOT_GAIN = 0.7


def dashpot_stable_servo_speed(v_max: float, gain: float) -> float:
    """The servo speed limit [m/s] ``v_max`` capped so that its dashpot loop gain ``gain`` (at
    ``v_max``; G ∝ v) stays at :data:`SERVO_DASHPOT_GAIN`."""
    return v_max if gain <= SERVO_DASHPOT_GAIN else v_max * SERVO_DASHPOT_GAIN / gain


def damping_ratio(e: float) -> float:
    """Damping ratio ζ of a linear oscillator whose restitution is e: -ln e/√(π² + ln² e)."""
    return -tsuji_beta(e)


def tsuji_beta(e: float) -> float:
    """β = ln e / √(ln² e + π²) (Tsuji et al. 1992)."""
    if e >= 1.0:
        return 0.0
    le = math.log(e)
    return le / math.sqrt(le * le + math.pi ** 2)


def _e_from_beta_input(beta: float) -> float:
    """Inverse of :func:`tsuji_beta`: the e fed in that gives ``beta``."""
    if beta == 0.0:
        return 1.0
    return math.exp(math.pi * beta / math.sqrt(1 - beta * beta))


@functools.lru_cache(maxsize=256)
def delivered_restitution(e_input: float) -> float:
    """Restitution actually delivered by Hertz + Tsuji damping + tensile clipping when ``e_input``
    is given to the engine. Independent of speed, size and stiffness (the law is scale-free), so
    one dimensionless integration (m* = 1, 4/3 E*√R* = 1, v = 1) suffices."""
    beta = tsuji_beta(e_input)
    if beta == 0.0:
        return 1.0
    c = 2 * math.sqrt(5 / 6) * abs(beta) * math.sqrt(2 * 0.75)   # E* = 3/4, R* = m* = 1
    return _clipped_restitution(lambda x, v: x ** 1.5 + c * x ** 0.25 * v)


def _clipped_restitution(force) -> float:
    """Restitution of a unit-mass contact m x'' = -max(force(x, x'), 0) entered at x' = 1: the
    speed left when the clipped force vanishes while separating (or the overlap closes)."""
    def rhs(t, y):
        x = max(y[0], 0.0)
        return [y[1], -max(force(x, y[1]), 0.0) if x > 0 else 0.0]

    def zero_force(t, y):                 # the clipped force vanishes while separating
        return force(max(y[0], 1e-300), y[1]) if y[1] < 0 else 1.0
    zero_force.terminal = True
    zero_force.direction = -1

    def left(t, y):
        return y[0]
    left.terminal = True
    left.direction = -1
    from scipy.integrate import solve_ivp
    sol = solve_ivp(rhs, (0, 50), [1e-12, 1.0], events=[zero_force, left], rtol=1e-10, atol=1e-13,
                    max_step=0.01)
    return float(-sol.y[1, -1])


@functools.lru_cache(maxsize=256)
@remembered
def restitution_input(e_target: float) -> float:
    """The restitution to feed a Tsuji law whose tensile force is clipped (engines with
    ``limitForce``/``limit_damping``) so that a collision delivers ``e_target``; raises
    DerivationError below what the clipped law can deliver (see orchestrator.derive's docstring)."""
    if e_target >= 1.0:
        return 1.0
    f = lambda e_in: delivered_restitution(round(e_in, 12)) - e_target
    lo, hi = 1e-4, 1.0 - 1e-9
    from scipy.optimize import brentq
    if f(lo) > 0:
        raise DerivationError(f"restitution {e_target} is below what Tsuji damping with clipping can deliver "
                              f"({delivered_restitution(lo):.3f})")
    return float(brentq(f, lo, hi, xtol=1e-10))


@functools.lru_cache(maxsize=256)
def _sqrt_damping_restitution(b: float) -> float:
    """e_n of X'' = -5/4 X^1.5 - b √X X' (Hertz with damping ∝ √δ δ̇, clipped; X = δ/δ_max
    of the elastic impact, τ = t v/δ_max)."""
    return _clipped_restitution(lambda x, v: 1.25 * x ** 1.5 + b * math.sqrt(x) * v)


def sqrt_damping_gamma(e_target: float, m_eff: float, R_eff: float, E_eff: float, v: float) -> float:
    """γ [1/(m s)] of a damping force F_damp = γ m* √(R* δ) δ̇ (clipped) that delivers
    ``e_target`` for an impact at normal speed ``v`` [m/s]. With this law e_n varies with speed
    (as the ratio of damping to elastic force grows like v^(1/5)): it is exact only at ``v``."""
    if e_target >= 1.0:
        return 0.0
    b = _sqrt_damping_b(e_target)
    d0 = hertz_max_overlap(m_eff, R_eff, E_eff, v)
    return b * v / (d0 * math.sqrt(R_eff * d0))


@remembered
def _sqrt_damping_b(e_target: float) -> float:
    """The dimensionless damping b of :func:`_sqrt_damping_restitution` that delivers ``e_target``."""
    from scipy.optimize import brentq
    return float(brentq(lambda b: _sqrt_damping_restitution(round(b, 12)) - e_target, 1e-9, 50.0, xtol=1e-12))
