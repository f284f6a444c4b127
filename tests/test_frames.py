"""frames.h5: the layout of DESIGN.md, NaN rows, contacts, walls, atomic writes, tables, VTK."""
from __future__ import annotations

import subprocess

import h5py
import numpy as np
import pytest

from orchestrator.frames import FrameWriter, Frames, load, write_frames


def make(path, T=4, N=5, **kw):
    rng = np.random.default_rng(0)
    pos = rng.random((T, N, 3))
    pos[1, 2] = np.nan                         # particle id 12 absent from frame 1
    vel = rng.random((T, N, 3))
    write_frames(path, ids=np.arange(10, 10 + N), radius=np.full(N, 1e-5), time=np.arange(T) * 0.1,
                 position=pos, velocity=vel, controls={"angle": np.linspace(0, 0.1, T)},
                 contacts={2: {"i": [10, 11], "j": [11, 12], "point": np.zeros((2, 3)),
                               "normal": [[1, 0, 0], [0, 1, 0]], "fn": np.ones((2, 3)), "ft": np.zeros((2, 3))}},
                 walls={"piston": {"time": [0, 1], "force": [[0, 0, 1], [0, 0, 2]]}},
                 meta={"engine": "test", "case": {"name": "x"}}, **kw)
    return pos, vel


def test_layout_matches_design(tmp_path):
    make(tmp_path / "frames.h5")
    with h5py.File(tmp_path / "frames.h5") as h:
        for name in ("particles/id", "particles/radius", "frames/time", "frames/step", "frames/angle",
                     "frames/position", "frames/velocity", "contacts/2/i", "contacts/2/fn", "walls/piston/force"):
            assert name in h, name
        assert h["frames/position"].shape == (4, 5, 3)
        assert h["meta"].attrs["engine"] == "test"
        assert "units" in h["meta"].attrs


def test_a_finished_file_opens_while_a_process_holds_its_writers_descriptor(tmp_path):
    """A process forked by another thread (a threaded sweep starting an engine) holds, until its exec
    closes it, a copy of the descriptor of a frames file being written, and with it HDF5's exclusive
    lock. Here a child keeps that copy for as long as the test needs (``close_fds=False``: HDF5's
    descriptor is inheritable, Python's own are not), so the race is not left to timing: the renamed,
    finished file must still open through ``Frames`` (with HDF5's lock it fails with errno 11;
    benchmarks/bench_h5_lock.py counts how often the real race hits)."""
    path = tmp_path / "frames.h5"
    writer = FrameWriter(path, ids=np.arange(3), radius=np.full(3, 1e-5))
    writer.append(0.0, position=np.ones((3, 3)))
    child = subprocess.Popen(["sleep", "60"], close_fds=False)
    try:
        writer.close()
        np.testing.assert_array_equal(load(path).position, np.ones((1, 3, 3)))
    finally:
        child.kill()
        child.wait()


def test_round_trip_and_nan_rows(tmp_path):
    pos, vel = make(tmp_path / "frames.h5")
    fr = load(tmp_path)                           # a run directory works too
    np.testing.assert_array_equal(fr.position, pos)
    np.testing.assert_array_equal(fr.velocity, vel)
    assert fr.ids.tolist() == [10, 11, 12, 13, 14]
    assert fr.angle[-1] == pytest.approx(0.1)
    f1 = fr[1]
    assert not f1.present()[2] and f1.present().sum() == 4
    df = f1.to_dataframe()
    assert len(df) == 4 and 12 not in df.id.values
    assert {"x", "y", "z", "vx", "vy", "vz", "radius"} <= set(df.columns)
    assert fr.meta["case"] == {"name": "x"}


def test_contacts_and_walls_as_tables(tmp_path):
    make(tmp_path / "frames.h5")
    fr = Frames(tmp_path / "frames.h5")
    c = fr.contacts(2)
    assert c.i.tolist() == [10, 11] and "fn_z" in c.columns
    with pytest.raises(KeyError, match="no contacts"):
        fr.contacts(0)
    assert fr.wall("piston").force_z.tolist() == [1.0, 2.0]


def test_writer_is_atomic(tmp_path):
    path = tmp_path / "frames.h5"
    with pytest.raises(RuntimeError):
        with FrameWriter(path, [1, 2], [1.0, 1.0]) as w:
            w.append(0.0, position=np.zeros((2, 3)))
            raise RuntimeError("engine died")
    assert not path.exists() and not (tmp_path / "frames.h5.partial").exists()
    w = FrameWriter(path, [1, 2], [1.0, 1.0])
    w.append(0.0, position=np.zeros((2, 3)))
    assert not path.exists()                      # only a .partial until close
    w.close()
    assert Frames(path).n_frames == 1


def test_writer_checks_shapes_and_declared_fields(tmp_path):
    w = FrameWriter(tmp_path / "f.h5", [1, 2], [1.0, 1.0], fields=("position",))
    with pytest.raises(ValueError, match="expected shape"):
        w.append(0.0, position=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="not declared"):
        w.append(0.0, position=np.zeros((2, 3)), velocity=np.zeros((2, 3)))
    w.abort()


def test_buffered_writes_span_blocks(tmp_path, monkeypatch):
    monkeypatch.setattr(FrameWriter, "BUFFER_BYTES", 1000)    # force many flushes
    pos = np.random.default_rng(1).random((50, 20, 3))
    write_frames(tmp_path / "f.h5", np.arange(20), np.ones(20), np.arange(50.0), pos)
    np.testing.assert_array_equal(Frames(tmp_path / "f.h5").position, pos)


def test_vtk_export_readable(tmp_path):
    import meshio
    pos, _ = make(tmp_path / "frames.h5")
    out = Frames(tmp_path / "frames.h5").to_vtk(1, tmp_path / "f1.vtu")
    m = meshio.read(out)
    assert m.points.shape == (4, 3)                           # the absent particle is left out
    np.testing.assert_allclose(m.point_data["radius"], 1e-5)
    assert set(m.point_data["id"].tolist()) == {10, 11, 13, 14}


def test_a_wall_group_with_a_membrane_mesh_reads_as_a_table(tmp_path):
    """A YADE triaxial's ``membrane`` group holds per-frame node positions (S, nodes, 3), its
    triangles and a node radius beside ``time``: ``wall`` gives the per-sample columns as a table and
    the rest in ``attrs`` (it raised pandas' "Per-column arrays must each be 1-dimensional", and so
    did ``walls`` on every YADE triaxial run)."""
    nodes = np.arange(2 * 4 * 3, dtype=float).reshape(2, 4, 3)
    tri = np.array([[0, 1, 2], [1, 2, 3], [0, 2, 3]])
    write_frames(tmp_path / "m.h5", ids=np.arange(2), radius=np.full(2, 1e-5), time=[0.0, 0.1],
                 position=np.zeros((2, 2, 3)),
                 walls={"membrane": {"time": [0.0, 1.0], "step": [0, 10], "node_position": nodes,
                                     "triangles": tri, "node_radius": [1e-4]},
                        "platen": {"time": [0.0, 1.0], "force": [[0, 0, 1], [0, 0, 2]]}})
    fr = Frames(tmp_path / "m.h5")
    m = fr.wall("membrane")
    assert list(m.columns) == ["step", "time"] and m.step.tolist() == [0, 10]
    np.testing.assert_array_equal(m.attrs["node_position"], nodes)
    np.testing.assert_array_equal(m.attrs["triangles"], tri)
    assert set(fr.walls) == {"membrane", "platen"} and fr.walls["platen"].force_z.tolist() == [1.0, 2.0]
