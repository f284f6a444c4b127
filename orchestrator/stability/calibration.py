"""μ calibration in plane shear (seed 000 §3.2): sweep the Coulomb friction μ at fixed normal
stress, take the steady-state μ_macro(μ), fit the exponential saturating function

    μ_macro(μ) = μ₀ + A (1 − exp(−μ/μ_c))

(μ₀: frictionless spheres, μ₀ + A: the plateau at large μ, μ_c: the saturation scale), and invert
it for the μ that gives a target μ_macro: μ = −μ_c ln(1 − (target − μ₀)/A). The seed finds
μ ≈ 0.58 with 10 000 grains at 15 kPa (``cases/plane_shear_seed.yaml``).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy.optimize import curve_fit

from .sweep import sweep
from ..analysis._common import save_figure


def saturating(mu, mu0, A, mu_c):
    return mu0 + A * (1 - np.exp(-np.asarray(mu, float) / mu_c))


def fit_saturating(mu, mu_macro, sigma=None) -> dict:
    """Least-squares fit of :func:`saturating`; needs 3 points or more."""
    mu = np.asarray(mu, float)
    y = np.asarray(mu_macro, float)
    ok = np.isfinite(y)
    mu, y = mu[ok], y[ok]
    sig = None
    if sigma is not None:
        sig = np.asarray(sigma, float)[ok]
        if not np.all(np.isfinite(sig) & (sig > 0)):
            sig = None
    if len(mu) < 3:
        raise ValueError(f"calibration: {len(mu)} finite points; the saturating fit needs at least 3")
    p0 = [max(y.min() - 0.02, 0.0), max(y.max() - y.min(), 0.05), max(0.2, float(np.median(mu)))]
    popt, pcov = curve_fit(saturating, mu, y, p0=p0, sigma=sig, absolute_sigma=sig is not None,
                           bounds=([-1.0, 0.0, 1e-3], [2.0, 5.0, 20.0]), maxfev=20000)
    res = y - saturating(mu, *popt)
    return {"mu0": float(popt[0]), "A": float(popt[1]), "mu_c": float(popt[2]),
            "plateau": float(popt[0] + popt[1]), "cov": pcov.tolist(), "rms_residual": float(np.sqrt(np.mean(res ** 2))),
            "n_points": int(len(mu))}


def invert(target: float, fit: dict) -> float:
    """μ with μ_macro(μ) = target; raises ValueError outside (μ₀, μ₀ + A)."""
    x = (target - fit["mu0"]) / fit["A"]
    if not 0 < x < 1:
        raise ValueError(f"target mu_macro {target:g} lies outside the fitted range ({fit['mu0']:.3f}, "
                         f"{fit['plateau']:.3f}): no friction coefficient reaches it")
    return float(-fit["mu_c"] * math.log(1 - x))


def invert_uncertainty(target: float, fit: dict, n: int = 2000, seed: int = 0) -> float:
    """Standard deviation of the inverted μ from the fit's covariance (Monte Carlo)."""
    rng = np.random.default_rng(seed)
    try:
        draws = rng.multivariate_normal([fit["mu0"], fit["A"], fit["mu_c"]], np.asarray(fit["cov"]), n)
    except (ValueError, np.linalg.LinAlgError):
        return float("nan")
    out = []
    for mu0, A, mc in draws:
        x = (target - mu0) / A if A > 0 else -1
        if 0 < x < 1 and mc > 0:
            out.append(-mc * math.log(1 - x))
    return float(np.std(out)) if len(out) > n // 2 else float("nan")


#: the scene the calibration is defined on (seed 000 §3.2): μ_macro = |F_x|/|F_z| at fixed normal stress
SCENE = "plane_shear"


