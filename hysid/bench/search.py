"""``hysid bench search``: hysid's fit and campaigns against what a user would pick instead, where it is hard.

In one run and at equal evaluation budgets, on each problem of
:mod:`hysid.bench.search_problems` (memory models a local method struggles
with, and the thesis model as an easy control), every method searches from
``seeds`` seeds:

* ``fit``: :func:`hysid.fit` with its defaults (on memory models the memetic
  islands of :mod:`island.memetic` with their default budget);
* ``campaign_{2,4}_{processes,single}``: :func:`hysid.campaign` with 2 and 4
  islands, as processes over Zenoh and as threads of one process, stopped at
  the budget (their defaults otherwise);
* the peers of :mod:`hysid.bench.search_peers`: scipy ``least_squares``
  multi-start, scipy ``differential_evolution``, CMA-ES with restarts (pycma)
  and a pygmo archipelago where pygmo installs.

Every method gets the problem's loops, model and bounds (hard, the same box for
all) and the budget :data:`BUDGET` (the peers count their evaluations through
:class:`hysid.bench.search_peers.Tracker`; hysid's methods count theirs: a
candidate or a residual vector is one evaluation, a Jacobian its 2 D probes).
The data (truth and noise) are fixed per problem; the seeds vary the searches.

Per problem and method: the success rate (final fitness within
:data:`SUCCESS_RTOL` relative of the best fitness any method found on that
problem) with its 95 % Wilson interval, the median evaluations and seconds to
success (from the method's trace where it has one, else its end), and the
final fitness quantiles relative to the best. ``ok``: hysid's default
campaign (:data:`CAMPAIGN`) is non-inferior to every peer on every problem by
the paired rule of ``hysid bench islands mixed`` (the seed-by-seed
difference of success rates has its 95 % interval above -10 points,
:func:`hysid.bench.rates.paired`) and ahead of all of them (a higher
success rate than each) on the hardest half of the problems: the
``len(problems) // 2`` problems whose best peer has the lowest success rate
(ties: the lower mean peer rate first).

Also reported: whether ``fit``'s independent seeds agree within 1 % of the
fitness on every problem (``fit_seeds_agree``), and the campaign's wall-time
speedup from 1 to 2 island processes on a memory model at equal total
evaluations (``speedup``, target 1.7; :data:`SPEEDUP_REPEATS` pairs in turn, the ratio of the medians),
and the wall time of a memory-model fit with every default, as a user runs it, on 10 and 40 loops
(``fit_time``, :func:`fit_times`: the real friction damper and a simulated MR damper; target under
:data:`FIT_TIME_LIMIT_S` each).
"""

from __future__ import annotations

import inspect
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

import hysid
from coordinator.launch import island_specs, run_campaign
from coordinator.state import Coordinator
from coordinator.store import Store
from hysid.bench.islands import SPEEDUP_TARGET
from hysid.bench.rates import NON_INFERIORITY_MARGIN, paired, wilson
from hysid.bench.search_peers import PEERS, pygmo_available
from hysid.bench.search_problems import MR_LEVELS, PROBLEMS, Problem, build, extracted, mr_damper_records
from hysid.bench.validation import DAMPER
from hysid.campaigns import default_options
from hysid.report import jsondoc
from hysid_model.errors import HysidInputError
from hysid_model.extraction import extract_loop
from hysid_model.problem import build_objective
from island.config import CampaignConfig
from island.memetic import BUDGET
from island.termination import Termination

