"""``hysid bench islands [speedup|migration|mixed|pygmo|latency|all]``: what the island model buys and costs.

Each part is a ratio (or a rate) measured in one run on the Synth set (section 5.2):

* **speedup**: on an expensive objective, time to a target fitness of 1 PSO
  island process with swarm 2p against 2 PSO island processes with p each (same
  total swarm and initial swarm, one-gene additional population, migration
  every 2 iterations over Zenoh); target: ratio >= 1.7. Two objectives: the
  faithful port of the thesis' ``erreval``
  (:class:`hysid_model.thesis_port.ThesisObjective`) and, under ``memory``, a
  model with a memory term, ``thesis+bouc_wen`` (its compiled per-sample
  force, :mod:`hysid_model.sampled`: the objectives real campaigns with memory
  terms run);
* **migration**: at equal total evaluations (a campaign budget), islands that
  migrate (ring) against isolated islands: success rate (search best below a
  fitness threshold, before any polish) over at least 20 seeds; target:
  migration wins;
* **mixed**: at equal total evaluations (a campaign budget; every island
  searches until the coordinator stops), half GA and half PSO islands with
  each share of :mod:`island.share` (staged, the default; adaptive; fixed, so
  that GA and PSO islands overlap for the whole campaign) against GA-only and
  PSO-only ones: success rates over 300 seeds (at least 20; in-process
  islands) with 95 % Wilson intervals, at three budgets and two thresholds
  cut from one campaign each, and each mix against the better of the two
  seed by seed (the difference with its interval, a sign test; which ended
  lower); target: at the middle budget and the upper threshold the default
  mix at least as good as the better of the two (its seed-by-seed
  difference's 95 % interval above -10 points: non-inferiority);
* **pygmo**: hysid's PSO islands over Zenoh against a pygmo archipelago of PSO
  islands (``pygmo.pso`` with constriction and velocity memory, ring topology,
  multiprocessing islands, migration after every 5 generations), same
  objective, same number of islands, population and evaluation budget: time
  to target and final parameter error (:mod:`hysid.bench.pygmo_islands`). pygmo is an optional, bench-only
  dependency (``pip install pygmo``); without it this part says so;
* **latency**: migrant messages through a Zenoh router on loopback (two
  client sessions, as two islands): messages and migrants per second, and the
  one-way latency (median, 99th percentile), also in units of one GA iteration
  (:mod:`hysid.bench.latency`).

The success rates of migration and mixed are compared as :mod:`hysid.bench.rates` does.

Times run from the moment every island is a member (islands start together)
to the coordinator's record of the global best reaching the target. Every part
searches from scratch (``start=False``): the survey's linear estimate alone
reaches the Synth set's optimum, which would leave nothing to measure.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from hysid.bench.island_campaigns import campaign, time_to
from hysid.bench.latency import latency
from hysid.bench.pygmo_islands import versus_pygmo
from hysid.bench.rates import NON_INFERIORITY_MARGIN, ended_lower, paired, wilson
from hysid_model.errors import HysidInputError
from island.migration import Migration
from island.termination import Termination

SPEEDUP_TARGET = 1.7
PARTS = ("speedup", "migration", "mixed", "pygmo", "latency")
MIXES = {
    "ga": (["ga"], "fixed"),
    "pso": (["pso"], "fixed"),
    "mixed_fixed": (["ga", "pso"], "fixed"),
    "mixed_adaptive": (["ga", "pso"], "adaptive"),
    "mixed": (["ga", "pso"], "staged"),
}
"""The campaigns of the mixed part, as (algorithms, share): GA islands only, PSO islands only, and half
and half with each share (``mixed``: the default one, staged)."""
MIX_LABELS = {"mixed": "GA+PSO staged", "mixed_adaptive": "GA+PSO adaptive", "mixed_fixed": "GA+PSO fixed", "ga": "GA only", "pso": "PSO only"}


SPEEDUP_OBJECTIVES = {
    "thesis_port": ("thesis", "thesis_port", "thesis_port (ThesisObjective, loop by loop)", 1e-2),
    "memory": ("thesis+bouc_wen", "closed_form", "thesis+bouc_wen (Bouc-Wen memory term, compiled per-sample force)", 1e-4),
}
"""The objectives of the speedup part: (model, objective kind, description, target fitness). The memory
model's search runs to a lower target: at 1e-2 it is over within a few hundred evaluations."""


