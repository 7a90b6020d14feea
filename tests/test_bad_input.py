"""Bad input gives one HysidInputError line naming the file and the problem (exit status 2 through the CLI)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from hysid.cli import main
from hysid_model.datasets import load_dataset
from hysid_model.errors import HysidInputError
from hysid_model.readers.csv_series import write_series
from hysid_model.synth import synth_loops
from support import hysid

FREQ = 10.0
HEADER = "time_s,displacement_m,force_n"


def rows(cycles: float = 6.0, fs: float = 2000.0, freq: float = FREQ) -> list[str]:
    t = np.arange(int(cycles / freq * fs)) / fs
    theta = 2 * np.pi * freq * t
    x, force = 1e-3 * np.sin(theta), 50 * np.sin(theta + 0.3)
    return [f"{a!r},{b!r},{c!r}" for a, b, c in zip(t.tolist(), x.tolist(), force.tolist())]


def dataset(tmp_path: Path, body: list[str] | None = None, header: str = HEADER, manifest: str | None = None, toml: str | None = None) -> Path:
    """A one-record dataset directory whose parts can be spoiled."""
    d = tmp_path / "ds"
    d.mkdir()
    (d / "run.csv").write_text("\n".join([header] + (rows() if body is None else body)) + "\n")
    (d / "manifest.csv").write_text(f"file,frequency_hz\nrun.csv,{FREQ}\n" if manifest is None else manifest)
    if toml is not None:
        (d / "dataset.toml").write_text(toml)
    return d


def error_of(spec, **kwargs) -> str:
    with pytest.raises(HysidInputError) as info:
        load_dataset(spec, **kwargs)
    message = str(info.value)
    assert "\n" not in message
    return message


def spoiled(d: Path, name: str, text: str) -> str:
    """The one-line error of loading the dataset ``d`` once its file ``name`` holds ``text``."""
    (d / name).write_text(text)
    return error_of(d)


def cli_error(args: list[str], capsys) -> str:
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("hysid: error: ") and "Traceback" not in err and err.count("\n") == 1
    return err


def test_missing_or_misspelled_column(tmp_path, capsys):
    d = dataset(tmp_path, header="time_s,displacement_m,forse_n")
    message = error_of(d)
    assert "run.csv" in message and "missing column 'force_n' (found 'forse_n')" in message
    assert "expected columns time_s, displacement_m, force_n, the header has: 'time_s', 'displacement_m', 'forse_n'" in message
    assert "force_n" in cli_error(["loops", str(d)], capsys)


@pytest.mark.parametrize(
    ("row", "line", "expected"),
    [
        (2, "0.001,0.0,nan", "run.csv: line 4: force_n is nan"),
        (2, "0.001,inf,1.0", "line 4: displacement_m is inf"),
        (5, "0.0025,abc,1.0", "run.csv: line 7: displacement_m 'abc' is not a number"),
        (5, "0.0025,1.0", "line 7: 2 values for the 3 columns"),
    ],
)
def test_nan_inf_text_and_ragged_rows_name_column_and_line(tmp_path, row, line, expected):
    body = rows()
    body[row] = line
    assert expected in error_of(dataset(tmp_path, body))


def test_time_must_increase(tmp_path):
    body = rows()
    body[10], body[11] = body[11], body[10]
    assert "run.csv: line 13: time_s does not increase (0.005 after 0.0055)" in error_of(dataset(tmp_path, body))


def test_fewer_than_two_steady_cycles(tmp_path):
    assert "fewer than 2 steady cycles" in error_of(dataset(tmp_path, rows(cycles=1.6)))
    toml = '[[tests]]\nfile = "run.csv"\nsteady_t0_s = 0.1\nsteady_t1_s = 0.25\n'
    d2 = tmp_path / "two"
    d2.mkdir()
    assert "run.csv: fewer than 2 steady cycles (1.50 cycles" in error_of(dataset(d2, toml=toml))


def test_manifest_frequency_disagreeing_with_the_data(tmp_path, capsys):
    d = dataset(tmp_path, manifest="file,frequency_hz\nrun.csv,10.5\n")
    message = error_of(d)
    assert "run.csv: the data's frequency 10 Hz disagrees with the manifest's 10.5 Hz by 4.8 %" in message
    assert "disagrees" in cli_error(["loops", str(d)], capsys)


@pytest.mark.parametrize("value", ["-0.04", '"heavy"', "true", "nan"])
def test_negative_or_non_numeric_mass(tmp_path, capsys, value):
    d = dataset(tmp_path, toml=f"meq_kg = {value}\n")
    assert "dataset.toml: meq_kg must be a mass in kg >= 0 (0 = unknown)" in error_of(d)
    assert "meq_kg" in cli_error(["loops", str(d)], capsys)


def test_listed_file_missing(tmp_path):
    d = dataset(tmp_path, manifest=f"file,frequency_hz\nrun.csv,{FREQ}\nrun2.csv,{FREQ}\n")
    assert "manifest.csv: line 3: listed file 'run2.csv' does not exist" in error_of(d)


def test_empty_files(tmp_path):
    d = dataset(tmp_path)
    assert "run.csv: the file is empty" in spoiled(d, "run.csv", "")
    assert "run.csv: the header is there but there are no data rows" in spoiled(d, "run.csv", HEADER + "\n")
    assert "manifest.csv: the file is empty" in spoiled(d, "manifest.csv", "")


def test_manifest_without_header_or_with_duplicates(tmp_path):
    d = dataset(tmp_path, manifest=f"run.csv,{FREQ}\n")
    assert "manifest.csv: the first line must be the header 'file,frequency_hz' (found 'run.csv,10.0')" in error_of(d)
    assert "manifest.csv: line 3: 'run.csv' is listed twice (also on line 2)" in spoiled(
        d, "manifest.csv", f"file,frequency_hz\nrun.csv,{FREQ}\nrun.csv,{FREQ}\n"
    )
    assert "line 2: frequency_hz 'fast' is not a positive number" in spoiled(d, "manifest.csv", "file,frequency_hz\nrun.csv,fast\n")


def test_invalid_toml_and_bad_bounds(tmp_path):
    d = dataset(tmp_path, toml="name = 'x\nmeq_kg = 1\n")
    assert "dataset.toml: invalid TOML" in error_of(d)
    assert "dataset.toml: bounds.xi0 must be [lower, upper] with lower < upper" in spoiled(d, "dataset.toml", "[bounds]\nxi0 = [0.1, 0.0]\n")
    assert "dataset.toml: [[tests]] file 'other.csv' is not listed in manifest.csv" in spoiled(
        d, "dataset.toml", '[[tests]]\nfile = "other.csv"\nsteady_t0_s = 0\nsteady_t1_s = 1\n'
    )


def test_unknown_dataset_path(tmp_path, capsys):
    missing = tmp_path / "nowhere"
    assert f"{missing}: no such dataset" in error_of(missing)
    assert "no such dataset" in cli_error(["loops", str(missing)], capsys)
    empty = tmp_path / "empty"
    empty.mkdir()
    assert "no dataset here" in error_of(empty)


def test_mat_without_loop_and_v73(tmp_path):
    d = tmp_path / "mat"
    d.mkdir()
    loops = synth_loops(n_points=20)
    scipy.io.savemat(d / "SAMPLE2_05mm_25Hz.mat", {"HexpT": loops.top[0], "HexpB": loops.bottom[0]})
    scipy.io.savemat(d / "SAMPLE2_05mm_26Hz.mat", {"top": loops.top[1], "bottom": loops.bottom[1]})
    assert "SAMPLE2_05mm_26Hz.mat: no HexpT/HexpB loop in this .mat file (variables: bottom, top)" in error_of(d)
    (d / "SAMPLE2_05mm_26Hz.mat").unlink()
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan 1 00:00:00 2024 HDF5 schema 1.00 ."
    (d / "SAMPLE2_05mm_27Hz.mat").write_bytes(header.ljust(116, b" ") + b"\0" * 8 + b"\x00\x02IM" + b"\0" * 512)
    assert "SAMPLE2_05mm_27Hz.mat: MATLAB v7.3 (HDF5) files are not supported" in error_of(d)
    (d / "SAMPLE2_05mm_27Hz.mat").write_bytes(b"")
    assert "SAMPLE2_05mm_27Hz.mat: the file is empty" in error_of(d)
    (d / "SAMPLE2_05mm_27Hz.mat").unlink()
    scipy.io.savemat(d / "ef.mat", {"ef": np.array([25.0, 26.0])})
    assert "ef.mat: ef has 2 frequencies for 1 loop files" in error_of(d)


def test_lvm_needs_sample_rate_and_channels(tmp_path):
    d = tmp_path / "lvm"
    d.mkdir()
    t = np.arange(2000) / 2000.0
    np.savetxt(d / "TRAC1.lvm", np.column_stack([np.sin(2 * np.pi * 10 * t), np.cos(2 * np.pi * 10 * t)]))
    assert "TRAC1.lvm: a headerless .lvm has no time column; set sample_rate_hz in" in error_of(d)
    (d / "TRAC1.lvm").write_text(
        "LabVIEW Measurement\t\nSeparator\tTab\nX_Columns\tOne\n***End_of_Header***\t\n\nChannels\t2\t\t\n***End_of_Header***\t\t\t\n"
        "X_Value\tVoltage\tVoltage_0\tComment\n" + "".join(f"{a}\t{np.sin(a)}\t{np.cos(a)}\n" for a in t)
    )
    assert "TRAC1.lvm: no channel names contain 'disp' or 'position' (channels: 'Voltage', 'Voltage_0'); set displacement_channel" in error_of(d)


def test_manifest_and_loops_file_together_and_bad_tidy(tmp_path):
    d = dataset(tmp_path)
    assert "holds both manifest.csv (raw records) and loops.csv (extracted loops); keep one" in spoiled(d, "loops.csv", "# hysid-loops v1\n")
    (d / "manifest.csv").unlink()
    assert "loops.csv: header line '# name: ...' missing" in error_of(d)
    assert "unsupported loops file version 'hysid-loops v9'" in spoiled(d, "loops.csv", "# hysid-loops v9\n")
    assert "loops.csv: meq_kg must be a positive mass or 'unknown'" in spoiled(d, "loops.csv", "# hysid-loops v1\n# name: x\n# meq_kg: -1\n# meta: {}\n")


def test_synth_never_overwrites(tmp_path, capsys):
    out = tmp_path / "taken"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    assert "already exists and is not empty; choose a new directory" in cli_error(["synth", str(out)], capsys)  # the one --out policy
    assert (out / "keep.txt").read_text() == "mine" and len(list(out.iterdir())) == 1
    assert "noise must be a percentage from 0 to 100" in cli_error(["loops", "synth", "--noise", "150"], capsys)
    assert "points per branch must be an integer >= 2" in cli_error(["loops", "synth", "--points", "1"], capsys)


# The outside probe's bad files (issue 23): each a real file through the real command line, in a process of its own
# (so that a traceback or a RuntimeWarning would reach its stderr as a user sees it).

PROBE_FS = 2000.0


def sweep_records(directory: Path, freqs: list[float], force_of=None, *, damping: float = 20.0, clip: float | None = None, swap: bool = False) -> Path:
    """Records of a 0.5 kg, 2e4 N/m specimen (resonance 31.8 Hz) at 1 mm, written as CSV files with a manifest;
    ``force_of(k, force)`` spoils record k's force; ``clip`` clips every force at that share of the set's largest
    (noise after the clip, as a converter after a saturated amplifier adds it); ``swap`` swaps the columns."""
    directory.mkdir()
    rng = np.random.default_rng(0)
    w_all = 2 * np.pi * np.asarray(freqs)
    peak = float(np.max(np.hypot(2e4 - 0.5 * w_all**2, damping * w_all))) * 1e-3
    lines = ["file,frequency_hz"]
    for k, f in enumerate(freqs):
        t = np.arange(int(20 / f * PROBE_FS)) / PROBE_FS
        w = 2 * np.pi * f
        x = 1e-3 * np.sin(w * t)
        force = (2e4 - 0.5 * w * w) * x + damping * w * 1e-3 * np.cos(w * t)
        if clip is not None:
            force = np.clip(force, -clip * peak, clip * peak)
        force = force + 1e-4 * peak * rng.standard_normal(t.size)
        x = x + 1e-7 * rng.standard_normal(t.size)
        if force_of is not None:
            force = force_of(k, force)
        write_series(directory / f"r{k}.csv", t, force * 1e-4 if swap else x, x * 1e4 if swap else force)
        lines.append(f"r{k}.csv,{f!r}")
    (directory / "manifest.csv").write_text("\n".join(lines) + "\n")
    return directory


def run_cli(*args: str) -> subprocess.CompletedProcess:
    done = subprocess.run(hysid(*args), capture_output=True, text=True, timeout=600)
    assert "Traceback" not in done.stderr and "RuntimeWarning" not in done.stderr, done.stderr
    return done


def one_error_line(done: subprocess.CompletedProcess) -> str:
    assert done.returncode == 2 and done.stderr.startswith("hysid: error: ") and done.stderr.count("\n") == 1, done.stderr
    return done.stderr


def test_values_near_1e300_are_one_line(tmp_path):
    """They overflowed into a NaN cycle count in the steady window's search (a traceback)."""
    d = sweep_records(tmp_path / "d", [20.0, 25.0, 30.0], force_of=lambda k, force: force * 1e300)
    err = one_error_line(run_cli("loops", str(d)))
    assert "r0.csv: the force reaches 1.24e+301 N, beyond any physical force" in err


