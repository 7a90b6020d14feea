"""Suspicious but usable records warn (HysidWarning) and the work goes on (hysid_model/plausibility.py):
displacement distortion, clipping, unit slips, swapped columns; `hysid loops` reports THD and clipping."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from hysid.cli import main
from hysid_model.datasets import load_dataset, write_dataset
from hysid_model.errors import HysidWarning
from hysid_model.synth import RawRecord
from support import DAMPER as REAL

FS = 4096.7


def shaker(label: str, freq: float, x0: float, *, seed: int = 0, waveform=np.sin, stiffness: float = 2e4, cycles: int = 10) -> RawRecord:
    """A stiff, damped specimen under the displacement x0 * waveform(theta); the force follows x and x'."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(cycles / freq * FS)) / FS
    theta = 2 * np.pi * freq * t + 0.4
    x = x0 * waveform(theta)
    force = stiffness * (x + 0.3 * np.gradient(x, theta)) + 1e-3 * stiffness * x0 * rng.standard_normal(t.size)
    return RawRecord(label, freq, x0, t, x + 1e-4 * x0 * rng.standard_normal(t.size), force, 0.0)


def loads(directory: Path) -> tuple[object, list[str]]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        loops = load_dataset(directory)
    return loops, [str(w.message) for w in caught if issubclass(w.category, HysidWarning)]


def test_displacement_distortion_above_five_percent_warns_but_is_not_clipping(tmp_path):
    """10 % third harmonic, flattening the peaks smoothly: THD is reported, no clipping is claimed."""
    records = [shaker("clean", 11.0, 1e-3), shaker("distorted", 13.0, 1e-3, waveform=lambda th: np.sin(th) + 0.1 * np.sin(3 * th))]
    loops, messages = loads(write_dataset(tmp_path / "d", records))
    assert [m for m in messages if "THD" in m] and "distorted (10 %)" in next(m for m in messages if "THD" in m)
    assert "clean" not in next(m for m in messages if "THD" in m)
    assert not [m for m in messages if "clipped" in m]
    assert [r["clipped"] for r in loops.rows()] == [None, None]


