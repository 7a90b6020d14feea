"""``hysid reproduce thesis``: the published tables as data, and the regenerated section 5.2.1."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from hysid import thesis_tables as tt
from hysid.cli import main
from hysid.reproduce import cramer_rao_bounds, parse_seeds
from hysid_model.errors import HysidInputError
from hysid_model.synth import TRUE_PARAMS


def test_published_summaries_follow_from_the_published_runs():
    """Mean, sample sigma and |sigma/mean| of Tables 5.5-5.12 and Table 5.13 recomputed from the runs."""
    for key, runs in tt.RUNS.items():
        for p, values in runs.items():
            v = np.array(values)
            mean, std, rel = tt.SUMMARY[key][p]
            assert v.mean() == pytest.approx(mean, rel=2e-3, abs=1e-6), (key, p)
            assert v.std(ddof=1) == pytest.approx(std, rel=5e-3), (key, p)
            assert abs(v.std(ddof=1) / v.mean()) == pytest.approx(rel, rel=5e-3), (key, p)
            assert abs(mean - TRUE_PARAMS[p]) == pytest.approx(tt.TABLE_5_13[p][key], rel=0.02, abs=1e-6), (key, p)


def test_modal_list_under_table_5_3_follows_from_the_parameters():
    for x0, (fn, xi) in tt.MODAL_UNDER_TABLE_5_3.items():
        assert round((TRUE_PARAMS["w0"] + TRUE_PARAMS["S_w"] * x0) / (2 * np.pi), 1) == fn
        assert round(TRUE_PARAMS["xi0"] + TRUE_PARAMS["S_xi"] * x0, 4) == xi


def test_cramer_rao_bound_grows_linearly_with_the_noise():
    bounds = cramer_rao_bounds((0, 10, 20, 30))
    assert np.all(bounds[0] == 0)
    assert np.all(bounds[10] > 0)
    np.testing.assert_allclose(bounds[20], 2 * bounds[10], rtol=1e-6)
    np.testing.assert_allclose(bounds[30], 3 * bounds[10], rtol=1e-6)
    # far below the scatter of the thesis' runs (Tables 5.6, 5.10): sigma of 4 runs of S_w was ~55 rad/s/m at 10 %
    assert bounds[10][3] < 10.0


def test_parse_seeds():
    assert parse_seeds(None, 3) == [0, 1, 2]
    assert parse_seeds("7, 8", 2) == [7, 8]
    for text, runs in (("1,2", 3), ("a,b", 2), ("-1", 1)):
        with pytest.raises(HysidInputError, match="noise_seeds="):
            parse_seeds(text, runs)
    with pytest.raises(HysidInputError, match="runs=0"):
        parse_seeds(None, 0)


@pytest.fixture(scope="module")
def reproduction(tmp_path_factory):
    out = tmp_path_factory.mktemp("repro") / "thesis"
    code = main(["reproduce", "thesis", "--runs", "2", "--seeds-noise", "3,4", "--out", str(out)])
    assert code == 0
    return out


@pytest.mark.slow
def test_reproduce_writes_every_table(reproduction):
    text = (reproduction / "report.md").read_text()
    for n in range(5, 14):
        assert f"Table 5.{n}" in text, n
    for algo, noise in tt.TABLE_NUMBERS:
        heading = f"### Table 5.{tt.TABLE_NUMBERS[(algo, noise)]}: {algo.upper()}, {noise} % noise"
        section = text.split(heading)[1].split("###")[0]
        rows = [r for r in section.splitlines() if r.startswith("|") and not r.startswith("|:")][1:]
        assert len(rows) == 4 * 3, heading  # 4 parameters x (published, thesis-faithful, hysid defaults)
        assert "| published |" in section and "| thesis-faithful |" in section and "| hysid defaults |" in section
    figures = sorted(p.name for p in reproduction.glob("*.png"))
    assert len(figures) == 12
    for n in range(2, 14):
        name = next(f for f in figures if f.startswith(f"fig5_{n}_"))
        assert (reproduction / name).stat().st_size > 20_000
        assert f"]({name})" in text


@pytest.mark.slow
def test_reproduce_json_has_every_cell(reproduction):
    doc = json.loads((reproduction / "reproduction.json").read_text())
    assert doc["noise_seeds"] == [3, 4]
    cells = {(c["setting"], c["algo"], c["noise_pct"]): c for c in doc["cells"]}
    assert len(cells) == 2 * 2 * 4
    for (setting, _algo, noise), c in cells.items():
        assert len(c["runs"]["xi0"]) == 2
        assert c["polish"] == (setting == "hysid")
        assert c["weights"] == ("ml" if setting == "hysid" and noise > 0 else "thesis")
        # every run lands near the truth; the polished ones within a few Cramer-Rao bounds
        for p in tt.PARAMS:
            assert c["abs_error_of_mean"][p] == pytest.approx(abs(c["mean"][p] - TRUE_PARAMS[p]))
        if setting == "hysid" and noise > 0:
            for p in tt.PARAMS:
                assert c["abs_error_of_mean"][p] < 5 * doc["cramer_rao"][str(noise)][p]
        if setting == "hysid" and noise == 0:
            for p in tt.PARAMS:
                assert c["abs_error_of_mean"][p] < 1e-6 * abs(TRUE_PARAMS[p])


def test_reproduce_bad_seeds_is_a_one_line_error(capsys):
    assert main(["reproduce", "thesis", "--runs", "3", "--seeds-noise", "1,2"]) == 2
    err = capsys.readouterr().err
    assert re.fullmatch(r"hysid: error: --seeds-noise .*\n", err)


@pytest.mark.parametrize(("args", "name"), [(["--seeds", "5"], "--seeds"), (["--thesis-runs", "6"], "--thesis-runs")])
def test_bench_accuracy_rejects_too_few_draws(capsys, args, name):
    assert main(["bench", "accuracy", *args]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert re.fullmatch(rf"hysid: error: {name} [^\n]+\n", captured.err)