def test_one_record_with_zero_force_is_one_line(tmp_path):
    """Four lines of RuntimeWarning (log10 of 0, in the unit-slip check) came before the error of the fit."""
    d = sweep_records(tmp_path / "d", [20.0, 25.0, 30.0], force_of=lambda k, force: force * 0.0 if k == 1 else force)
    err = one_error_line(run_cli("loops", str(d)))
    assert "r1.csv: the force is 0 N in every sample: no loop to extract" in err


@pytest.mark.slow  # over 3 s (fast lane, 2 cores, 2026-11-29)
def test_a_force_clipped_at_a_fifth_of_its_largest_is_named(tmp_path):
    """A force channel saturated at 20 % of the sweep's largest force: the loops are usable but their force tops are
    the sensor's, which the warning says (as for a clipped displacement)."""
    d = sweep_records(tmp_path / "d", [25.7, 30.2, 31.7, 36.2, 37.2, 39.2], damping=0.58, clip=0.2)
    done = run_cli("loops", str(d))
    assert done.returncode == 0 and done.stderr.count("\n") == 1
    assert "clipped: r0: force flat at +2.068 N; r3: force flat at +2.068 N" in done.stderr
    assert "(a load cell or its amplifier at the end of its range?)" in done.stderr


@pytest.mark.slow
def test_a_fit_of_force_clipped_loops_writes_its_report(tmp_path):
    """The same clipped sweep through `hysid fit`: the parabola through the peak of its compliance dipped below zero,
    the half-power figure's axis limits became NaN (a traceback) and no report.md was written."""
    d = sweep_records(tmp_path / "d", [25.7, 30.2, 31.7, 36.2, 37.2, 39.2], damping=0.58, clip=0.2)
    out = tmp_path / "out"
    done = run_cli("fit", str(d), "--model", "baseline", "--out", str(out), "--quiet")
    assert done.returncode == 0 and "clipped: r0: force flat at" in done.stderr
    assert (out / "report.md").is_file() and (out / "half_power.png").is_file()


@pytest.mark.slow  # over 3 s (fast lane, 2 cores, 2026-11-29)
def test_columns_swapped_with_plausible_magnitudes_are_named(tmp_path):
    """Force (about 10 N) and displacement (1 mm) swapped and scaled to look like a mm and tens of N: the fit gave
    xi0 at its bound with a generic warning. The loops generate energy, and their lag grows with frequency."""
    d = sweep_records(tmp_path / "d", [25.0, 28.0, 31.0, 34.0, 37.0], swap=True)
    done = run_cli("loops", str(d))
    assert done.returncode == 0 and done.stderr.count("\n") == 1
    assert "the loops generate energy in r0 (a lag of 22.3 deg), r1 (a lag of 37.9 deg)" in done.stderr
    assert "the lag grows with frequency, a passive specimen's mirrored: force and displacement look swapped" in done.stderr