def speedup_on(which: str, seeds: int, population: int) -> dict[str, Any]:
    """1 PSO island of swarm 2p vs 2 PSO islands of p on one of :data:`SPEEDUP_OBJECTIVES`."""
    model, kind, description, target = SPEEDUP_OBJECTIVES[which]
    times: dict[int, list[float]] = {1: [], 2: []}
    evaluations: dict[int, list[int]] = {1: [], 2: []}
    per_island: dict[int, list[float]] = {1: [], 2: []}
    """Evaluations per island recorded when the global best reached the target."""
    with tempfile.TemporaryDirectory(prefix="hysid-bench-") as tmp:
        for seed in range(seeds):
            for n in (1, 2):
                p = population // n
                options = {"population": p, "initial_population": 2 * p, "iterations": 100_000, "addpop_level": 1}
                c = campaign(
                    Path(tmp),
                    f"speedup-{which}-{n}-{seed}",
                    "pso",
                    n,
                    options,
                    Migration(interval=2, k=2),
                    Termination(target=target, time_limit_s=900),
                    seed,
                    model=model,
                    objective_kind=kind,
                    start=False,
                )
                t = time_to(c, target)
                if t is None:
                    raise RuntimeError(f"speedup bench ({which}): {n} island(s), seed {seed} did not reach fitness {target:g} ({c.stop_reason})")
                times[n].append(t)
                evaluations[n].append(c.evaluations)
                per_island[n].append(next(e for _, f, e, _ in c.best_trace if f <= target) / n)
    ratio = float(np.median(times[1]) / np.median(times[2]))
    return {
        "objective": description,
        "model": model,
        "algo": "pso",
        "population_total": population,
        "target_fitness": target,
        "seeds": seeds,
        "time_1_island_s": times[1],
        "time_2_islands_s": times[2],
        "evaluations_1_island": evaluations[1],
        "evaluations_2_islands": evaluations[2],
        "work_ratio": float(np.median(per_island[1]) / np.median(per_island[2])),
        "ratio": ratio,
        "ratio_target": SPEEDUP_TARGET,
        "ok": ratio >= SPEEDUP_TARGET,
    }


def speedup(seeds: int = 5, population: int = 40) -> dict[str, Any]:
    """Part (a): 1 PSO island of swarm 2p vs 2 PSO islands of p on the thesis' own objective and on a memory model
    (the latter under ``memory``)."""
    return {**speedup_on("thesis_port", seeds, population), "memory": speedup_on("memory", seeds, population)}


def migration(seeds: int = 20, islands: int = 4, population: int = 20, budget: int = 8_600, threshold: float = 1e-5) -> dict[str, Any]:
    """Part (b): success rate with and without migration at equal total evaluations (in-process islands)."""
    if seeds < 20:
        raise HysidInputError("the success rate needs at least 20 seeds", param="seeds", value=seeds)
    options = {"population": population, "initial_population": 2 * population, "iterations": 100_000}
    finals: dict[str, list[float]] = {"migration": [], "isolated": []}
    with tempfile.TemporaryDirectory(prefix="hysid-bench-") as tmp:
        for seed in range(seeds):
            for label, interval in (("migration", 5), ("isolated", 0)):
                c = campaign(
                    Path(tmp),
                    f"{label}-{seed}",
                    "pso",
                    islands,
                    options,
                    Migration(interval=interval, k=2),
                    Termination(budget=budget),
                    seed,
                    single_node=True,
                    start=False,
                )
                assert c.best is not None
                finals[label].append(c.best.fitness)
    rate = {k: float(np.mean(np.array(v) <= threshold)) for k, v in finals.items()}
    return {
        "algo": "pso",
        "islands": islands,
        "population": population,
        "budget_evaluations": budget,
        "threshold": threshold,
        "seeds": seeds,
        "success_rate": rate,
        "median_final_fitness": {k: float(np.median(v)) for k, v in finals.items()},
        "ok": rate["migration"] > rate["isolated"],
    }


MIXED_MODEL = "thesis+coulomb_friction"
"""The mixed part's model: the thesis model plus a friction force the Synth set does not have (five
parameters, one of them zero at the optimum), searched from scratch: the thesis' GA stays orders of
magnitude behind its PSO there, which is what a fixed half-GA share pays for."""
MIXED_BUDGETS = (10_000, 15_000, 20_000)
MIXED_THRESHOLDS = (1e-5, 1e-6)
MIXED_TARGET = (15_000, 1e-5)
"""Where the target is judged: PSO-only islands succeed there about three times in four, so that a
better or a worse mix can show (at 20,000 evaluations and 1e-5 every PSO-only campaign succeeds)."""
MIXED_SEEDS = 300
"""Seeds of the mixed part: the islands are threads, so the same seed gives another campaign from run to
run, and at 100 seeds that spread alone moved a rate by several points."""


MIXED_FIRST_SEED = 1300
"""The mixed part's seeds start here, on seeds no share policy was ever tried on (they were designed on
0-59, 200-259, 300-359 and 3000-3099; this bench ran on 1000-1099 three times and on 1000-1299 once)."""