def test_a_clipped_displacement_warns_and_loops_reports_it(tmp_path, capsys):
    """A stroke limit flattens one side at +0.8 mm: the flat top is found and its level reported."""
    clipped = shaker("clipped", 12.0, 1e-3, waveform=lambda th: np.minimum(np.sin(th), 0.8))
    d = write_dataset(tmp_path / "d", [shaker("ok", 10.0, 1e-3), clipped])
    loops, messages = loads(d)
    assert any("clipped: clipped: displacement flat at +0.8 mm" in m for m in messages)
    rows = loops.rows()
    assert rows[0]["clipped"] is None and rows[1]["clipped"] == "displacement"
    assert rows[1]["clip_level"] == pytest.approx(0.8e-3, rel=0.01)
    assert main(["loops", str(d), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)[1]["clipped"] == "displacement"
    assert main(["loops", str(d)]) == 0
    out, err = capsys.readouterr()
    assert "clipped: clipped: displacement flat at +0.8 mm" in out and "hysid: warning:" in err and "x_thd_%" in out


def test_the_real_damper_1hz_1_5in_record_is_velocity_limited_and_distorted(capsys):
    """The actuator cannot reach 1.5 in at 1 Hz: its speed flattens at 0.17 m/s, X0 stops at 31.6 mm, THD 10.9 %.
    No other record of the set is clipped or that distorted."""
    loops, messages = loads(REAL)
    rows = {r["label"]: r for r in loops.rows()}
    limited = rows.pop("1Hz30lbtension1.5amplitude")
    assert limited["clipped"] == "velocity" and limited["clip_level"] == pytest.approx(0.173, abs=0.003)
    assert limited["x0_m"] == pytest.approx(0.0316, abs=2e-4) and limited["x_distortion"] == pytest.approx(0.109, abs=0.003)
    assert all(r["clipped"] is None and r["x_distortion"] < 0.02 for r in rows.values())
    assert any("clipped: 1Hz30lbtension1.5amplitude: velocity flattened at 0.173 m/s" in m for m in messages)
    assert main(["loops", str(REAL)]) == 0
    assert "clipped: 1Hz30lbtension1.5amplitude: velocity flattened at 0.173 m/s" in capsys.readouterr().out


def test_a_displacement_in_mm_under_an_m_header_warns(tmp_path):
    """Issue 10, bug 8: one record written in mm under displacement_m (X0 = 1000 'mm') among 0.5-2 mm ones."""
    records = [shaker(f"r{k}", 10.0 + k, a, seed=k) for k, a in enumerate([0.5e-3, 1e-3, 2e-3, 1.5e-3])]
    slip = records[1]
    records[1] = RawRecord(slip.label, slip.freq_hz, slip.x0, slip.t, slip.x * 1e3, slip.force, 0.0)
    _, messages = loads(write_dataset(tmp_path / "d", records))
    slips = [m for m in messages if "unit slip" in m]
    assert len(slips) == 1 and "r1 (X0 = 1000 mm)" in slips[0] and "against X0 = 0.5-2 mm" in slips[0]
    assert not any("r0 " in m or "r2 " in m for m in slips)


def test_a_force_in_kn_under_an_n_header_and_an_amplitude_sweep(tmp_path):
    records = [shaker(f"r{k}", 10.0 + k, 1e-3, seed=k) for k in range(3)]
    kn = records[2]
    records[2] = RawRecord(kn.label, kn.freq_hz, kn.x0, kn.t, kn.x, kn.force / 1e3, 0.0)
    _, messages = loads(write_dataset(tmp_path / "kn", records))
    assert any("unit slip" in m and "r2 (X0 = 1 mm)" in m for m in messages)
    sweep = [shaker(f"s{k}", 10.0, a, seed=k) for k, a in enumerate([1e-5, 3e-5, 1e-4, 3e-4, 1e-3])]
    _, messages = loads(write_dataset(tmp_path / "sweep", sweep))
    assert not [m for m in messages if "unit slip" in m]  # a sweep over two decades is not a slip


def test_swapped_displacement_and_force_columns_warn(tmp_path):
    """Issue 12: columns swapped (header unchanged) give X0 in the tens of 'metres' and a force of a millinewton:
    a warning (not an error: data in other units can be legitimate) that names the swap."""
    rec = shaker("run", 10.0, 2e-3)
    d = write_dataset(tmp_path / "d", [RawRecord("run", 10.0, 2e-3, rec.t, rec.force, rec.x, 0.0)])
    _, messages = loads(d)
    assert any(
        "displacement and force look swapped in run (X0 = " in m
        and 'set displacement_channel = "force_n", displacement_unit = "m", force_channel = "displacement_m" and force_unit = "N" in dataset.toml' in m
        for m in messages
    )
    metres = write_dataset(tmp_path / "m", [RawRecord("run", 10.0, 2e-3, rec.t, rec.x * 1e3, rec.force, 0.0)])
    _, messages = loads(metres)
    assert any(
        "the displacement moves as no rig does in run (peak velocity 126 m/s)" in m and "X0 up to 2 m" in m and "mm under its m header? x 0.001 (mm)" in m
        for m in messages
    )
    assert not any("look swapped" in m for m in messages)


def physics_messages(messages: list[str]) -> list[str]:
    return [m for m in messages if any(k in m for k in ("no rig", "too small for the motion", "look swapped", "generate energy"))]


def sweep(freqs=(5.0, 10.0, 20.0, 40.0), amps=(0.1e-3, 0.3e-3, 0.5e-3, 0.8e-3), **kwargs) -> list[RawRecord]:
    return [shaker(f"r{k}", f, a, seed=k, **kwargs) for k, (f, a) in enumerate(zip(freqs, amps))]


def test_a_plausible_sweep_gives_no_physics_warning(tmp_path):
    """5-40 Hz at 0.1-0.8 mm on a 2e4 N/m specimen: at most 0.2 m/s and 5 g, force leading the motion: nothing to say.
    Nor for the thesis' beam sample 2 at its high amplitude, 0.8 mm at 440 Hz (Table 5.18): 2.2 m/s and 620 g."""
    _, messages = loads(write_dataset(tmp_path / "d", sweep()))
    assert messages == []
    t = np.arange(40 * 50) / (440.0 * 50)
    theta = 2 * np.pi * 440.0 * t
    beam = RawRecord("SAMPLE2_08mm_440Hz", 440.0, 0.8e-3, t, 0.8e-3 * np.sin(theta), 2.0 * np.sin(theta + 0.3), 0.0)
    _, messages = loads(write_dataset(tmp_path / "beam", [beam]))
    assert messages == []


def test_millimetres_under_a_metre_header_all_below_one_are_named_from_the_physics(tmp_path):
    """Issue 21: every value below 1 (0.1-0.8 'm') and the mass unknown passed without a word (X0 < 1 m, no loop apart
    from the others). 0.8 m at 40 Hz is 201 m/s and 5200 g; x 1e-3 makes it 0.2 m/s and 5.2 g."""
    records = [RawRecord(r.label, r.freq_hz, r.x0, r.t, r.x * 1e3, r.force, 0.0) for r in sweep()]
    _, messages = loads(write_dataset(tmp_path / "d", records))
    found = physics_messages(messages)
    assert len(found) == 1 and "the displacement moves as no rig does in r0 (peak velocity 3.14 m/s), r1 (" in found[0]
    assert "r3 (peak velocity 201 m/s)" in found[0]
    assert "mm under its m header? x 0.001 (mm) makes it at most 0.201 m/s and 5.15 g" in found[0]


def test_kilonewtons_under_a_newton_header_are_named_from_the_stiffness(tmp_path):
    """The force 1000 times too small for the motion: 20 N/m of dynamic stiffness... of a 2e4 N/m specimen at 1e-3;
    the motion itself is plausible, so the force's unit is named."""
    records = [RawRecord(r.label, r.freq_hz, r.x0, r.t, r.x, r.force / 1e3, 0.0) for r in sweep(stiffness=200.0)]
    _, messages = loads(write_dataset(tmp_path / "d", records))
    found = physics_messages(messages)
    assert len(found) == 1 and "the force is too small for the motion: a dynamic stiffness |F1|/X0 of 0.2" in found[0]
    assert 'a unit slip? the force in kN under its N header (force_unit = "kN"), in dataset.toml, making it 2' in found[0]


def resonant(label: str, freq: float, x0: float, seed: int = 0) -> RawRecord:
    """A 0.5 kg, 2e4 N/m, 10 % damped specimen (resonance at 31.8 Hz) under x0 sin(theta)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(20 / freq * FS)) / FS
    w = 2 * np.pi * freq
    x = x0 * np.sin(w * t + 0.3)
    force = (2e4 - 0.5 * w * w) * x + 20.0 * w * x0 * np.cos(w * t + 0.3)
    return RawRecord(label, freq, x0, t, x + 1e-4 * x0 * rng.standard_normal(t.size), force + 0.01 * rng.standard_normal(t.size), 0.0)


def test_columns_swapped_with_plausible_magnitudes_are_named_from_the_energy_and_the_phase(tmp_path):
    """Issue 23: force (tens of N) and displacement (mm) swapped, scaled so that both columns look like a mm and tens of
    N: fitted to a wrong answer with only a generic warning. The loops generate energy, and their lag grows with
    frequency through the resonance: a passive specimen's phase mirrored, i.e. swapped columns (a reversed sign
    would rise from -180 degrees)."""
    records = [resonant(f"r{k}", float(f), 1e-3, seed=k) for k, f in enumerate(np.linspace(25.0, 38.0, 8))]
    swapped = [RawRecord(r.label, r.freq_hz, r.x0, r.t, r.force * 1e-4, r.x * 1e4, 0.0) for r in records]
    loops, messages = loads(write_dataset(tmp_path / "swapped", swapped))
    found = physics_messages(messages)
    assert len(found) == 1 and "the loops generate energy in all 8 records (a lag of" in found[0]
    assert "the lag grows with frequency, a passive specimen's mirrored: force and displacement look swapped" in found[0]
    assert [w["code"] for w in loops.meta["warnings"]] == ["swapped_columns"]
    reversed_sign = [RawRecord(r.label, r.freq_hz, r.x0, r.t, r.x, -r.force, 0.0) for r in records]
    loops, messages = loads(write_dataset(tmp_path / "reversed", reversed_sign))
    found = physics_messages(messages)
    assert len(found) == 1 and "the force's (or the displacement's) sign looks reversed" in found[0]
    assert [w["code"] for w in loops.meta["warnings"]] == ["sign_reversed"]
    _, messages = loads(write_dataset(tmp_path / "right", records))
    assert physics_messages(messages) == []


def test_columns_swapped_on_a_friction_specimen_are_named_from_the_harmonics(tmp_path):
    """A friction damper's force is square-ish and the shaker's displacement a clean sine; swapped, the 'displacement'
    carries the force's harmonics."""

    def friction(label, freq, seed):
        rng = np.random.default_rng(seed)
        t = np.arange(int(10 / freq * FS)) / FS
        theta = 2 * np.pi * freq * t
        x = 2e-3 * np.sin(theta)
        force = 300.0 * np.tanh(np.cos(theta) / 0.05) + 1e4 * x
        return RawRecord(label, freq, 2e-3, t, force * 1e-5 + 1e-7 * rng.standard_normal(t.size), x * 1e5, 0.0)

    _, messages = loads(write_dataset(tmp_path / "d", [friction(f"r{k}", f, k) for k, f in enumerate((2.0, 4.0, 8.0))]))
    found = physics_messages(messages)
    assert len(found) == 1 and "displacement and force look swapped" in found[0]
    assert "the 'displacement' carries the force's harmonics" in found[0] and 'displacement_channel = "force_n"' in found[0]
