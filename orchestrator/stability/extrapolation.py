"""Extrapolate a convergence ladder to full fidelity, and the cheapest setting within a tolerance.

Each knob of :mod:`.convergence` is mapped to a *fidelity distance* ``h`` that vanishes in the
ideal limit and to which an observable's error is, to leading order, proportional:

=================  ==============================  ==================================================
knob               h(value)                        why (leading-order error ∝ h)
=================  ==============================  ==================================================
``dt_fraction``    value                           contact onset resolved to ±dt: O(dt) in dense flow
``rate_scale``     value                           μ(I) = μ_s + b I for small I (GDR MiDi 2004; Jop,
                                                   Forterre & Pouliquen 2006): the inertial number
                                                   scales with the knob
``stiffness_scale``  value^(-2/3)                  Hertz overlap at a fixed load, δ/d ∝ (p/E*)^(2/3)
                                                   (Johnson 1985 §4.2): the softness effects scale so
``count``          value^(-1/3)                    the boundary layer's share of the sample, d/L ∝ N^(-1/3)
``size_scale``     value^(-1)                      the same share, d/L ∝ 1/size
other              value                           generic
=================  ==============================  ==================================================

The model is y(h) = a + b h, fitted by weighted least squares over the rungs (weights from each
rung's own standard error where the run reported one). The full-fidelity value is y(h_full), with
h_full = h(``full``) (``full`` = None: the ideal limit h = 0, i.e. dt → 0, quasi-static, rigid,
infinite system; or the seed's setting, e.g. its stiffness as a multiple of the case's). Its
uncertainty ("sem") is the half-width of a 68 % interval at h_full: the larger of the fit's standard
error from the rungs' own standard errors and the one from the residual scatter (three rungs or
more, widened by Student's t for n − 2 degrees of freedom); two rungs fix the line exactly and give
only the former. The cheapest setting predicted within ``tolerance`` of y_full is
the largest h with |b (h − h_full)| ≤ tolerance |y_full|, turned back into the knob's value; its
engine time comes from a power law t ∝ value^q fitted to the rungs' engine times.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.stats import t as student_t

__all__ = ["fidelity_distance", "knob_value", "extrapolate", "power_law_time"]

#: h = value ** exponent for the knobs with a physical scaling (module docstring)
_EXPONENT = {"dt_fraction": 1.0, "rate_scale": 1.0, "stiffness_scale": -2.0 / 3.0, "count": -1.0 / 3.0,
             "size_scale": -1.0}


def fidelity_distance(knob: str, value) -> np.ndarray:
    """h(value) [-] of the module docstring, element-wise. None stands for the ideal limit, h = 0
    (dt → 0, quasi-static, rigid grains, an infinite system)."""
    p = _EXPONENT.get(knob, 1.0)

    def h(x):
        if x is None:
            return 0.0
        v = abs(float(x))
        return math.inf if (v == 0 and p < 0) else v ** p     # zero stiffness or grains: infinitely far
    return np.asarray([h(x) for x in np.atleast_1d(np.asarray(value, object))], float)


def knob_value(knob: str, h: float) -> float:
    """The knob's value at fidelity distance ``h`` (inverse of :func:`fidelity_distance`)."""
    p = _EXPONENT.get(knob, 1.0)
    if h <= 0:
        return math.inf if p < 0 else 0.0
    return float(h ** (1.0 / p))


def power_law_time(values, times) -> tuple[float, float] | None:
    """(c, q) of t = c value^q fitted in log-log to the finite, positive (value, time) pairs;
    None with fewer than two."""
    v, t = np.asarray(values, float), np.asarray(times, float)
    ok = np.isfinite(v) & np.isfinite(t) & (v > 0) & (t > 0)
    if ok.sum() < 2 or np.ptp(np.log(v[ok])) == 0:
        return None
    q, lc = np.polyfit(np.log(v[ok]), np.log(t[ok]), 1)
    return float(math.exp(lc)), float(q)


