"""Contact detection you can count (issue 17 item 1): rendered packings with a known contact list.

The packings come from :func:`orchestrator.ct.synth.contact_packing`: DEM-like contacts (overlap
at most 1 % of the radii sum) and every other pair at least 0.5 voxel apart. Face-adjacent labels
alone report every pair closer than about 1.5 voxels; the local greyscale test of
``Segmentation.contacts`` must bring precision >= 0.95 at recall >= 0.98.
"""
import numpy as np
import pytest
from scipy.special import erf

from orchestrator.ct import segment, synth

VS = 1e-5


def _score(radius_range, psf, noise, size, seed=0):
    c, r, con = synth.contact_packing((size,) * 3, VS, radius_range, seed=seed)
    scan = synth.render_scan((size,) * 3, VS, c, r, noise=noise, psf_sigma=psf, drift=0.05,
                             seed=seed + 2, supersample=3)
    seg = segment.segment(scan)
    s = synth.score_contacts(seg, c, r, con)
    s["blur_sigma"] = seg.blur_sigma()
    print(f"\ncontacts {2 * radius_range[0]:.0f}-{2 * radius_range[1]:.0f} voxels across, PSF {psf}, "
          f"noise {noise:.0%}: {s['true']} true, {s['candidates']} candidates -> {s['detected']} detected, "
          f"precision {s['precision']:.3f} recall {s['recall']:.3f}; Z true {s['z_true']:.2f}, "
          f"candidates {s['z_candidates']:.2f}, refined {s['z_refined']:.2f}; normal error median "
          f"{s['normal_err_median_deg']:.1f} deg")
    return s


def test_gap_fraction_is_the_blurred_slab_for_flat_surfaces():
    s = 1.3
    for g in (0.0, 0.3, 1.0, 2.5):
        assert segment.gap_fraction(g, 1e9, 1e9, s) == pytest.approx(1 - erf(g / (2 * np.sqrt(2) * s)), abs=1e-6)
    # curvature opens the gap around the contact point: smaller grains look less solid there
    assert segment.gap_fraction(0.0, 4.0, 4.0, s) < segment.gap_fraction(0.0, 12.0, 12.0, s) < 1.0
    assert segment.gap_fraction(0.5, 6.0, 6.0, s) < segment.gap_fraction(0.3, 6.0, 6.0, s)


def test_precision_and_recall_on_a_packing_with_known_contacts():
    s = _score((5.0, 7.5), 0.8, 0.10, 80)
    assert s["recall_candidates"] == 1.0
    assert s["precision"] >= 0.95
    assert s["recall"] >= 0.98
    assert s["candidates"] > 1.2 * s["true"]                 # the refinement had something to remove
    assert abs(s["z_refined"] - s["z_true"]) < 0.1 * s["z_true"]
    assert s["normal_err_median_deg"] < 8.0
    assert s["blur_sigma"] == pytest.approx(np.hypot(0.8, 1.0), rel=0.12)


@pytest.mark.slow
@pytest.mark.parametrize("radius_range, psf, noise, size", [
    ((4.0, 5.0), 0.5, 0.03, 96),            # 8-10 voxels: needs the scale-aware merge height
    ((5.0, 6.0), 0.8, 0.06, 96),
    ((6.0, 8.0), 1.2, 0.10, 96),
    ((8.0, 10.0), 1.2, 0.10, 96),
    ((12.0, 13.4), 0.8, 0.06, 96),          # the DEM packing: 12.7 voxels per radius
])
def test_precision_and_recall_over_psf_noise_and_size(radius_range, psf, noise, size):
    s = _score(radius_range, psf, noise, size)
    assert s["precision"] >= 0.95
    assert s["recall"] >= 0.98
