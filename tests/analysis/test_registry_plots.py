import json

import numpy as np
import pytest
from matplotlib.figure import Figure

from orchestrator.analysis import ANALYSES, parse_specs, run_analyses
from orchestrator.analysis import plots

FAST = {"shearband": {"control": "angle", "bins_z": 10}, "profiles": {"bins_z": 10, "bins_r": 5},
        "energy": {"youngs_modulus": 63e9, "poisson_ratio": 0.2}}


@pytest.fixture(scope="module")
def results(shear_cell):
    return {name: fn(shear_cell, **FAST.get(name, {})) for name, fn in ANALYSES.items()}


def test_every_plot_function_is_used_and_returns_a_figure(results):
    used = set()
    for name, res in results.items():
        fig = res.plot()
        assert isinstance(fig, Figure), name
        assert fig.axes and any(ax.has_data() for ax in fig.axes), f"{name}: empty plot"
        used.add(res.plotter.__name__)
    assert used == set(plots.__all__)


def test_a_result_shows_itself_in_a_notebook_with_its_plot(results):
    """``Result._repr_html_``: the scalars, the tables' sizes and the plot as an inline PNG."""
    res = results["rdf"]
    page = res._repr_html_()
    assert "<b>rdf</b>" in page and "<code>rdf</code>" in page and page.count('src="data:image/png;base64,') == 1
    assert "first_peak_d50" in page and f"{res.scalars['first_peak_d50']:.4g}" in page


def test_run_analyses_writes_csv_png_and_summary(shear_cell, tmp_path):
    specs = ["rdf", {"d2min": {"pairs": [[0, 5]]}}, {"rdf": {"edge_correction": False}},
             {"friction": {"torque_wall": "bottom"}}]      # the bottom wall has no torque: error
    s = run_analyses(shear_cell, specs, tmp_path)
    assert list(s) == ["rdf", "d2min", "rdf_2", "friction"]
    for label in ("rdf", "d2min", "rdf_2"):
        assert s[label]["status"] == "ok"
        for f in s[label]["files"]:
            assert (tmp_path / f).stat().st_size > 0
        assert f"{label}.png" in s[label]["files"]
    assert (tmp_path / "d2min_particles.csv").exists()
    assert s["friction"]["status"] == "error" and "torque" in s["friction"]["error"]
    on_disk = json.loads((tmp_path / "analysis_summary.json").read_text())
    assert on_disk["rdf_2"]["scalars"]["edge_correction"] is False
    assert not list(tmp_path.glob(".*"))               # no temporary files left behind


def test_run_analyses_accepts_a_path(shear_cell, tmp_path):
    s = run_analyses(shear_cell.path, ["coordination"], tmp_path, plots=False)
    assert s["coordination"]["status"] == "ok"
    assert not (tmp_path / "coordination.png").exists()


def test_bad_specs_are_rejected_before_running():
    with pytest.raises(ValueError, match="unknown analysis 'd2mni'"):
        parse_specs(["rdf", "d2mni"])
    with pytest.raises(ValueError, match="options must be a mapping"):
        parse_specs([{"rdf": 3}])
    assert parse_specs([{"rdf": None}]) == [("rdf", {})]


def test_main_entry_point(shear_cell, tmp_path, capsys):
    from orchestrator.analysis.__main__ import main
    assert main([str(shear_cell.path), str(tmp_path), 'rdf:{"bins": 20}']) == 0
    assert (tmp_path / "rdf_rdf.csv").exists()


def test_d2min_plot_stays_readable_over_many_frame_pairs():
    """A long run has dozens of frame pairs: the plot draws at most plots.MAX_CURVES of them
    (first and last kept), and the round-off D²min of affinely moving grains (~1e-31) does not
    stretch the axis over tens of decades (the PDF starts at the 1 % quantile)."""
    import pandas as pd
    from orchestrator.analysis._common import Result
    rng = np.random.default_rng(0)
    rows = []
    for k in range(30):
        d2 = rng.lognormal(-6, 1, 400)
        d2[:3] = 1e-31                                  # round-off values
        rows.append(pd.DataFrame({"frame0": k, "frame1": k + 1, "control0": 0.01 * k, "control1": 0.01 * (k + 1),
                                  "d2min_d50": d2, "eps_q": rng.lognormal(-3, 1, 400)}))
    res = Result("d2min", tables={"particles": pd.concat(rows)}, scalars={"control": "axial_strain"})
    fig = plots.plot_d2min(res)
    a1 = fig.axes[0]
    assert len(a1.get_lines()) == plots.MAX_CURVES
    labels = [t.get_text() for t in a1.get_legend().get_texts()]
    assert labels[0] == "0→0.01" and labels[-1] == "0.29→0.3"
    assert a1.get_xlim()[0] > 1e-8
