"""Kinetic against elastic energy per frame: the quasi-static check of seed 001 §3.2 ("keeping
kinetic energy below 5 % of internal energy").

- Kinetic energy K = Σ ½ m |v|² over the particles [J] (translation; frames hold no angular
  velocity for every engine, so rotation is left out and K is a lower bound), and its non-affine
  part K' = Σ ½ m |v − (a + L x)|², with the mean velocity field a + L x (L the sample's velocity
  gradient) fitted by least squares to the frame's velocities: K' leaves out the imposed
  deformation (the platen's motion) and measures the grains' agitation.
- Elastic (internal) energy U = Σ over grain-grain contacts of the Hertz normal strain energy
  U_c = (2/5) F δ with δ = (3F / (4 E* √R*))^(2/3) (Johnson 1985, eq. 4.23; E* = E / (2(1 − ν²))
  for two grains of the same material, R* = r_i r_j / (r_i + r_j)) [J]. F is the contact's normal
  force as the engine wrote it (it includes the contact's damping force, small in a quasi-static
  state). Wall, platen and membrane contacts are left out, and so is the tangential spring energy
  (≤ μ² of the normal energy's order for Mindlin), so U is also a lower bound of the internal
  energy.

The ratio K/U is what the seed bounds by 0.05; K'/U is reported beside it. With stiff grains
(E = 92.1 GPa) U is small, so at a given inertial number the imposed motion alone can make K/U
large on a tall sample (K ∝ (ε̇ H)², U ∝ H): K'/U tells agitation from affine motion. CT frames have neither velocities nor forces: the
analysis then refuses with a message saying so.
"""
from __future__ import annotations

import json

import numpy as np
import pandas as pd

from ._common import Result, control_values, frame_indices, present
from .neighbors import contacts_to_rows
from ..units import to_si
from .plots import plot_energy

__all__ = ["kinetic_energy", "nonaffine_kinetic_energy", "hertz_normal_energy", "effective_modulus", "analyze_energy"]

#: seed 001 §3.2: quasi-static while K < 5 % of the internal energy
SEED_LIMIT = 0.05


def kinetic_energy(mass: np.ndarray, velocity: np.ndarray) -> float:
    """Translational kinetic energy Σ ½ m |v|² [J] of the present rows (NaN rows skipped).

    mass : (N,) [kg]; velocity : (N, 3) [m/s].
    """
    v = np.asarray(velocity, float)
    m = np.asarray(mass, float)
    ok = present(v)
    return float(0.5 * np.sum(m[ok] * np.einsum("ij,ij->i", v[ok], v[ok])))


def nonaffine_kinetic_energy(mass: np.ndarray, position: np.ndarray, velocity: np.ndarray) -> float:
    """Kinetic energy of the velocities minus their least-squares affine field a + L x [J].

    mass : (N,) [kg]; position : (N, 3) [m]; velocity : (N, 3) [m/s]. The field is fitted with
    mass weights (12 unknowns: a and the velocity gradient L); NaN rows are skipped.
    """
    x = np.asarray(position, float)
    v = np.asarray(velocity, float)
    m = np.asarray(mass, float)
    ok = present(x) & present(v)
    x, v, m = x[ok], v[ok], m[ok]
    if len(m) < 4:
        return kinetic_energy(m, v)
    A = np.hstack([np.ones((len(x), 1)), x - x.mean(axis=0)])
    w = np.sqrt(m)[:, None]
    coef, *_ = np.linalg.lstsq(A * w, v * w, rcond=None)
    dv = v - A @ coef
    return float(0.5 * np.sum(m * np.einsum("ij,ij->i", dv, dv)))


def effective_modulus(youngs_modulus: float, poisson_ratio: float) -> float:
    """E* = E / (2 (1 − ν²)) [Pa] of two grains of one material (Johnson 1985, eq. 4.22)."""
    return float(youngs_modulus) / (2.0 * (1.0 - float(poisson_ratio) ** 2))


def hertz_normal_energy(fn: np.ndarray, r_i: np.ndarray, r_j: np.ndarray, e_star: float) -> np.ndarray:
    """Hertz strain energy (2/5) F δ of each contact [J].

    fn : (M,) normal force magnitudes [N]; r_i, r_j : (M,) radii [m]; e_star : E* [Pa].
    δ = (3F / (4 E* √R*))^(2/3) is the overlap that carries F (Johnson 1985, eq. 4.23).
    """
    f = np.abs(np.asarray(fn, float))
    rs = np.asarray(r_i, float) * np.asarray(r_j, float) / (np.asarray(r_i, float) + np.asarray(r_j, float))
    delta = (3.0 * f / (4.0 * e_star * np.sqrt(rs))) ** (2.0 / 3.0)
    return 0.4 * f * delta


