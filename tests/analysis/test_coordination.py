import numpy as np
import pytest

from orchestrator.analysis.coordination import analyze_coordination, coordination_from_pairs, neighbor_counts
from orchestrator.analysis.containers import make_container
from orchestrator.analysis.neighbors import geometric_contacts
from orchestrator.frames import Frames, write_frames

D = 30e-6


def _lattice(kind, n=7):
    g = np.arange(n)
    cells = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3).astype(float)
    if kind == "sc":
        return cells * D, 0.5 * D
    if kind == "bcc":
        a = 2 * D / np.sqrt(3)
        return np.concatenate([cells, cells + 0.5]) * a, 0.5 * D
    if kind == "fcc":
        a = np.sqrt(2) * D
        base = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]])
        return (cells[:, None, :] + base[None]).reshape(-1, 3) * a, 0.5 * D


@pytest.mark.parametrize("kind,z", [("sc", 6), ("bcc", 8), ("fcc", 12)])
def test_lattice_coordination_from_geometry(kind, z):
    p, r = _lattice(kind)
    rad = np.full(len(p), r)
    i, j = geometric_contacts(p, rad, tolerance=0.01)
    zz = coordination_from_pairs(len(p), i, j)
    dist = make_container("box", p).distance_to_boundary(p)
    inner = dist > 1.01 * D
    assert np.all(zz[inner] == z)
    assert np.all(zz[dist < 1e-3 * D] < z)          # particles on the surface lose neighbours


def test_analyze_coordination_contacts_walls_and_rattlers(tmp_path):
    p, r = _lattice("fcc", 4)
    n = len(p)
    ids = np.arange(n) + 1000
    i, j = geometric_contacts(p, np.full(n, r), 0.01)
    wall = -1                                           # wall contacts: id that is no particle
    ci = np.r_[ids[i], ids[0], ids[1]]
    cj = np.r_[ids[j], wall, wall]
    pos = np.stack([p, p])
    pos[1, n - 1] = np.nan
    fr = Frames(write_frames(tmp_path / "f.h5", ids, np.full(n, r), [0, 1], pos,
                             contacts={0: {"i": ci, "j": cj}}))
    res = analyze_coordination(fr, tolerance=0.01)
    s = res.tables["summary"]
    assert list(s["source"]) == ["contacts", "geometry"]
    zc = res.tables["particles"].query("frame == 0").set_index("id")["z"]
    zg = res.tables["particles"].query("frame == 1").set_index("id")["z"]
    # the contact list and the geometry agree on a particle whose neighbours are all present
    assert zc.loc[ids[0]] == zg.loc[ids[0]] == 3
    assert ids[n - 1] not in zg.index                      # absent particle not counted
    res_w = analyze_coordination(fr, at=[0], include_walls=True, tolerance=0.01)
    zw = res_w.tables["particles"].set_index("id")["z"]
    assert zw.loc[ids[0]] == zc.loc[ids[0]] + 1
    assert s["mean_z"].iloc[0] == pytest.approx(2 * len(i) / n)
    assert res.tables["distribution"].groupby("frame")["p"].sum().round(12).eq(1).all()


def test_neighbor_counts():
    p, r = _lattice("sc", 5)
    c = neighbor_counts(p, 1.01 * D)
    assert c.max() == 6 and c.min() == 3
