"""Raw records as other tools write them: CSV dialects, NI TDMS, HDF5, tidy long CSV, folders without a manifest.

Every test writes real files (numpy, npTDMS, h5py) in tmp_path and reads them back through load_dataset;
each format must give the same loops as the plain CSV record of the same samples."""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from hysid.cli import main
from hysid_model.datasets import load_dataset, write_dataset
from hysid_model.errors import HysidInputError, HysidWarning
from hysid_model.loops import LoopSet
from hysid_model.synth import RawRecord
from support import FS, record, same_loops

RECORDS = [record("run1", 9.0, 1e-3, 1), record("run2", 12.5, 2e-3, 2)]


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> LoopSet:
    """The loops of RECORDS written as hysid's own CSV records."""
    return load_dataset(write_dataset(tmp_path_factory.mktemp("ref") / "d", RECORDS))


def manifest(directory: Path, files: list[str]) -> None:
    rows = [f"{name},{rec.freq_hz!r}" for name, rec in zip(files, RECORDS)]
    (directory / "manifest.csv").write_text("\n".join(["file,frequency_hz"] + rows) + "\n")


def csv_dataset(directory: Path, write) -> Path:
    """A dataset directory of one CSV per record, each written by ``write(path, record)``, and a manifest."""
    directory.mkdir()
    for rec in RECORDS:
        write(directory / f"{rec.label}.csv", rec)
    manifest(directory, [f"{r.label}.csv" for r in RECORDS])
    return directory


def test_csv_headers_in_any_case_with_semicolons_and_decimal_commas(tmp_path, reference):
    def write(path: Path, rec: RawRecord) -> None:
        lines = ["# exported by a DAQ", "# operator: somebody", "Time_S;Displacement_M;FORCE_N"]
        lines += [f"{t:.12g};{x:.12g};{f:.12g}".replace(".", ",") for t, x, f in zip(rec.t, rec.x, rec.force)]
        path.write_text("\n".join(lines) + "\n")

    same_loops(load_dataset(csv_dataset(tmp_path / "eu", write)), reference)


def test_tab_separated_csv_with_unit_suffixes_is_converted(tmp_path, reference):
    def write(path: Path, rec: RawRecord) -> None:
        data = np.column_stack([rec.t * 1e3, rec.x * 1e3, rec.force / 4.4482216152605])
        np.savetxt(path, data, delimiter="\t", fmt="%.15g", header="time_ms\tdisplacement_mm\tforce_lbf", comments="")

    same_loops(load_dataset(csv_dataset(tmp_path / "units", write)), reference)


@pytest.mark.parametrize(
    "header, scale",
    [
        ("Time [s],Displacement [mm],Force [N]", (1.0, 1e3, 1.0)),
        ("Time (s),Position (mm),Load (kN)", (1.0, 1e3, 1e-3)),
        ("t/s,x/m,F/N", (1.0, 1.0, 1.0)),
        ("TIME;DISP_MM;FORCE_N", (1.0, 1e3, 1.0)),
        ("Zeit [ms],Weg [mm],Kraft [N]", (1e3, 1e3, 1.0)),
        ("time s,disp_m,load_N", (1.0, 1.0, 1.0)),
    ],
)
def test_csv_headers_as_daq_software_writes_them(tmp_path, reference, header, scale):
    """Units in brackets, parentheses, after a slash, a space or an underscore; the usual words for each quantity."""
    delimiter = ";" if ";" in header else ","

    def write(path: Path, rec: RawRecord) -> None:
        data = np.column_stack([rec.t * scale[0], rec.x * scale[1], rec.force * scale[2]])
        np.savetxt(path, data, delimiter=delimiter, fmt="%.15g", header=header, comments="")

    same_loops(load_dataset(csv_dataset(tmp_path / "daq", write)), reference)


def test_headers_without_units_are_read_as_si_with_a_warning(tmp_path, reference):
    def write(path: Path, rec: RawRecord) -> None:
        np.savetxt(path, np.column_stack([rec.t, rec.x, rec.force]), delimiter=",", fmt="%.15g", header="t,x,force", comments="")

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        same_loops(load_dataset(csv_dataset(tmp_path / "bare", write)), reference)
    units = [str(w.message) for w in caught if "states no unit" in str(w.message)]
    assert units == [  # once per dataset, with how many records said it
        "channel 'x' states no unit: read as m (set displacement_unit in dataset.toml if it is not) (in 2 of 2 records)",
        "channel 'force' states no unit: read as N (set force_unit in dataset.toml if it is not) (in 2 of 2 records)",
    ]


