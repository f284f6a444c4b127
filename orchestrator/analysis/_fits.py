"""Fitted laws shared by measures and their plots (pure functions, no frames): the discrete
power law of cluster sizes and the fractal dimension (seed 001, §4.3), the erf shear-band profile
(seed 000, eq. 2)."""
from __future__ import annotations

import numpy as np
from scipy import optimize, special

__all__ = ["powerlaw_fit", "fractal_dimension", "erf_profile"]


def powerlaw_fit(sizes, s_min: int = 1) -> dict:
    """Discrete power-law MLE P(s) = s^(−τ)/ζ(τ, s_min) for s >= s_min.

    Returns ``tau``, ``tau_err`` (1/sqrt of the observed Fisher information), ``n`` (clusters
    used), ``s_min``. NaN when fewer than 5 clusters.
    """
    s = np.asarray(sizes, float)
    s = s[s >= s_min]
    n = len(s)
    if n < 5 or np.all(s == s_min):
        return {"tau": np.nan, "tau_err": np.nan, "n": n, "s_min": s_min}
    sl = np.sum(np.log(s))

    def nll(t):
        return n * np.log(special.zeta(t, s_min)) + t * sl

    r = optimize.minimize_scalar(nll, bounds=(1.0001, 10.0), method="bounded", options={"xatol": 1e-8})
    t = float(r.x)
    h = 1e-4 * max(t, 1)
    curv = (nll(t + h) - 2 * nll(t) + nll(t - h)) / h ** 2
    err = 1.0 / np.sqrt(curv) if curv > 0 else np.nan
    return {"tau": t, "tau_err": float(err), "n": n, "s_min": s_min}


def log_binned(sizes, p, per_decade: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """A discrete distribution ``p`` over integer ``sizes`` averaged over logarithmic bins: (each
    bin's geometric centre [-], the mean of P over the integers the bin spans [-]), empty bins left
    out. The per-size histogram's tail is a floor of sizes seen once (1/N each), which hides the
    power law; binned, the points follow P(s) itself (Clauset, Shalizi & Newman 2009, SIAM Rev. 51,
    661, sec. 3 and fig. 1). The bins' sums of P times their widths add up to the sum of ``p``."""
    s = np.asarray(sizes, dtype=float)
    p = np.asarray(p, dtype=float)
    if not len(s):
        return np.empty(0), np.empty(0)
    top = float(s.max()) + 1.0
    n_bins = max(int(np.ceil(np.log10(top) * per_decade)), 1)
    edges = np.unique(np.floor(np.geomspace(1.0, top, n_bins + 1)))
    if edges[-1] < top:
        edges = np.append(edges, top)
    idx = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, len(edges) - 2)
    sums = np.bincount(idx, weights=p, minlength=len(edges) - 1)[: len(edges) - 1]
    width = np.diff(edges)
    centre = np.sqrt(edges[:-1] * (edges[1:] - 1.0))
    keep = sums > 0
    return centre[keep], (sums / width)[keep]


def fractal_dimension(sizes, rg, s_min: int = 3) -> dict:
    """Fit R_g = A s^(1/d_f) on clusters with s >= s_min (least squares in log–log).

    Returns ``d_f``, ``d_f_err``, ``slope`` (1/d_f), ``slope_err``, ``n`` (clusters used).
    """
    s = np.asarray(sizes, float)
    rg = np.asarray(rg, float)
    m = (s >= s_min) & (rg > 0) & np.isfinite(rg)
    if m.sum() < 3 or len(np.unique(s[m])) < 2:
        return {"d_f": np.nan, "d_f_err": np.nan, "slope": np.nan, "slope_err": np.nan, "n": int(m.sum())}
    x, y = np.log(s[m]), np.log(rg[m])
    A = np.c_[x, np.ones_like(x)]
    coef, res, *_ = np.linalg.lstsq(A, y, rcond=None)
    dof = max(len(x) - 2, 1)
    sig2 = float(np.sum((y - A @ coef) ** 2) / dof)
    cov = sig2 * np.linalg.inv(A.T @ A)
    slope, se = float(coef[0]), float(np.sqrt(cov[0, 0]))
    return {"d_f": 1.0 / slope, "d_f_err": se / slope ** 2, "slope": slope, "slope_err": se, "n": int(m.sum())}


def erf_profile(z, z_sb, w_sb):
    """Eq. 2 of seed 000: ½ + ½ erf((z − z_sb)/w_sb)."""
    return 0.5 + 0.5 * special.erf((np.asarray(z, float) - z_sb) / w_sb)
