"""Readers and load_dataset: every format round-trips (write -> read -> the same LoopSet), plus the data CLI."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from hysid.cli import main
from hysid_model.datasets import load_dataset, write_dataset
from hysid_model.extraction import centre_branches, extract_loop
from hysid_model.loops import LoopSet
from hysid_model.readers.dataset_dir import read_config
from hysid_model.readers.lvm import read_lvm
from hysid_model.readers.tidy import read_loops, write_loops
from hysid_model.synth import AMPLITUDES_M, FREQUENCIES_HZ, MEQ_KG, RawRecord, synth_loops
from support import DAMPER as REAL


def sine_record(label: str, freq: float, x0: float, seed: int, fs: float = 4000.0, cycles: int = 8) -> RawRecord:
    """A steady record: x = x0 sin(wt), F = a stiff, damped loop with a 3rd harmonic, plus noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(cycles / freq * fs)) / fs
    theta = 2 * np.pi * freq * t
    force = 1e4 * x0 * (np.sin(theta + 0.4) + 0.1 * np.sin(3 * theta)) + 0.05 * rng.standard_normal(t.size)
    return RawRecord(label, freq, x0, t, x0 * np.sin(theta), force, 0.05)


def assert_same_loops(a: LoopSet, b: LoopSet, rtol: float = 0.0, atol: float = 0.0) -> None:
    for name in ("freq_hz", "x0", "top", "bottom", "sigma"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=rtol, atol=atol, equal_nan=True, err_msg=name)
    np.testing.assert_array_equal(a.cycles, b.cycles)
    assert a.labels == b.labels
    assert a.meq_kg == b.meq_kg


