"""``hysid bench ingest [generated|daq|small|all]``: raw records to loops, against the time numpy alone takes to parse
the same files.

Three sets of raw records with a manifest, each measured in a fresh Python process (so that its peak memory is
ingestion's alone):

* **generated** (by default 16 records of 30 s at 10240 Hz, hysid CSV records ``time_s,displacement_m,force_n``
  with 12 digits): shaker displacement with 3 % distortion and noise, ramped up over the first second; the force
  of a stiff, damped specimen with friction, a decaying start-up transient and noise;
* **daq**: shaped like a DAQ's export, 16 records of 100k samples at 10 kHz (``Time [s];Weg [mm];Kraft [kN]``,
  semicolons, a few decimals, as a lab's rubber-mount records came): round excitation frequencies 1-50 Hz (rates
  locked to them), displacement harmonics of 5-10 % (third) and up to 3 % (second), the amplitude drifting by 2-4 %
  along a heating curve after a 0.5 s ramp, a hardening, damped specimen with friction, force and displacement
  noise;
* **small**: 50 such records of 0.5 MB each (18432 samples at 2048 Hz, a rate that is a ratio of small integers
  times the frequencies), where a fixed cost per record shows.

In alternating rounds (parse first, then load; then load first, then parse), each set:

* ``parse_s``: ``np.loadtxt`` of every file with its delimiter, numpy alone;
* ``load_s``: :func:`hysid_model.datasets.load_dataset` of the directory (what ``hysid.load`` and ``hysid loops``
  do: read every record through hysid's readers, extract its loop, check the set);
* ``extract_s``: :func:`hysid_model.extraction.extract_loop` on every record already read.

``ratio`` = (load_s - parse_s) / parse_s, everything ``hysid.load`` does beyond numpy's parse of the same files
(the readers' checks and unit conversion, the extraction, the set's checks), the median over the rounds of each
round's ratio (target <= 2); ``extract_ratio`` = extract_s / parse_s (the median likewise); ``mb_per_s`` = CSV
megabytes per second of ``load_s``; ``peak_rss_mb`` the process's peak resident memory, ``baseline_rss_mb`` its
size before reading (the interpreter and its imports) and ``rss_growth_mb`` the difference, what reading took
(target <= 3 x ``data_mb``, the CSV size). The machine's load average is kept
with each set (the rounds alternate so that a change of load hits both measurements alike).
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hysid_model.datasets import load_dataset
from hysid_model.errors import HysidInputError
from hysid_model.extraction import extract_loop
from hysid_model.readers.csv_series import write_series
from hysid_model.readers.dataset_dir import read_config
from hysid_model.readers.records import read_record

RECORDS = 16
SECONDS = 30.0
SAMPLE_RATE_HZ = 10240.0
ROUNDS = 3
TARGET_RATIO = 2.0
TARGET_RSS = 3.0
DAQ_FREQUENCIES_HZ = (1.0, 2.0, 5.0, 10.0, 20.0, 30.0, 40.0, 50.0)
"""The round excitation frequencies of a lab's test matrix."""
DAQ_HEADER = "Time [s];Weg [mm];Kraft [kN]"
DAQ_FORMAT = ("%.6f", "%.5f", "%.5f")
"""A DAQ's export: time in us, displacement to 10 nm, force to 10 mN."""


@dataclass(frozen=True)
class IngestSet:
    """A set of raw records: ``style`` "hysid" (``time_s,displacement_m,force_n``, 12 digits) or "daq"
    (``DAQ_HEADER``, ``DAQ_FORMAT``)."""

    name: str
    records: int
    samples: int
    sample_rate_hz: float
    style: str

    @property
    def delimiter(self) -> str:
        return ";" if self.style == "daq" else ","


DAQ = IngestSet("daq", 16, 100_000, 10_000.0, "daq")
SMALL = IngestSet("small", 50, 18_432, 2048.0, "daq")
PARTS = ("generated", "daq", "small")


