"""Big records in bounded memory (issue 37, Deliver 3): a CSV record is parsed in chunks straight into its three
columns (the compiled reader of hysid_model/readers/numbers.py, the same numbers as numpy's), and its extraction
takes the memory of a bounded number of samples beyond the record's own.

The speed and the peak resident memory of whole sets are measured by ``hysid bench ingest``."""

from __future__ import annotations

import io
import tracemalloc
import warnings
from pathlib import Path

import numpy as np
import pytest

from hysid_model import steady
from hysid_model.datasets import load_dataset
from hysid_model.extraction import extract_loop
from hysid_model.readers import csv_series
from hysid_model.readers.dataset_dir import read_config
from hysid_model.readers.records import read_record


def mixed_rows(n: int, seed: int) -> tuple[list[str], np.ndarray]:
    """Rows of three numbers as different tools write them (12 digits, fixed decimals, Python's repr, numpy's
    ``%.18e``, exponents beyond 1e22, integers, nan and inf), and the values."""
    rng = np.random.default_rng(seed)
    values = rng.standard_normal((n, 3)) * 10.0 ** rng.integers(-30, 30, (n, 3))
    formats = ["{:.12g}", "{:.6f}", "{!r}", "{:.18e}", "{:.0f}"]
    rows = []
    for k, row in enumerate(values):
        rows.append(";".join(formats[(k + j) % len(formats)].format(float(v)) for j, v in enumerate(row)))
    rows[7] = "nan;-inf;+1.5E+3"
    return rows, values


def test_the_compiled_reader_reads_the_numbers_numpy_reads(tmp_path):
    """A file above COMPILED_BYTES with decimal commas, CRLF, blank and comment lines, a text column it does not
    read, spaces around fields: the same float64 numbers, bit for bit, as np.loadtxt of the text with points."""
    rows, _ = mixed_rows(40_000, 1)
    lines = ["# exported by a DAQ", "Zeit;Status;Weg;Kraft"]
    for k, row in enumerate(rows):
        t, x, f = row.split(";")
        lines.append(f"{t}; OK ;{x} ; {f}".replace(".", ","))
        if k % 997 == 0:
            lines += ["", "# a comment line"]
    path = tmp_path / "big.csv"
    path.write_bytes("\r\n".join(lines).encode("utf-8") + b"\r\n")
    assert path.stat().st_size > csv_series.COMPILED_BYTES
    dialect = csv_series.sniff(path)
    assert dialect.header_line == 1 and dialect.names == ["Zeit", "Status", "Weg", "Kraft"]
    got = csv_series.read_columns(path, dialect, [3, 0, 2])
    text = path.read_text().replace(",", ".")
    expected = np.loadtxt(io.StringIO(text), delimiter=";", skiprows=2, usecols=[3, 0, 2], comments="#").T
    assert got.shape == (3, 40_000) and all(column.flags.c_contiguous for column in got)
    np.testing.assert_array_equal(got, expected)  # NaN where NaN, every other number bit for bit


@pytest.mark.parametrize("rows", [5_000, 40_000])  # np.loadtxt's side of COMPILED_BYTES (past MAX_LINE), the compiled reader's
@pytest.mark.parametrize("newline", ["\r\n", "\r"])
def test_lines_ended_as_labs_end_them_read_as_lines_ended_in_a_newline(tmp_path, rows, newline):
    """Windows' CRLF and the bare CR of old Mac software and some DAQ exports, after a free-text preamble in cp1252,
    with decimal commas: the same numbers, bit for bit, as the same file with ``\\n`` line ends."""
    numbers, _ = mixed_rows(rows, 3)
    lines = ["Prüfstand: Hydropuls HP 25", "Probe: Drahtseil 3", "", "Zeit [s];Weg [mm];Kraft [kN]", *(r.replace(".", ",") for r in numbers)]
    paths = {}
    for name, end in (("lf", "\n"), ("lab", newline)):
        paths[name] = tmp_path / f"{name}.csv"
        paths[name].write_bytes((end.join(lines) + end).encode("cp1252"))
    assert paths["lab"].stat().st_size > csv_series.MAX_LINE and (paths["lab"].stat().st_size > csv_series.COMPILED_BYTES) == (rows > 5_000)
    read = {name: csv_series.read_columns(path, csv_series.sniff(path), [0, 1, 2]) for name, path in paths.items()}
    assert read["lab"].shape == (3, rows)
    np.testing.assert_array_equal(read["lab"], read["lf"])


