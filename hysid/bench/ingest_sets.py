"""The record sets of ``hysid bench ingest`` (:mod:`hysid.bench.ingest`), written as dataset directories.

* **generated** (hysid CSV records ``time_s,displacement_m,force_n``, 12 digits): shaker displacement with 3 %
  distortion and noise, ramped up over the first second; the force of a stiff, damped specimen with friction, a
  decaying start-up transient and noise (by default 16 records of 30 s at 10240 Hz, 225 MB: the 200 MB set);
* **daq**: shaped like a DAQ's export, 16 records of 100k samples at 10 kHz (``Time [s];Weg [mm];Kraft [kN]``,
  semicolons, a few decimals, as a lab's rubber-mount records came): round excitation frequencies 1-50 Hz (rates
  locked to them), displacement harmonics of 5-10 % (third) and up to 3 % (second), the amplitude drifting by 2-4 %
  along a heating curve after a 0.5 s ramp, a hardening, damped specimen with friction, force and displacement
  noise; **large** is 4 such records of 720 s each (7.2 M rows, 200 MB a file: the 800 MB set, and records as
  big as the one that took 1.45 GB);
* **small**: 50 such records of 0.5 MB each (18432 samples at 2048 Hz, a rate that is a ratio of small integers
  times the frequencies), where a fixed cost per record shows;
* **lab**: a wire-rope isolator's tests as a German lab exports them, 16 records of 12 s at 10 kHz (3 MB each,
  46 MB): a free-text preamble in Windows-1252 (rig, specimen, date, rate), ``Zeit [s];Weg [mm];Kraft [kN]`` with
  decimal commas, file names such as ``WR_f0,5Hz_2mm.csv`` and a ``;`` manifest with decimal commas; the force of a
  softening Bouc-Wen isolator (:data:`WIRE_ROPE`) driven by a shaker with 2 % third harmonic, ramped up over 1 s,
  with force and displacement noise;
* **damper**: the real friction damper's records of the repository (``data/arts-friction-damper``, 10 records at
  1024 Hz), copied as they are.
"""

from __future__ import annotations

import io
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.model import build_model
from hysid_model.readers.csv_series import write_series
from hysid_model.synth import simulate_raw

DAQ_FREQUENCIES_HZ = (1.0, 2.0, 5.0, 10.0, 20.0, 30.0, 40.0, 50.0)
"""The round excitation frequencies of a lab's test matrix."""
DAQ_HEADER = "Time [s];Weg [mm];Kraft [kN]"
DAQ_FORMAT = ("%.6f", "%.5f", "%.5f")
"""A DAQ's export: time in us, displacement to 10 nm, force to 10 mN."""
LAB_FREQUENCIES_HZ = (0.5, 1.0, 2.0, 4.0)
LAB_AMPLITUDES_MM = (0.5, 1.0, 2.0, 4.0)
LAB_HEADER = "Zeit [s];Weg [mm];Kraft [kN]"
LAB_FORMAT = ("%.4f", "%.5f", "%.6f")
WIRE_ROPE = {"xi0": 0.04, "w0": 2 * np.pi * 18.0, "meq": 0.3, "bw_k": 4.0e4, "bw_zy": 0.4e-3, "bw_r": -0.5}
"""A wire-rope isolator (as the search bench's): a 3.8 kN/m spring, light viscous damping and a softening hysteretic
spring of 40 kN/m yielding at 0.4 mm."""
DAMPER = Path(__file__).resolve().parents[2] / "data" / "arts-friction-damper"


@dataclass(frozen=True)
class IngestSet:
    """A set of raw records: ``style`` "hysid" (``time_s,displacement_m,force_n``, 12 digits), "daq" (``DAQ_HEADER``,
    ``DAQ_FORMAT``), "lab" (preamble, decimal commas) or "copy" (the real damper's files)."""

    name: str
    records: int
    samples: int
    sample_rate_hz: float
    style: str

    @property
    def delimiter(self) -> str:
        return "," if self.style in ("hysid", "copy") else ";"


DAQ = IngestSet("daq", 16, 100_000, 10_000.0, "daq")
LARGE = IngestSet("large", 4, 7_200_000, 10_000.0, "daq")
SMALL = IngestSet("small", 50, 18_432, 2048.0, "daq")
LAB = IngestSet("lab", 16, 120_000, 10_000.0, "lab")
DAMPER_SET = IngestSet("damper", 10, 28_673, 1024.0, "copy")


