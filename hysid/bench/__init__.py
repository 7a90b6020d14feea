"""Benchmarks behind ``hysid bench <name>``: one module per bench, shared helpers here.

A bench module ``hysid/bench/<name>.py`` exposes ``run(...) -> dict`` (the
results, JSON-serializable; invalid arguments raise :class:`HysidInputError`)
and ``to_text(result) -> str``, and is registered in :mod:`hysid.cli.bench`. Speed goals are stated as ratios measured in
one run, so that they hold on any machine; :func:`environment` records the
machine a result came from.
"""

from __future__ import annotations

import datetime
import hashlib
import json
import os
import platform
import resource
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from hysid_model.errors import HysidInputError

SINGLE_THREAD_ENV = {name: "1" for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
"""Thread limits for BLAS/OpenMP so that a measurement uses one core."""


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as info:
            for line in info:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def environment() -> dict[str, Any]:
    """When and where a bench ran: ``date``, ``machine`` (hostname, cpu model, cores), ``python``, ``numpy``."""
    return {
        "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
        "machine": {
            "hostname": socket.gethostname(),
            "cpu_model": cpu_model(),
            "cores": os.cpu_count(),
            "cores_available": len(os.sched_getaffinity(0)),
            "load_avg_1m": round(os.getloadavg()[0], 2),
        },
        "python": platform.python_version(),
        "numpy": np.__version__,
    }


def peak_rss_mb() -> float:
    """Peak resident memory (MB) of this process and of its finished children, whichever is larger."""
    kib = max(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
    return kib / 1024.0


def run_on_one_core(function: str, timeout_s: float = 600.0) -> Any:
    """Call ``"package.module:function"`` (no arguments, JSON-serializable result) in a fresh
    Python pinned to one CPU with BLAS/OpenMP limited to one thread, and return its result.

    The pinning has to happen before numpy loads, hence the subprocess.
    """
    module, name = function.split(":")
    cpu = max(os.sched_getaffinity(0))
    code = f"import os, json, sys; os.sched_setaffinity(0, {{{cpu}}}); import {module} as m; json.dump(m.{name}(), sys.stdout)"
    env = {**os.environ, **SINGLE_THREAD_ENV}
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=timeout_s)
    if done.returncode != 0:
        tail = done.stderr.strip().splitlines()[-1:] or ["(no output)"]
        raise RuntimeError(f"one-core measurement {function} failed (exit {done.returncode}): {tail[0]}")
    return json.loads(done.stdout)


def write_section(path: Path, name: str, text: str) -> None:
    """Put ``text`` into the Markdown file ``path`` between ``<!-- bench NAME -->`` and ``<!-- /bench NAME -->``, in place
    of what was there (appended where the file has no such section, the file made where there is none), so
    that benches sharing a document (docs/VALIDATION.md) each rewrite their own part only."""
    start, end = f"<!-- bench {name} -->", f"<!-- /bench {name} -->"
    block = f"{start}\n{text.strip()}\n{end}"
    old = path.read_text(encoding="utf-8") if path.exists() else ""
    if start in old and end in old.split(start, 1)[1]:
        before, rest = old.split(start, 1)
        new = before + block + rest.split(end, 1)[1]
    else:
        new = old.rstrip("\n") + ("\n\n" if old.strip() else "") + block + "\n"
    path.write_text(new, encoding="utf-8")


def git_commit() -> str | None:
    """The commit of the checkout this code runs from (None outside a git checkout)."""
    try:
        done = subprocess.run(["git", "rev-parse", "HEAD"], cwd=Path(__file__).parent, capture_output=True, text=True, timeout=30)
    except OSError:
        return None
    if done.returncode != 0:
        return None
    return done.stdout.strip() or None


def source_hash(path: str | Path) -> str:
    """sha256 of a bench's module (its ``__file__``): its cases, seeds and criterion as a run ran them."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def sweep(
    bench: str,
    source: str | Path,
    groups: Iterable[str],
    seeds: Iterable[int],
    outcome: Callable[[str, int], dict[str, Any]],
    say: Callable[[str, int, dict[str, Any]], str],
    judge: Callable[[dict[str, dict[str, dict[str, Any]]]], dict[str, Any]],
    progress: Callable[[int, int, str], None] | None = None,
) -> dict[str, Any]:
    """The :func:`sweep_result` of bench ``bench`` (defined in ``source``): every group's ``outcome(group, seed)`` on
    every seed, by group and by seed (as text), in order, judged by ``judge``; after each outcome,
    ``progress(done, total, say(group, seed, record))``."""
    began, cpu = time.perf_counter(), time.process_time()
    groups, seeds = list(groups), list(seeds)
    outcomes: dict[str, dict[str, dict[str, Any]]] = {group: {} for group in groups}
    for group in groups:
        for seed in seeds:
            outcomes[group][str(seed)] = record = outcome(group, seed)
            if progress is not None:
                progress(sum(map(len, outcomes.values())), len(groups) * len(seeds), say(group, seed, record))
    return sweep_result(bench, source, outcomes, judge(outcomes), began, cpu)


def sweep_result(bench: str, source: str | Path, outcomes: dict[str, Any], judged: dict[str, Any], began: float, cpu: float) -> dict[str, Any]:
    """The result of a bench that sweeps seeds for a test, as that test reads it: the bench's name, ``definitions``
    (:func:`source_hash` of ``source``, the module defining the sweep: the test refuses a result of other
    definitions), the git commit, the ``outcomes`` and their verdict ``judged``, and the wall and CPU seconds since
    ``began`` (:func:`time.perf_counter`) and ``cpu`` (:func:`time.process_time`)."""
    return {
        "bench": bench,
        "definitions": source_hash(source),
        "commit": git_commit(),
        "outcomes": outcomes,
        **judged,
        "wall_s": time.perf_counter() - began,
        "cpu_s": time.process_time() - cpu,
    }


def verdict(ok: bool) -> str:
    """The word a bench's text gives a target it met (``PASS``) or missed (``FAIL``)."""
    return "PASS" if ok else "FAIL"


def check_chosen(given: Iterable[str], known: Iterable[str], what: str) -> None:
    """Every name ``given`` is one of ``known``, else a one-line error naming the first that is not and the
    choices (the option is ``what``'s plural: ``--cases``, ``--specimens``, ...)."""
    choices = list(known)
    unknown = [n for n in given if n not in choices]
    if unknown:
        raise HysidInputError(f"unknown {what} {unknown[0]!r}; choose from {', '.join(choices)}", param=f"{what}s", value=unknown[0])
