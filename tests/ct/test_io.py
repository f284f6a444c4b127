"""Reading and writing scans; clear errors for unreadable or inconsistent scans."""
import numpy as np
import pytest
import tifffile

from orchestrator.ct.io import Scan, ScanError, check_series, read_scan, read_series, write_scan


def _scan(shape=(6, 7, 8), vs=2.2e-6, origin=(1e-3, 2e-3, 3e-3), seed=0):
    v = np.random.default_rng(seed).integers(0, 60000, shape).astype(np.uint16)
    return Scan(v, vs, origin, time=1.5, controls={"angle": 0.1})


def test_tiff_roundtrip_keeps_voxel_size_origin_time(tmp_path):
    s = _scan()
    write_scan(s, tmp_path / "a.tif")
    r = read_scan(tmp_path / "a.tif")
    assert np.array_equal(r.volume, s.volume)
    assert r.voxel_size == pytest.approx(2.2e-6)
    assert np.allclose(r.origin, s.origin)
    assert r.time == 1.5 and r.controls == {"angle": 0.1}
    # world coordinates: voxel [k, j, i] -> origin + vs * (i, j, k)
    assert np.allclose(r.to_world([1, 2, 3]), np.array(s.origin) + 2.2e-6 * np.array([3, 2, 1]))
    assert np.allclose(r.to_voxel(r.to_world([1.5, 2, 3])), [1.5, 2, 3])


def test_imagej_spacing_is_read(tmp_path):
    v = np.zeros((3, 4, 5), np.uint8)
    tifffile.imwrite(tmp_path / "ij.tif", v, imagej=True, resolution=(1 / 3.0, 1 / 3.0),
                     metadata={"spacing": 3.0, "unit": "um", "axes": "ZYX"})
    assert read_scan(tmp_path / "ij.tif").voxel_size == pytest.approx(3e-6)


def test_stack_npy_raw(tmp_path):
    s = _scan()
    d = tmp_path / "stack"
    d.mkdir()
    for k in range(s.shape[0]):
        tifffile.imwrite(d / f"slice_{k}.tif", s.volume[k])     # natural order: 0, 1, ... 10
    r = read_scan(d, voxel_size=2.2e-6)
    assert np.array_equal(r.volume, s.volume)
    r = read_scan(str(d / "slice_*.tif"), voxel_size=2.2e-6)
    assert np.array_equal(r.volume, s.volume)
    write_scan(s, tmp_path / "a.npy")
    r = read_scan(tmp_path / "a.npy")
    assert np.array_equal(r.volume, s.volume) and r.voxel_size == pytest.approx(2.2e-6)
    s.volume.astype(">u2").tofile(tmp_path / "a.raw")
    r = read_scan(tmp_path / "a.raw", shape=s.shape, dtype="uint16", byte_order=">", voxel_size=2.2e-6)
    assert np.array_equal(r.volume, s.volume)
    r = read_scan(s.volume, voxel_size=1e-6)
    assert r.shape == s.shape


def test_clear_errors(tmp_path):
    with pytest.raises(ScanError, match="no such file"):
        read_scan(tmp_path / "missing.tif", voxel_size=1e-6)
    (tmp_path / "bad.tif").write_bytes(b"this is not a tiff")
    with pytest.raises(ScanError, match=r"bad\.tif: cannot read as TIFF"):
        read_scan(tmp_path / "bad.tif", voxel_size=1e-6)
    np.zeros(100, np.uint16).tofile(tmp_path / "a.raw")
    with pytest.raises(ScanError, match=r"a\.raw: file has 200 bytes, but shape \(5, 5, 5\)"):
        read_scan(tmp_path / "a.raw", shape=(5, 5, 5), dtype="uint16", voxel_size=1e-6)
    with pytest.raises(ScanError, match="needs shape"):
        read_scan(tmp_path / "a.raw", voxel_size=1e-6)
    tifffile.imwrite(tmp_path / "novs.tif", np.zeros((2, 3, 3), np.uint8))
    with pytest.raises(ScanError, match="no voxel size"):
        read_scan(tmp_path / "novs.tif")
    with pytest.raises(ScanError, match="metres"):
        Scan(np.zeros((2, 2, 2)), 2.2)          # 2.2 "um" given as metres
    d = tmp_path / "stack"
    d.mkdir()
    tifffile.imwrite(d / "s0.tif", np.zeros((4, 4), np.uint8))
    tifffile.imwrite(d / "s1.tif", np.zeros((4, 5), np.uint8))
    with pytest.raises(ScanError, match=r"s1\.tif: slice 1 .* has shape \(4, 5\).*s0\.tif has \(4, 4\)"):
        read_scan(d, voxel_size=1e-6)


def test_inconsistent_series_names_file_and_difference(tmp_path):
    a = _scan()
    b = _scan(shape=(6, 7, 9))
    write_scan(a, tmp_path / "scan_0.tif")
    write_scan(b, tmp_path / "scan_1.tif")
    with pytest.raises(ScanError, match=r"scan_1\.tif: shape \(6, 7, 9\) differs from \(6, 7, 8\)"):
        read_series([tmp_path / "scan_0.tif", tmp_path / "scan_1.tif"])
    c = Scan(a.volume, 2.3e-6, a.origin, source="c.tif")
    with pytest.raises(ScanError, match=r"c\.tif: voxel size 2\.3e-06 m differs from 2\.2e-06 m"):
        check_series([a, c])
    ok = read_series(str(tmp_path / "scan_0.tif"))
    assert len(ok) == 1
