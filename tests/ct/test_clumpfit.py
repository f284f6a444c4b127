"""Clumps from CT grains (orchestrator.ct.clumpfit): spheres and unions of spheres are recovered,
irregular grains rendered by synth are matched in volume and shape, libraries load in
orchestrator.clumps, and `orchestrator ct shapes` makes one from a scan or a label volume."""
import numpy as np
import pytest
import yaml

from orchestrator.clumps import LibraryError, load_library, mass_properties
from orchestrator.ct import clumpfit, segment, synth
from orchestrator.ct.cli import main
from orchestrator.ct.io import Scan, write_scan

VS = 1e-5


def _spheres_mask(n, centres, radii):
    """Voxels [z, y, x] of an n^3 grid whose centre (x, y, z) lies in one of the spheres [voxels]."""
    z, y, x = np.indices((n, n, n))
    m = np.zeros((n, n, n), bool)
    for (cx, cy, cz), r in zip(centres, radii):
        m |= (x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2 <= r * r
    return m


def _to_voxels(spheres, mask):
    """Spheres [x, y, z, r] [m] about the mask's centroid -> [x, y, z, r] in the mask's voxel coordinates."""
    c = np.argwhere(mask).mean(axis=0)[::-1]
    return spheres / VS + np.r_[c, 0.0]


def _sh_grain_mask(coefs, seed):
    """One irregular grain rendered with partial volume (synth.render_phase), solid fraction >= 0.5."""
    rad = synth._GridRadial(coefs, coefs.shape[0] - 1)
    n = int(2 * rad.rmax / VS) + 4
    rot = synth._random_rotation(np.random.default_rng(seed))
    phase = synth.render_phase((n, n, n), VS, [synth.Grain(np.full(3, (n - 1) / 2 * VS), rad.rmax, rad, rot)],
                               supersample=3)
    return phase >= 0.5


@pytest.mark.parametrize("centre, radius", [((15.5, 15.3, 14.8), 9.6), ((12.2, 12.7, 11.4), 6.3)])
def test_a_sphere_is_one_sphere(centre, radius):
    """Measured: centre within 0.094 voxel, radius within 0.031 voxel, volume ratio 1.010-1.013."""
    m = _spheres_mask(32, [centre], [radius])
    s = _to_voxels(clumpfit.fit_clump(m, VS), m)
    assert s.shape == (1, 4)
    assert np.linalg.norm(s[0, :3] - centre) < 0.3
    assert abs(s[0, 3] - radius) < 0.3
    q = clumpfit.clump_quality(m, VS, clumpfit.fit_clump(m, VS))
    assert q["coverage"] > 0.99 and q["outside"] < 0.03 and q["n_spheres"] == 1


def test_two_overlapping_spheres_are_recovered():
    """Measured: centres on the true ones, radii 10.05 and 8.06 for 10 and 8 (the EDT radius: distance
    to the nearest voxel outside, sqrt(101) and sqrt(65))."""
    true = np.array([[18, 22, 24, 10], [30, 24, 23, 8]], float)
    m = _spheres_mask(48, true[:, :3], true[:, 3])
    s = _to_voxels(clumpfit.fit_clump(m, VS, n_spheres=6), m)
    assert len(s) == 2
    for t, f in zip(true, s):                       # largest first
        assert np.linalg.norm(f[:3] - t[:3]) < 0.5 and abs(f[3] - t[3]) < 0.5
    # without refinement the spheres are inscribed: not one voxel of the union outside the grain
    q = clumpfit.clump_quality(m, VS, clumpfit.fit_clump(m, VS, refine=False))
    assert q["outside"] == 0.0 and q["coverage"] > 0.98


def test_irregular_grains_volume_coverage_and_shape():
    """Four SH grains (degree 15, roughness 0.15, r0 10 voxels) with 8 spheres. Measured: volume
    ratio 0.977-1.035, coverage 0.915-0.956, outside 0.060-0.083; clump minus grain: sphericity
    -0.005..0.042, elongation -0.011..0.011, flatness 0.010..0.025, hull ratio -0.059..0.002; the
    union's volume by orchestrator.clumps.mass_properties within 0.5 % of the voxel count. Over 8
    such grains: 0.977-1.035, 0.915-0.956, 0.049-0.083 (6 spheres: 0.953-1.033, 0.888-0.940,
    0.065-0.096)."""
    coefs = synth.random_sh_grains(4, 10 * VS, roughness=0.15, seed=3)
    limits = {"sphericity": 0.06, "elongation": 0.03, "flatness": 0.04, "hull_ratio": 0.07}
    rows = []
    for k, c in enumerate(coefs):
        m = _sh_grain_mask(c, k)
        s = clumpfit.fit_clump(m, VS, n_spheres=8)
        q = clumpfit.clump_quality(m, VS, s)
        rows.append(q)
        assert 0.95 <= q["volume_ratio"] <= 1.05
        assert q["coverage"] >= 0.90
        assert q["outside"] <= 0.10
        assert 2 <= len(s) <= 8
        for f, lim in limits.items():
            assert abs(q[f"{f}_clump"] - q[f"{f}_grain"]) < lim, f
        # the union's volume by orchestrator.clumps' own grid integration agrees with the voxel count
        assert mass_properties(s)["volume"] == pytest.approx(q["volume_ratio"] * m.sum() * VS ** 3, rel=0.02)
    print("\nclumpfit, 4 SH grains, 8 spheres: " + "; ".join(
        f"vol {q['volume_ratio']:.3f} cov {q['coverage']:.3f} out {q['outside']:.3f} "
        f"elong {q['elongation_grain']:.3f}/{q['elongation_clump']:.3f}" for q in rows))


def test_written_library_loads(tmp_path):
    m1 = _spheres_mask(32, [(15.5, 15.3, 14.8)], [9.6])
    m2 = _spheres_mask(48, [(18, 22, 24), (30, 24, 23)], [10, 8])
    shapes = [clumpfit.fit_clump(m, VS) for m in (m1, m2)]
    quality = [clumpfit.clump_quality(m, VS, s) for m, s in zip((m1, m2), shapes)]
    p = clumpfit.write_shape_library(tmp_path / "lib.yaml", shapes, ["ball", "pair"], meta={"seed": 7},
                                     quality=quality, comment="test library\nsecond line")
    lib = load_library(p)
    assert len(lib) == 2 and [len(s) for s in lib] == [1, 2]
    for a, b in zip(lib, shapes):
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-11)
    text = p.read_text()
    assert text.startswith("# test library\n# second line\n")
    doc = yaml.safe_load(text)
    assert doc["meta"]["seed"] == 7 and doc["meta"]["unit"] == "m"
    assert [s["name"] for s in doc["shapes"]] == ["ball", "pair"]
    assert doc["shapes"][1]["quality"]["n_spheres"] == 2
    assert not list(tmp_path.glob("*.partial"))
    apart = np.array([[0, 0, 0, 1.0], [5, 0, 0, 1.0]])
    with pytest.raises(LibraryError, match=r"shape 1 \(b\)"):
        clumpfit.write_shape_library(tmp_path / "bad.yaml", [shapes[0], apart], ["a", "b"])
    assert not (tmp_path / "bad.yaml").exists()


