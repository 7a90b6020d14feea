"""``hysid bench ingest``: raw records to loops, against the time numpy alone takes to parse the same files.

A generated set of realistic raw records (by default 16 records of 30 s at
10240 Hz, hysid CSV records with a manifest): shaker displacement with 3 %
distortion and noise, ramped up over the first second; the force of a stiff,
damped specimen with friction, a decaying start-up transient and noise. In one
fresh Python process (so that its peak memory is ingestion's alone), twice
each, the best kept:

* ``parse_s``: ``np.loadtxt`` of every file, numpy alone;
* ``extract_s``: :func:`hysid_model.extraction.extract_loop` on every parsed
  record (steady window, frequency, displacement harmonics, branches);
* ``load_s``: :func:`hysid_model.datasets.load_dataset` of the directory
  (read, extract, check: what ``hysid loops`` does).

``ratio`` = extract_s / parse_s (target <= 2), ``load_ratio`` = load_s /
parse_s, ``mb_per_s`` = CSV megabytes per second of ``load_s``,
``peak_rss_mb`` the process's peak resident memory (target <= 3 x
``data_mb``, the CSV size) and ``baseline_rss_mb`` its size before reading.
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from hysid_model.datasets import load_dataset
from hysid_model.errors import HysidInputError
from hysid_model.extraction import extract_loop
from hysid_model.readers.csv_series import write_series

RECORDS = 16
SECONDS = 30.0
SAMPLE_RATE_HZ = 10240.0
REPEATS = 2
TARGET_RATIO = 2.0
TARGET_RSS = 3.0


def raw_record(k: int, n_records: int, seconds: float, rate: float) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """(frequency, t, x, F) of record k: 5-40 Hz, X0 0.5-2 mm, as described in the module docstring."""
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


def write_records(directory: Path, n_records: int, seconds: float, rate: float) -> None:
    """The raw records as a dataset directory (one CSV each, manifest.csv), written one at a time."""
    rows = ["file,frequency_hz"]
    for k in range(n_records):
        freq, t, x, force = raw_record(k, n_records, seconds, rate)
        write_series(directory / f"rec{k:02d}.csv", t, x, force)
        rows.append(f"rec{k:02d}.csv,{freq!r}")
    (directory / "manifest.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def measure(directory: str) -> dict[str, Any]:
    """The timings and memory of one directory (runs in a fresh process, see :func:`run`)."""
    baseline = _rss_mb()
    root = Path(directory)
    rows = [line.split(",") for line in (root / "manifest.csv").read_text().splitlines()[1:]]
    files = [(root / name, float(freq)) for name, freq in rows]
    best = {"parse_s": np.inf, "extract_s": np.inf, "load_s": np.inf}
    warnings.simplefilter("ignore")  # the records are distorted on purpose: the warnings are not the bench
    for _ in range(REPEATS):
        start = time.perf_counter()
        for path, _ in files:
            np.loadtxt(path, delimiter=",", skiprows=1)
        best["parse_s"] = min(best["parse_s"], time.perf_counter() - start)
        extract = 0.0
        for path, freq in files:
            t, x, force = np.loadtxt(path, delimiter=",", skiprows=1).T.copy()
            start = time.perf_counter()
            extract_loop(t, x, force, source=str(path), nominal_freq_hz=freq)
            extract += time.perf_counter() - start
        best["extract_s"] = min(best["extract_s"], extract)
        start = time.perf_counter()
        loops = load_dataset(root)
        best["load_s"] = min(best["load_s"], time.perf_counter() - start)
    return {**best, "cycles": int(np.sum(loops.cycles)), "baseline_rss_mb": baseline, "peak_rss_mb": _rss_mb()}


def run(records: int = RECORDS, seconds: float = SECONDS, sample_rate_hz: float = SAMPLE_RATE_HZ) -> dict[str, Any]:
    """Ingestion speed: extraction against numpy's parse of the same raw records, and peak memory."""
    if isinstance(records, bool) or not isinstance(records, int) or records < 1:
        raise HysidInputError("must be an integer >= 1", param="records", value=records)
    if not seconds >= 1.0:
        raise HysidInputError("must be at least 1 s", param="seconds", value=seconds)
    if not sample_rate_hz >= 500.0:
        raise HysidInputError("must be at least 500 Hz", param="sample_rate_hz", value=sample_rate_hz)
    with tempfile.TemporaryDirectory(prefix="hysid-bench-ingest-") as tmp:
        write_records(Path(tmp), records, seconds, sample_rate_hz)
        data_mb = sum(p.stat().st_size for p in Path(tmp).glob("*.csv")) / 1e6
        code = "import json, sys; from hysid.bench.ingest import measure; json.dump(measure(sys.argv[1]), sys.stdout)"
        done = subprocess.run([sys.executable, "-c", code, tmp], capture_output=True, text=True, timeout=3600)
    if done.returncode != 0:
        tail = done.stderr.strip().splitlines()[-1:] or ["(no output)"]
        raise RuntimeError(f"ingest measurement failed (exit {done.returncode}): {tail[0]}")
    m = json.loads(done.stdout)
    return {
        "records": records,
        "seconds": seconds,
        "sample_rate_hz": sample_rate_hz,
        "samples": records * int(seconds * sample_rate_hz),
        "data_mb": round(data_mb, 2),
        "cycles": m["cycles"],
        "parse_s": m["parse_s"],
        "extract_s": m["extract_s"],
        "load_s": m["load_s"],
        "ratio": m["extract_s"] / m["parse_s"],
        "load_ratio": m["load_s"] / m["parse_s"],
        "mb_per_s": data_mb / m["load_s"],
        "baseline_rss_mb": m["baseline_rss_mb"],
        "peak_rss_mb": m["peak_rss_mb"],
        "rss_ratio": m["peak_rss_mb"] / data_mb,
        "target_ratio": TARGET_RATIO,
        "target_rss_ratio": TARGET_RSS,
        "meets_targets": m["extract_s"] / m["parse_s"] <= TARGET_RATIO and m["peak_rss_mb"] <= TARGET_RSS * data_mb,
    }


def to_text(result: dict[str, Any]) -> str:
    r = result
    return "\n".join([
        f"{r['records']} raw records of {r['seconds']:g} s at {r['sample_rate_hz']:g} Hz: {r['data_mb']:.1f} MB of CSV, {r['cycles']} cycles",
        f"  numpy parse        {r['parse_s']:.2f} s",
        f"  hysid extraction   {r['extract_s']:.2f} s   ratio {r['ratio']:.2f} (target <= {r['target_ratio']:g})",
        f"  hysid load (both)  {r['load_s']:.2f} s   ratio {r['load_ratio']:.2f}, {r['mb_per_s']:.1f} MB/s",
        f"  peak memory        {r['peak_rss_mb']:.0f} MB ({r['rss_ratio']:.2f} x the data, target <= {r['target_rss_ratio']:g}; "
        f"{r['baseline_rss_mb']:.0f} MB before reading)",
        f"  targets {'met' if r['meets_targets'] else 'NOT met'}",
    ])