def extrapolate(knob: str, values, y, y_sem=None, full=None, tolerance: float = 0.05, times=None) -> dict:
    """Fit y = a + b h(value) over the rungs and extrapolate to ``full`` (module docstring).

    Parameters: ``values`` the knob's values of the rungs; ``y`` the observable at each (NaN: the
    rung is left out); ``y_sem`` each rung's standard error of y (None or NaN: unknown);
    ``full`` the knob's full-fidelity value (None: the ideal limit); ``tolerance`` relative;
    ``times`` the rungs' engine times [s] for the predicted cost.

    Returns a dict: ``value_full``, ``sem_full`` (NaN when nothing measures it), ``slope`` (b),
    ``rungs`` used, ``h_full``, ``cheapest`` (the knob's value predicted within ``tolerance``;
    NaN if the fit has no slope to bound), ``cheapest_time_s`` (from the time power law; NaN
    without times), ``where`` the cheapest value lies against the rungs ("within the rungs", "finer
    than every rung: run it to confirm", "cheaper than every rung: an extrapolation of the fit"),
    ``note``.
    """
    vals = np.asarray(values, float)
    y = np.asarray(y, float)
    sem = np.full_like(y, np.nan) if y_sem is None else np.asarray(
        [np.nan if s is None else float(s) for s in y_sem], float)
    ok = np.isfinite(vals) & np.isfinite(y)
    h, yy, ss = fidelity_distance(knob, vals[ok]), y[ok], sem[ok]
    h_full = float(fidelity_distance(knob, full)[0])
    out = {"rungs": int(ok.sum()), "h_full": h_full, "value_full": math.nan, "sem_full": math.nan,
           "slope": math.nan, "cheapest": math.nan, "cheapest_time_s": math.nan, "where": "",
           "note": ""}
    if ok.sum() < 2 or np.ptp(h) == 0:
        out["note"] = "fewer than two rungs with a value: nothing to extrapolate"
        return out
    if not np.isfinite(h_full):
        out["note"] = f"full = {full} is infinitely far from the ideal limit of {knob}: nothing to extrapolate to"
        return out
    n = len(h)
    known = np.isfinite(ss) & (ss > 0)
    w = np.where(known, 1.0 / np.where(known, ss, 1.0) ** 2, np.nan)
    if known.all():
        wt = w
    else:                        # unknown standard errors: equal weights
        wt = np.ones(n)
    A = np.column_stack([np.ones(n), h])
    AtW = A.T * wt
    cov_unit = np.linalg.inv(AtW @ A)
    a, b = cov_unit @ (AtW @ yy)
    g = np.array([1.0, h_full])
    y_full = float(a + b * h_full)
    var = []
    if known.all():                       # from the rungs' own standard errors
        var.append(float(g @ cov_unit @ g))
    if n > 2:                             # from the residual scatter about the line, widened by Student's
        r = yy - (a + b * h)              # t for its n - 2 degrees of freedom so that ±sem holds the truth
        s2 = float(np.sum(wt * r ** 2) / (n - 2))       # 68 % of the time (t = 1.84 for 3 rungs, 1.32 for 4)
        var.append(s2 * float(g @ cov_unit @ g) * student_t.ppf(0.5 + 0.6827 / 2, n - 2) ** 2)
    out.update(value_full=y_full, slope=float(b), sem_full=math.sqrt(max(var)) if var else math.nan)
    if not var:
        out["note"] = "two rungs without standard errors: the line is exact, its uncertainty unknown"
    if b == 0 or y_full == 0:
        return out
    h_max = h_full + tolerance * abs(y_full) / abs(b)
    cheapest = knob_value(knob, h_max)
    out["cheapest"] = cheapest
    out["where"] = ("finer than every rung: run it to confirm" if h_max < h.min() else
                    "cheaper than every rung: an extrapolation of the fit" if h_max > h.max() else "within the rungs")
    if times is not None:
        tt = np.asarray(times, float)[ok]
        law = power_law_time(vals[ok], tt)
        if law is not None and np.isfinite(cheapest) and cheapest > 0:
            out["cheapest_time_s"] = float(law[0] * cheapest ** law[1])
    return out