@pytest.fixture(scope="module")
def small_scan(tmp_path_factory):
    """Five irregular grains (r0 8 voxels) in a 64^3 scan, not touching; the fifth is cut by the
    border. PSF 0.8 voxel, noise 5 % of the contrast."""
    coefs = synth.random_sh_grains(5, 8 * VS, roughness=0.12, seed=11)
    centres = np.array([[20, 20, 20], [44, 20, 44], [20, 44, 44], [44, 44, 20], [1, 32, 32]], float) * VS
    rng = np.random.default_rng(12)
    grains = [synth.Grain(p, r.rmax, r, synth._random_rotation(rng))
              for p, r in zip(centres, (synth._GridRadial(c, 15) for c in coefs))]
    scan = synth.render_scan((64, 64, 64), VS, None, grains=grains, supersample=3, psf_sigma=0.8, noise=0.05, seed=13)
    d = tmp_path_factory.mktemp("clumpscan")
    write_scan(scan, d / "scan.tif")
    return d / "scan.tif", scan


def test_library_from_segmentation_skips_border_grains(small_scan):
    _, scan = small_scan
    seg = segment.segment(scan, h=2 * VS)
    g = seg.grains
    assert len(g) == 5 and g["at_border"].sum() == 1
    shapes, q = clumpfit.shape_library_from_segmentation(seg, n_spheres=4, min_voxels=500)
    assert len(shapes) == 4 and len(q) == 4
    assert set(q["label"]) == set(g.loc[~g["at_border"], "label"])
    assert (q["volume_ratio"].between(0.9, 1.1)).all() and (q["coverage"] >= 0.85).all()


def test_cli_shapes_from_scan_and_from_labels(small_scan, tmp_path, capsys):
    path, _ = small_scan
    out = tmp_path / "lib.yaml"
    assert main(["ct", "shapes", str(path), "-o", str(out), "--spheres", "3", "--min-voxels", "500",
                 "--h", "20 um"]) == 0
    lib = load_library(out)
    assert len(lib) == 4 and all(1 <= len(s) <= 3 for s in lib)
    doc = yaml.safe_load(out.read_text())
    assert doc["meta"]["source"] == str(path) and doc["meta"]["n_spheres"] == 3
    # the same from `ct segment --labels` output
    assert main(["ct", "segment", str(path), "--out", str(tmp_path / "seg"), "--labels", "--no-shape",
                 "--h", "20 um"]) == 0
    out2 = tmp_path / "lib2.yaml"
    assert main(["ct", "shapes", str(tmp_path / "seg" / "scan_labels.tif"), "-o", str(out2), "--spheres", "3",
                 "--min-voxels", "500"]) == 0
    lib2 = load_library(out2)
    assert len(lib2) == 4
    for a, b in zip(lib, lib2):
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-11)


def test_cli_shapes_bad_input_exits_2_with_one_message(tmp_path, capsys):
    missing = tmp_path / "nope.tif"
    assert main(["ct", "shapes", str(missing), "-o", str(tmp_path / "lib.yaml")]) == 2
    err = capsys.readouterr().err
    assert "nope.tif: no such file or directory" in err and "Traceback" not in err
    write_scan(Scan(np.ones((5, 5, 5), np.uint16), VS), tmp_path / "x_labels.tif")
    assert main(["ct", "shapes", str(tmp_path / "x_labels.tif"), "-o", str(tmp_path / "lib.yaml")]) == 2
    err = capsys.readouterr().err
    assert "x_grains.csv" in err and "ct segment --labels" in err
    assert main(["ct", "shapes", str(missing), "-o", str(tmp_path / "lib.txt")]) == 2
    assert "lib.txt" in capsys.readouterr().err
    assert main(["ct", "shapes", str(missing), "-o", str(tmp_path / "lib.yaml"), "--spheres", "0"]) == 2
    assert "--spheres 0" in capsys.readouterr().err
    write_scan(Scan(np.full((8, 8, 8), 7, np.uint16), VS), tmp_path / "flat.tif")
    assert main(["ct", "shapes", str(tmp_path / "flat.tif"), "-o", str(tmp_path / "lib.yaml")]) == 2
    assert "single grey value" in capsys.readouterr().err
    assert not (tmp_path / "lib.yaml").exists()
