"""``hysid bench ingest [generated|large|lab|damper|daq|small|all]``: raw records to loops, against the time numpy
alone takes to parse the same files, and the memory it takes against the largest file.

The record sets (:mod:`hysid.bench.ingest_sets`): **generated** (225 MB in 16 records: the 200 MB set), **large**
(820 MB in 4 records of 7.2 M rows: the 800 MB set, each file as big as the one that once took 1.45 GB), **lab** (a
wire-rope isolator's 16 tests as a German lab exports them, 3 MB each: preamble, decimal commas, 10 kHz), **damper**
(the real friction damper's records), **daq** and **small** (DAQ-shaped exports, the latter where a fixed cost per
record shows). Each set is measured in a fresh Python process: one load first (``first_load_s``: it also pays what hysid loads
on first use, scipy's special functions and the compiled reader), then alternating rounds (parse first, then load;
then load first, then parse):

* ``parse_s``: numpy alone, ``np.loadtxt`` of every file with its delimiter and lines before the numbers (with
  decimal commas: the text with commas turned to points, as a numpy user would);
* ``load_s``: :func:`hysid_model.datasets.load_dataset` of the directory (what ``hysid.load`` and ``hysid loops`` do:
  read every record through hysid's readers, extract its loop, check the set);
* ``extract_s``: :func:`hysid_model.extraction.extract_loop` on every record already read.

``load_ratio`` = load_s / parse_s, the median over the rounds of each round's ratio (target <= 2: everything
``hysid.load`` does, reading included, within twice numpy's parse alone); ``extract_ratio`` = extract_s / parse_s
likewise; ``load_cpu_ratio`` = the same ratio of CPU times (``time.process_time``; on a loaded machine the
wall-clock ratio also counts the time each waited for a core); ``mb_per_s`` = CSV megabytes per second of ``load_s``. Memory: before each load the process' peak
resident size is reset (Linux ``/proc/self/clear_refs``), and ``rss_growth_mb`` is the largest rise of it over the
resident size before the load, the first load included (which loads the compiled reader; ``rss_growth_warm_mb``: the
rounds' largest). Target:
``rss_growth_mb`` <= 2 x ``largest_file_mb`` + ``FIXED_MB`` (records are read one at a time, so the sum of the
files does not count). The machine's load average is kept with each set.
"""

from __future__ import annotations

import io
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
import warnings
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from hysid.bench.ingest_sets import DAMPER_SET, DAQ, LAB, LARGE, SMALL, IngestSet, parse_plan, write_set
from hysid_model.datasets import load_dataset
from hysid_model.errors import HysidInputError
from hysid_model.extraction import extract_loop
from hysid_model.readers.dataset_dir import read_config, read_manifest
from hysid_model.readers.records import read_record

RECORDS = 16
SECONDS = 30.0
SAMPLE_RATE_HZ = 10240.0
ROUNDS = 3
TARGET_RATIO = 2.0
TARGET_RSS = 2.0
FIXED_MB = 256.0
"""The memory target's fixed part: the compiled reader (numba and its cached code, 125 MB resident once loaded) and
the extraction of a record's steady cycles, which takes at most ``hysid_model.steady.MAX_SAMPLES`` samples at once
(about 100 MB)."""
PARTS = ("generated", "large", "lab", "damper", "daq", "small")
FIXED_SETS = {"large": LARGE, "lab": LAB, "damper": DAMPER_SET, "daq": DAQ, "small": SMALL}


def _status_mb(key: str) -> float | None:
    """``VmRSS`` or ``VmHWM`` of this process in MB (None where /proc is not there)."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return None


def _reset_peak() -> bool:
    """Reset the peak resident size to the current one (Linux), so that the next peak is the next step's alone."""
    try:
        with open("/proc/self/clear_refs", "w", encoding="ascii") as refs:
            refs.write("5")
        return _status_mb("VmHWM") is not None
    except OSError:
        return False