def mixed(seeds: int = MIXED_SEEDS, islands: int = 4, population: int = 20) -> dict[str, Any]:
    """Part mixed: GA+PSO islands (each share) against GA-only and PSO-only ones at
    equal total evaluations (a campaign budget; every island searches until the coordinator stops) on
    :data:`MIXED_MODEL`: success rates (the global best the coordinator knew when the islands had
    reported at most ``budget`` evaluations, before any polish, below a threshold) at each of
    :data:`MIXED_BUDGETS` and :data:`MIXED_THRESHOLDS`, cut from one campaign per seed and mix of the
    largest budget; target at :data:`MIXED_TARGET`: the default (staged) mix at least as good as the better
    of GA-only and PSO-only, seed by seed within :data:`NON_INFERIORITY_MARGIN`; the final fitness there is
    compared seed by seed too. ``evaluations_at_stop`` is what the islands had spent when they heard
    the stop order (it overshoots the largest budget a little)."""
    if seeds < 20:
        raise HysidInputError("the success rate needs at least 20 seeds", param="seeds", value=seeds)
    options = {"population": population, "initial_population": 2 * population}
    finals: dict[str, dict[int, list[float]]] = {k: {b: [] for b in MIXED_BUDGETS} for k in MIXES}
    spent: dict[str, list[int]] = {k: [] for k in MIXES}
    moves: dict[str, dict[str, int]] = {k: {} for k, (algos, share) in MIXES.items() if len(algos) > 1 and share != "fixed"}
    with tempfile.TemporaryDirectory(prefix="hysid-bench-") as tmp:
        for seed in range(MIXED_FIRST_SEED, MIXED_FIRST_SEED + seeds):
            for label, (algos, share) in MIXES.items():
                c = campaign(
                    Path(tmp),
                    f"mixed-{label}-{seed}",
                    algos,
                    islands,
                    options,
                    Migration(interval=5, k=2),
                    Termination(budget=max(MIXED_BUDGETS)),
                    seed,
                    single_node=True,
                    start=False,
                    model=MIXED_MODEL,
                    share=share,
                )
                for budget in MIXED_BUDGETS:
                    within = [f for _, f, evaluations, _ in c.best_trace if evaluations <= budget]  # the stop overshoots: cut at the budget
                    finals[label][budget].append(within[-1] if within else np.inf)
                spent[label].append(c.evaluations)
                for m in c.sharing.moves:
                    moves[label][f"{m.src}->{m.dst}"] = moves[label].get(f"{m.src}->{m.dst}", 0) + 1
    rates: dict[str, dict[str, Any]] = {}
    for label in MIXES:
        rates[label] = {}
        for budget in MIXED_BUDGETS:
            f = np.array(finals[label][budget])
            for threshold in MIXED_THRESHOLDS:
                k = int(np.sum(f <= threshold))
                rates[label][f"{budget}@{threshold:g}"] = {"rate": k / seeds, "wilson95": wilson(k, seeds)}
            rates[label][f"{budget}@median"] = float(np.median(f))
    at = f"{MIXED_TARGET[0]}@{MIXED_TARGET[1]:g}"
    rate = {k: rates[k][at]["rate"] for k in MIXES}
    better = max(("ga", "pso"), key=lambda k: rate[k])
    final = {k: np.array(finals[k][MIXED_TARGET[0]]) for k in MIXES}
    success = {k: final[k] <= MIXED_TARGET[1] for k in MIXES}
    mixes = [k for k, (algos, _) in MIXES.items() if len(algos) > 1]
    versus = {k: paired(success[k], success[better]) for k in mixes}
    return {
        "model": MIXED_MODEL,
        "islands": islands,
        "population": population,
        "seeds": seeds,
        "first_seed": MIXED_FIRST_SEED,
        "budget_evaluations": MIXED_TARGET[0],
        "threshold": MIXED_TARGET[1],
        "mixes": {k: "+".join(a) + f" ({s} share)" for k, (a, s) in MIXES.items()},
        "success_rate": rate,
        "grid": rates,
        "better_single": better,
        "paired": versus,
        "ended_lower": {k: ended_lower(final[k], final[better]) for k in mixes},
        "margin": NON_INFERIORITY_MARGIN,
        "moves": moves,
        "mean_evaluations_at_stop": {k: float(np.mean(v)) for k, v in spent.items()},
        "ok": versus["mixed"]["difference95"][0] >= -NON_INFERIORITY_MARGIN,
    }


def run(parts: list[str] | tuple[str, ...] = PARTS) -> dict[str, Any]:
    """Island model: 2-island speedup, migration vs isolation, hysid vs pygmo, migration latency."""
    unknown = [p for p in parts if p not in PARTS]
    if unknown:
        raise HysidInputError(f"choose one of {', '.join(PARTS)} or all", param="part", value=unknown[0])
    functions: dict[str, Callable[[], dict[str, Any]]] = {"speedup": speedup, "migration": migration, "mixed": mixed, "pygmo": versus_pygmo, "latency": latency}
    out: dict[str, Any] = {}
    for part in parts:
        start = time.perf_counter()
        out[part] = {**functions[part](), "bench_s": time.perf_counter() - start}
    return out


