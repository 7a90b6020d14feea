"""The fit report: Markdown, strict JSON and PNG figures in a real directory."""

from __future__ import annotations

import json
import re
from dataclasses import replace

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.image import imread
from matplotlib.lines import Line2D

from hysid.fitting import fit
from hysid.report import jsondoc
from hysid.report.figures import convergence_figure
from hysid.report.style import figure_legend, new_figure, save, styled
from hysid_model.synth import synth_loops
from support import GA_SMALL as SMALL_GA

FIGURES = ("convergence.png", "loops.png", "residuals.png", "half_power.png")


@pytest.fixture(scope="module")
def report_dir(tmp_path_factory):
    result = fit(synth_loops(20.0, seed=2), algo="ga", runs=2, seed=5, options=SMALL_GA)
    out = tmp_path_factory.mktemp("report")
    path = result.write_report(out)
    return out, path, result


def test_report_files_are_written(report_dir):
    out, path, result = report_dir
    assert path == out / "report.md"
    assert result.report == str(path)
    text = path.read_text()
    for name in FIGURES:
        png = out / name
        assert png.stat().st_size > 20_000, name
        assert f"]({name})" in text, name
        height, width = imread(png).shape[:2]
        assert width >= 4.5 * 150 and height >= 2.5 * 150, (name, width, height)  # >= 150 dpi at print size
    assert (out / "result.json").exists()
    assert "[`result.json`](result.json)" in text


def test_report_tells_parameters_amplitudes_half_power_and_runs(report_dir):
    _, path, result = report_dir
    text = path.read_text()
    for heading in (
        "## Parameters",
        "## Damping ratio and natural frequency at each amplitude",
        "## Half-power cross-check of the damping (Eq. 2.7)",
        "## Runs",
        "## Model vs measured loops",
        "## Residuals",
    ):
        assert heading in text
    for name in result.model.names:
        assert f"| `{name}` |" in text
    assert "Cramer-Rao" in text  # noisy Synth set: sigma known, ML weights by default
    assert len(re.findall(r"^\| (\*\*)?run \d", text, flags=re.M)) == 2
    rows = re.findall(r"^\| (0\.5|1|1\.5) \| 40 \|", text, flags=re.M)
    assert rows == ["0.5", "1", "1.5"]


def test_result_json_is_strict_and_complete(report_dir):
    out, _, result = report_dir
    doc = json.loads((out / "result.json").read_text(), parse_constant=lambda c: pytest.fail(f"non-JSON constant {c}"))
    assert set(doc["params"]) == set(result.model.names) == set(doc["stderr"])
    assert doc["report"] == str(out / "report.md")
    assert len(doc["runs"]) == 2 and [r["seed"] for r in doc["runs"]] == [5, 6]
    assert doc["fitness"] == min(r["fitness"] for r in doc["runs"])
    assert len(doc["history"]) == SMALL_GA["iterations"] + 1


def test_jsondoc_turns_numpy_and_nan_into_plain_json():
    text = jsondoc.dumps({"a": np.float64(np.nan), "b": np.arange(3), "c": (np.int64(2), float("inf")), "d": np.bool_(True)})
    assert json.loads(text) == {"a": None, "b": [0, 1, 2], "c": [2, None], "d": True}


@pytest.mark.slow  # over 3 s (fast lane, 2 cores, 2026-11-29)
def test_report_without_a_resonance_in_the_sweep(tmp_path):
    loops = synth_loops(0.0)
    low = loops.subset(np.flatnonzero(loops.freq_hz < 29.0))
    result = fit(low, algo="ga", options=SMALL_GA, polish=False)
    assert not any(hp.ok for hp in result.half_power)
    text = result.write_report(tmp_path / "r").read_text()
    assert "n/a: resonance peak at the edge of the frequency sweep" in text
    assert (tmp_path / "r" / "half_power.png").stat().st_size > 20_000


def test_convergence_figure_skips_runs_without_history(tmp_path):
    """A campaign adds its global best as a run with no history; the figure still shows the others."""
    result = fit(synth_loops(0.0), algo="ga", options=SMALL_GA, polish=False)
    bare = replace(result.runs[0], label="global best", history=[])
    path = convergence_figure(tmp_path / "c.png", [("", [result.runs[0], bare])], "best fitness")
    assert path.stat().st_size > 20_000


@styled
def _legend_extent(labels: list[str], png):
    """The figure legend of ``labels`` on a page-wide figure in the reports' style, saved as ``png``: the figure and
    the legend's extent."""
    fig = new_figure(3.0)
    fig.add_subplot().plot([0.0, 1.0])
    legend = figure_legend(fig, [Line2D([], []) for _ in labels], labels, "outside upper center")
    save(fig, png)
    return fig, legend.get_window_extent(FigureCanvasAgg(fig).get_renderer())


def _edges_blank(png) -> bool:
    """Nothing is drawn on the two outermost pixel columns of either side: no text runs off the figure."""
    image = imread(png)[:, :, :3]
    return bool((image[:, :2] > 0.99).all() and (image[:, -2:] > 0.99).all())


def test_a_figure_legend_fits_the_page_width_in_as_few_rows_as_it_can(tmp_path):
    """Figures keep the page's width (no tight bounding box), so the figure legend must fit in it as saved: entries
    that fit stay on one row, the five of the effective-stiffness figure (wider than the page at the resolution it
    is saved at) and ten long ones wrap onto more rows, and nothing runs off either side of the saved image."""
    _, one = _legend_extent(["measured"], tmp_path / "one.png")
    fig, short = _legend_extent(["X0 = 0.5 mm", "X0 = 1 mm", "loops"], tmp_path / "short.png")
    assert short.height == pytest.approx(one.height) and short.width <= fig.bbox.width and _edges_blank(tmp_path / "short.png")
    effective = ["X0 = 0.5 mm", "X0 = 1 mm", "X0 = 1.5 mm", "fitted model (+- one standard error)", "each loop's own"]
    fig, five = _legend_extent(effective, tmp_path / "five.png")
    assert five.width <= fig.bbox.width and _edges_blank(tmp_path / "five.png")
    fig, long = _legend_extent([f"X0 = {a} mm, fitted model (+- one standard error)" for a in range(1, 11)], tmp_path / "long.png")
    assert long.width <= fig.bbox.width and long.height > 1.5 * one.height and _edges_blank(tmp_path / "long.png")
