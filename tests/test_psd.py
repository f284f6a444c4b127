"""The one truncated-log-normal sampler (orchestrator.psd.truncated_lognormal), used by the
plane-shear and shear-cell scenes (by median) and the triaxial scene (by truncated mean)."""
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import norm

from orchestrator import psd
from orchestrator.scenes.triaxial import PSD


def test_untruncated_median_and_sigma_recovered():
    # bounds 6 sigma out: the truncation removes ~2e-9 of the mass
    d = psd.truncated_lognormal(200_000, math.log(1e-3), 0.25, 1e-3 * math.exp(-1.5), 1e-3 * math.exp(1.5), 1)
    x = np.log(d)
    # standard errors: median ~1.25 sigma/sqrt(n) = 7e-4, sigma sigma/sqrt(2n) = 4e-4
    assert np.median(x) == pytest.approx(math.log(1e-3), abs=4e-3)
    assert np.std(x) == pytest.approx(0.25, rel=0.01)


def test_truncation_respected_and_moments_of_the_truncated_law():
    mu, s, lo, hi = math.log(30e-6), 0.3, 25e-6, 50e-6
    d = psd.truncated_lognormal(100_000, mu, s, lo, hi, np.random.default_rng(2))
    assert d.min() >= lo and d.max() <= hi and len(d) == 100_000
    # truncated normal in ln d: median at Phi^-1 of the middle of [Phi(a), Phi(b)]
    a, b = (math.log(lo) - mu) / s, (math.log(hi) - mu) / s
    med = mu + s * norm.ppf(0.5 * (norm.cdf(a) + norm.cdf(b)))
    assert np.median(np.log(d)) == pytest.approx(med, abs=3e-3)
    assert np.mean(d) == pytest.approx(psd.truncated_lognormal_mean(mu, s, lo, hi), rel=2e-3)
    # the lower cut removes ~27 % of the untruncated law: the sample median is not exp(mu)
    assert abs(np.median(d) / 30e-6 - 1) > 0.05


def test_seeded_and_degenerate():
    d = psd.lognormal_diameters(5000, 30e-6, 25e-6, 50e-6, 0.12, 7)
    assert np.array_equal(d, psd.lognormal_diameters(5000, 30e-6, 25e-6, 50e-6, 0.12, 7))
    assert np.all(psd.lognormal_diameters(10, 30e-6, 25e-6, 50e-6, 0.0, 7) == 30e-6)
    with pytest.raises(ValueError, match="d_min <= median <= d_max"):
        psd.lognormal_diameters(10, 60e-6, 25e-6, 50e-6, 0.12, 7)
    with pytest.raises(ValueError, match="outside"):
        psd.truncated_lognormal(10, math.log(60e-6), 0.0, 25e-6, 50e-6, 7)


def test_triaxial_psd_draws_through_the_same_sampler_and_hits_its_mean():
    p = PSD(min="0.8 mm", max="1.6 mm", mean="1.1 mm", spread=0.25)
    d = p.sample(50_000, np.random.default_rng(3))
    mu = psd.lognormal_mu_for_mean(1.1e-3, 0.25, 0.8e-3, 1.6e-3)
    assert np.array_equal(d, psd.truncated_lognormal(50_000, mu, 0.25, 0.8e-3, 1.6e-3, np.random.default_rng(3)))
    assert d.min() >= 0.8e-3 and d.max() <= 1.6e-3
    assert np.mean(d) == pytest.approx(1.1e-3, rel=3e-3)


# ------------------------------------------------------------------------------------------------
# the loose packer (random sequential addition) in its two containers
# ------------------------------------------------------------------------------------------------
def _min_gap(pos, r, L=None):
    """Smallest |x_i - x_j| - r_i - r_j over all pairs (minimum image in x, y when L is given)."""
    d = pos[:, None, :] - pos[None, :, :]
    if L is not None:
        d[..., :2] -= L * np.round(d[..., :2] / L)
    gap = np.linalg.norm(d, axis=-1) - r[:, None] - r[None, :]
    return gap[np.triu_indices(len(r), 1)].min()


def test_rsa_cylinder_inside_no_overlap_target_fraction():
    rng = np.random.default_rng(1)
    R, H, clear, phi = 6.0, 12.0, 0.05, 0.25
    r = rng.uniform(0.4, 0.6, int(phi * np.pi * R ** 2 * H / (4 / 3 * np.pi * 0.5 ** 3 * 1.0)))
    pos = psd.pack_cylinder(r, R, 0.0, H, 2, wall_clearance=clear)
    assert np.isfinite(pos).all()                                   # every grain placed
    assert np.sum(4 / 3 * np.pi * r ** 3) / (np.pi * R ** 2 * H) >= 0.24   # the target fraction, all placed
    assert np.all(np.hypot(pos[:, 0], pos[:, 1]) + r <= R - clear + 1e-12)
    assert np.all(pos[:, 2] - r >= clear - 1e-12) and np.all(pos[:, 2] + r <= H - clear + 1e-12)
    assert _min_gap(pos, r) >= 0.0 and psd.max_overlap(pos, r) == 0.0
    assert np.array_equal(pos, psd.pack_cylinder(r, R, 0.0, H, 2, wall_clearance=clear))


