"""Results to take away: tables as plain dicts, CSV files (``--csv``, ``to_csv()``) and pandas DataFrames."""

from __future__ import annotations

import csv
import json
import sys

import numpy as np
import pytest

import hysid
from hysid.cli import main
from hysid_model.errors import HysidInputError
from support import GA_SMALL, sizes


@pytest.fixture(scope="module")
def result():
    return hysid.fit(hysid.load("synth", noise_pct=5.0, noise_seed=1), algo="ga", seed=1, options=GA_SMALL)


def read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_fit_tables_hold_parameters_with_errors_and_every_amplitude(result):
    tables = result.tables()
    rows = {r["parameter"]: r for r in tables["parameters"]}
    for name, value in result.params.items():
        assert rows[name]["value"] == value and rows[name]["stderr"] == result.stderr[name] and rows[name]["status"] == "fitted"
    assert rows["meq"] == {"parameter": "meq", "value": 0.04, "stderr": 0.0, "unit": "kg", "lower": 0.04, "upper": 0.04, "status": "fixed"}
    assert rows["k"]["status"] == "derived: meq w0^2" and rows["k"]["stderr"] == result.combinations["k"][1] > 0
    amplitudes = tables["amplitudes"]  # one row per amplitude level and frequency
    assert len(amplitudes) == 120 and sorted({a["x0_m"] for a in amplitudes}) == [0.0005, 0.001, 0.0015]
    level = {a.x0: (a, hp) for a, hp in zip(result.amplitudes, result.half_power)}
    for row in amplitudes:
        a, hp = level[row["x0_m"]]
        assert (row["fn_hz"], row["xi"], row["xi_stderr"], row["k_n_per_m"], row["c_n_s_per_m"]) == (
            a.values["fn_hz"],
            a.values["xi"],
            a.stderr["xi"],
            a.values["k"],
            a.values["c"],
        )
        assert row["xi_half_power"] == hp.xi and row["xi_half_power"] == pytest.approx(row["xi"], rel=0.05)
        w = 2 * np.pi * row["f_hz"]  # the linear oscillator's k_eff is k - m w^2, its xi_eq c w / (2 k_eff) below resonance
        k_dyn = a.values["k"] - a.values["m"] * w**2
        assert row["k_eff_n_per_m"] == pytest.approx(k_dyn, rel=1e-6) and row["k_eff_n_per_m_stderr"] > 0
        assert row["xi_eq"] == (pytest.approx(a.values["c"] * w / (2 * k_dyn), rel=1e-3) if k_dyn > 0 else None)
    assert json.loads(json.dumps(tables)) == tables  # plain dicts of plain values


def test_to_csv_writes_what_tables_holds_at_full_precision(result, tmp_path):
    paths = result.to_csv(tmp_path / "t")
    assert sorted(paths) == ["amplitudes", "parameters"]
    for name, rows in result.tables().items():
        back = read_csv(paths[name])
        assert list(back[0]) == list(rows[0])
        for row, got in zip(rows, back):
            for key, value in row.items():
                assert got[key] == ("" if value is None else str(value)) if not isinstance(value, float) else float(got[key]) == value


def test_dataframes_when_pandas_is_there_and_a_clear_error_when_not(result, monkeypatch):
    pd = pytest.importorskip("pandas")
    frames = result.to_dataframes()
    assert isinstance(frames["amplitudes"], pd.DataFrame)
    level = {a.x0: a.values["xi"] for a in result.amplitudes}
    np.testing.assert_array_equal(frames["amplitudes"]["xi"].to_numpy(), [level[x0] for x0 in frames["amplitudes"]["x0_m"]])
    monkeypatch.setitem(sys.modules, "pandas", None)  # as if pandas were not installed
    with pytest.raises(HysidInputError, match=r"DataFrames need pandas \(pip install 'hysid\[pandas\]'\)"):
        result.to_dataframes()


@pytest.mark.slow  # over 3 s
def test_csv_flag_of_fit_campaign_and_diagnose(tmp_path, capsys):
    assert (
        main(
            [
                "campaign",
                "--single-node",
                "--islands",
                "2",
                *sizes(20, 40, 10),
                "--quiet",
                "--csv",
                "--no-figures",
                "--out",
                str(tmp_path / "c"),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert out.rstrip().endswith(f"tables: {tmp_path / 'c' / 'parameters.csv'}, {tmp_path / 'c' / 'amplitudes.csv'}, {tmp_path / 'c' / 'islands.csv'}")
    islands = read_csv(tmp_path / "c" / "islands.csv")
    assert [i["island"] for i in islands] == ["island-0", "island-1"] and all(i["iterations"] == "10" for i in islands)
    assert [i["algorithms"].split(" -> ")[0] for i in islands] == ["ga", "pso"]  # what each searched with, beside its name
    doc = json.loads((tmp_path / "c" / "result.json").read_text())
    rows = read_csv(tmp_path / "c" / "parameters.csv")
    assert {r["parameter"]: float(r["value"]) for r in rows if not r["status"].startswith("derived")} == {**doc["params"], **doc["fixed"]}
    assert {r["parameter"]: float(r["value"]) for r in rows if r["status"].startswith("derived")} == {k: v["value"] for k, v in doc["combinations"].items()}

    loops = hysid.load("synth", noise_pct=5.0, noise_seed=2)
    subset = loops.subset(np.arange(0, loops.n_loops, 4))
    diagnosis = hysid.diagnose(subset, "baseline", cross_validate=False)
    tables = diagnosis.tables()
    assert [s["effect"] for s in tables["steps"]] == ["amplitude_dependent_frequency", "amplitude_dependent_damping"]
    assert [g["step"] for g in tables["gap"]] == [label for label, _ in diagnosis.fits()]
    assert {r["parameter"]: r["value"] for r in tables["parameters"] if r["status"] == "fitted"} == diagnosis.params
    assert sorted(diagnosis.to_csv(tmp_path / "d")) == ["amplitudes", "gap", "parameters", "steps"]
