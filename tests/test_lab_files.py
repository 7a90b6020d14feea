"""Files as labs write them (issue 37, items 1-4): German manifests, free-text preambles, one HDF5 or TDMS file of
one group per test, the header mistakes of several files in one error.

Every test writes the files as a lab's software or spreadsheet does (cp1252, ``;``, decimal commas, CRLF) in
tmp_path and reads them back through load_dataset or the command line; each must give the loops of the same samples
written as hysid's own CSV records."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from hysid.cli import main
from hysid_model.datasets import load_dataset, write_dataset
from hysid_model.errors import HysidInputError, HysidWarning
from hysid_model.loops import LoopSet
from hysid_model.synth import RawRecord
from support import record, same_loops

RECORDS = [record("probe_f9,5Hz", 9.5, 1e-3, 3), record("probe_f12,5Hz", 12.5, 2e-3, 4)]
PREAMBLE = ["Prüfstand: Hydropuls HP 25", "Datum: 12.03.2024   Uhrzeit: 10:14", "Probe: Drahtseil 3, Sollwert 9,5 Hz", ""]


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> LoopSet:
    """The loops of RECORDS written as hysid's own CSV records (their frequencies from their names)."""
    d = write_dataset(tmp_path_factory.mktemp("ref") / "d", RECORDS)
    (d / "manifest.csv").unlink()
    return load_dataset(d)


def german_csv(path: Path, rec: RawRecord, preamble: list[str] = (), header: str = "Zeit [s];Weg [mm];Kraft [kN]") -> None:
    """A record as a German lab exports it: cp1252, CRLF, ``;``, decimal commas, mm and kN, 12 digits."""
    rows = [f"{t:.12g};{x * 1e3:.12g};{f * 1e-3:.12g}".replace(".", ",") for t, x, f in zip(rec.t, rec.x, rec.force)]
    (path).write_bytes("\r\n".join([*preamble, header, *rows, ""]).encode("cp1252"))


def german_set(directory: Path, preamble: list[str] = ()) -> Path:
    directory.mkdir()
    for rec in RECORDS:
        german_csv(directory / f"{rec.label}.csv", rec, preamble)
    return directory


@pytest.mark.parametrize(
    "manifest, encoding",
    [
        ("file,frequency_hz\nprobe_f9,5Hz.csv,9.5\nprobe_f12,5Hz.csv,12.5\n", "utf-8"),  # unquoted names holding the separator
        ("file,frequency_hz\nprobe_f9,5Hz.csv,9,5\nprobe_f12,5Hz.csv,12,5\n", "utf-8"),  # and decimal commas in the frequency
        ("File;Frequency_Hz\r\nprobe_f9,5Hz.csv;9,5\r\nprobe_f12,5Hz.csv;12,5\r\n", "cp1252"),  # a German spreadsheet's export
        ('file,frequency_hz\n"probe_f9,5Hz.csv",9.5\n"probe_f12,5Hz.csv",12.5\n', "utf-8"),  # quoted, as before
    ],
)
def test_a_manifest_of_german_file_names_as_spreadsheets_write_it(tmp_path, reference, manifest, encoding):
    d = german_set(tmp_path / "d")
    (d / "manifest.csv").write_bytes(manifest.encode(encoding))
    loops = load_dataset(d)
    same_loops(loops, reference)
    assert loops.meta["per_loop"]["file"] == ["probe_f9,5Hz.csv", "probe_f12,5Hz.csv"]
    assert loops.meta["per_loop"]["nominal_frequency_hz"] == [9.5, 12.5]


def test_a_manifest_row_that_names_no_file_says_which(tmp_path):
    d = german_set(tmp_path / "d")
    (d / "manifest.csv").write_text("file;frequency_hz\nprobe_f9,5Hz.csv;9,5\nprobe_f2,5Hz.csv;2,5\n")
    with pytest.raises(HysidInputError, match=r"manifest.csv: line 3: listed file 'probe_f2,5Hz.csv' does not exist"):
        load_dataset(d)


def test_a_free_text_preamble_is_skipped_with_a_warning_naming_it(tmp_path, reference, capsys):
    """Lines of free text (not ``#``) before the header: skipped with one warning for the set, which names them and
    the way to say so; ``skip_rows`` in dataset.toml or ``--skip-rows`` reads them without it."""
    d = german_set(tmp_path / "d", PREAMBLE)
    with pytest.warns(HysidWarning) as caught:
        loops = load_dataset(d)
    same_loops(loops, reference)
    notes = [str(w.message) for w in caught if "free text" in str(w.message)]
    assert notes == [
        "skipped 3 lines of free text before the header line 5 ('Zeit [s];Weg [mm];Kraft [kN]'), starting with line 1 "
        "'Prüfstand: Hydropuls HP 25'; skip_rows = 4 in dataset.toml (or --skip-rows 4) says so and keeps this quiet "
        "(in 2 of 2 records)"
    ]
    (d / "dataset.toml").write_text("skip_rows = 4\n")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", HysidWarning)
        same_loops(load_dataset(d), reference)
    assert not [w for w in caught if "free text" in str(w.message)]
    (d / "dataset.toml").unlink()
    assert main(["loops", str(d), "--skip-rows", "4"]) == 0
    out, err = capsys.readouterr()
    assert "free text" not in err and "probe_f12,5Hz" in out