def raw_record(k: int, n_records: int, seconds: float, rate: float) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """(frequency, t, x, F) of record k of the generated set: 5-40 Hz, X0 0.5-2 mm (module docstring)."""
    rng = np.random.default_rng(k)
    freq = float(np.geomspace(5.0, 40.0, n_records)[k]) if n_records > 1 else 10.0
    x0 = (0.5e-3, 1e-3, 2e-3)[k % 3]
    t = np.arange(int(seconds * rate)) / rate
    theta = 2 * np.pi * freq * t + rng.uniform(0, 2 * np.pi)
    ramp = 0.5 - 0.5 * np.cos(np.pi * np.clip(t, 0.0, 1.0))
    shape = np.sin(theta) + 0.03 * np.sin(3 * theta + 0.4) + 0.01 * np.sin(2 * theta)
    velocity = np.cos(theta) + 0.09 * np.cos(3 * theta + 0.4) + 0.02 * np.cos(2 * theta)
    stiffness = 2e5
    force = ramp * stiffness * x0 * (shape + 0.2 * velocity + 0.15 * np.tanh(velocity / 0.05))
    force += 0.3 * stiffness * x0 * np.exp(-t / 0.5) * np.sin(2 * np.pi * 1.6 * freq * t)
    force += 0.01 * stiffness * x0 * rng.standard_normal(t.size)
    x = x0 * ramp * shape + 2e-3 * x0 * rng.standard_normal(t.size)
    return freq, t, x, force


def daq_record(k: int, samples: int, rate: float) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """(nominal frequency, t, x, F) of record k of a DAQ-shaped set (module docstring), in s, m, N."""
    rng = np.random.default_rng(1000 + k)
    freq = DAQ_FREQUENCIES_HZ[k % len(DAQ_FREQUENCIES_HZ)]
    x0 = (0.5e-3, 1e-3, 2e-3)[k % 3]
    t = np.arange(samples) / rate
    theta = 2 * np.pi * freq * t + rng.uniform(0, 2 * np.pi)
    ramp = 0.5 - 0.5 * np.cos(np.pi * np.clip(t / 0.5, 0.0, 1.0))
    heating = 1.0 + rng.uniform(0.02, 0.04) * (1.0 - np.exp(-t / (0.4 * t[-1])))
    h3, h2 = rng.uniform(0.05, 0.10), rng.uniform(0.0, 0.03)
    shape = np.sin(theta) + h3 * np.sin(3 * theta + 0.4) + h2 * np.sin(2 * theta + 1.0)
    velocity = np.cos(theta) + 3 * h3 * np.cos(3 * theta + 0.4) + 2 * h2 * np.cos(2 * theta + 1.0)
    amplitude = x0 * ramp * heating
    x = amplitude * shape
    stiffness = 2e5
    force = stiffness * x * (1.0 + 0.3 * (x / x0) ** 2) + 0.2 * stiffness * amplitude * velocity
    force += 0.05 * stiffness * x0 * ramp * np.tanh(velocity / 0.05) + 0.01 * stiffness * x0 * rng.standard_normal(samples)
    x += 2e-3 * x0 * rng.standard_normal(samples)
    return freq, t, x, force