def test_a_header_without_a_force_column_names_what_it_has_and_the_dataset_toml_keys(tmp_path):
    path = tmp_path / "d" / "run.csv"
    path.parent.mkdir()
    path.write_text("Time [s],Displacement [mm],Frequency [Hz]\n0,1,10\n")
    with pytest.raises(
        HysidInputError,
        match=r"missing column 'force_n'.*the header has: 'Time \[s\]', 'Displacement \[mm\]', 'Frequency \[Hz\]'.*force_channel in dataset.toml",
    ):
        load_dataset(path)


@pytest.mark.parametrize("name, hz", [("run_9,5Hz", 9.5), ("run_9p5Hz", 9.5), ("run 12.25 Hz", 12.25), ("light_12_Hz", 12.0), ("s2_05mm_436Hz", 436.0)])
def test_frequencies_in_record_names_with_decimal_commas_and_p(name, hz):
    from hysid_model.readers.dataset_dir import frequency_in_name

    assert frequency_in_name(name) == hz


def test_csv_channels_and_units_named_in_dataset_toml(tmp_path, reference):
    """A header of the rig's own names, and the mm-under-_m slip fixed by declaring the unit."""

    def write(path: Path, rec: RawRecord) -> None:
        np.savetxt(path, np.column_stack([rec.force / 1e3, rec.t, rec.x * 1e3]), delimiter=",", fmt="%.15g", header="Load,Zeit,displacement_m", comments="")

    d = csv_dataset(tmp_path / "named", write)
    (d / "dataset.toml").write_text('time_channel = "zeit"\nforce_channel = "LOAD"\nforce_unit = "kN"\ndisplacement_unit = "mm"\n')
    same_loops(load_dataset(d), reference)


def write_tdms(path: Path, rec: RawRecord, *, with_time: bool, group: str = "Measurement") -> None:
    nptdms = pytest.importorskip("nptdms")
    dt = float(rec.t[1] - rec.t[0])
    objects = [
        nptdms.ChannelObject(group, "Displacement", rec.x * 1e3, properties={"unit_string": "mm", "wf_increment": dt, "wf_start_offset": 0.0}),
        nptdms.ChannelObject(group, "Force", rec.force / 1e3, properties={"unit_string": "kN"}),
    ]
    if with_time:
        objects.insert(0, nptdms.ChannelObject(group, "time_ms", rec.t * 1e3))
    with nptdms.TdmsWriter(path) as writer:
        writer.write_segment(objects)


def test_tdms_records_read_like_csv_records(tmp_path, reference):
    """A manifest of .tdms files: one with a time channel, one with waveform timing only; units from unit_string."""
    d = tmp_path / "tdms"
    d.mkdir()
    write_tdms(d / "run1.tdms", RECORDS[0], with_time=True)
    write_tdms(d / "run2.tdms", RECORDS[1], with_time=False)
    manifest(d, ["run1.tdms", "run2.tdms"])
    same_loops(load_dataset(d), reference)
    nptdms = pytest.importorskip("nptdms")
    with nptdms.TdmsWriter(d / "run1.tdms") as writer:  # a name and a stated unit that disagree
        writer.write_segment(
            [
                nptdms.ChannelObject("g", "time_s", RECORDS[0].t),
                nptdms.ChannelObject("g", "force_n", RECORDS[0].force),
                nptdms.ChannelObject("g", "displacement_m", RECORDS[0].x * 1e3, properties={"unit_string": "mm"}),
            ]
        )
    with pytest.raises(HysidInputError, match=r"run1.tdms: channel 'g/displacement_m' states the unit 'mm' but its name says m; set displacement_unit"):
        load_dataset(d)
    (d / "dataset.toml").write_text('displacement_unit = "mm"\n')
    same_loops(load_dataset(d), reference)


def test_a_single_tdms_file_with_channels_named_in_dataset_toml(tmp_path, reference):
    nptdms = pytest.importorskip("nptdms")
    d = tmp_path / "one"
    d.mkdir()
    rec = RECORDS[0]
    with nptdms.TdmsWriter(d / "run1.tdms") as writer:
        writer.write_segment(
            [
                nptdms.ChannelObject("Rig", "LVDT", rec.x / 0.0254, properties={"unit_string": "in"}),
                nptdms.ChannelObject("Rig", "Load cell", rec.force),
            ]
        )
    (d / "dataset.toml").write_text('displacement_channel = "Rig/LVDT"\nforce_channel = "load cell"\nsample_rate_hz = 3000\n')
    same_loops(load_dataset(d / "run1.tdms"), reference.subset([0]))
    (d / "dataset.toml").write_text('displacement_channel = "LVDT"\nforce_channel = "load cell"\n')
    with pytest.raises(HysidInputError, match=r"run1.tdms: no time channel .* set sample_rate_hz in"):
        load_dataset(d / "run1.tdms")