def test_a_preamble_that_cannot_be_told_from_a_header_gets_an_error_with_the_way_out(tmp_path, reference, capsys):
    """A first line with as many fields as the data (``Probe;Seil 3;Nr 2``) may be a header: the error about its
    columns says how many lines to skip, and ``--skip-rows`` reads the file."""
    d = tmp_path / "d"
    d.mkdir()
    german_csv(d / "run.csv", RECORDS[0], ["Probe;Seil 3;Nr 2", "Datum;12.03.2024;10:14", ""])
    with pytest.raises(HysidInputError) as info:
        load_dataset(d / "run.csv")
    assert "missing column 'time_s', 'displacement_m', 'force_n'" in str(info.value)
    assert str(info.value).endswith("if lines 1-3 are a preamble, skip them: skip_rows = 3 in dataset.toml or --skip-rows 3")
    assert main(["loops", str(d / "run.csv"), "--skip-rows", "3"]) == 0
    assert capsys.readouterr().out.startswith("d: 1 loops")
    np.testing.assert_allclose(load_dataset(d / "run.csv", skip_rows=3).top, reference.subset([0]).top, rtol=1e-6, atol=1e-9 * np.abs(reference.top).max())
    assert main(["loops", str(d), "--skip-rows", "-1"]) == 2
    assert "--skip-rows -1: must be a whole number of lines >= 0" in capsys.readouterr().err


@pytest.mark.parametrize("layout", ["datasets", "compound", "nested"])
def test_one_hdf5_file_of_one_group_per_test(tmp_path, reference, layout):
    """Every group holding a displacement and a force channel is a test, named after the group, its frequency from
    the group's frequency_hz attribute or its name; the layouts of the README."""
    h5py = pytest.importorskip("h5py")
    d = tmp_path / "h5"
    d.mkdir()
    with h5py.File(d / "tests.h5", "w") as f:
        for k, rec in enumerate(RECORDS):
            name = rec.label if layout != "nested" else f"Prüfling/{rec.label}"
            group = f.create_group(name)
            if layout == "compound":
                table = np.zeros(rec.t.size, dtype=[("Zeit", float), ("Weg", float), ("Kraft", float)])
                table["Zeit"], table["Weg"], table["Kraft"] = rec.t, rec.x * 1e3, rec.force / 1e3
                group["samples"] = table
                (d / "dataset.toml").write_text('displacement_unit = "mm"\nforce_unit = "kN"\n')
            else:
                group["time_s"] = rec.t
                group.create_dataset("Weg", data=rec.x * 1e3).attrs["units"] = "mm"
                group.create_dataset("Kraft", data=rec.force / 1e3).attrs["units"] = "kN"
            if k == 1:
                group.attrs["frequency_hz"] = rec.freq_hz
    loops = load_dataset(d)
    same_loops(loops, reference if layout != "nested" else relabelled(reference, "Prüfling/"))
    assert loops.meta["per_loop"]["nominal_frequency_hz"] == [9.5, 12.5]
    (d / "manifest.csv").write_text("file,frequency_hz\ntests.h5,9.5\n")
    with pytest.raises(HysidInputError, match=r"'tests.h5' holds 2 records; a file of several records .* is read without a manifest"):
        load_dataset(d)


def relabelled(loops: LoopSet, prefix: str) -> LoopSet:
    out = loops.subset(np.arange(loops.n_loops))
    out.labels = [prefix + label for label in loops.labels]
    return out


def test_one_tdms_file_of_one_group_per_test(tmp_path, reference):
    nptdms = pytest.importorskip("nptdms")
    d = tmp_path / "tdms"
    d.mkdir()
    dt = float(RECORDS[0].t[1])
    with nptdms.TdmsWriter(d / "tests.tdms") as writer:
        for rec in RECORDS:
            writer.write_segment(
                [
                    nptdms.GroupObject(rec.label, properties={"frequency_hz": rec.freq_hz}),
                    nptdms.ChannelObject(rec.label, "Weg", rec.x * 1e3, properties={"unit_string": "mm", "wf_increment": dt}),
                    nptdms.ChannelObject(rec.label, "Kraft", rec.force, properties={"unit_string": "N"}),
                ]
            )
    same_loops(load_dataset(d / "tests.tdms"), reference)


def test_header_mistakes_of_several_files_come_in_one_error(tmp_path, capsys):
    """Typos in the headers of several files: one error names every bad file (those with the same mistake
    together), not one file per run; the good file is not named."""
    records = [record(f"run{k}", 10.0, 1e-3, k, cycles=4) for k in range(1, 5)]
    d = write_dataset(tmp_path / "d", records)
    for name, header in (
        ("run1.csv", "time_s,displacement_m,forse_n"),
        ("run3.csv", "time_s,displacement_m,forse_n"),
        ("run4.csv", "time_s,displacment_mm,force_n"),
    ):
        lines = (d / name).read_text().splitlines()
        (d / name).write_text("\n".join([header] + lines[1:]) + "\n")
    with pytest.raises(HysidInputError) as info:
        load_dataset(d)
    message = str(info.value)
    assert message.startswith(f"{d}: 3 of 4 records cannot be read: run1.csv, run3.csv: missing column 'force_n' (found 'forse_n')")
    assert "; run4.csv: missing column 'displacement_m' (found 'displacment_mm')" in message and "run2" not in message
    assert main(["loops", str(d)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "run1.csv, run3.csv" in err and "run4.csv" in err


def test_channel_mistakes_of_several_hdf5_files_come_in_one_error(tmp_path):
    h5py = pytest.importorskip("h5py")
    d = tmp_path / "h5"
    d.mkdir()
    for k, rec in enumerate(RECORDS):
        with h5py.File(d / f"run{k}.h5", "w") as f:
            f["time_s"], f["displacement_m"], f["Load_cell_2"] = rec.t, rec.x, rec.force
    (d / "manifest.csv").write_text("file,frequency_hz\nrun0.h5,9.5\nrun1.h5,12.5\n")
    with pytest.raises(HysidInputError, match=r": 2 of 2 records cannot be read: run0.h5, run1.h5: no force channel"):
        load_dataset(d)