def _loadtxt(path: Path, plan: dict[str, Any]) -> np.ndarray:
    """numpy's parse of one file (see the module docstring)."""
    if not plan["decimal_comma"]:
        return np.loadtxt(path, delimiter=plan["delimiter"], skiprows=plan["skiprows"], encoding=plan["encoding"])
    text = path.read_text(encoding=plan["encoding"]).replace(",", ".")
    return np.loadtxt(io.StringIO(text), delimiter=plan["delimiter"], skiprows=plan["skiprows"])


def measure(directory: str, plan_json: str, rounds: int) -> dict[str, Any]:
    """The timings and memory of one directory (runs in a fresh process, see :func:`run`)."""
    root = Path(directory)
    plan = json.loads(plan_json)
    rows = read_manifest(root / "manifest.csv")
    files = [(root / row.file, row.frequency_hz) for row in rows]
    config = read_config(root)
    warnings.simplefilter("ignore")  # the records are distorted on purpose: the warnings are not the bench

    def parse() -> float:
        start, cpu = time.perf_counter(), time.process_time()
        for path, _ in files:
            _loadtxt(path, plan)
        times["parse_cpu_s"].append(time.process_time() - cpu)
        return time.perf_counter() - start

    def load() -> tuple[float, int, float]:
        resettable = _reset_peak()
        before = _status_mb("VmRSS") if resettable else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        start, cpu = time.perf_counter(), time.process_time()
        loops = load_dataset(root)
        elapsed = time.perf_counter() - start
        times["load_cpu_s"].append(time.process_time() - cpu)
        peak = _status_mb("VmHWM") if resettable else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        return elapsed, int(np.sum(loops.cycles)), float(peak - before)

    times: dict[str, list[float]] = {"parse_s": [], "load_s": [], "extract_s": [], "rss_growth_mb": [], "parse_cpu_s": [], "load_cpu_s": []}
    first_s, _, first_growth = load()  # what hysid loads on first use (scipy's special functions, the compiled reader)
    times["load_cpu_s"].clear()  # the first load is not a round
    for r in range(rounds):
        if r % 2 == 0:
            times["parse_s"].append(parse())
            load_s, cycles, growth = load()
        else:
            load_s, cycles, growth = load()
            times["parse_s"].append(parse())
        times["load_s"].append(load_s)
        times["rss_growth_mb"].append(growth)
        extract = 0.0
        for (path, freq), row in zip(files, rows):
            series = read_record(path, config)
            start = time.perf_counter()
            extract_loop(series.t, series.x, series.force, source=str(path), nominal_freq_hz=freq, steady_window=config.window(row.file))
            extract += time.perf_counter() - start
            del series
        times["extract_s"].append(extract)
    return {**times, "cycles": cycles, "first_load_s": first_s, "first_rss_growth_mb": first_growth, "peak_reset": _reset_peak()}