def _material(frames, youngs_modulus, poisson_ratio):
    """(E, ν) from the options, else from the case stored in the frames' meta."""
    if youngs_modulus is not None and poisson_ratio is not None:
        return float(youngs_modulus), float(poisson_ratio)
    case = frames.meta.get("case")
    if isinstance(case, str):
        case = json.loads(case)
    mat = (case or {}).get("material", {})
    if "youngs_modulus" not in mat or "poisson_ratio" not in mat:
        raise ValueError(f"{frames.path}: energy needs the grains' Young's modulus and Poisson ratio; these frames "
                         "carry no case material (CT frames?): pass youngs_modulus [Pa] and poisson_ratio")
    E = youngs_modulus if youngs_modulus is not None else to_si(mat["youngs_modulus"], "pressure")
    nu = poisson_ratio if poisson_ratio is not None else float(mat["poisson_ratio"])
    return float(E), float(nu)


def analyze_energy(frames, at=None, control: str | None = None, stride: int | None = None,
                   youngs_modulus: float | None = None, poisson_ratio: float | None = None,
                   limit: float = SEED_LIMIT) -> Result:
    """K, U and K/U of every frame with velocities and contacts (default: all of them).

    Options: ``at``/``stride``/``control`` select frames as elsewhere; ``youngs_modulus`` [Pa] and
    ``poisson_ratio`` (default: the case's material from the frames' meta); ``limit``: the K/U
    bound reported against (seed 001 §3.2: 0.05).

    Tables: ``summary`` (frame, control, kinetic [J], kinetic_nonaffine [J], elastic [J], ratio,
    ratio_nonaffine, n_contacts). Scalars: ``ratio_max``, ``ratio_median``, ``fraction_above_limit``
    (of the selected frames that have contacts; a frame without contacts has ratio NaN), the same
    two for K'/U, ``limit``.
    """
    if "velocity" not in frames.fields or not frames.contact_frames:
        raise ValueError(f"{frames.path}: energy needs velocities and contact forces in the frames "
                         f"(fields: {list(frames.fields)}, frames with contacts: {len(frames.contact_frames)}); "
                         "turn on output.velocity and output.contacts in the case")
    if frames.mass is None:
        raise ValueError(f"{frames.path}: energy needs particle masses (particles/mass)")
    E, nu = _material(frames, youngs_modulus, poisson_ratio)
    e_star = effective_modulus(E, nu)
    cname, cvals = control_values(frames, control)
    have = set(frames.contact_frames)
    ks = [k for k in (frame_indices(frames, at, control, stride or 1)) if k in have]
    rows = []
    vel = frames.velocity
    for k in ks:
        c = frames.contact_arrays(k)
        i, j = contacts_to_rows(frames, c["i"], c["j"])
        gg = (i >= 0) & (j >= 0)
        fn = np.linalg.norm(np.asarray(c["fn"], float).reshape(-1, 3)[gg], axis=1)
        # the radii of the spheres that touch: the particles', or, for a clump sample's grains, the
        # member spheres' the contact list carries (orchestrator.grains)
        ri = np.asarray(c["radius_i"], float)[gg] if "radius_i" in c else frames.radius[i[gg]]
        rj = np.asarray(c["radius_j"], float)[gg] if "radius_j" in c else frames.radius[j[gg]]
        u = float(np.sum(hertz_normal_energy(fn, ri, rj, e_star)))
        kin = kinetic_energy(frames.mass, vel[k])
        kna = nonaffine_kinetic_energy(frames.mass, frames.position[k], vel[k])
        rows.append({"frame": k, "control": cvals[k], "kinetic": kin, "kinetic_nonaffine": kna, "elastic": u,
                     "ratio": kin / u if u > 0 else np.nan, "ratio_nonaffine": kna / u if u > 0 else np.nan,
                     "n_contacts": int(gg.sum())})
    s = pd.DataFrame(rows, columns=["frame", "control", "kinetic", "kinetic_nonaffine", "elastic", "ratio",
                                    "ratio_nonaffine", "n_contacts"])
    r = s["ratio"].to_numpy(float)
    fin = r[np.isfinite(r)]
    rn = s["ratio_nonaffine"].to_numpy(float)
    fin_n = rn[np.isfinite(rn)]
    return Result("energy", tables={"summary": s},
                  scalars={"ratio_max": float(np.max(fin)) if fin.size else np.nan,
                           "ratio_median": float(np.median(fin)) if fin.size else np.nan,
                           "fraction_above_limit": float(np.mean(fin > limit)) if fin.size else np.nan,
                           "ratio_nonaffine_median": float(np.median(fin_n)) if fin_n.size else np.nan,
                           "fraction_nonaffine_above_limit": float(np.mean(fin_n > limit)) if fin_n.size else np.nan,
                           "limit": float(limit), "control": cname},
                  options={"youngs_modulus": E, "poisson_ratio": nu, "limit": limit},
                  plotter=plot_energy)
