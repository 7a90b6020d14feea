"""``hysid bench diagnose``: are hidden effects named, and nothing else, over 10 noise seeds? The statistics of
``tests/test_diagnose.py``.

Every case of :mod:`hysid.bench.diagnose_cases` (each library effect hidden alone, the thesis story of section
4.3, a control, two effects together, an effect outside the library, a band too narrow to tell two effects
apart) is diagnosed on each of its seeds, in a pool of processes over the cores this process may use (one
seed a task). For each case and seed: what was named, the status, whether the seed was right and whether the
checks that must hold on every seed held, with its wall and CPU time; for each case the verdict
(:func:`hysid.bench.diagnose_cases.verdict`: at least 9 of 10 right). The result carries
:func:`hysid.bench.diagnose_cases.definitions_hash` and the git commit, so that the test that reads it can tell
whether the cases changed since.
"""

from __future__ import annotations

import os
import resource
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from multiprocessing import get_context
from typing import Any

from hysid.bench import check_chosen, git_commit, verdict
from hysid.bench import diagnose_cases as dc
from hysid.report import jsondoc
from hysid_model.errors import HysidInputError


def seed_outcome(name: str, seed: int) -> dict[str, Any]:
    """One case's outcome on one seed, with the wall and CPU time it took (in a pool's process)."""
    began, cpu = time.perf_counter(), time.process_time()
    record = dc.cases()[name].outcome(seed)
    return {**record, "wall_s": time.perf_counter() - began, "cpu_s": time.process_time() - cpu}


def children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run(names: tuple[str, ...] | None = None, workers: int | None = None, progress: Callable[[int, int, str], None] | None = None) -> dict[str, Any]:
    """Hidden effects named over 10 noise seeds (at least 9 right per case): the statistics tests/test_diagnose.py reads.

    ``progress(done, total, what)`` is called as each seed's diagnosis comes in."""
    known = dc.cases()
    names = names if names else tuple(known)
    check_chosen(names, known, "case")
    workers = workers or len(os.sched_getaffinity(0))
    if workers < 1:
        raise HysidInputError("need at least 1 worker process", param="workers", value=workers)
    began, cpu, children = time.perf_counter(), time.process_time(), children_cpu_s()
    with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn")) as pool:  # spawn: no forked numba or BLAS threads
        futures = {pool.submit(seed_outcome, name, seed): (name, seed) for name in names for seed in dc.SEEDS}
        records = {}
        for future in as_completed(futures):
            name, seed = key = futures[future]
            records[key] = record = future.result()
            if progress is not None:
                progress(len(records), len(futures), f"{name} seed {seed}: {'right' if record['met'] else 'wrong'}, {record['cpu_s']:.0f} s CPU")
    out: dict[str, Any] = {}
    for name in names:
        per_seed = {seed: records[name, seed] for seed in dc.SEEDS}
        out[name] = {
            "description": known[name].description,
            **dc.verdict(known[name], per_seed),
            "wall_s": sum(r["wall_s"] for r in per_seed.values()),
            "cpu_s": sum(r["cpu_s"] for r in per_seed.values()),
            "per_seed": {str(seed): r for seed, r in per_seed.items()},
        }
    result = {
        "bench": "diagnose",
        "definitions": dc.definitions_hash(),
        "commit": git_commit(),
        "criterion": {"seeds": len(dc.SEEDS), "required": dc.REQUIRED},
        "workers": workers,
        "cases": out,
        "ok": all(c["ok"] for c in out.values()),
        "wall_s": time.perf_counter() - began,
        "cpu_s": time.process_time() - cpu + children_cpu_s() - children,
    }
    return jsondoc.plain(result)


def to_text(result: dict[str, Any]) -> str:
    c = result["criterion"]
    lines = [
        f"hysid bench diagnose: at least {c['required']} of {c['seeds']} seeds right per case  {verdict(result['ok'])}  "
        f"({result['wall_s']:.0f} s wall, {result['cpu_s']:.0f} s CPU, {result['workers']} processes)"
    ]
    for name, case in result["cases"].items():
        extra = f", {case['wrong']} wrong names" if case["wrong"] else ""
        extra += f", every-seed checks failed on seeds {case['strict_failed']}" if case["strict_failed"] else ""
        lines.append(f"  {name:<40} {case['met']:>2}/{case['seeds']} right{extra}  {case['cpu_s']:.0f} s CPU  {'ok' if case['ok'] else 'FAIL'}")
    return "\n".join(lines)
