"""``hysid fit``: the single-node fit through the real CLI, its JSON, and its argument errors."""

from __future__ import annotations

import contextlib
import io
import json
import re

import numpy as np
import pytest

from hysid import thesis_tables as tt
from hysid.cli import main
from hysid.fitting import fit
from hysid_model.problem import build_objective
from hysid_model.synth import TRUE_PARAMS, synth_loops
from hysid_model.uncertainty import cramer_rao_stderr, standard_errors


def run_cli(capsys, args: list[str]) -> tuple[int, str, str]:
    code = main(args)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.fixture(scope="module")
def clean_json(tmp_path_factory):
    """``hysid fit synth --json`` (GA for speed, polish on by default; its report without figures), run once for the module.

    capsys is function-scoped, so this module-scoped run captures stdout/stderr itself.
    """
    out = tmp_path_factory.mktemp("fit") / "clean"
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        code = main(["fit", "synth", "--algo", "ga", "--runs", "2", "--seed", "3", "--json", "--no-figures", "--out", str(out)])
    return code, stdout.getvalue(), stderr.getvalue(), out


def test_fit_synth_reaches_table_5_3(clean_json):
    code, stdout, stderr, _ = clean_json
    assert code == 0, stderr
    doc = json.loads(stdout)
    for name, value in TRUE_PARAMS.items():
        assert doc["params"][name] == pytest.approx(value, rel=1e-6), name


def test_fit_json_schema(clean_json):
    _code, stdout, stderr, out = clean_json
    assert stderr == ""  # no progress bar when stderr is not a terminal
    assert stdout.count("\n") == 1 and stdout.startswith("{")  # exactly one JSON object
    doc = json.loads(stdout)
    names = ["xi0", "S_xi", "w0", "S_w"]
    assert list(doc["params"]) == names and list(doc["stderr"]) == names
    assert all(isinstance(v, float) for v in doc["params"].values())
    assert all(v >= 0 for v in doc["stderr"].values())
    assert isinstance(doc["fitness"], float) and doc["fitness"] < 1e-20
    assert isinstance(doc["evaluations"], int) and doc["evaluations"] > 2 * 15_000
    assert len(doc["history"]) == 19
    for row in doc["history"]:
        assert set(row) == {"iteration", "best_fitness", "evaluations", "wall_s"}
    best = [r["best_fitness"] for r in doc["history"]]
    assert best == sorted(best, reverse=True)
    assert [r["seed"] for r in doc["runs"]] == [3, 4]
    assert doc["fitness"] == min(r["fitness"] for r in doc["runs"])
    assert doc["weights"] == "thesis" and doc["settings"]["polish"] is True
    assert doc["report"] == str(out / "report.md") and (out / "report.md").exists()


def test_derived_modal_values_match_the_list_under_table_5_3(clean_json):
    doc = json.loads(clean_json[1])
    derived = {round(d["x0_m"] * 1e3, 6): d for d in doc["derived"]}
    for x0, (fn, xi) in tt.MODAL_UNDER_TABLE_5_3.items():
        d = derived[round(x0 * 1e3, 6)]
        assert round(d["fn_hz"], 1) == fn
        assert round(d["xi"], 4) == xi
        assert d["m"] == pytest.approx(0.040)
        assert d["k"] == pytest.approx(d["m"] * (2 * np.pi * d["fn_hz"]) ** 2)
        assert d["c"] == pytest.approx(2 * d["m"] * d["xi"] * 2 * np.pi * d["fn_hz"])
    for hp in doc["half_power"]:
        assert abs(hp["xi"] - hp["xi_fit"]) <= hp["resolution"]


@pytest.mark.slow  # over 3 s (fast lane, 2 cores, 2026-11-29)
def test_fit_default_output_is_a_readable_summary(tmp_path, capsys):
    code, out, err = run_cli(capsys, ["fit", "synth", "--algo", "ga", "--noise", "10", "--noise-seed", "2", "--out", str(tmp_path / "r")])
    assert code == 0, err
    assert "120 loops" in out and "xi0" in out and "S_w" in out
    assert "Cramer-Rao" in out  # noisy Synth set: sigma is known, so ML weights by default
    assert "half-power" in out
    assert f"report: {tmp_path / 'r' / 'report.md'}" in out
    for name in ("report.md", "result.json", "convergence.png", "loops.png", "residuals.png", "half_power.png"):
        assert (tmp_path / "r" / name).exists(), name


