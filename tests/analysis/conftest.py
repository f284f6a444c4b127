"""Synthetic frame sets for the analysis tests (no engine needed)."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from orchestrator.frames import write_frames  # noqa: E402
from orchestrator.analysis.neighbors import geometric_contacts  # noqa: E402

D = 30e-6          # particle diameter scale [m] (seed 000: 30 um glass spheres)
Z_SB, W_SB = 6 * D, 3 * D   # shear band of the synthetic shear cell
CENTER = np.array([0.3 * D, -0.2 * D])  # off-axis rotation centre


def packing(n_side=12, height=10, jitter=0.05, seed=0):
    """Jittered simple-cubic packing (spacing D) cut to a cylinder; polydisperse radii."""
    rng = np.random.default_rng(seed)
    g = np.arange(n_side) - (n_side - 1) / 2
    x, y, z = np.meshgrid(g, g, np.arange(height), indexing="ij")
    p = np.c_[x.ravel(), y.ravel(), z.ravel()] * D
    p = p[np.hypot(p[:, 0], p[:, 1]) <= (n_side / 2 - 0.5) * D]
    p += rng.normal(scale=jitter * D, size=p.shape)
    r = rng.uniform(0.42, 0.5, len(p)) * D
    return p, r


def make_shear_cell(path, n_frames=6, dtheta=np.radians(0.5), seed=0):
    rng = np.random.default_rng(seed)
    p0, r = packing(seed=seed)
    n = len(p0)
    ids = np.arange(100, 100 + n)
    T = n_frames
    pos = np.empty((T, n, 3))
    angle = dtheta * np.arange(T)
    from scipy.special import erf
    prof = 0.5 + 0.5 * erf((p0[:, 2] - Z_SB) / W_SB)
    rel = p0[:, :2] - CENTER
    for k in range(T):
        th = angle[k] * prof
        c, s = np.cos(th), np.sin(th)
        pos[k, :, 0] = CENTER[0] + c * rel[:, 0] - s * rel[:, 1]
        pos[k, :, 1] = CENTER[1] + s * rel[:, 0] + c * rel[:, 1]
        pos[k, :, 2] = p0[:, 2]
    pos[1:, 5] = np.nan            # a particle lost after the first frame
    pos[0, 7] = np.nan             # a particle not yet tracked in the first frame
    contacts = {}
    stress = np.empty((T, n, 3, 3))
    for k in range(T):
        i, j = geometric_contacts(pos[k], r, tolerance=0.1)
        nrm = pos[k, j] - pos[k, i]
        nrm /= np.linalg.norm(nrm, axis=1)[:, None]
        f = rng.exponential(1e-3, len(i)) * (1 + 2 * nrm[:, 2] ** 2)
        contacts[k] = {"i": ids[i], "j": ids[j], "normal": nrm, "fn": -f[:, None] * nrm,
                       "ft": np.zeros((len(i), 3)), "point": pos[k, i] + r[i, None] * nrm}
        a = rng.normal(size=(n, 3, 3)) * 1e3
        stress[k] = -5e3 * np.eye(3) + 0.5 * (a + np.swapaxes(a, 1, 2))
    t = np.arange(T) * 0.1
    tw = np.linspace(0, t[-1], 50)
    walls = {"top": {"time": tw, "angle": np.interp(tw, t, angle), "torque": np.c_[0 * tw, 0 * tw, 2e-6 + 0 * tw],
                     "force": np.c_[0 * tw, 0 * tw, 1e-3 + 0 * tw]},
             "bottom": {"time": tw, "force": np.c_[0 * tw, 0 * tw, -1e-2 + 0 * tw]},
             # a triaxial time series (stage 1 then loading) for the 'triaxial' analysis
             "triaxial": {"time": tw, "stage": np.where(tw < 0.1, 1.0, 2.0), "axial_strain": 0.2 * tw,
                          "sigma1": 3e5 * (1 + 2 * np.tanh(20 * tw)), "sigma3": 3e5 + 0 * tw,
                          "volumetric_strain": -0.1 * tw ** 2, "volume": 1e-6 * (1 + 0.1 * tw ** 2)}}
    # velocities: the finite-difference motion plus a small random agitation (energy analysis)
    vel = np.gradient(np.nan_to_num(pos), t[1] - t[0], axis=0) + rng.normal(0, 1e-4, pos.shape)
    return write_frames(path, ids, r, t, pos, controls={"angle": angle, "axial_strain": 0.0025 * np.arange(T)},
                        contacts=contacts, walls=walls, stress=stress, velocity=vel,
                        mass=2500.0 * 4.0 / 3.0 * np.pi * r ** 3)


@pytest.fixture(scope="session")
def shear_cell(tmp_path_factory):
    from orchestrator.frames import Frames
    p = tmp_path_factory.mktemp("frames") / "frames.h5"
    make_shear_cell(p)
    return Frames(p)