def success_line(head: str, r: dict[str, Any], labels: dict[str, str]) -> str:
    """A success-rate part as one line: ``head``, budget, threshold, seeds, then each rate by its label."""
    rates = ", ".join(f"{label} {100 * r['success_rate'][key]:.0f} %" for key, label in labels.items())
    return (
        f"{head}, {r['budget_evaluations']:,} evaluations, success = fitness <= {r['threshold']:g}, {r['seeds']} seeds): "
        f"{rates} {'OK' if r['ok'] else 'MISSED'}"
    )


def to_text(result: dict[str, Any]) -> str:
    lines = []
    if "speedup" in result:
        for label, r in (("thesis erreval", result["speedup"]), (result["speedup"]["memory"]["model"], result["speedup"]["memory"])):
            lines.append(
                f"speedup ({label} objective, PSO, swarm {r['population_total']} in total, target {r['target_fitness']:g}): "
                f"1 island {np.median(r['time_1_island_s']):.1f} s, 2 islands {np.median(r['time_2_islands_s']):.1f} s (medians of {r['seeds']}) "
                f"-> ratio {r['ratio']:.2f} (target >= {r['ratio_target']}) {'OK' if r['ok'] else 'MISSED'}; "
                f"evaluations per island to target: ratio {r['work_ratio']:.2f} (what the time ratio tends to on two idle cores)"
            )
    if "migration" in result:
        r = result["migration"]
        lines.append(success_line(f"migration ({r['islands']} PSO islands", r, {"migration": "with migration", "isolated": "isolated"}))
    if "mixed" in result:
        r = result["mixed"]
        lines.append(
            success_line(f"mixed ({r['model']}, {r['islands']} islands", r, MIX_LABELS)
            + f" (the staged mix at least as good as the better one: its paired 95 % interval above -{100 * r['margin']:.0f} points)"
        )
        for key in r["grid"]["mixed"]:
            if not key.endswith("@median"):
                lines.append(
                    f"  {key.replace('@', ' evaluations, <= ')}: "
                    + ", ".join(
                        f"{label} {100 * r['grid'][k][key]['rate']:.0f} % [{100 * r['grid'][k][key]['wilson95'][0]:.0f}-{100 * r['grid'][k][key]['wilson95'][1]:.0f}]"
                        for k, label in MIX_LABELS.items()
                    )
                )
        lines.append(
            f"  paired at the target, seed by seed, against {MIX_LABELS[r['better_single']]}: "
            + "; ".join(
                f"{MIX_LABELS[k]} {100 * p['difference']:+.0f} points [{100 * p['difference95'][0]:+.0f}, {100 * p['difference95'][1]:+.0f}] "
                f"(only it {p['only_a']} seeds, only {MIX_LABELS[r['better_single']]} {p['only_b']}, sign test p {p['sign_test_p']:.2g})"
                for k, p in r["paired"].items()
            )
        )
        lines.append(
            f"  final fitness at {r['budget_evaluations']:,} evaluations, seed by seed, against {MIX_LABELS[r['better_single']]}: "
            + "; ".join(
                f"{MIX_LABELS[k]} lower in {e['lower']}, higher in {e['higher']} (Wilcoxon p {e['wilcoxon_p']:.2g})" for k, e in r["ended_lower"].items()
            )
        )
        lines.append("  moves: " + "; ".join(f"{MIX_LABELS[k]} {v or 'none'}" for k, v in r["moves"].items()))
    if "pygmo" in result:
        r = result["pygmo"]
        if "skipped" in r:
            lines.append(f"pygmo: skipped: {r['skipped']}")
        else:
            for k, s in r["summary"].items():
                t = s["median_time_to_target_s"]
                lines.append(
                    f"{k:>6}: reached {r['target_fitness']:g} in {s['reached_target']}/{r['seeds']} runs, median time "
                    f"{'n/a' if t is None else f'{t:.2f} s'}, median parameter error {s['median_parameter_error']:.2e}"
                )
            ratio = r["time_ratio_pygmo_over_hysid"]
            lines.append(f"pygmo / hysid time to target: {'n/a' if ratio is None else f'{ratio:.2f}'}")
    if "latency" in result:
        r = result["latency"]
        lines.append(
            f"latency: {r['messages_per_s']:,.0f} messages/s ({r['migrants_per_s']:,.0f} migrants/s), one-way median "
            f"{r['latency_median_ms']:.2f} ms, p99 {r['latency_p99_ms']:.2f} ms = {r['latency_in_ga_iterations']:.2f} thesis GA iterations"
        )
    return "\n".join(lines)
