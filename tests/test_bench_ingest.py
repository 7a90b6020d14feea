"""`hysid bench ingest` (hysid/bench/ingest.py): it runs end to end on a small set and reports consistent numbers."""

from __future__ import annotations

import json

import pytest

from hysid.cli import main


@pytest.mark.slow
def test_bench_ingest_reports_its_ratios_and_memory(capsys):
    assert main(["bench", "ingest", "--records", "2", "--seconds", "3", "--rate", "6037", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["records"] == 2 and doc["samples"] == 2 * 18111 and doc["cycles"] > 20
    for key in ("parse_s", "extract_s", "load_s", "mb_per_s", "peak_rss_mb", "data_mb"):
        assert doc[key] > 0, key
    assert doc["ratio"] == pytest.approx(doc["extract_s"] / doc["parse_s"])
    assert doc["load_ratio"] == pytest.approx(doc["load_s"] / doc["parse_s"])
    assert doc["peak_rss_mb"] >= doc["baseline_rss_mb"] and "machine" in doc and "date" in doc


def test_bench_ingest_rejects_an_empty_set(capsys):
    assert main(["bench", "ingest", "--records", "0"]) == 2
    assert "--records 0: must be an integer >= 1" in capsys.readouterr().err
