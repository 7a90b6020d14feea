"""A dataset cannot steer hysid outside its directory, exhaust memory, or crash the reader (issue 12, items 5 and 6).

Paths are confined to the dataset directory; error messages never echo files outside it; extraction memory
is linear in the record length; hostile files give one-line errors."""

from __future__ import annotations

import os
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from hysid.cli import main
from hysid_model.datasets import load_dataset, write_dataset
from hysid_model.errors import HysidInputError
from hysid_model.extraction import extract_loop
from hysid_model.loops import LoopSet
from hysid_model.readers.tidy import write_loops
from hysid_model.synth import RawRecord, synth_loops

SECRET = "TOP-SECRET-LINE"


def sine(label: str = "run", seconds: float = 1.0, fs: float = 2000.0, freq: float = 10.0) -> RawRecord:
    t = np.arange(int(seconds * fs)) / fs
    theta = 2 * np.pi * freq * t
    return RawRecord(label, freq, 1e-3, t, 1e-3 * np.sin(theta), 50 * np.sin(theta + 0.3), 0.0)


@pytest.fixture
def outside(tmp_path) -> Path:
    """A record-shaped file outside the dataset directory, whose first line must never be shown."""
    path = tmp_path / "secret.csv"
    path.write_text(f"{SECRET},b,c\n1,2,3\n")
    return path


def error_of(spec) -> str:
    with pytest.raises(HysidInputError) as info:
        load_dataset(spec)
    message = str(info.value)
    assert "\n" not in message and SECRET not in message
    return message


@pytest.mark.parametrize("listed", ["../secret.csv", "sub/../../secret.csv", "ABSOLUTE"])
def test_manifest_rows_outside_the_directory_are_refused(tmp_path, outside, capsys, listed):
    d = write_dataset(tmp_path / "d", [sine()])
    name = str(outside) if listed == "ABSOLUTE" else listed
    (d / "manifest.csv").write_text(f"file,frequency_hz\n{name},10\n")
    assert "is not a file inside the dataset directory" in error_of(d)
    assert main(["loops", str(d)]) == 2
    err = capsys.readouterr().err
    assert SECRET not in err and err.count("\n") == 1


def test_links_out_of_the_directory_are_not_followed(tmp_path, outside):
    d = write_dataset(tmp_path / "d", [sine()])
    os.symlink(outside, d / "linked.csv")
    (d / "manifest.csv").write_text("file,frequency_hz\nlinked.csv,10\n")
    assert "'linked.csv' links outside the dataset directory" in error_of(d)
    (d / "manifest.csv").unlink()  # a folder scan does not follow it either
    assert "'linked.csv' links outside the dataset directory" in error_of(d)
    (d / "linked.csv").unlink()
    os.symlink(d / "run.csv", d / "inner.csv")  # a link that stays inside is fine
    (d / "manifest.csv").write_text("file,frequency_hz\ninner.csv,10\nrun.csv,10\n")
    assert load_dataset(d).n_loops == 2


def test_extraction_memory_is_linear_in_the_record_length():
    """Peak memory of one extraction at 10 kHz for 6 s and 24 s: 4x the samples take about 4x the memory (the
    sliding median made it grow with samples x cycles: 13.4 GiB for 60 s), and under 400 bytes a sample."""
    peaks = []
    for seconds in (6.0, 24.0):
        rec = sine(seconds=seconds, fs=10000.0)
        tracemalloc.start()
        extract_loop(rec.t, rec.x, rec.force, source="long.csv")
        peaks.append(tracemalloc.get_traced_memory()[1] / rec.t.size)
        tracemalloc.stop()
    assert peaks[1] < 1.3 * peaks[0] and peaks[1] < 400


@pytest.mark.parametrize("where", ["header", "middle"])
def test_a_huge_line_is_refused_without_reading_it_whole(tmp_path, where):
    """A 20 MB line (a 200 MB one took 1.67 GB) is an error after a bounded read."""
    d = write_dataset(tmp_path / "d", [sine()])
    lines = (d / "run.csv").read_text().splitlines()
    huge = ",1.0" * 5_000_000
    if where == "header":
        lines[0] += huge
    else:
        lines[700] += huge
    (d / "run.csv").write_text("\n".join(lines) + "\n")
    error_of(d)  # the compiled reader's code loads once per process, and tracemalloc would count the compiler's memory
    tracemalloc.start()
    message = error_of(d)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert f"line {1 if where == 'header' else 701} is longer than 65536 characters" in message
    assert peak < 12e6


def test_a_deeply_nested_meta_line_is_one_line_error(tmp_path):
    path = tmp_path / "loops.csv"
    write_loops(synth_loops(n_points=10).subset([0, 1]), path)
    lines = path.read_text().splitlines()
    lines[3] = "# meta: " + "[" * 100_000
    path.write_text("\n".join(lines) + "\n")
    assert "the '# meta:' line nests too deeply" in error_of(path)
    lines[3] = '# meta: {"a": 1}'
    lines.insert(4, "# x_harmonics: " + "[" * 100_000)
    path.write_text("\n".join(lines) + "\n")
    assert "the '# x_harmonics:' line must be a JSON array" in error_of(path)


def test_an_absurd_mass_is_refused_at_load(tmp_path, capsys):
    """meq_kg = 1e300 gave an SVD error 50 s into a fit; now dataset.toml, a loops file and a LoopSet refuse it."""
    d = write_dataset(tmp_path / "d", [sine()])
    (d / "dataset.toml").write_text("meq_kg = 1e300\n")
    assert "meq_kg = 1e+300 kg is not a plausible equivalent mass (at most 1e+07 kg)" in error_of(d)
    assert main(["loops", str(d)]) == 2 and "meq_kg" in capsys.readouterr().err
    path = tmp_path / "loops.csv"
    write_loops(synth_loops(n_points=10).subset([0]), path)
    path.write_text(path.read_text().replace("# meq_kg: 0.04", "# meq_kg: 1e300"))
    assert "not a plausible equivalent mass" in error_of(path)
    loops = synth_loops(n_points=10)
    with pytest.raises(HysidInputError, match=r"meq_kg = 100000 kg is not plausible: its inertia force"):
        LoopSet(loops.name, loops.freq_hz, loops.x0, loops.top, loops.bottom, loops.sigma, meq_kg=1e5)
    assert LoopSet(loops.name, loops.freq_hz, loops.x0, loops.top, loops.bottom, loops.sigma, meq_kg=0.04).meq_kg == 0.04


def test_a_complex_mat_file_is_an_error_not_a_silent_cast(tmp_path):
    loops = synth_loops(n_points=20)
    d = tmp_path / "mat"
    d.mkdir()
    scipy.io.savemat(d / "SAMPLE2_05mm_25Hz.mat", {"HexpT": loops.top[0] * (1 + 0.5j), "HexpB": loops.bottom[0]})
    assert "SAMPLE2_05mm_25Hz.mat: HexpT holds complex numbers" in error_of(d)