def test_hdf5_records_from_datasets_and_compound_fields(tmp_path, reference):
    h5py = pytest.importorskip("h5py")
    d = tmp_path / "h5"
    d.mkdir()
    with h5py.File(d / "run1.h5", "w") as f:
        g = f.create_group("test")
        g["time_s"] = RECORDS[0].t
        g["displacement_m"] = RECORDS[0].x
        force = g.create_dataset("Force", data=RECORDS[0].force * 1e3)
        force.attrs["units"] = "mN"
    table = np.zeros(RECORDS[1].t.size, dtype=[("displacement_um", float), ("force_n", float)])
    table["displacement_um"], table["force_n"] = RECORDS[1].x * 1e6, RECORDS[1].force
    with h5py.File(d / "run2.hdf5", "w") as f:
        ds = f.create_dataset("samples", data=table)
        ds.attrs["sample_rate_hz"] = FS
    manifest(d, ["run1.h5", "run2.hdf5"])
    same_loops(load_dataset(d), reference)


def test_tdms_and_hdf5_channels_in_a_group_named_as_daq_software_names_them(tmp_path, reference):
    """Channels inside a group, named by the words of the README (Weg, Kraft), with or without a unit in the
    name: ``Messung/Weg [mm]`` and ``Messung/Kraft`` (unit stated by the file) in TDMS, ``Messung/Weg`` and
    ``Messung/Kraft [kN]`` in HDF5."""
    nptdms = pytest.importorskip("nptdms")
    h5py = pytest.importorskip("h5py")
    d = tmp_path / "grouped"
    d.mkdir()
    dt = float(RECORDS[0].t[1] - RECORDS[0].t[0])
    with nptdms.TdmsWriter(d / "run1.tdms") as writer:
        writer.write_segment(
            [
                nptdms.ChannelObject("Messung", "Weg [mm]", RECORDS[0].x * 1e3, properties={"wf_increment": dt, "wf_start_offset": 0.0}),
                nptdms.ChannelObject("Messung", "Kraft", RECORDS[0].force / 1e3, properties={"unit_string": "kN"}),
            ]
        )
    with h5py.File(d / "run2.h5", "w") as f:
        g = f.create_group("Messung")
        g["Zeit [s]"] = RECORDS[1].t
        g["Weg"] = RECORDS[1].x
        g["Kraft [kN]"] = RECORDS[1].force / 1e3
    manifest(d, ["run1.tdms", "run2.h5"])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        same_loops(load_dataset(d), reference)
    assert [str(w.message) for w in caught if "states no unit" in str(w.message)] == [
        "channel 'Messung/Weg' states no unit: read as m (set displacement_unit in dataset.toml if it is not)"
    ]


def test_daq_files_that_cannot_be_records(tmp_path):
    h5py = pytest.importorskip("h5py")
    d = tmp_path / "bad"
    d.mkdir()
    with h5py.File(d / "c.h5", "w") as f:
        f["time_s"] = RECORDS[0].t
        f["displacement_m"] = RECORDS[0].x.astype(complex)
        f["force_n"] = RECORDS[0].force
    with pytest.raises(HysidInputError, match=r"c.h5: channel 'displacement_m' holds complex numbers"):
        load_dataset(d / "c.h5")
    with h5py.File(d / "d.h5", "w") as f:
        f["displacement_m"] = RECORDS[0].x
        f["force_n"] = RECORDS[0].force
        f["force_kN"] = RECORDS[0].force
    with pytest.raises(HysidInputError, match=r"d.h5: no time channel"):
        load_dataset(d / "d.h5")
    (d / "dataset.toml").write_text("sample_rate_hz = 3000\n")
    assert load_dataset(d / "d.h5").n_loops == 1  # force_n is the default name; force_kN is not consulted
    (d / "e.tdms").write_bytes(b"TDSm not really")
    with pytest.raises(HysidInputError, match=r"e.tdms: (not a readable TDMS file|holds no channels)"):
        load_dataset(d / "e.tdms")


