"""The YADE decks' pure runtime (engines/yade_runtime: mesh, control, series), without YADE: the
membrane's geometry and pressure forces against closed-form cylinder values, the servo and
membrane-correction laws, and the chunk/series writers."""
from __future__ import annotations

import math

import numpy as np
import pytest

from engines.yade_runtime import control, mesh, series

NT, NZ, R, H = 12, 6, 2.0e-3, 6.0e-3


def _cylinder(nt=NT, nz=NZ, radius=R, height=H):
    x = mesh.node_positions(nt, nz, radius, 0.0, height / nz)
    return x, mesh.triangles(nt, nz)


def test_mesh_topology_closes_around_the_sample_and_faces_outwards():
    x, tri = _cylinder()
    assert x.shape == (NT * (NZ + 1), 3) and tri.shape == (2 * NT * NZ, 3)
    av = mesh.area_vectors(x, tri)
    cen = x[tri].mean(axis=1)
    radial = av[:, 0] * cen[:, 0] + av[:, 1] * cen[:, 1]
    assert np.all(radial > 0)                                  # every normal points outwards
    assert abs(av[:, 2].sum()) < 1e-12 * np.abs(av).sum()     # staggered facets tilt in pairs: no net axial area
    # every edge is shared by two facets except the open top and bottom rows
    e = mesh.edges(tri)
    assert len(e) == NT * NZ * 3 + NT
    assert np.allclose(np.abs(av.sum(axis=0)), 0.0, atol=1e-18)   # closed around the axis


def test_inner_geometry_is_the_polygon_prism_shrunk_by_the_node_radius():
    x, _ = _cylinder()
    rn = 1e-4
    poly_area = 0.5 * NT * R ** 2 * math.sin(2 * math.pi / NT)
    poly_per = 2 * NT * R * math.sin(math.pi / NT)
    g = mesh.inner_geometry(x, NT, rn, 1e-3, 5e-3)
    assert g["volume"] == pytest.approx((poly_area - rn * poly_per + math.pi * rn ** 2) * 4e-3, rel=1e-12)
    assert g["area"] == pytest.approx((poly_per - 2 * math.pi * rn) * 4e-3, rel=1e-12)


def test_pressure_forces_push_inwards_with_p_on_the_inner_surface_and_no_net_force():
    x, tri = _cylinder()
    p, rn = 1.0e5, 1e-4
    f = mesh.pressure_forces(x, tri, NT, rn, p, -1.0, 1.0)      # platens beyond the sheet: all loaded
    assert np.allclose(f.sum(axis=0), 0.0, atol=1e-12 * p * R * H)
    inward = -(f[:, 0] * x[:, 0] + f[:, 1] * x[:, 1]) / np.hypot(x[:, 0], x[:, 1])
    assert np.all(inward > 0)
    # total inward force = p x inner perimeter x height x cos(half a facet angle) on a 12-gon
    per = 2 * NT * R * math.sin(math.pi / NT)
    lateral = per * H                                           # facet area of the centre surface
    expected = p * (per - 2 * math.pi * rn) / per * lateral * math.cos(math.pi / NT)
    assert inward.sum() == pytest.approx(expected, rel=2e-2)    # nodes' radial directions vs facet normals


def test_pressure_loads_only_the_membrane_between_the_platens():
    x, tri = _cylinder()
    dz = H / NZ
    f = mesh.pressure_forces(x, tri, NT, 0.0, 1e5, dz, 2 * dz)    # one row of cells loaded
    loaded = np.linalg.norm(f, axis=1) > 0
    rows = np.nonzero(loaded.reshape(NZ + 1, NT).any(axis=1))[0]
    assert list(rows) == [1, 2]
    half = mesh.pressure_forces(x, tri, NT, 0.0, 1e5, dz, 1.5 * dz)
    assert np.abs(half).sum() == pytest.approx(0.5 * np.abs(f).sum(), rel=1e-12)


def test_neighbour_mean_leaves_a_uniform_motion_undamped():
    x, tri = _cylinder()
    L = mesh.neighbour_mean_matrix(len(x), mesh.edges(tri))
    assert np.allclose(L.sum(axis=1), 1.0)
    v = np.tile([1.0, -2.0, 0.5], (len(x), 1))
    assert np.allclose(v - L @ v, 0.0)
    v[0] += 1.0
    assert np.linalg.norm(v - L @ v) > 0


