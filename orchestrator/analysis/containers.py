"""Sample containers (the region where particle centres may lie) for edge-corrected statistics.

A container knows its volume [m³], whether points are inside, the distance of points to its
boundary, and its isotropised set covariance γ̄(r) = <|W ∩ (W + r u)|>_u [m³] (average over
directions u of the volume shared by the window and its translate), which is what the
Ohser–Stoyan edge-corrected pair-correlation estimator needs (see :mod:`.rdf`). Both γ̄ are exact
(1-D / 2-D quadrature of closed-form integrands).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._common import present

__all__ = ["Box", "Cylinder", "infer_container", "make_container"]


@dataclass
class Box:
    """Axis-aligned box ``lo`` <= x <= ``hi`` [m]."""
    lo: np.ndarray
    hi: np.ndarray

    def __post_init__(self):
        self.lo = np.asarray(self.lo, float)
        self.hi = np.asarray(self.hi, float)
        if np.any(self.hi <= self.lo):
            raise ValueError(f"box: hi {self.hi} must exceed lo {self.lo}")

    @property
    def volume(self) -> float:
        return float(np.prod(self.hi - self.lo))

    def contains(self, p) -> np.ndarray:
        p = np.asarray(p, float)
        return np.all((p >= self.lo) & (p <= self.hi), axis=-1)

    def distance_to_boundary(self, p) -> np.ndarray:
        p = np.asarray(p, float)
        return np.minimum(p - self.lo, self.hi - p).min(axis=-1)

    def set_covariance(self, r) -> np.ndarray:
        """γ̄(r) = (1/4π) ∫ Π_a (L_a − r|u_a|)₊ dΩ, by Gauss–Legendre quadrature on the octant."""
        r = np.atleast_1d(np.asarray(r, float))
        L = self.hi - self.lo
        c, wc = np.polynomial.legendre.leggauss(96)          # cos θ on (0, 1)
        c = 0.5 * (c + 1.0)
        wc = 0.5 * wc
        ph, wp = np.polynomial.legendre.leggauss(96)         # φ on (0, π/2)
        ph = 0.25 * np.pi * (ph + 1.0)
        wp = 0.25 * np.pi * wp
        s = np.sqrt(1.0 - c ** 2)
        ux = np.abs(np.outer(s, np.cos(ph)))
        uy = np.abs(np.outer(s, np.sin(ph)))
        uz = np.repeat(c[:, None], len(ph), axis=1)
        w = np.outer(wc, wp) * 8.0 / (4.0 * np.pi)           # 8 octants, normalised by 4π
        out = np.empty(len(r))
        for n, rr in enumerate(r):
            f = (np.clip(L[0] - rr * ux, 0, None) * np.clip(L[1] - rr * uy, 0, None)
                 * np.clip(L[2] - rr * uz, 0, None))
            out[n] = np.sum(w * f)
        return out

    def to_dict(self):
        return {"type": "box", "lo": self.lo.tolist(), "hi": self.hi.tolist()}


@dataclass
class Cylinder:
    """Upright cylinder: axis parallel to z through ``center`` (x, y), ``radius``, z in [zmin, zmax] [m]."""
    center: np.ndarray
    radius: float
    zmin: float
    zmax: float

    def __post_init__(self):
        self.center = np.asarray(self.center, float)[:2]
        if self.radius <= 0 or self.zmax <= self.zmin:
            raise ValueError(f"cylinder: need radius > 0 and zmax > zmin, got {self.radius}, {self.zmin}..{self.zmax}")

    @property
    def height(self) -> float:
        return float(self.zmax - self.zmin)

    @property
    def volume(self) -> float:
        return float(np.pi * self.radius ** 2 * self.height)

    def contains(self, p) -> np.ndarray:
        p = np.asarray(p, float)
        rho = np.hypot(p[..., 0] - self.center[0], p[..., 1] - self.center[1])
        return (rho <= self.radius) & (p[..., 2] >= self.zmin) & (p[..., 2] <= self.zmax)

    def distance_to_boundary(self, p) -> np.ndarray:
        p = np.asarray(p, float)
        rho = np.hypot(p[..., 0] - self.center[0], p[..., 1] - self.center[1])
        return np.minimum(self.radius - rho, np.minimum(p[..., 2] - self.zmin, self.zmax - p[..., 2]))

    def set_covariance(self, r) -> np.ndarray:
        """γ̄(r) = ∫₀¹ A(r sqrt(1−c²)) (H − r c)₊ dc with A(d) the lens area of two discs of
        radius R at distance d (exact integrand, Gauss–Legendre quadrature)."""
        r = np.atleast_1d(np.asarray(r, float))
        R, H = float(self.radius), self.height
        c, w = np.polynomial.legendre.leggauss(400)
        c = 0.5 * (c + 1.0)
        w = 0.5 * w
        d = np.outer(r, np.sqrt(1.0 - c ** 2))
        x = np.clip(d / (2.0 * R), 0.0, 1.0)
        lens = 2.0 * R ** 2 * (np.arccos(x) - x * np.sqrt(1.0 - x ** 2))
        hz = np.clip(H - np.outer(r, c), 0.0, None)
        return (lens * hz) @ w

    def to_dict(self):
        return {"type": "cylinder", "center": self.center.tolist(), "radius": float(self.radius),
                "zmin": float(self.zmin), "zmax": float(self.zmax)}


def infer_container(position: np.ndarray, kind: str = "auto"):
    """Smallest upright box or cylinder holding the present centres.

    ``kind="auto"`` picks a cylinder when the centres leave the corners of their bounding box
    empty (fewer than 2 % of the centres outside the inscribed circle, a box would hold ~21 %).
    """
    p = np.asarray(position, float)
    p = p[present(p)]
    if len(p) < 4:
        raise ValueError("need at least 4 particle centres to infer a container")
    lo, hi = p.min(axis=0), p.max(axis=0)
    c = 0.5 * (lo[:2] + hi[:2])
    rho = np.hypot(p[:, 0] - c[0], p[:, 1] - c[1])
    if kind == "auto":
        rin = 0.5 * min(hi[0] - lo[0], hi[1] - lo[1])
        kind = "cylinder" if np.mean(rho > rin * 1.0001) < 0.02 else "box"
    if kind == "box":
        return Box(lo, hi)
    if kind == "cylinder":
        return Cylinder(c, float(rho.max()), float(lo[2]), float(hi[2]))
    raise ValueError(f"container kind must be 'auto', 'box' or 'cylinder', got {kind!r}")


def make_container(spec, position=None):
    """A container from a spec: None/"auto"/"box"/"cylinder" (inferred from ``position``), a
    container object, or a dict ``{"type": "cylinder", "center": [x, y], "radius": R, "zmin":
    .., "zmax": ..}`` / ``{"type": "box", "lo": [...], "hi": [...]}`` [m]."""
    if isinstance(spec, (Box, Cylinder)):
        return spec
    if spec is None or isinstance(spec, str):
        if position is None:
            raise ValueError("a container must be given explicitly when there are no positions to infer it from")
        return infer_container(position, spec or "auto")
    spec = dict(spec)
    t = spec.pop("type", None)
    if t == "box":
        return Box(**spec)
    if t == "cylinder":
        return Cylinder(**spec)
    raise ValueError(f"container type must be 'box' or 'cylinder', got {t!r}")