@pytest.mark.parametrize("module, suffix, extra", [("nptdms", ".tdms", "npTDMS"), ("h5py", ".h5", "h5py")])
def test_a_missing_optional_reader_is_one_line_naming_the_extra(tmp_path, monkeypatch, capsys, module, suffix, extra):
    path = tmp_path / f"run{suffix}"
    path.write_bytes(b"\0" * 64)
    monkeypatch.setitem(sys.modules, module, None)  # as if it were not installed: importing it raises ImportError
    with pytest.raises(HysidInputError, match=rf"run{suffix}: reading .* files needs {extra}: pip install 'hysid\[daq\]'"):
        load_dataset(path)
    assert main(["loops", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "hysid[daq]" in err and "Traceback" not in err


def test_tidy_long_csv_of_several_records(tmp_path, reference):
    """record,time_s,channel,value,unit rows (a database export) in any order, and the wide form with a record column."""
    rows = ["record,time_s,channel,value,unit,frequency_hz"]
    for rec in RECORDS:
        for t, x, f in zip(rec.t.tolist(), rec.x.tolist(), rec.force.tolist()):
            rows.append(f"{rec.label},{t!r},disp,{x * 1e3!r},mm,{rec.freq_hz}")
            rows.append(f"{rec.label},{t!r},force,{f!r},N,{rec.freq_hz}")
    body = rows[1:]
    np.random.default_rng(0).shuffle(body)
    d = tmp_path / "long"
    d.mkdir()
    (d / "all.csv").write_text("\n".join(rows[:1] + body) + "\n")
    (d / "dataset.toml").write_text('displacement_channel = "disp"\nforce_channel = "force"\n')
    loops = load_dataset(d / "all.csv")
    same_loops(loops, reference)
    assert loops.meta["per_loop"]["nominal_frequency_hz"] == [9.0, 12.5]
    wide = ["record;time_s;displacement_m;force_n"] + [
        f"{rec.label};{t:.15g};{x:.15g};{f:.15g}".replace(".", ",") for rec in RECORDS for t, x, f in zip(rec.t.tolist(), rec.x.tolist(), rec.force.tolist())
    ]
    w = tmp_path / "wide"
    w.mkdir()
    (w / "runs.csv").write_text("\n".join(wide) + "\n")
    with pytest.warns(HysidWarning, match=r"no manifest.csv; frequencies estimated from the data: run1 9 Hz, run2 12.5 Hz"):
        same_loops(load_dataset(w), reference)


def test_long_csv_whose_channels_disagree(tmp_path):
    rec = RECORDS[0]
    rows = ["record,time_s,channel,value"]
    rows += [f"a,{t!r},displacement_m,{x!r}" for t, x in zip(rec.t.tolist(), rec.x.tolist())]
    rows += [f"a,{t!r},force_n,{f!r}" for t, f in zip(rec.t[:-5].tolist(), rec.force[:-5].tolist())]
    (tmp_path / "a.csv").write_text("\n".join(rows) + "\n")
    with pytest.raises(HysidInputError, match=r"record 'a': 'displacement_m' and 'force_n' are not sampled at the same times"):
        load_dataset(tmp_path / "a.csv")


def test_a_folder_of_csv_records_without_a_manifest(tmp_path, reference, capsys):
    """Frequencies are estimated from the data, reported as a warning, and the manifest that fixes them is kept
    in loops.meta and printed by `hysid loops`; a CSV that holds no record is left out with a warning."""
    d = tmp_path / "plain"
    write_dataset(d, RECORDS)
    (d / "manifest.csv").unlink()
    (d / "notes.csv").write_text("date,operator\n2024-01-01,me\n")
    with pytest.warns(HysidWarning) as caught:
        loops = load_dataset(d)
    messages = [str(w.message) for w in caught]
    assert any("left out notes.csv" in m for m in messages)
    assert any("frequencies estimated from the data: run1 9 Hz, run2 12.5 Hz" in m for m in messages)
    same_loops(loops, reference)
    assert loops.meta["estimated_manifest"] == "file,frequency_hz\nrun1.csv,9\nrun2.csv,12.5\n"
    (d / "manifest.csv").write_text(loops.meta["estimated_manifest"])
    same_loops(load_dataset(d), reference)
    (d / "manifest.csv").unlink()
    assert main(["loops", str(d)]) == 0
    out, err = capsys.readouterr()
    assert "hysid: warning:" in err and "frequencies estimated from the data" in err
    assert "manifest.csv it would write" in out and "run2.csv,12.5" in out
    assert main(["loops", str(d), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["frequency_hz"] for r in rows] == pytest.approx([9.0, 12.5], rel=1e-5)