def test_noisy_fit_errors_are_consistent_with_their_standard_errors():
    loops = synth_loops(20.0, seed=11)
    ml = fit(loops, algo="ga", seed=1)
    assert ml.weights == "ml"
    obj = build_objective(loops, "thesis", "ml")
    np.testing.assert_allclose(list(ml.stderr.values()), cramer_rao_stderr(obj, ml.theta), rtol=1e-6)
    for name, value in TRUE_PARAMS.items():
        assert abs(ml.params[name] - value) < 4 * ml.stderr[name], name
    thesis = fit(loops, algo="ga", seed=1, weights="thesis")
    assert "sandwich" in thesis.stderr_method
    obj = build_objective(loops, "thesis", "thesis")
    np.testing.assert_allclose(list(thesis.stderr.values()), standard_errors(obj, thesis.theta), rtol=1e-6)
    # ML is efficient: its standard errors are no larger than the thesis weights'
    assert all(ml.stderr[n] <= thesis.stderr[n] * 1.001 for n in TRUE_PARAMS)


def test_no_polish_keeps_the_search_result():
    result = fit(synth_loops(0.0), algo="ga", polish=False, start=False, options={"initial_population": 400, "population": 60, "iterations": 4})
    run = result.runs[0]
    assert run.polish is None
    assert run.fitness == run.search_fitness and np.array_equal(run.theta, run.search_theta)
    assert result.fitness > 1e-12  # a short search alone, without the survey's start, does not reach the noiseless optimum


def test_the_survey_start_of_noiseless_thesis_loops_is_the_truth():
    """The thesis model is linear per loop: the survey's per-loop oscillators, drawn against amplitude, are Eq. 4.8-4.10."""
    result = fit(synth_loops(0.0), algo="ga", polish=False, options={"initial_population": 60, "population": 20, "iterations": 1})
    assert result.fitness < 1e-20


def test_out_must_not_be_a_file(tmp_path, capsys):
    existing = tmp_path / "notes.txt"
    existing.write_text("keep me\n")
    code, out, err = run_cli(capsys, ["fit", "synth", "--out", str(existing)])
    assert code == 2 and out == ""
    assert re.fullmatch(r"hysid: error: --out [^\n]+: exists and is not a directory\n", err)
    assert existing.read_text() == "keep me\n"


@pytest.mark.parametrize(
    ("args", "names"),
    [
        (["fit", "synth", "--algo", "de"], "--algo"),
        (["fit", "synth", "--model", "quadratic"], "model"),
        (["fit", "synth", "--model", "thesis+warp_drive"], "warp_drive"),
        (["fit", "synth", "--weights", "equal"], "--weights"),
        (["fit", "synth", "--runs", "-1"], "--runs"),
        (["fit", "synth", "--runs", "0"], "--runs"),
        (["fit", "synth", "--weights", "ml"], "sigma"),
        (["fit", "synth", "--noise", "-5"], "noise"),
        (["fit", "synth", "--seed", "-2"], "--seed"),
        (["fit", "/nonexistent/loops/dir"], "/nonexistent/loops/dir"),
    ],
)
def test_bad_arguments_are_one_line_errors(tmp_path, capsys, args, names):
    code, out, err = run_cli(capsys, args + ["--out", str(tmp_path / "r")])
    assert code == 2
    assert out == ""
    assert re.fullmatch(r"hysid: error: [^\n]+\n", err), err
    assert names in err
    assert "Traceback" not in err
    assert not (tmp_path / "r").exists()


def test_a_parameter_pinned_on_a_bound_is_flagged():
    loops = synth_loops(0.0)
    loops.meta["bounds"] = {"w0": (100.0, 150.0)}  # the truth, 189.1 rad/s, lies outside
    result = fit(loops, model="baseline", algo="ga", runs=1, seed=0, polish=True, options={"initial_population": 300, "population": 60, "iterations": 3})
    assert "w0" in result.at_bounds
    assert "w0 ended on a bound" in result.summary()
    assert result.to_dict()["at_bounds"] == result.at_bounds
