"""Synthetic scans with ground truth shared by the CT tests (small volumes, generated once)."""
import numpy as np
import pytest

from orchestrator.ct import segment, synth

VS = 1e-5            # voxel size [m]


@pytest.fixture(scope="session")
def sphere_packing():
    """700 polydisperse spheres, 10-15 voxels across, touching (packing fraction ~0.49), in a
    120^3 scan with PSF blur, noise of 10 % of the contrast, 10 % hollow grains, 5 % drift."""
    rng = np.random.default_rng(0)
    n = 700
    r = rng.uniform(5.0, 7.5, n) * VS
    c = synth.pack_spheres(r, box=((2 * VS,) * 3, (118 * VS,) * 3), seed=1)
    hollow = np.where(rng.random(n) < 0.1, 0.5, 0.0)
    scan = synth.render_scan((120, 120, 120), VS, c, r, hollow=hollow, noise=0.1, psf_sigma=0.8,
                             drift=0.05, seed=3)
    seg = segment.segment(scan)
    return dict(centres=c, radii=r, hollow=hollow, scan=scan, seg=seg)