def test_servo_moves_the_platen_down_under_too_little_stress_and_clips():
    assert control.servo_velocity(0.5, 1.0, 2.0) == pytest.approx(-1.0)
    assert control.servo_velocity(-0.5, 1.0, 2.0) == pytest.approx(1.0)
    assert control.servo_velocity(10.0, 1.0, 2.0) == -2.0
    assert control.servo_velocity(-10.0, 1.0, 2.0) == 2.0
    assert control.ramp(50, 100) == 0.5 and control.ramp(500, 100) == 1.0 and control.ramp(3, 0) == 1.0


def test_drag_ramp_falls_linearly_to_zero():
    assert control.drag_ramp(1000, 1000, 400) == 1.0
    assert control.drag_ramp(1100, 1000, 400) == pytest.approx(0.75)
    assert control.drag_ramp(1400, 1000, 400) == 0.0 and control.drag_ramp(2000, 1000, 400) == 0.0
    assert control.drag_ramp(1000, 1000, 0) == 0.0


def test_servo_pid_settings_reproduce_the_servo_law():
    """YADE's ServoPIDController (v = clip(kP (|F| - target) + iTerm, v_max) along +z, iTerm += kI (|F| -
    target) per update) with the derived settings is the stage-1 law v = -v_max clip(g e + g_i S, -1, 1),
    e = 1 - F/(p A), S the sum of e."""
    p, area, gain, gi, v_max = 3e5, 1.1e-4, 0.7, 0.01, 0.02
    for p_now in (p, 0.3 * p):
        target, kP, kI = control.servo_pid_settings(p_now, area, gain, v_max, p, gi)
        for F in np.linspace(0, 3 * p_now * area, 13):
            v_pid = max(-v_max, min(v_max, kP * (abs(F) - target)))
            assert v_pid == pytest.approx(control.servo_velocity(1 - F / (p_now * area), gain, v_max), abs=1e-15)
        # the integral: five updates at the same error sum to 5 e
        F = 0.9 * p_now * area
        i_term = sum(kI * (F - target) for _ in range(5))
        assert i_term == pytest.approx(-v_max * gi * 5 * control.force_error(F, target))
    target, kP, kI = control.servo_pid_settings(0.0, area, gain, v_max, p)      # ramp start: error 1
    assert max(-v_max, min(v_max, kP * (0.0 - target))) == pytest.approx(-v_max * gain) and kI == 0.0
    assert control.force_error(0.0, 0.0) == 1.0


def test_membrane_correction_raises_the_pressure_when_the_grains_feel_less_and_stays_bounded():
    corr, avg = control.membrane_correction(1.0, None, 0.9e5, 1e5, 20, 0.5, 0.1)
    assert avg == 0.9e5 and corr == pytest.approx(1 + 0.5 / 20 * (1 / 0.9 - 1))
    for _ in range(10000):
        corr, avg = control.membrane_correction(corr, avg, 0.5e5, 1e5, 20, 0.5, 0.1)
    assert corr == pytest.approx(1.1)
    corr, avg = control.membrane_correction(1.0, 1e5, 1e5, 1e5, 20, 0.5, 0.1)
    assert corr == 1.0
    assert control.iso_converged(1.01e5, 0.99e5, 1e5, 0.02) and not control.iso_converged(1.03e5, 1e5, 1e5, 0.02)
    # the drag stage's creep test: relative change of the chunk-mean volume below the tolerance, never
    # before a last chunk exists
    assert control.creep_settled(1.0002, 1.0, 3e-4) and not control.creep_settled(0.9995, 1.0, 3e-4)
    assert not control.creep_settled(1.0, 0.0, 3e-4)


def test_window_series_rows_are_means_of_the_samples(tmp_path):
    name = str(tmp_path / "walls.npy")
    w = series.WindowSeries(name, n_values=2, window=3)
    for k in range(7):
        w.add(10 * (k + 1), [k, 2.0 * k])
    w.flush()
    rows = np.load(name)
    assert rows.tolist() == [[30.0, 1.0, 2.0], [60.0, 4.0, 8.0]]
    with pytest.raises(ValueError, match="3 values, expected 2"):
        w.add(1, [1, 2, 3])


def test_chunk_arrays_stack_frames_and_concatenate_contacts(tmp_path):
    buf = {"iter": [1, 2], "time": [0.1, 0.2], "position": [[(0, 0, 0)], [(1, 1, 1)]],
           "c_count": [2, 1], "c_i": [np.array([1, 2]), np.array([3])]}
    out = series.chunk_arrays(buf)
    assert out["position"].shape == (2, 1, 3) and out["c_i"].tolist() == [1, 2, 3]
    assert out["c_count"].tolist() == [2, 1]
    series.save_npz_atomic(str(tmp_path / "c.npz"), **out)
    with np.load(tmp_path / "c.npz") as z:
        assert z["c_i"].tolist() == [1, 2, 3]
    assert not list(tmp_path.glob("*.partial*"))