def test_a_bad_line_in_a_big_file_is_named(tmp_path):
    rows, _ = mixed_rows(60_000, 2)
    rows[45_000] = "1,5;zwei;3"
    path = tmp_path / "big.csv"
    path.write_text("a;b;c\n" + "\n".join(rows).replace(".", ",") + "\n")
    with pytest.raises(Exception, match=r"big.csv: line 45002: b 'zwei' is not a number"):
        csv_series.read_columns(path, csv_series.sniff(path), [0, 1, 2])


def long_record(seconds: float, rate: float = 10_000.0, freq: float = 5.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(5)
    t = np.arange(int(seconds * rate)) / rate
    theta = 2 * np.pi * freq * t
    x = 1e-3 * np.sin(theta) + 1e-6 * rng.standard_normal(t.size)
    return t, x, 50 * np.sin(theta + 0.3) + 5 * np.sign(np.cos(theta)) + 0.2 * rng.standard_normal(t.size)


@pytest.mark.slow
def test_a_long_record_is_extracted_in_bounded_memory():
    """Twice the samples, hardly more memory: beyond MAX_SAMPLES the steps that need their samples together take
    every k-th cycle, the passes over every sample a piece at a time (a 7.2 M-sample record took 1.4 GB, 14 copies of
    it in the per-cycle fits alone); the loop of the longer record is the same loop."""
    peaks, loops = [], []
    for seconds in (100.0, 200.0):
        t, x, force = long_record(seconds)
        tracemalloc.start()
        loops.append(extract_loop(t, x, force, source="long.csv", nominal_freq_hz=5.0))
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    assert peaks[1] < 1.15 * peaks[0] and peaks[1] < 60 * t.size  # bytes; the record's own three columns are 24 a sample
    per_cycle = 10_000.0 / 5.0
    assert all(0.9 * steady.MAX_SAMPLES < loop.cycles * per_cycle <= steady.MAX_SAMPLES for loop in loops)  # every 2nd, every 4th cycle
    np.testing.assert_allclose(loops[1].top, loops[0].top, atol=0.05)
    assert loops[1].freq_hz == pytest.approx(5.0, rel=1e-7)


@pytest.mark.slow
def test_a_big_csv_record_is_read_into_its_columns_alone(tmp_path):
    """Reading a 40 MB record takes its three float64 columns and a chunk (numpy's parse, a copy of its columns and
    the decimal-comma text took over 4 times the columns); loading it takes under twice the file plus a fixed part."""
    t, x, force = long_record(140.0)
    path = tmp_path / "long_5Hz.csv"
    body = io.StringIO()
    np.savetxt(body, np.column_stack([t, x * 1e3, force / 1e3]), delimiter=";", fmt=("%.4f", "%.6f", "%.6f"))
    path.write_text("Zeit [s];Weg [mm];Kraft [kN]\n" + body.getvalue().replace(".", ","))
    del body
    columns = 3 * 8 * t.size
    config = read_config(tmp_path)
    read_record(path, config)  # the compiled reader's code loads once per process; tracemalloc would count the compiler
    tracemalloc.start()
    series = read_record(path, config)
    read_peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert series.t.size == t.size and read_peak < columns + (8 << 20)
    del series
    tracemalloc.start()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        loops = load_dataset(path)
    load_peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert loops.freq_hz[0] == pytest.approx(5.0, rel=1e-7)
    assert load_peak < 2 * Path(path).stat().st_size + (100 << 20)