def centred_synth(n_loops: int = 4) -> LoopSet:
    """Synth loops centred like centercurveloop, so a .mat round trip has nothing to change."""
    loops = synth_loops(5.0, seed=1, n_points=60).subset(np.arange(0, 120, 120 // n_loops))
    pairs = [centre_branches(t, b) for t, b in zip(loops.top, loops.bottom)]
    loops.top = np.array([p[0] for p in pairs])
    loops.bottom = np.array([p[1] for p in pairs])
    loops.sigma = np.full(loops.n_loops, np.nan)
    loops.cycles = np.ones(loops.n_loops, dtype=int)
    return loops


def test_tidy_file_round_trip_is_exact(tmp_path):
    records = [sine_record("a", 11.0, 1e-3, 1), sine_record("b", 13.5, 2e-3, 2)]
    write_dataset(tmp_path / "raw", records, name="two", meq_kg=0.02)
    loops = load_dataset(tmp_path / "raw")
    write_loops(loops, tmp_path / "loops.csv")
    back = read_loops(tmp_path / "loops.csv")
    assert_same_loops(loops, back)
    assert back.name == "two"
    assert back.meta == json.loads(json.dumps(loops.meta))
    for name in ("top", "bottom", "sigma", "freq_hz", "x0"):
        assert np.array_equal(getattr(loops, name), getattr(back, name), equal_nan=True)


def test_raw_csv_dataset_round_trip(tmp_path):
    records = [sine_record(f"run{k}", f, a, seed=k) for k, (f, a) in enumerate([(9.0, 1e-3), (10.5, 1.5e-3), (12.25, 5e-4)])]
    write_dataset(tmp_path / "raw", records, name="beams", meq_kg=0.05, bounds={"xi0": (0.0, 0.2)}, true_params={"xi0": 0.01})
    loops = load_dataset(tmp_path / "raw")
    direct = [extract_loop(r.t, r.x, r.force, source=r.label, nominal_freq_hz=r.freq_hz) for r in records]
    assert loops.name == "beams" and loops.meq_kg == 0.05
    assert loops.meta["bounds"] == {"xi0": (0.0, 0.2)} and loops.meta["true_params"] == {"xi0": 0.01}
    assert loops.labels == ["run0", "run1", "run2"]
    np.testing.assert_allclose(loops.freq_hz, [d.freq_hz for d in direct], rtol=1e-9)
    np.testing.assert_allclose(loops.x0, [r.x0 for r in records], rtol=1e-4)
    np.testing.assert_allclose(loops.top, np.array([d.top for d in direct]), rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(loops.sigma, [d.sigma for d in direct], rtol=1e-6)
    assert list(loops.cycles) == [d.cycles for d in direct] == [7, 7, 7]  # 8 periods, the last one a sample short
    write_dataset(tmp_path / "tidy", loops)
    assert_same_loops(loops, load_dataset(tmp_path / "tidy"))


def test_dataset_toml_mass_bounds_and_steady_window(tmp_path):
    rec = sine_record("run", 10.0, 1e-3, seed=3, cycles=10)
    write_dataset(tmp_path / "d", [rec], name="x")
    (tmp_path / "d" / "dataset.toml").write_text(
        'name = "windowed"\nmeq_kg = 0\n[bounds]\nxi0 = [0, 0.5]\n[[tests]]\nfile = "run.csv"\nsteady_t0_s = 0.2\nsteady_t1_s = 0.6\n'
    )
    loops = load_dataset(tmp_path / "d")
    assert loops.name == "windowed" and loops.meq_kg is None
    assert loops.meta["bounds"] == {"xi0": (0.0, 0.5)}
    assert loops.cycles[0] == 4
    assert loops.meta["per_loop"]["steady_t0_s"][0] == pytest.approx(0.2)


def write_mat_dir(directory: Path, loops: LoopSet, names: list[str], swap: bool = False) -> None:
    directory.mkdir()
    for name, top, bottom in zip(names, loops.top, loops.bottom):
        scipy.io.savemat(directory / f"{name}.mat", {"HexpT": bottom if swap else top, "HexpB": top if swap else bottom})


def test_thesis_mat_files_round_trip_with_ef_vector(tmp_path):
    loops = centred_synth()
    names = [f"SAMPLE2_{a * 1e4:02.0f}mm_{f:g}Hz" for f, a in zip(loops.freq_hz, loops.x0)]
    write_mat_dir(tmp_path / "mat", loops, names, swap=True)  # PrepareExpData saved HexpB first: orientation is checked
    scipy.io.savemat(tmp_path / "mat" / "efSample2.mat", {"ef": loops.freq_hz + 0.1})  # measured, not nominal
    back = load_dataset(tmp_path / "mat", n_points=60)
    expected = loops.subset(np.arange(loops.n_loops))
    expected.freq_hz = loops.freq_hz + 0.1
    expected.labels = names
    expected.meq_kg = None
    assert_same_loops(expected, back, atol=1e-12)
    np.testing.assert_allclose(back.meta["per_loop"]["nominal_x0_m"], loops.x0)


def test_thesis_mat_files_with_manifest_or_names_only(tmp_path):
    loops = centred_synth()
    names = [f"loop{k}" for k in range(loops.n_loops)]
    write_mat_dir(tmp_path / "m", loops, names)
    rows = "\n".join(f"{n}.mat,{float(f)!r}" for n, f in zip(names[::-1], loops.freq_hz[::-1]))
    (tmp_path / "m" / "manifest.csv").write_text(f"file,frequency_hz\n{rows}\n")
    (tmp_path / "m" / "dataset.toml").write_text("meq_kg = 0.04\n")
    back = load_dataset(tmp_path / "m", n_points=60)
    reverse = loops.subset(np.arange(loops.n_loops)[::-1])
    reverse.labels = names[::-1]
    assert_same_loops(reverse, back, atol=1e-12)
    named = [f"S_{a * 1e4:02.0f}mm_{f:g}Hz" for f, a in zip(loops.freq_hz, loops.x0)]
    write_mat_dir(tmp_path / "n", loops, named)
    single = load_dataset(tmp_path / "n" / f"{named[1]}.mat", n_points=60)
    assert single.freq_hz[0] == loops.freq_hz[1] and single.labels == [named[1]]
    np.testing.assert_allclose(single.top[0], loops.top[1], atol=1e-12)


def lvm_text(t, x_mm, force, *, x_columns: str = "One", decimal: str = ".", names=("Displacement", "Force"), units=("mm", "Newtons")) -> str:
    """A standard LVM file (one segment) as LabVIEW's Write To Measurement File lays it out."""

    def num(v: float) -> str:
        return repr(float(v)).replace(".", decimal)

    def per_channel(a: str, b: str) -> str:  # with X_Columns Multi every channel takes two cells
        return f"{a}\t\t{b}\t" if x_columns == "Multi" else f"{a}\t{b}\t"

    head = [
        "LabVIEW Measurement\t",
        "Writer_Version\t2",
        "Reader_Version\t2",
        "Separator\tTab",
        f"Decimal_Separator\t{decimal}",
        "Multi_Headings\tNo",
        f"X_Columns\t{x_columns}",
        "Time_Pref\tRelative",
        "Operator\ttest",
        "Date\t2006/05/01",
        "Time\t12:00:00",
        "***End_of_Header***\t",
        "\t",
    ]
    n = len(t)
    dx = num(t[1] - t[0])
    seg = [
        "Channels\t2\t\t",
        f"Samples\t{per_channel(n, n)}",
        f"Y_Unit_Label\t{per_channel(*units)}",
        f"X_Dimension\t{per_channel('Time', 'Time')}",
        f"X0\t{per_channel(num(t[0]), num(t[0]))}",
        f"Delta_X\t{per_channel(dx, dx)}",
        "***End_of_Header***\t\t\t",
    ]
    if x_columns == "Multi":
        seg.append(f"X_Value\t{names[0]}\tX_Value\t{names[1]}\tComment")
        rows = [f"{num(a)}\t{num(b)}\t{num(a)}\t{num(c)}" for a, b, c in zip(t, x_mm, force)]
    else:
        seg.append(f"X_Value\t{names[0]}\t{names[1]}\tComment")
        rows = [f"{num(a) if x_columns == 'One' else ''}\t{num(b)}\t{num(c)}" for a, b, c in zip(t, x_mm, force)]
    return "\n".join(head + seg + rows) + "\n"


def test_standard_lvm_round_trip(tmp_path):
    rec = sine_record("r", 20.0, 1e-3, seed=4)
    config = read_config(tmp_path)
    for k, (x_columns, decimal) in enumerate([("One", "."), ("No", ","), ("Multi", ".")]):
        path = tmp_path / f"r{k}.lvm"
        path.write_text(lvm_text(rec.t, rec.x * 1e3, rec.force, x_columns=x_columns, decimal=decimal))
        series = read_lvm(path, config)
        np.testing.assert_allclose(series.t, rec.t, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(series.x, rec.x, rtol=1e-12, atol=1e-18)
        np.testing.assert_allclose(series.force, rec.force, rtol=1e-12)
    (tmp_path / "manifest.csv").write_text("file,frequency_hz\nr0.lvm,20\nr1.lvm,20\nr2.lvm,20\n")
    loops = load_dataset(tmp_path)
    direct = extract_loop(rec.t, rec.x, rec.force, source="r", nominal_freq_hz=20.0)
    np.testing.assert_allclose(loops.top, np.array([direct.top] * 3), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(loops.sigma, direct.sigma, rtol=1e-6)


def test_lvm_channels_by_configured_number_and_unit(tmp_path):
    rec = sine_record("r", 20.0, 1e-3, seed=5)
    (tmp_path / "a.lvm").write_text(lvm_text(rec.t, rec.x * 1e3 / 25.4, rec.force / 1e3, names=("ch0", "ch1"), units=("", "")))
    (tmp_path / "dataset.toml").write_text('displacement_channel = 1\nforce_channel = "ch1"\ndisplacement_unit = "in"\nforce_unit = "kN"\n')
    series = read_lvm(tmp_path / "a.lvm", read_config(tmp_path))
    np.testing.assert_allclose(series.x, rec.x, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(series.force, rec.force, rtol=1e-12)


def test_headerless_lvm_of_the_thesis_rig(tmp_path):
    """TRAC<i>.lvm: two columns, displacement in mm and force in N, no time; sample rate from dataset.toml."""
    freqs = {1: 401.0, 2: 402.5, 10: 470.0}
    fs = 20000.0
    for i, f in freqs.items():
        rec = sine_record(f"TRAC{i}", f, 5e-4, seed=i, fs=fs, cycles=40)
        np.savetxt(tmp_path / f"TRAC{i}.lvm", np.column_stack([rec.x * 1e3, rec.force]), delimiter="\t", fmt="%.9g")
    (tmp_path / "dataset.toml").write_text(f"sample_rate_hz = {fs}\nmeq_kg = 0.03\n")
    series = read_lvm(tmp_path / "TRAC10.lvm", read_config(tmp_path))
    np.testing.assert_allclose(series.t, rec.t, rtol=1e-12)
    np.testing.assert_allclose(series.x, rec.x, rtol=1e-8)
    np.testing.assert_allclose(series.force, rec.force, rtol=1e-8)
    loops = load_dataset(tmp_path)
    assert loops.labels == ["TRAC1", "TRAC2", "TRAC10"]  # natural order
    np.testing.assert_allclose(loops.freq_hz, list(freqs.values()), rtol=1e-5)
    np.testing.assert_allclose(loops.x0, 5e-4, rtol=1e-5)
    assert loops.meq_kg == 0.03


def test_load_synth_and_added_noise(tmp_path):
    assert_same_loops(load_dataset("synth", noise_pct=10, noise_seed=3), synth_loops(10, 3))
    noisy = synth_loops(5.0, seed=0)
    write_dataset(tmp_path / "s", noisy)
    again = load_dataset(tmp_path / "s", noise_pct=10, noise_seed=7)
    np.testing.assert_allclose(again.sigma, np.hypot(noisy.sigma, noisy.peak_force * 0.1))
    assert not np.allclose(again.top, noisy.top)
    assert_same_loops(again, load_dataset(tmp_path / "s", noise_pct=10, noise_seed=7))
    assert again.meta["added_noise_pct"] == 10


def test_subset_keeps_per_loop_meta_aligned(tmp_path):
    records = [sine_record(f"run{k}", 9.0 + k, 1e-3 * (k + 1), seed=k) for k in range(3)]
    write_dataset(tmp_path / "raw", records)
    loops = load_dataset(tmp_path / "raw")
    sub = loops.subset([2, 0])
    assert sub.meta["per_loop"]["file"] == ["run2.csv", "run0.csv"]
    assert sub.meta["per_loop"]["phase_deg"] == [loops.meta["per_loop"]["phase_deg"][i] for i in (2, 0)]


def test_cli_loops_on_the_real_friction_damper(capsys):
    dataset = REAL
    assert main(["loops", str(dataset), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert len(rows) == 10
    for row in rows:
        assert row["cycles"] == 3  # the constant-amplitude window of every record is 3 periods
        assert 45.0 < row["phase_deg"] < 75.0  # dataset.toml: force leads displacement by +48..+71 deg
        assert row["sigma_n"] > 0 and 1e4 < row["peak_force_n"] < 2.5e4
    assert main(["loops", str(dataset)]) == 0
    table = capsys.readouterr().out.splitlines()
    clipped = [line for line in table if line.startswith("clipped: ")]  # the 1 Hz / 1.5 in record (test_plausibility.py)
    assert table[1].split()[:3] == ["label", "freq_Hz", "X0_mm"] and len(table) == len(rows) + 2 + len(clipped)


def test_cli_synth_then_loops(tmp_path, capsys):
    out = tmp_path / "synth10"
    assert main(["synth", str(out), "--noise", "10", "--seed", "2"]) == 0
    capsys.readouterr()
    assert main(["loops", str(out), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    expected = synth_loops(10, 2)
    assert [r["label"] for r in rows] == expected.labels
    np.testing.assert_array_equal([r["sigma_n"] for r in rows], expected.sigma)
    assert main(["loops", "synth", "--noise", "10", "--noise-seed", "2", "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == rows


@pytest.mark.slow  # over 3 s (fast lane, 2 cores, 2026-11-29)
def test_cli_synth_raw_is_extracted_back(tmp_path, capsys):
    out = tmp_path / "raw"
    assert main(["synth", str(out), "--raw", "--noise", "2"]) == 0
    assert len(list(out.glob("SYNTH_*.csv"))) == 120
    loops = load_dataset(out)
    assert loops.meq_kg == MEQ_KG and loops.meta["true_params"]["w0"] == pytest.approx(189.1239)
    np.testing.assert_allclose(loops.freq_hz, np.tile(FREQUENCIES_HZ, 3), rtol=1e-5)
    np.testing.assert_allclose(loops.x0, np.repeat(AMPLITUDES_M, 40), rtol=1e-3)
    assert np.all(loops.cycles >= 9) and loops.has_sigma
