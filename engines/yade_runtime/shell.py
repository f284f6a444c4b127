"""Shell-pressure lateral boundary (substitute ``shell_pressure``): the confining pressure as
radial forces on the outer shell of grains, the same law as the LIGGGHTS triaxial deck
(templates/liggghts/triaxial.in.j2, docs/triaxial.md), so that the two engines can be compared
on one boundary. numpy only (no YADE): unit-tested without the engine.

The sample between the platens is cut into ``bands`` horizontal bands x ``sectors`` angular
sectors. In cell c, R_c = max(rho_i + r_i) over its grains (rho: distance from the axis); its
shell is the grains with rho_i + r_i > R_c - w. Each shell grain gets the inward radial force
F_i = p (2 pi/S) R_c h r_i^2 / sum_shell r_j^2 (h = band height): the cell's envelope area times p,
shared in proportion to r^2. The boundary's lateral area is sum_c (2 pi/S) R_c h and its volume
sum_c (pi/S) R_c^2 h (each grain's r^2-weighted share, as LIGGGHTS sums them)."""
from __future__ import annotations

import math

import numpy as np


def cells(pos: np.ndarray, zb: float, zt: float, bands: int, sectors: int) -> np.ndarray:
    """Cell index band * sectors + sector of each grain (grains beyond the platens or on the
    seam go to the nearest band/sector, as the LIGGGHTS deck clamps them)."""
    h = (zt - zb) / bands
    kb = np.clip(np.floor((pos[:, 2] - zb) / h), 0, bands - 1)
    th = np.arctan2(pos[:, 1], pos[:, 0])
    sb = np.clip(np.floor((th + math.pi) / (2 * math.pi / sectors)), 0, sectors - 1)
    return (kb * sectors + sb).astype(int)


def shell_forces(pos: np.ndarray, radius: np.ndarray, zb: float, zt: float, p: float, bands: int, sectors: int,
                 w: float):
    """Forces [N] (n, 3) on the grains (zero off the shell), and the boundary's total radial
    force [N], lateral area [m^2] and volume [m^3]. ``pos`` (n, 3) and ``radius`` (n,) in m,
    ``p`` in Pa, ``w`` the shell thickness in m."""
    n_cells = bands * sectors
    h = (zt - zb) / bands
    c = cells(pos, zb, zt, bands, sectors)
    rho = np.hypot(pos[:, 0], pos[:, 1])
    edge = rho + radius
    R = np.zeros(n_cells)
    np.maximum.at(R, c, edge)
    shell = edge > R[c] - w
    r2 = radius * radius
    S = np.bincount(c[shell], weights=r2[shell], minlength=n_cells)
    dphi = 2 * math.pi / sectors
    fr = np.where(shell, p * dphi * h * r2 * R[c] / (S[c] + 1e-300), 0.0)
    f = np.zeros_like(pos)
    f[:, 0] = -fr * pos[:, 0] / (rho + 1e-12)
    f[:, 1] = -fr * pos[:, 1] / (rho + 1e-12)
    occupied = S > 0
    area = float(np.sum(dphi * h * R[occupied]))
    volume = float(np.sum(0.5 * dphi * h * R[occupied] ** 2))
    return f, float(fr.sum()), area, volume
