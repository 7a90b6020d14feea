"""`hysid bench ingest` (hysid/bench/ingest.py): it runs end to end on a small set and reports consistent numbers;
its DAQ-shaped records read as a lab's export does (semicolons, mm and kN in the header)."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from hysid.bench import ingest, ingest_sets
from hysid.cli import main
from hysid_model.datasets import load_dataset


@pytest.mark.slow
def test_bench_ingest_reports_its_ratios_and_memory(capsys):
    assert main(["bench", "ingest", "generated", "--records", "2", "--seconds", "3", "--rate", "6037", "--rounds", "2", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert list(doc["sets"]) == ["generated"]
    r = doc["sets"]["generated"]
    assert r["records"] == 2 and r["samples"] == 18111 and r["cycles"] > 20
    for key in ("parse_s", "extract_s", "load_s", "mb_per_s", "rss_growth_mb", "data_mb", "largest_file_mb"):
        assert r[key] > 0, key
    assert all(len(r["rounds"][key]) == 2 for key in ("parse_s", "load_s", "extract_s", "rss_growth_mb"))
    parse, load = np.array(r["rounds"]["parse_s"]), np.array(r["rounds"]["load_s"])
    assert r["load_ratio"] == pytest.approx(np.median(load / parse))
    assert r["rss_growth_warm_mb"] == max(r["rounds"]["rss_growth_mb"]) <= r["rss_growth_mb"] and r["peak_reset"]
    assert r["first_load_s"] > 0
    assert r["rss_bound_mb"] == pytest.approx(2 * r["largest_file_mb"] + ingest.FIXED_MB)
    assert r["largest_file_mb"] == pytest.approx(r["data_mb"] / 2, rel=0.01)
    assert doc["meets_targets"] == r["meets_targets"] and "machine" in doc and "date" in doc


def test_daq_shaped_records_read_as_a_labs_export(tmp_path):
    """Two records as the DAQ set writes them: the header's units (mm, kN) make SI loops at the manifest's frequencies,
    with the drift, the distortion and the amplitude the generator put in."""
    spec = ingest_sets.IngestSet("t", 2, 8192, 2048.0, "daq")
    ingest_sets.write_daq_records(tmp_path, spec)
    assert (tmp_path / "rec00.csv").read_text().splitlines()[0] == "Time [s];Weg [mm];Kraft [kN]"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        loops = load_dataset(tmp_path)
    np.testing.assert_allclose(loops.freq_hz, ingest_sets.DAQ_FREQUENCIES_HZ[:2], rtol=1e-4)
    np.testing.assert_allclose(loops.x0, [0.5e-3 * 1.03, 1e-3 * 1.03], rtol=0.03)
    distortion = np.array(loops.meta["per_loop"]["x_distortion"])
    assert np.all((distortion > 0.04) & (distortion < 0.11))


def test_bench_ingest_rejects_an_empty_set(capsys):
    assert main(["bench", "ingest", "--records", "0"]) == 2
    assert "--records 0: must be an integer >= 1" in capsys.readouterr().err


def test_bench_ingest_names_its_sets(capsys):
    assert main(["bench", "ingest", "huge"]) == 2
    assert "generated, large, lab, damper, daq, small or all" in capsys.readouterr().err