def raw_record(k: int, n_records: int, seconds: float, rate: float) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """(frequency, t, x, F) of record k of the generated set: 5-40 Hz, X0 0.5-2 mm, as described in the module
    docstring."""
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
        np.savetxt(directory / f"rec{k:02d}.csv", np.column_stack([t, x * 1e3, force * 1e-3]), delimiter=";",
                   fmt=DAQ_FORMAT, header=DAQ_HEADER, comments="")
        rows.append(f"rec{k:02d}.csv,{freq:g}")
    (directory / "manifest.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def measure(directory: str, delimiter: str, rounds: int) -> dict[str, Any]:
    """The timings and memory of one directory (runs in a fresh process, see :func:`run`)."""
    baseline = _rss_mb()
    root = Path(directory)
    rows = [line.split(",") for line in (root / "manifest.csv").read_text().splitlines()[1:]]
    files = [(root / name, float(freq)) for name, freq in rows]
    config = read_config(root)
    warnings.simplefilter("ignore")  # the records are distorted on purpose: the warnings are not the bench

    def parse() -> float:
        start = time.perf_counter()
        for path, _ in files:
            np.loadtxt(path, delimiter=delimiter, skiprows=1)
        return time.perf_counter() - start

    def load() -> tuple[float, int]:
        start = time.perf_counter()
        loops = load_dataset(root)
        return time.perf_counter() - start, int(np.sum(loops.cycles))

    times: dict[str, list[float]] = {"parse_s": [], "load_s": [], "extract_s": []}
    for r in range(rounds):
        if r % 2 == 0:
            times["parse_s"].append(parse())
            load_s, cycles = load()
        else:
            load_s, cycles = load()
            times["parse_s"].append(parse())
        times["load_s"].append(load_s)
        extract = 0.0
        for path, freq in files:
            series = read_record(path, config)
            start = time.perf_counter()
            extract_loop(series.t, series.x, series.force, source=str(path), nominal_freq_hz=freq)
            extract += time.perf_counter() - start
        times["extract_s"].append(extract)
    return {**times, "cycles": cycles, "baseline_rss_mb": baseline, "peak_rss_mb": _rss_mb()}


def _measured(spec: IngestSet, directory: Path, rounds: int, write: Any) -> dict[str, Any]:
    """Write a set into ``directory``, measure it in a fresh process, and summarize (medians of the rounds' ratios)."""
    write()
    data_mb = sum(p.stat().st_size for p in directory.glob("rec*.csv")) / 1e6
    code = "import json, sys; from hysid.bench.ingest import measure; json.dump(measure(sys.argv[1], sys.argv[2], int(sys.argv[3])), sys.stdout)"
    load_before = os.getloadavg()[0]
    done = subprocess.run([sys.executable, "-c", code, str(directory), spec.delimiter, str(rounds)], capture_output=True, text=True,
                          timeout=3600)
    if done.returncode != 0:
        tail = done.stderr.strip().splitlines()[-1:] or ["(no output)"]
        raise RuntimeError(f"ingest measurement of {spec.name} failed (exit {done.returncode}): {tail[0]}")
    m = json.loads(done.stdout)
    parse, load, extract = (np.array(m[key]) for key in ("parse_s", "load_s", "extract_s"))
    ratio = float(np.median((load - parse) / parse))
    return {
        **asdict(spec),
        "seconds": spec.samples / spec.sample_rate_hz,
        "data_mb": round(data_mb, 2),
        "cycles": m["cycles"],
        "rounds": {key: m[key] for key in ("parse_s", "load_s", "extract_s")},
        "parse_s": float(np.median(parse)),
        "load_s": float(np.median(load)),
        "extract_s": float(np.median(extract)),
        "ratio": ratio,
        "extract_ratio": float(np.median(extract / parse)),
        "load_ratio": float(np.median(load / parse)),
        "mb_per_s": data_mb / float(np.median(load)),
        "baseline_rss_mb": m["baseline_rss_mb"],
        "peak_rss_mb": m["peak_rss_mb"],
        "rss_growth_mb": m["peak_rss_mb"] - m["baseline_rss_mb"],
        "rss_ratio": (m["peak_rss_mb"] - m["baseline_rss_mb"]) / data_mb,
        "load_avg_1m": [round(load_before, 2), round(os.getloadavg()[0], 2)],
        "meets_targets": ratio <= TARGET_RATIO and m["peak_rss_mb"] - m["baseline_rss_mb"] <= TARGET_RSS * data_mb,
    }


def run(parts: list[str] | tuple[str, ...] = PARTS, records: int = RECORDS, seconds: float = SECONDS,
        sample_rate_hz: float = SAMPLE_RATE_HZ, rounds: int = ROUNDS) -> dict[str, Any]:
    """Ingestion speed: hysid.load against numpy's parse of the same raw records, and peak memory."""
    unknown = [p for p in parts if p not in PARTS]
    if unknown or not parts:
        raise HysidInputError(f"choose one of {', '.join(PARTS)} or all", param="part", value=unknown[0] if unknown else "")
    if isinstance(records, bool) or not isinstance(records, int) or records < 1:
        raise HysidInputError("must be an integer >= 1", param="records", value=records)
    if not seconds >= 1.0:
        raise HysidInputError("must be at least 1 s", param="seconds", value=seconds)
    if not sample_rate_hz >= 500.0:
        raise HysidInputError("must be at least 500 Hz", param="sample_rate_hz", value=sample_rate_hz)
    if isinstance(rounds, bool) or not isinstance(rounds, int) or rounds < 1:
        raise HysidInputError("must be an integer >= 1", param="rounds", value=rounds)
    sets: dict[str, Any] = {}
    for part in parts:
        with tempfile.TemporaryDirectory(prefix=f"hysid-bench-ingest-{part}-") as tmp:
            directory = Path(tmp)
            if part == "generated":
                spec = IngestSet("generated", records, int(seconds * sample_rate_hz), sample_rate_hz, "hysid")
                sets[part] = _measured(spec, directory, rounds, lambda: write_records(directory, records, seconds, sample_rate_hz))
            else:
                spec = DAQ if part == "daq" else SMALL
                sets[part] = _measured(spec, directory, rounds, lambda: write_daq_records(directory, spec))
    return {
        "sets": sets,
        "target_ratio": TARGET_RATIO,
        "target_rss_ratio": TARGET_RSS,
        "meets_targets": all(s["meets_targets"] for s in sets.values()),
    }


def to_text(result: dict[str, Any]) -> str:
    lines = []
    for r in result["sets"].values():
        lines += [
            f"{r['name']}: {r['records']} raw records of {r['samples']} samples at {r['sample_rate_hz']:g} Hz: "
            f"{r['data_mb']:.1f} MB of CSV, {r['cycles']} cycles (load average {r['load_avg_1m'][0]:g} -> {r['load_avg_1m'][1]:g})",
            f"  numpy parse        {r['parse_s']:.2f} s",
            f"  hysid load         {r['load_s']:.2f} s   beyond the parse: ratio {r['ratio']:.2f} (target <= {result['target_ratio']:g}), "
            f"{r['mb_per_s']:.1f} MB/s",
            f"  extraction alone   {r['extract_s']:.2f} s   ratio {r['extract_ratio']:.2f}",
            f"  memory             {r['rss_growth_mb']:.0f} MB for reading ({r['rss_ratio']:.2f} x the data, target <= "
            f"{result['target_rss_ratio']:g}; peak {r['peak_rss_mb']:.0f} MB, {r['baseline_rss_mb']:.0f} MB before reading)",
        ]
    lines.append(f"targets {'met' if result['meets_targets'] else 'NOT met'} (medians of {len(next(iter(result['sets'].values()))['rounds']['parse_s'])} "
                 "alternating rounds)")
    return "\n".join(lines)
