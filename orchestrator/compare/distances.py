"""Distances between two measurements of the same quantity.

* :func:`l2` — relative L2 distance of two profiles y(x): ‖y_b − y_a‖₂ / ‖y_a‖₂ with the norm
  ∫ … dx by the trapezoidal rule on A's grid (B interpolated linearly onto A's points inside B's
  range; points outside are left out and counted). 0 for identical profiles; 1 when B is zero.
* :func:`ks` — the two-sample Kolmogorov–Smirnov statistic sup |F_a − F_b| of two samples and its
  p-value (:func:`scipy.stats.ks_2samp`); NaNs are dropped. 0 for identical samples.
* :func:`rel_error` — (b − a)/|a| of two scalars; when a = 0 the absolute difference is returned
  and flagged.

Each returns a :class:`Distance` (value, metric, details) so that tables say what was computed.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Distance", "l2", "ks", "rel_error"]


@dataclass
class Distance:
    metric: str               # "rel_L2", "KS", "rel_error", "abs_diff"
    value: float
    a: float = float("nan")   # a summary of A (norm, median, value)
    b: float = float("nan")
    n_a: int = 0
    n_b: int = 0
    p_value: float = float("nan")
    details: dict = field(default_factory=dict)


def _trapz(y, x):
    y, x = np.asarray(y, float), np.asarray(x, float)
    if len(x) < 2:
        return float(np.sum(y))
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(x)))


def l2(x_a, y_a, x_b, y_b) -> Distance:
    """Relative L2 distance of profile B from profile A (see the module doc)."""
    x_a, y_a = np.asarray(x_a, float), np.asarray(y_a, float)
    x_b, y_b = np.asarray(x_b, float), np.asarray(y_b, float)
    ok_a = np.isfinite(x_a) & np.isfinite(y_a)
    ok_b = np.isfinite(x_b) & np.isfinite(y_b)
    x_a, y_a, x_b, y_b = x_a[ok_a], y_a[ok_a], x_b[ok_b], y_b[ok_b]
    if len(x_a) == 0 or len(x_b) == 0:
        return Distance("rel_L2", float("nan"), n_a=len(x_a), n_b=len(x_b), details={"reason": "empty profile"})
    o = np.argsort(x_b, kind="stable")
    x_b, y_b = x_b[o], y_b[o]
    inside = (x_a >= x_b[0] - 1e-12 * max(1.0, abs(x_b[0]))) & (x_a <= x_b[-1] + 1e-12 * max(1.0, abs(x_b[-1])))
    xa, ya = x_a[inside], y_a[inside]
    if len(xa) == 0:
        return Distance("rel_L2", float("nan"), n_a=len(x_a), n_b=len(x_b), details={"reason": "no overlap in x"})
    yb = np.interp(xa, x_b, y_b) if len(x_b) > 1 else np.full_like(xa, y_b[0])
    na = np.sqrt(_trapz(ya ** 2, xa))
    nd = np.sqrt(_trapz((yb - ya) ** 2, xa))
    nb = np.sqrt(_trapz(yb ** 2, xa))
    if na > 0:
        v = nd / na
    else:
        v = 0.0 if nd == 0 else float("inf")
    return Distance("rel_L2", float(v), a=float(na), b=float(nb), n_a=int(len(x_a)), n_b=int(len(x_b)),
                    details={"points_outside_b": int((~inside).sum())})


def ks(sample_a, sample_b) -> Distance:
    """Two-sample Kolmogorov–Smirnov statistic (and p-value) of B against A."""
    from scipy.stats import ks_2samp
    a = np.asarray(sample_a, float).ravel()
    b = np.asarray(sample_b, float).ravel()
    a, b = a[np.isfinite(a)], b[np.isfinite(b)]
    if len(a) == 0 or len(b) == 0:
        return Distance("KS", float("nan"), n_a=len(a), n_b=len(b), details={"reason": "empty sample"})
    r = ks_2samp(a, b)
    return Distance("KS", float(r.statistic), a=float(np.median(a)), b=float(np.median(b)), n_a=len(a), n_b=len(b),
                    p_value=float(r.pvalue))


def rel_error(a, b) -> Distance:
    """(b − a)/|a|; the absolute difference (metric ``abs_diff``) when a = 0."""
    a, b = float(a), float(b)
    if not (np.isfinite(a) and np.isfinite(b)):
        return Distance("rel_error", float("nan"), a=a, b=b, details={"reason": "non-finite value"})
    if a == 0:
        return Distance("abs_diff", b - a, a=a, b=b)
    return Distance("rel_error", (b - a) / abs(a), a=a, b=b)