DISPLACEMENT = "measured"
"""How every method's objective reads the displacement (the peers' objective is built so): one objective for all,
so that their fitness values compare (``hysid fit`` would otherwise decide the reading from the data)."""
SUCCESS_RTOL = 1e-6
MIN_SEEDS = 30
CAMPAIGNS = {"campaign_2_processes": (2, False), "campaign_4_processes": (4, False), "campaign_2_single": (2, True), "campaign_4_single": (4, True)}
METHODS = ("fit", *CAMPAIGNS, *PEERS)
CAMPAIGN = "campaign_4_processes"
"""The campaign ``ok`` judges: ``hysid campaign``'s default, 4 island processes."""
SPEEDUP_PROBLEM = "mr_damper_1v"
SPEEDUP_BUDGET = 300_000
SPEEDUP_REPEATS = 3
"""Pairs of 1- and 2-island campaigns: one campaign's wall time on this 2-core VM varied by 19 % between
identical runs (38.5-45.7 s for the same 300,052 evaluations)."""
FIT_TIME_LIMIT_S = 60.0
"""A memory-model fit of 10-40 loops with the defaults finishes within this on a 2-core machine."""
FIT_TIME_MR_FREQS_HZ = np.array([0.5, 1.0, 1.5, 2.0, 3.0])
FIT_TIME_MR_AMPLITUDES_M = np.linspace(2.5e-3, 20e-3, 8)
"""The 40 loops of the simulated MR damper (1 V) that :func:`fit_times` fits."""
FIT_TIME_POINTS: int = inspect.signature(extract_loop).parameters["n_points"].default
"""Samples per branch of those loops: what extraction gives by default (:func:`hysid_model.extraction.extract_loop`)."""
QUICK: dict[str, Any] = {"seeds": 3, "problems": ("mr_damper_1v", "thesis_easy"), "budget": 3000, "speedup_budget": 20_000, "speedup_repeats": 1}
"""The quick mode (tests, a look): 3 seeds, two problems, small budgets; ``ok`` is not meaningful there."""


def run_method(problem: Problem, method: str, seed: int, budget: int) -> dict[str, Any]:
    """One search of ``method`` on ``problem``: final fitness, evaluations, seconds, trace (evaluations, s, best)."""
    began = time.perf_counter()
    if method == "fit":
        trace: list[tuple[int, float, float]] = []
        result = hysid.fit(
            problem.loops,
            problem.model,
            bounds=problem.bounds,
            seed=seed,
            displacement=DISPLACEMENT,
            progress=lambda run, row: trace.append((row.evaluations, row.wall_s, row.best_fitness)),
        )
        return {"fitness": result.fitness, "evaluations": result.evaluations, "wall_s": time.perf_counter() - began, "trace": trace}
    if method in CAMPAIGNS:
        islands, single = CAMPAIGNS[method]
        outcome = hysid.campaign(
            problem.loops,
            problem.model,
            islands=islands,
            name=f"search-{seed}",
            bounds=problem.bounds,
            displacement=DISPLACEMENT,
            seed=1000 * seed,
            termination=Termination(budget=budget),
            single_node=single,
        )
        return {"fitness": outcome.fit.fitness, "evaluations": outcome.fit.evaluations, "wall_s": time.perf_counter() - began, "trace": []}
    objective = build_objective(problem.loops, problem.model, bounds=problem.bounds)
    return PEERS[method](objective, budget, seed)


def first_success(run: dict[str, Any], threshold: float) -> tuple[float, float]:
    """Evaluations and seconds at which ``run`` first reached ``threshold`` (its trace, else its end)."""
    hit = next(((e, t) for e, t, f in run["trace"] if f <= threshold), None)
    return (float(hit[0]), float(hit[1])) if hit is not None else (float(run["evaluations"]), float(run["wall_s"]))


def summarize(runs: dict[str, list[dict[str, Any]]]) -> dict[str, Any]:
    """Success rates, times to success and fitness quantiles of every method on one problem."""
    best = min(r["fitness"] for rs in runs.values() for r in rs)
    threshold = best * (1 + SUCCESS_RTOL) if best > 0 else SUCCESS_RTOL
    out: dict[str, Any] = {"best_fitness": best, "threshold": threshold, "methods": {}}
    for method, rs in runs.items():
        f = np.array([r["fitness"] for r in rs])
        ok = f <= threshold
        reached = [first_success(r, threshold) for r, s in zip(rs, ok) if s]
        out["methods"][method] = {
            "seeds": len(rs),
            "success_rate": float(ok.mean()),
            "wilson95": wilson(int(ok.sum()), len(rs)),
            "median_evaluations_to_success": float(np.median([e for e, _ in reached])) if reached else None,
            "median_s_to_success": float(np.median([t for _, t in reached])) if reached else None,
            "median_s": float(np.median([r["wall_s"] for r in rs])),
            "median_evaluations": float(np.median([r["evaluations"] for r in rs])),
            "fitness_over_best_quantiles": {str(q): float(np.quantile(f / best - 1.0, q / 100)) for q in (0, 25, 50, 75, 100)},
            "success": ok.tolist(),
        }
    return out