def _measured(spec: IngestSet, directory: Path, rounds: int, seconds: float) -> dict[str, Any]:
    """Write a set into ``directory``, measure it in a fresh process, and summarize (medians of the rounds' ratios)."""
    write_set(directory, spec, seconds)
    sizes = [p.stat().st_size / 1e6 for p in directory.glob("*.csv") if p.name != "manifest.csv"]
    code = "import json, sys; from hysid.bench.ingest import measure; json.dump(measure(sys.argv[1], sys.argv[2], int(sys.argv[3])), sys.stdout)"
    load_before = os.getloadavg()[0]
    done = subprocess.run([sys.executable, "-c", code, str(directory), json.dumps(parse_plan(spec)), str(rounds)], capture_output=True, text=True, timeout=7200)
    if done.returncode != 0:
        tail = done.stderr.strip().splitlines()[-1:] or ["(no output)"]
        raise RuntimeError(f"ingest measurement of {spec.name} failed (exit {done.returncode}): {tail[0]}")
    m = json.loads(done.stdout)
    parse, load, extract, parse_cpu, load_cpu = (np.array(m[key]) for key in ("parse_s", "load_s", "extract_s", "parse_cpu_s", "load_cpu_s"))
    ratio = float(np.median(load / parse))
    growth, largest = max(m["first_rss_growth_mb"], *m["rss_growth_mb"]), max(sizes)
    bound = TARGET_RSS * largest + FIXED_MB
    return {
        **asdict(spec),
        "seconds": spec.samples / spec.sample_rate_hz,
        "data_mb": round(sum(sizes), 2),
        "largest_file_mb": largest,
        "cycles": m["cycles"],
        "rounds": {key: m[key] for key in ("parse_s", "load_s", "extract_s", "rss_growth_mb", "parse_cpu_s", "load_cpu_s")},
        "parse_s": float(np.median(parse)),
        "load_s": float(np.median(load)),
        "extract_s": float(np.median(extract)),
        "load_ratio": ratio,
        "extract_ratio": float(np.median(extract / parse)),
        "load_cpu_ratio": float(np.median(load_cpu / parse_cpu)),
        "mb_per_s": sum(sizes) / float(np.median(load)),
        "rss_growth_mb": growth,
        "rss_growth_warm_mb": max(m["rss_growth_mb"]),
        "first_load_s": m["first_load_s"],
        "rss_bound_mb": bound,
        "rss_per_largest_file": growth / largest,
        "peak_reset": m["peak_reset"],
        "load_avg_1m": [round(load_before, 2), round(os.getloadavg()[0], 2)],
        "meets_targets": ratio <= TARGET_RATIO and growth <= bound,
    }


def run(
    parts: list[str] | tuple[str, ...] = PARTS, records: int = RECORDS, seconds: float = SECONDS, sample_rate_hz: float = SAMPLE_RATE_HZ, rounds: int = ROUNDS
) -> dict[str, Any]:
    """Ingestion speed: hysid.load against numpy's parse of the same raw records, and peak memory against the largest file."""
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
        spec = FIXED_SETS.get(part) or IngestSet("generated", records, int(seconds * sample_rate_hz), sample_rate_hz, "hysid")
        with tempfile.TemporaryDirectory(prefix=f"hysid-bench-ingest-{part}-") as tmp:
            sets[part] = _measured(spec, Path(tmp), rounds, seconds)
    return {
        "sets": sets,
        "target_ratio": TARGET_RATIO,
        "target_rss": f"{TARGET_RSS:g} x the largest file + {FIXED_MB:g} MB",
        "meets_targets": all(s["meets_targets"] for s in sets.values()),
    }


def to_text(result: dict[str, Any]) -> str:
    lines = []
    for r in result["sets"].values():
        lines += [
            f"{r['name']}: {r['records']} raw records of {r['samples']} samples at {r['sample_rate_hz']:g} Hz: "
            f"{r['data_mb']:.1f} MB of CSV (largest file {r['largest_file_mb']:.1f} MB), {r['cycles']} cycles "
            f"(load average {r['load_avg_1m'][0]:g} -> {r['load_avg_1m'][1]:g})",
            f"  numpy parse        {r['parse_s']:.2f} s",
            f"  hysid load         {r['load_s']:.2f} s   {r['load_ratio']:.2f} x the parse (target <= {result['target_ratio']:g}), {r['mb_per_s']:.1f} MB/s",
            f"  extraction alone   {r['extract_s']:.2f} s   {r['extract_ratio']:.2f} x the parse",
            f"  CPU time           load {r['load_cpu_ratio']:.2f} x the parse (process_time, fairer on a loaded machine)",
            f"  memory             {r['rss_growth_mb']:.0f} MB for loading ({r['rss_per_largest_file']:.2f} x the largest file; "
            f"target <= {r['rss_bound_mb']:.0f} MB = {result['target_rss']})"
            + f"; {r['rss_growth_warm_mb']:.0f} MB in the rounds after the first load ({r['first_load_s']:.2f} s)",
        ]
    lines.append(
        f"targets {'met' if result['meets_targets'] else 'NOT met'} (medians of {len(next(iter(result['sets'].values()))['rounds']['parse_s'])} "
        "alternating rounds; memory: the largest of them)"
    )
    return "\n".join(lines)
