"""Kinetic/elastic energy analysis (seed 001 §3.2 quasi-static check): closed forms."""
import numpy as np
import pytest

from orchestrator.analysis.energy import (analyze_energy, effective_modulus, hertz_normal_energy, kinetic_energy,
                                          nonaffine_kinetic_energy)
from orchestrator.frames import Frames, write_frames

E, NU = 70e9, 0.25


def test_hertz_energy_is_the_work_of_the_hertz_force():
    """U(δ) = ∫ F dδ with F = (4/3) E* √R* δ^{3/2} (Johnson 1985, eq. 4.23): U = (8/15) E* √R* δ^{5/2}."""
    es = effective_modulus(E, NU)
    r1, r2 = 20e-6, 35e-6
    rs = r1 * r2 / (r1 + r2)
    delta = np.array([1e-9, 5e-8, 3e-7])
    f = 4 / 3 * es * np.sqrt(rs) * delta ** 1.5
    u = hertz_normal_energy(f, np.full(3, r1), np.full(3, r2), es)
    assert u == pytest.approx(8 / 15 * es * np.sqrt(rs) * delta ** 2.5, rel=1e-12)
    # numerical integral of F dδ from 0 to δ_max
    d = np.linspace(0, delta[-1], 200001)
    assert u[-1] == pytest.approx(np.trapezoid(4 / 3 * es * np.sqrt(rs) * d ** 1.5, d), rel=1e-6)


def test_nonaffine_energy_removes_any_affine_field_and_keeps_fluctuations():
    rng = np.random.default_rng(3)
    x = rng.uniform(-1e-3, 1e-3, (500, 3))
    m = rng.uniform(1e-9, 3e-9, 500)
    L = np.array([[0.1, 0.3, 0], [0, -0.2, 0.5], [0.7, 0, -1.0]]) * 1e3
    v_aff = x @ L.T + np.array([0.2, -0.1, 0.05])
    assert kinetic_energy(m, v_aff) > 0
    assert nonaffine_kinetic_energy(m, x, v_aff) == pytest.approx(0, abs=1e-12 * kinetic_energy(m, v_aff))
    dv = rng.normal(0, 0.3, (500, 3))
    dv -= np.average(dv, axis=0, weights=m)
    k_fluct = kinetic_energy(m, dv)
    # the fit also absorbs the random fluctuation's own affine part: 12 of 1500 degrees of freedom
    assert nonaffine_kinetic_energy(m, x, v_aff + dv) == pytest.approx(k_fluct, rel=0.03)
    x[7] = np.nan                                   # absent rows are skipped
    assert np.isfinite(nonaffine_kinetic_energy(m, x, v_aff + dv))


def test_analyze_energy_on_a_hertz_chain(tmp_path):
    """Two touching grains with a known overlap and known speeds: K, U and K/U exactly."""
    r = 25e-6
    es = effective_modulus(E, NU)
    delta = 2e-8
    f = 4 / 3 * es * np.sqrt(r / 2) * delta ** 1.5
    pos = np.array([[[0, 0, 0], [2 * r - delta, 0, 0]]] * 2)
    vel = np.array([[[0.01, 0, 0], [0, 0, 0]], [[0, 0, 0], [0, 0.02, 0]]])
    mass = np.full(2, 2500 * 4 / 3 * np.pi * r ** 3)
    contacts = {k: {"i": np.array([1]), "j": np.array([2]), "fn": np.array([[-f, 0, 0]]),
                    "ft": np.zeros((1, 3)), "normal": np.array([[1.0, 0, 0]]),
                    "point": np.array([[r, 0, 0]])} for k in (0, 1)}
    fr = Frames(write_frames(tmp_path / "f.h5", [1, 2], np.full(2, r), [0, 1], pos, mass=mass,
                             contacts=contacts, velocity=vel))
    res = analyze_energy(fr, youngs_modulus=E, poisson_ratio=NU)
    s = res.tables["summary"]
    u = 8 / 15 * es * np.sqrt(r / 2) * delta ** 2.5
    assert s["elastic"].to_numpy() == pytest.approx([u, u], rel=1e-9)
    assert s["kinetic"].to_numpy() == pytest.approx(0.5 * mass[0] * np.array([0.01 ** 2, 0.02 ** 2]), rel=1e-12)
    assert res.scalars["ratio_max"] == pytest.approx(0.5 * mass[0] * 0.02 ** 2 / u, rel=1e-9)
    res.plot()
    with pytest.raises(ValueError, match="poisson_ratio"):
        analyze_energy(fr)                          # no case in the meta: the material must be given