def judge(problems: dict[str, Any], peers: list[str]) -> dict[str, Any]:
    """The campaign against every peer on every problem (non-inferiority), and on the hardest half (ahead)."""
    peer_best = {p: max(r["methods"][m]["success_rate"] for m in peers) for p, r in problems.items()}
    peer_mean = {p: float(np.mean([r["methods"][m]["success_rate"] for m in peers])) for p, r in problems.items()}
    hardest = sorted(problems, key=lambda p: (peer_best[p], peer_mean[p]))[: max(len(problems) // 2, 1)]
    versus: dict[str, dict[str, Any]] = {}
    for p, r in problems.items():
        mine = np.array(r["methods"][CAMPAIGN]["success"])
        versus[p] = {m: paired(mine, np.array(r["methods"][m]["success"])) for m in peers}
    non_inferior = all(v["difference95"][0] >= -NON_INFERIORITY_MARGIN for pv in versus.values() for v in pv.values())
    ahead = all(problems[p]["methods"][CAMPAIGN]["success_rate"] > problems[p]["methods"][m]["success_rate"] for p in hardest for m in peers)
    return {
        "campaign": CAMPAIGN,
        "peers": peers,
        "hardest": hardest,
        "peer_best_rate": peer_best,
        "paired": versus,
        "non_inferior": non_inferior,
        "ahead_on_hardest": ahead,
        "margin": NON_INFERIORITY_MARGIN,
        "ok": non_inferior and ahead,
    }


def speedup(budget: int, problem: Problem, repeats: int = SPEEDUP_REPEATS) -> dict[str, Any]:
    """Wall time of a campaign of ``budget`` evaluations with 1 and with 2 island processes (from the moment
    every island is a member until the campaign has stopped, its islands' goodbyes included), on a memory
    model, the islands' defaults; ``repeats`` pairs taken in turn (1, 2, 1, 2, ...), so that a slow spell of
    the machine falls on both. The ratio is of the median seconds per evaluation (the stop overshoots the
    budget a little)."""
    times: dict[int, list[dict[str, float]]] = {1: [], 2: []}
    with tempfile.TemporaryDirectory(prefix="hysid-bench-") as tmp:
        for repeat in range(repeats):
            for n in (1, 2):
                name = f"speedup-{n}-{repeat}"
                config = CampaignConfig.create(
                    problem.loops,
                    name=name,
                    model=problem.model,
                    bounds=problem.bounds,
                    min_islands=n,
                    options=default_options(problem.loops, problem.model, problem.bounds),
                    until_stopped=True,
                )
                coordinator = Coordinator(Store(Path(tmp) / f"{name}.sqlite"), config, problem.loops, Termination(budget=budget))
                run_campaign(coordinator, island_specs(n, ["pso"], 0), polish=False)
                ended = time.monotonic()
                assert coordinator.full_at is not None
                times[n].append({"s": ended - coordinator.full_at, "evaluations": coordinator.evaluations})
                coordinator.store.close()
    per_evaluation = {n: float(np.median([t["s"] / t["evaluations"] for t in runs])) for n, runs in times.items()}
    ratio = per_evaluation[1] / per_evaluation[2]
    return {
        "problem": problem.name,
        "model": problem.model,
        "budget": budget,
        "repeats": repeats,
        "one_island": times[1],
        "two_islands": times[2],
        "median_s_per_evaluation": {str(n): v for n, v in per_evaluation.items()},
        "ratio": ratio,
        "target": SPEEDUP_TARGET,
        "ok": ratio >= SPEEDUP_TARGET,
    }


def fit_times() -> dict[str, Any]:
    """Wall time of :func:`hysid.fit` with every default (the reading of the displacement included) on a model
    with memory: the real ARTS-Lab friction damper (10 loops as :func:`hysid.load` extracts them) with
    ``baseline+coulomb_friction+bouc_wen``, and a simulated MR damper at 1 V (40 loops, 0.5-3 Hz, 2.5-20 mm,
    extracted at the default 100 samples per branch) with ``mr_damper``; loading not counted."""
    cases = {
        "arts_friction_damper": (lambda: hysid.load(DAMPER), "baseline+coulomb_friction+bouc_wen"),
        "mr_damper_40_loops": (
            lambda: extracted(
                "mr_damper_1v_40",
                mr_damper_records(MR_LEVELS["mr_damper_1v"], freqs_hz=FIT_TIME_MR_FREQS_HZ, amplitudes_m=FIT_TIME_MR_AMPLITUDES_M),
                None,
                points=FIT_TIME_POINTS,
            ),
            "mr_damper",
        ),
    }
    out: dict[str, Any] = {}
    for name, (make, model) in cases.items():
        loops = make()
        began = time.perf_counter()
        result = hysid.fit(loops, model)
        out[name] = {
            "model": model,
            "loops": loops.n_loops,
            "samples_per_branch": loops.n_samples,
            "s": time.perf_counter() - began,
            "evaluations": result.evaluations,
            "fitness": result.fitness,
            "rms_pct": result.quality["rms_residual_pct"],
            "displacement": (result.displacement_model or {}).get("displacement"),
            "at_bounds": result.at_bounds,
        }
    return {"limit_s": FIT_TIME_LIMIT_S, "cases": out, "ok": all(c["s"] < FIT_TIME_LIMIT_S for c in out.values())}


def run(
    seeds: int = MIN_SEEDS,
    quick: bool = False,
    problems: tuple[str, ...] = PROBLEMS,
    methods: tuple[str, ...] = METHODS,
    budget: int = BUDGET,
    speedup_budget: int = SPEEDUP_BUDGET,
    partial: Path | None = None,
) -> dict[str, Any]:
    """Search where it is hard: hysid's fit and campaigns against least squares, DE, CMA-ES and pygmo at equal budgets.

    ``partial``: a file the results so far are written to after every problem (a long run's progress)."""
    if quick:
        seeds, problems, budget, speedup_budget = QUICK["seeds"], QUICK["problems"], QUICK["budget"], QUICK["speedup_budget"]
    elif seeds < 3:
        raise HysidInputError("the success rates need at least 3 seeds (--quick for a look)", param="seeds", value=seeds)
    repeats = QUICK["speedup_repeats"] if quick else SPEEDUP_REPEATS
    strange = [m for m in methods if m not in METHODS]
    if strange:
        raise HysidInputError(f"unknown method; choose from {', '.join(METHODS)}", param="methods", value=strange[0])
    unknown = [p for p in problems if p not in PROBLEMS]
    if unknown:
        raise HysidInputError(f"unknown problem; choose from {', '.join(PROBLEMS)}", param="problems", value=unknown[0])
    skipped = {}
    why = pygmo_available()
    if why is not None and "pygmo" in methods:
        methods, skipped["pygmo"] = tuple(m for m in methods if m != "pygmo"), why
    began = time.perf_counter()
    out: dict[str, Any] = {
        "problems": {},
        "budget_evaluations": budget,
        "seeds": seeds,
        "quick": quick,
        "skipped": skipped,
        "success_rtol": SUCCESS_RTOL,
        "preliminary": quick or seeds < MIN_SEEDS,
    }
    built = {}
    for name in problems:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            problem = built[name] = build(name)
            runs = {m: [run_method(problem, m, seed, budget) for seed in range(seeds)] for m in methods}
        fits = [r["fitness"] for r in runs.get("fit", [])]
        out["problems"][name] = {
            "description": problem.description,
            "model": problem.model,
            "loops": problem.loops.n_loops,
            "samples_per_branch": problem.loops.n_samples,
            "parameters": len(problem.bounds),
            "memory": problem.memory,
            **summarize(runs),
            "fit_seed_spread": float(max(fits) / min(fits) - 1.0) if fits else None,
        }
        peers = [m for m in methods if m in PEERS]
        if CAMPAIGN in methods and peers:
            out["judgement"] = judge(out["problems"], peers)
            out["ok"] = None if out["preliminary"] else out["judgement"]["ok"]
        if "fit" in methods:
            out["fit_seeds_agree"] = all(p["fit_seed_spread"] <= 0.01 for p in out["problems"].values())
        if partial is not None:  # what a long run has so far, problem by problem
            partial.write_text(jsondoc.dumps({**out, "bench_s": time.perf_counter() - began}, indent=2))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        target = built.get(SPEEDUP_PROBLEM) or build(SPEEDUP_PROBLEM)
        out["speedup"] = speedup(speedup_budget, target, repeats)
        out["fit_time"] = fit_times()
    out["bench_s"] = time.perf_counter() - began
    return out


LABELS = {
    "fit": "hysid fit",
    "campaign_2_processes": "campaign 2 proc",
    "campaign_4_processes": "campaign 4 proc",
    "campaign_2_single": "campaign 2 single",
    "campaign_4_single": "campaign 4 single",
    "least_squares": "least_squares multi-start",
    "differential_evolution": "differential_evolution",
    "cma_es": "CMA-ES (IPOP)",
    "pygmo": "pygmo archipelago",
}


def to_text(result: dict[str, Any]) -> str:
    lines = [
        f"search ({result['seeds']} seeds, {result['budget_evaluations']:,} evaluations each, success = within "
        f"{result['success_rtol']:g} of the best fitness found){' QUICK' if result['quick'] else ''}"
        f"{f' PRELIMINARY (fewer than {MIN_SEEDS} seeds: no verdict)' if result.get('preliminary') else ''}"
    ]
    for name, p in result["problems"].items():
        lines.append(f"{name}: {p['description']} ({p['model']}, {p['loops']} loops x {p['samples_per_branch']} samples, best {p['best_fitness']:.8g})")
        for m, s in p["methods"].items():
            e, t = s["median_evaluations_to_success"], s["median_s_to_success"]
            lines.append(
                f"  {LABELS.get(m, m):26s} {100 * s['success_rate']:5.1f} % [{100 * s['wilson95'][0]:.0f}-{100 * s['wilson95'][1]:.0f}]"
                f"  to success: {'-' if e is None else f'{e:,.0f} evaluations, {t:.2f} s'}"
                f"  median fitness/best - 1: {s['fitness_over_best_quantiles']['50']:.2g} (worst {s['fitness_over_best_quantiles']['100']:.2g})"
            )
        if p.get("fit_seed_spread") is not None:
            lines.append(f"  fit's seeds agree within {100 * p['fit_seed_spread']:.3g} % of the fitness")
    for peer, why in result["skipped"].items():
        lines.append(f"{peer}: skipped: {why}")
    if "judgement" in result:
        j = result["judgement"]
        lines.append(f"hardest half (lowest best-peer success rate): {', '.join(j['hardest'])}")
        lines.append(
            f"{LABELS[j['campaign']]} non-inferior to every peer on every problem (paired 95 % interval above -{100 * j['margin']:.0f} points): "
            f"{j['non_inferior']}; ahead of every peer on the hardest half: {j['ahead_on_hardest']} -> {'OK' if j['ok'] else 'MISSED'}"
        )
    if "fit_seeds_agree" in result:
        lines.append(f"fit's independent seeds agree within 1 % on every problem: {result['fit_seeds_agree']}")
    s = result["speedup"]
    seconds = lambda runs: ", ".join(f"{r['s']:.1f}" for r in runs)
    lines.append(
        f"speedup ({s['problem']}, {s['budget']:,} evaluations, {s.get('repeats', 1)} pairs in turn): 1 island {seconds(s['one_island'])} s, "
        f"2 islands {seconds(s['two_islands'])} s -> {s['ratio']:.2f} per evaluation, of the medians (target >= {s['target']}) {'OK' if s['ok'] else 'MISSED'}"
    )
    t = result["fit_time"]
    for name, c in t["cases"].items():
        lines.append(
            f"fit with the defaults, {name} ({c['model']}, {c['loops']} loops x {c['samples_per_branch']} samples): {c['s']:.1f} s, "
            f"{c['evaluations']:,} evaluations, RMS {c['rms_pct']:.3g} %"
        )
    lines.append(f"every memory-model fit under {t['limit_s']:.0f} s: {'OK' if t['ok'] else 'MISSED'}")
    lines.append(f"bench time {result['bench_s']:.0f} s")
    return "\n".join(lines)