def lab_record(k: int, samples: int, rate: float) -> tuple[float, float, np.ndarray, np.ndarray, np.ndarray]:
    """(frequency, amplitude in m, t, x, F) of record k of the lab set: the wire rope at its frequency and amplitude
    (module docstring), in s, m, N."""
    freq = LAB_FREQUENCIES_HZ[k // len(LAB_AMPLITUDES_MM) % len(LAB_FREQUENCIES_HZ)]
    x0 = LAB_AMPLITUDES_MM[k % len(LAB_AMPLITUDES_MM)] * 1e-3
    model = build_model("baseline+bouc_wen")
    cycles = samples * freq / rate
    peak = WIRE_ROPE["bw_k"] * WIRE_ROPE["bw_zy"] + WIRE_ROPE["meq"] * WIRE_ROPE["w0"] ** 2 * x0
    rec = simulate_raw(
        model,
        model.from_dict(WIRE_ROPE),
        np.array([freq]),
        np.array([x0]),
        noise_n=0.01 * peak,
        seed=2000 + k,
        sample_rate_hz=rate,
        cycles=int(np.ceil(cycles)),
        x_noise=1e-3,
        distortion={3: 0.02},
    )[0]
    t, x, force = rec.t[:samples], rec.x[:samples], rec.force[:samples]
    ramp = 0.5 - 0.5 * np.cos(np.pi * np.clip(t / 1.0, 0.0, 1.0))
    return freq, x0, t, x * ramp, force * ramp


def lab_name(freq: float, x0: float) -> str:
    """A lab's file name, its numbers with decimal commas (``WR_f0,5Hz_0,5mm.csv``)."""
    return f"WR_f{freq:g}Hz_{x0 * 1e3:g}mm".replace(".", ",") + ".csv"


def lab_preamble(k: int, freq: float, x0: float) -> list[str]:
    """The free text a lab's DAQ writes before the header (not ``#`` comments)."""
    return [
        "Prüfstand: Hydropuls HP 25 (servohydraulisch)",
        f"Probe: Drahtseilisolator WR-{k % 4 + 1}, Charge 2026/11",
        f"Datum: {20 + k % 8}.11.2026   Uhrzeit: 10:{k:02d}:00",
        "Abtastrate: 10 kHz",
        f"Sollwerte: Frequenz {freq:g} Hz; Amplitude {x0 * 1e3:g} mm".replace(".", ","),
        "Bemerkung: Raumtemperatur 21 °C",
        "",
    ]


def write_records(directory: Path, n_records: int, seconds: float, rate: float) -> None:
    """The generated set as a dataset directory (one CSV each, manifest.csv), written one record at a time."""
    rows = ["file,frequency_hz"]
    for k in range(n_records):
        freq, t, x, force = raw_record(k, n_records, seconds, rate)
        write_series(directory / f"rec{k:02d}.csv", t, x, force)
        rows.append(f"rec{k:02d}.csv,{freq!r}")
    (directory / "manifest.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")


def write_daq_records(directory: Path, spec: IngestSet) -> None:
    """A DAQ-shaped set as a dataset directory: one semicolon CSV per record in mm and kN, manifest.csv."""
    rows = ["file,frequency_hz"]
    for k in range(spec.records):
        freq, t, x, force = daq_record(k, spec.samples, spec.sample_rate_hz)
        np.savetxt(directory / f"rec{k:02d}.csv", np.column_stack([t, x * 1e3, force * 1e-3]), delimiter=";", fmt=DAQ_FORMAT, header=DAQ_HEADER, comments="")
        rows.append(f"rec{k:02d}.csv,{freq:g}")
    (directory / "manifest.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")


def write_lab_records(directory: Path, spec: IngestSet) -> None:
    """The lab set as a dataset directory: Windows-1252 files with a preamble and decimal commas, a ``;`` manifest
    whose frequencies have decimal commas too."""
    rows = ["file;frequency_hz"]
    for k in range(spec.records):
        freq, x0, t, x, force = lab_record(k, spec.samples, spec.sample_rate_hz)
        body = io.StringIO()
        np.savetxt(body, np.column_stack([t, x * 1e3, force * 1e-3]), delimiter=";", fmt=LAB_FORMAT)
        name = lab_name(freq, x0)
        text = "\r\n".join(lab_preamble(k, freq, x0) + [LAB_HEADER]) + "\r\n" + body.getvalue().replace(".", ",").replace("\n", "\r\n")
        (directory / name).write_text(text, encoding="cp1252", newline="")
        rows.append(f"{name};" + f"{freq:g}".replace(".", ","))
    (directory / "manifest.csv").write_text("\r\n".join(rows) + "\r\n", encoding="cp1252", newline="")


def copy_damper(directory: Path) -> None:
    """The real friction damper's records, manifest and dataset.toml, copied as they are."""
    if not (DAMPER / "manifest.csv").is_file():
        raise HysidInputError(f"the damper set needs the repository's records in {DAMPER}")
    for path in DAMPER.iterdir():
        if path.suffix in (".csv", ".toml"):
            shutil.copy(path, directory / path.name)


def write_set(directory: Path, spec: IngestSet, seconds: float = 30.0) -> None:
    """Write ``spec``'s records into ``directory`` (``seconds``: each generated record's length)."""
    if spec.style == "hysid":
        write_records(directory, spec.records, seconds, spec.sample_rate_hz)
    elif spec.style == "daq":
        write_daq_records(directory, spec)
    elif spec.style == "lab":
        write_lab_records(directory, spec)
    else:
        copy_damper(directory)


def parse_plan(spec: IngestSet) -> dict[str, object]:
    """How numpy alone parses the set's files: delimiter, lines before the numbers, decimal commas, encoding."""
    if spec.style == "lab":
        return {"delimiter": ";", "skiprows": len(lab_preamble(0, 1.0, 1e-3)) + 1, "decimal_comma": True, "encoding": "cp1252"}
    return {"delimiter": spec.delimiter, "skiprows": 1, "decimal_comma": False, "encoding": "utf-8"}