def test_rsa_periodic_box_minimum_image_and_target_fraction():
    rng = np.random.default_rng(3)
    L, H, phi = 5.0, 10.0, 0.30                 # 2-5 cells a side: the wrapped neighbour search matters
    r = rng.uniform(0.4, 0.6, int(phi * L * L * H / (4 / 3 * np.pi * 0.5 ** 3)))
    pos = psd.pack_box(r, L, 0.0, H, np.random.default_rng(4))
    assert np.isfinite(pos).all()
    assert np.sum(4 / 3 * np.pi * r ** 3) / (L * L * H) >= 0.29
    assert np.all((pos[:, :2] >= 0) & (pos[:, :2] < L))
    assert np.all(pos[:, 2] - r >= 0) and np.all(pos[:, 2] + r <= H)
    assert _min_gap(pos, r, L) >= 0.0                               # across the periodic faces too


def test_rsa_jams_with_a_clear_error():
    with pytest.raises(ValueError, match="could not place particle"):
        psd.pack_cylinder(np.full(500, 1.0), 5.0, 0.0, 5.0, 1)
    with pytest.raises(ValueError, match="could not place particle"):
        psd.pack_box(np.full(500, 1.0), 5.0, 0.0, 5.0, 1, max_tries=50)
    with pytest.raises(ValueError, match="smaller than a particle"):
        psd.pack_box(np.full(3, 1.0), 5.0, 0.0, 1.5, 1)


def _relax_all_pairs(pos, r, container, tol, scale, max_iter, separation=0.55):
    """The collective rearrangement of psd.relax_overlaps with every pair examined every sweep
    (O(n²), no neighbour list): the reference its Verlet list must reproduce."""
    pos = np.array(pos, dtype=float)
    vol = r ** 3
    i, j = np.triu_indices(len(r), 1)
    for it in range(max_iter):
        dv = pos[j] - pos[i]
        dist = np.linalg.norm(dv, axis=1)
        ov = r[i] + r[j] - dist
        m = ov > 0
        if (ov[m].max() / scale if m.any() else 0.0) < tol:
            return pos, it
        a, b, dv, dist, ov = i[m], j[m], dv[m], dist[m], ov[m]
        nvec = dv / dist[:, None]
        wi = vol[b] / (vol[a] + vol[b])
        disp = np.zeros_like(pos)
        np.add.at(disp, a, -(separation * ov * wi)[:, None] * nvec)
        np.add.at(disp, b, (separation * ov * (1 - wi))[:, None] * nvec)
        pos += disp
        container.project(pos, r)
    return pos, max_iter


def test_dense_packer_verlet_list_finds_every_overlap():
    """relax_overlaps' Verlet list (pairs within r_i + r_j + skin, rebuilt after skin/2 of motion)
    must see every overlapping pair a full search sees: same sweeps to converge and the same
    positions to rounding (a missed pair changes the path by ~ an overlap, ~1e-5 of the box here)."""
    rng = np.random.default_rng(4)
    r = rng.uniform(0.5, 1.0, 250)
    box = psd.Box((0.0, 0.0, 0.0), (11.0, 11.0, 11.0))
    x0 = rng.uniform(1.0, 10.0, (250, 3))
    ref, it_ref = _relax_all_pairs(x0, r, box, 1e-3, r.min(), 3000)
    pos, it, worst = psd.relax_overlaps(x0, r, box, 1e-3, r.min(), 3000)
    assert worst < 1e-3 and it == it_ref < 3000
    assert np.abs(pos - ref).max() < 1e-9
    assert psd.max_overlap(pos, r) < 1e-3 * r.min()


_PACK_DIGEST = """
import hashlib, numpy as np
from orchestrator.psd import lognormal_diameters
from orchestrator.scenes.triaxial import pack_cylinder
d = lognormal_diameters(300, 5.5e-4, 3e-4, 9e-4, 0.25, np.random.default_rng(1))
pos, _ = pack_cylinder(d / 2, 1.7e-3, 6.7e-3, np.random.default_rng(1))
print(hashlib.sha256(pos.tobytes()).hexdigest())
"""


def test_the_dense_packing_is_the_same_with_or_without_avx512():
    """NumPy's vectorised ``power`` takes an SVML path on CPUs with AVX-512 and differs by an ulp from
    the C library's ``pow``; the dense packer's weights carried it into packings 1e-12 apart and the
    triaxial smoke's trajectory apart after them (session 37). The packer now cubes with
    ``portable_cube``: the same packing with NumPy's AVX-512 dispatch on (where the CPU has it) and
    off (``NPY_DISABLE_CPU_FEATURES``, as on the machines without it)."""
    off = "AVX512F AVX512CD AVX512_SKX AVX512_CLX AVX512_CNL AVX512_ICL AVX512_SPR X86_V4"
    digests = []
    for disabled in ("", off):
        env = {**os.environ, "NPY_DISABLE_CPU_FEATURES": disabled}
        out = subprocess.run([sys.executable, "-c", _PACK_DIGEST], capture_output=True, text=True, env=env,
                             cwd=Path(__file__).resolve().parents[1], timeout=300)
        assert out.returncode == 0, out.stderr[-2000:]
        digests.append(out.stdout.strip())
    assert digests[0] == digests[1]