def check_calibration(case_path, mus, target: float | None = None) -> None:
    """Refuse, before any run, what :func:`calibrate` cannot use: a case that is not plane shear
    (:class:`CaseError` naming the case file and its scene) or friction coefficients that are not
    finite numbers of at least 0, or fewer than the 3 distinct ones the saturating fit needs
    (ValueError naming ``--mu``), a ``target`` that is not a finite number (naming ``--target``)."""
    from ..case import CaseError, load_case
    case = load_case(case_path)
    if case.scene.kind != SCENE:
        raise CaseError(case_path, [f"scene.kind: the case is a {case.scene.kind} scene; calibration needs a "
                                    f"{SCENE} case (seed 000 §3.2: mu_macro at a fixed normal stress): give one, "
                                    f"e.g. cases/plane_shear_smoke.yaml or cases/plane_shear_seed.yaml"])
    bad = [m for m in mus if isinstance(m, bool) or not isinstance(m, (int, float)) or not math.isfinite(m) or m < 0]
    if bad:
        raise ValueError(f"--mu: {', '.join(map(str, bad))}: a friction coefficient is a finite number of at least 0; "
                         "give them comma-separated, e.g. --mu 0,0.2,0.4,0.6,1.0")
    if len(set(float(m) for m in mus)) < 3:
        raise ValueError(f"--mu {','.join(map(str, mus))}: {len(set(float(m) for m in mus))} distinct friction "
                         "coefficient(s); the saturating fit needs at least 3: give more, e.g. --mu 0,0.2,0.4,0.6,1.0")
    if target is not None and not math.isfinite(target):
        raise ValueError(f"--target {target}: the target mu_macro is a finite number, e.g. --target 0.3")


def calibrate(case_path, mus: list[float], target: float | None = None, engines: list[str] | None = None,
              runs_root="runs", scheduler=None, workers: int | None = None, plot: str | Path | None = None) -> dict:
    """Sweep contact.friction over ``mus`` (through :func:`orchestrator.stability.sweep.sweep`),
    fit per engine, invert for ``target``. Returns {"table", "fits", "mu_for_target", "plot"}.
    The case and ``mus`` are checked first (:func:`check_calibration`): nothing runs on bad input."""
    check_calibration(case_path, mus, target)
    df = sweep(case_path, {"contact.friction": [float(m) for m in mus]}, engines=engines, runs_root=runs_root,
               scheduler=scheduler, workers=workers)
    fits, inv = {}, {}
    for eng, g in df.groupby("engine"):
        g = g[g["status"] == "complete"]
        try:
            f = fit_saturating(g["contact.friction"], g["mu_macro"], g.get("mu_macro_sem"))
        except (ValueError, RuntimeError) as exc:
            fits[eng] = {"error": str(exc)}
            continue
        fits[eng] = f
        if target is not None:
            try:
                inv[eng] = {"mu": invert(target, f), "mu_std": invert_uncertainty(target, f)}
            except ValueError as exc:
                inv[eng] = {"error": str(exc)}
    out = {"table": df, "fits": fits, "mu_for_target": inv, "target": target}
    if plot:
        out["plot"] = plot_calibration(df, fits, target, inv, plot)
    return out


def plot_calibration(df, fits, target, inv, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(5.5, 4))
    for eng, g in df.groupby("engine"):
        g = g[g["status"] == "complete"]
        ax.errorbar(g["contact.friction"], g["mu_macro"], yerr=g.get("mu_macro_sem"), fmt="o", label=eng, capsize=3)
        f = fits.get(eng, {})
        if "mu0" in f:
            x = np.linspace(0, max(df["contact.friction"].max() * 1.1, 0.1), 200)
            ax.plot(x, saturating(x, f["mu0"], f["A"], f["mu_c"]), "-",
                    label=f"{eng}: {f['mu0']:.3f} + {f['A']:.3f}(1-exp(-mu/{f['mu_c']:.3f}))")
        if target is not None and "mu" in inv.get(eng, {}):
            ax.plot([inv[eng]["mu"]], [target], "k*", ms=10)
    if target is not None:
        ax.axhline(target, ls="--", color="grey", lw=0.8)
    ax.set_xlabel("Coulomb friction coefficient mu [-]")
    ax.set_ylabel("steady-state mu_macro = |F_x|/|F_z| [-]")
    ax.legend(fontsize=7)
    fig.tight_layout()
    return save_figure(fig, path)