def test_reopen_series_keeps_rows_up_to_the_checkpoint_and_drops_a_cut_line(tmp_path):
    f = tmp_path / "triax.txt"
    f.write_text("# iter a\n10 1\n20 2\n30 3\n40 4")        # last line cut by the kill
    fh = series.reopen_series(str(f), 20)
    fh.write("30 9\n")
    fh.close()
    assert f.read_text() == "# iter a\n10 1\n20 2\n30 9\n"


def test_stability_history_patch_reaches_the_yade_monitor():
    """The stability history (orchestrator.stability.history, through the adapter's
    print_monitors) patches a rendered YADE deck so that the monitor (yade_runtime/monitors.py)
    trips at the given overlap and prints its figures at every check."""
    from pathlib import Path

    from engines.yade import Yade
    golden = Path(__file__).parent / "golden" / "shear_cell_smoke__yade.golden"
    text = Yade().print_monitors(golden.read_text(), 4.0)
    lines = text.splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith("ORCH_MON = json.loads("))
    assert lines[k + 1:k + 3] == ["ORCH_MON['overlap_limit'] = 4.0", "ORCH_MON['print_figures'] = True"]


def test_shell_pressure_puts_p_on_the_envelope_of_each_cell():
    """A ring of equal grains at radius R0 around an inner core: every ring grain is on its cell's
    shell, the core is not; the total inward force is p times the envelope area sum_c (2 pi/S) R_c h
    with R_c = R0 + r, and the volume is pi R_c^2 H (the LIGGGHTS deck's law)."""
    from engines.yade_runtime import shell
    r, R0, H, p = 1e-4, 2e-3, 4e-3, 1e5
    th = np.linspace(0, 2 * np.pi, 64, endpoint=False) + 0.01
    zs = np.linspace(0.5e-3, 3.5e-3, 8)
    ring = np.array([(R0 * np.cos(t), R0 * np.sin(t), z) for z in zs for t in th])
    core = np.array([(0.3 * R0 * np.cos(t), 0.3 * R0 * np.sin(t), z) for z in zs for t in th[::8]])
    pos = np.vstack([ring, core])
    rad = np.full(len(pos), r)
    f, flat, area, volume = shell.shell_forces(pos, rad, 0.0, H, p, bands=4, sectors=8, w=0.5 * r)
    Rc = R0 + r
    assert area == pytest.approx(2 * np.pi * Rc * H, rel=1e-12)
    assert volume == pytest.approx(np.pi * Rc ** 2 * H, rel=1e-12)
    assert flat == pytest.approx(p * area, rel=1e-12)
    assert np.all(f[len(ring):] == 0.0) and np.all(f[:, 2] == 0.0)
    inward = -(f[:len(ring), 0] * ring[:, 0] + f[:len(ring), 1] * ring[:, 1]) / R0
    assert np.allclose(inward, p * area / len(ring), rtol=1e-9)      # equal grains share equally
    assert np.allclose(f.sum(axis=0), 0.0, atol=1e-12 * flat)


def test_shell_cells_clamp_grains_beyond_the_platens_and_the_seam():
    from engines.yade_runtime import shell
    pos = np.array([(1.0, 0.0, -0.1), (1.0, 0.0, 1.2), (-1.0, -1e-18, 0.5), (-1.0, 0.0, 0.5)])
    c = shell.cells(pos, 0.0, 1.0, bands=2, sectors=4)
    assert c.tolist() == [0 * 4 + 2, 1 * 4 + 2, 1 * 4 + 0, 1 * 4 + 3]


def test_yade_membrane_substitute_is_recorded_and_unknown_names_are_refused():
    """YADE has a membrane, yet a case may name ``yade.membrane: shell_pressure`` (the LIGGGHTS
    boundary, for like-for-like runs): recorded as a substitution; another name is refused."""
    from engines.base import UnsupportedFeature
    from engines.yade import Yade
    eng = Yade()
    feats = ["hertz", "membrane"]
    assert eng.check(feats, {}) == [] and eng.check(feats, {"liggghts.membrane": "shell_pressure"}) == []
    subs = eng.check(feats, {"yade.membrane": "shell_pressure"})
    assert [(s.feature, s.mechanism) for s in subs] == [("membrane", "shell_pressure")]
    with pytest.raises(UnsupportedFeature, match="yade.membrane: rubber' is not offered"):
        eng.check(feats, {"yade.membrane": "rubber"})
