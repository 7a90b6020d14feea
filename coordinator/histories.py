"""What the coordinator checks of an island run's history messages, and the gaps in its stored rows.

* :class:`HistoryChecks`: a history whose counters the island cannot have
  reached (more evaluations than its algorithms, its iterations and the
  migrants it may take allow; an iteration beyond its budget; more migrants
  sent or taken than its epochs allow; more evaluations, or iterations of its
  population, than the time since it joined allows at :data:`SPEEDUP` times
  the rate the coordinator measures for its algorithm here), or that runs an
  algorithm or seed it was never given, is rejected as ``implausible``; a wall
  time longer than the run has existed is ``out_of_range``; so a claimed best
  below what the coordinator's re-evaluation of its vector gives is
  ``implausible`` (:func:`check_claim`). Budgets and the stall rule count only
  what passed: effort an island could really have spent;
* :class:`Gaps`: per island run, the iterations handled (stored, or thinned
  over capacity); rows missing below the last one handled (sent while this
  coordinator was down) are asked for again, a bounded number of times.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Collection, Sized

import numpy as np

from coordinator.records import Span, merged
from coordinator.store import Store
from hysid_model.objective import Objective
from hysid_model.thesis_port import ThesisObjective
from island.algorithms import make_optimizer
from island.config import CampaignConfig
from island.island_messages import History
from island.population import MAX_ITERATIONS, PopulationOptimizer
from island.run import run
from island.wire import MessageRejected

FITNESS_TOLERANCE = 1e-6
"""Relative slack when a claimed best fitness is compared with the coordinator's re-evaluation."""
SPEEDUP = 16.0
"""How many times faster than the coordinator's own measurement (:meth:`HistoryChecks.rate`) an island
may evaluate: a faster or less loaded host, a measurement taken while this one was busy. An island claiming
more effort than that, for the time since it joined, is lying (an honest one on a like host spends about
1/SPEEDUP of it, loaded ones less)."""
MEASURE_S = 0.3
"""How long the coordinator runs an island's algorithm here to measure its rate (in a thread of its own, from the
join of the first run of it; again, at most every :data:`REMEASURE_S`, when a claim is refused)."""
REMEASURE_S = 30.0
WALL_SLACK_S = 5.0
"""A run's wall time may exceed the time since the coordinator admitted it by this much (its clock
starts after the join)."""
BACKFILL_EVERY_S = 2.0
BACKFILL_ATTEMPTS = 5
"""How often, and how many times without progress, to ask an island again for history rows still missing."""


class HistoryChecks:
    """The counters an island run of one campaign can have reached.

    ``runs``: the runs that joined (the coordinator's, growing as islands
    join); each other one may send migrants. ``objective``: the campaign's,
    with which the rate of each algorithm is measured here.
    """

    def __init__(
        self, config: CampaignConfig, objective: Objective | ThesisObjective, runs: Sized, fresh: Callable[[], Objective | ThesisObjective] | None = None
    ) -> None:
        """``fresh()``: another instance of ``objective`` (a measurement runs beside the run loop, and an objective
        keeps caches of its own); default: ``objective`` itself."""
        self.config = config
        self.objective = objective
        self.fresh = fresh or (lambda: objective)
        self.bounds = objective.bounds
        self.runs = runs
        self._optimizers: dict[str, PopulationOptimizer] = {}
        self._rates: dict[str, float] = {}
        self._measured_at: dict[str, float] = {}
        self._measuring: dict[str, threading.Thread] = {}
        """The measurement of each algorithm's rate under way, in a thread of its own (the run loop never waits for
        one but the first of an algorithm, which starts when a run of it joins: long before its first history)."""
        self._lock = threading.Lock()

    def optimizer(self, algo: str) -> PopulationOptimizer:
        """An (unused) optimizer with an island's settings: what its evaluation counts may be."""
        if algo not in self._optimizers:
            self._optimizers[algo] = make_optimizer(algo, self.bounds, 0, self.config.island_options(algo))
        return self._optimizers[algo]

    def expect(self, algos: Collection[str]) -> None:
        """Runs of ``algos`` may report: start measuring the rate of each not measured yet."""
        for algo in algos:
            if algo not in self._measuring:
                self.measure(algo)

    def measure(self, algo: str) -> None:
        """Start measuring the rate of ``algo`` (:meth:`rate`) in a thread of its own, unless that is under way."""
        with self._lock:
            if algo in self._measuring and self._measuring[algo].is_alive():
                return
            thread = threading.Thread(target=self._measure, args=(algo,), name=f"rate-{algo}", daemon=True)
            self._measuring[algo] = thread
            self._measured_at[algo] = time.monotonic()
        thread.start()

    def _measure(self, algo: str) -> None:
        """Evaluations per second an island of ``algo`` reaches here: its optimizer with the campaign's settings (its
        initial population cut to one population) run on (another instance of) the campaign's objective for
        :data:`MEASURE_S`, per second of this thread's CPU time (a machine busy with other work does not lower it);
        the higher of this and any earlier measurement is kept."""
        options = self.config.island_options(algo)
        probe = self.optimizer(algo)
        optimizer = make_optimizer(algo, self.bounds, 0, {**options, "initial_population": probe.population, "iterations": MAX_ITERATIONS})
        objective = self.fresh()  # the run loop evaluates with its own meanwhile
        start, cpu = time.perf_counter(), time.thread_time()
        run(optimizer, objective, should_stop=lambda: time.perf_counter() - start >= MEASURE_S)
        measured = optimizer.evaluations / max(time.thread_time() - cpu, 1e-3)
        with self._lock:
            self._rates[algo] = max(self._rates.get(algo, 0.0), measured)

    def rate(self, algo: str) -> float:
        """Evaluations per second an island of ``algo`` reaches here (:meth:`_measure`): the latest measurement,
        waiting for the first one if it has not ended (started now if it never was)."""
        with self._lock:
            rate = self._rates.get(algo)
        if rate is None:
            self.measure(algo)
            self._measuring[algo].join()
            with self._lock:
                rate = self._rates.get(algo)
        if rate is None:  # the measurement failed in its thread: once more, here, so that its error shows
            self._measure(algo)
            rate = self._rates[algo]
        return rate

    def _remeasured(self, algos: Collection[str]) -> None:
        """Measure the rates of ``algos`` again, in the background, at most every :data:`REMEASURE_S` (a claim beyond
        the bound is refused meanwhile; its rows are asked for again once a later message shows the gap)."""
        for algo in algos:
            if time.monotonic() - self._measured_at.get(algo, -np.inf) >= REMEASURE_S:
                self.measure(algo)

    def effort_bound(self, algos: Collection[str], seconds: float) -> tuple[float, float]:
        """The most evaluations and iterations a run of ``algos`` can claim ``seconds`` after it joined:
        its initial population (every redraw counted), then :data:`SPEEDUP` times the rate measured here,
        plus the migrants it may take; the iterations of its smallest population at that."""
        evaluations = max(float(self.evaluation_bound(a, np.array([0.0]))[0]) + SPEEDUP * self.rate(a) * max(seconds, 0.0) for a in algos)
        iterations = evaluations / min(self.optimizer(a).population for a in algos)
        mig = self.config.migration
        migrants = (iterations // mig.interval if mig.interval else 0) * max(len(self.runs) - 1, 0) * mig.k
        return evaluations + migrants, iterations

    def evaluation_bound(self, algo: str, iterations: np.ndarray) -> np.ndarray:
        """The most evaluations an island run of ``algo`` can report after each of ``iterations``
        (floats): its own batches (:meth:`PopulationOptimizer.evaluation_bound`) plus the migrants it
        may take, ``k`` from each other island that joined per migration, plus the campaign's starting
        point and the global best once each."""
        mig = self.config.migration
        epochs = np.floor_divide(iterations, mig.interval) if mig.interval else np.zeros_like(iterations)
        return self.optimizer(algo).evaluation_bound(iterations) + epochs * max(len(self.runs) - 1, 0) * mig.k + 2

    def plausible(self, h: History, joined: str, seed: int, algos: Collection[str], iteration: int, seconds: float) -> None:
        """:class:`MessageRejected` ("implausible") for counters the island cannot have reached
        (``out_of_range`` for a wall time it cannot have run).

        ``joined`` and ``seed``: what the run joined with; ``algos``: every algorithm it has been told
        to run (:class:`coordinator.sharing.Sharing`); ``iteration``: the furthest one it reported before;
        ``seconds``: since the run joined, by the coordinator's clock.
        """
        if h.algo not in algos or h.seed != seed:
            raise MessageRejected("implausible", f"history of a {h.algo} run with seed {h.seed}; it joined as {joined} with seed {seed}")
        if h.rows.size:
            if h.rows[-1, 3] > seconds + WALL_SLACK_S:
                raise MessageRejected("out_of_range", f"a wall time of {h.rows[-1, 3]:.6g} s; the run joined {seconds:.0f} s ago")
            most_evaluations, most_iterations = self.effort_bound(algos, seconds)
            if h.rows[-1, 2] > most_evaluations or h.rows[-1, 0] > most_iterations:
                self._remeasured(algos)
                raise MessageRejected(
                    "implausible",
                    f"{h.rows[-1, 2]:.0f} evaluations in {h.rows[-1, 0]:.0f} iterations {seconds:.0f} s after it "
                    f"joined; at most {most_evaluations:.0f} in {most_iterations:.0f} possible",
                )
            iterations = h.rows[:, 0]
            budget = max(self.optimizer(a).iterations for a in algos)
            if iterations[-1] > budget:
                raise MessageRejected("implausible", f"iteration {iterations[-1]:.0f} beyond the island's budget of {budget}")
            bound = np.max([self.evaluation_bound(a, iterations) for a in algos], axis=0)
            if np.any(h.rows[:, 2] > bound):
                i = int(np.argmax(h.rows[:, 2] > bound))
                raise MessageRejected("implausible", f"{h.rows[i, 2]:.0f} evaluations after iteration {iterations[i]:.0f}, at most {bound[i]:.0f} possible")
        reached = max(iteration, int(h.rows[-1, 0]) if h.rows.size else 0)
        mig = self.config.migration
        epochs = reached // mig.interval if mig.interval else 0
        most = {"sent": epochs + 1, "received": epochs * max(len(self.runs) - 1, 0) * mig.k + 1}
        if h.stats["sent"] > most["sent"] or h.stats["received"] > most["received"] or h.stats["taken"] > h.stats["received"]:
            raise MessageRejected("implausible", f"migration counters {h.stats} after iteration {reached}")


def check_claim(h: History, f: float) -> None:
    """:class:`MessageRejected` ("implausible") if ``h`` claims a best below ``f``, the coordinator's
    own fitness of its best vector (within :data:`FITNESS_TOLERANCE`)."""
    floor = f * (1 - FITNESS_TOLERANCE)
    if h.best_f < floor or (h.rows.size and np.min(h.rows[:, 1]) < floor):
        raise MessageRejected("implausible", f"claims a best fitness below {f:.6g}, what its best vector really has")


class Gaps:
    """Which iterations of each island run of campaign ``name`` the coordinator handled (stored, or thinned:
    :mod:`coordinator.thinning`), kept in memory as spans (read from the database at a run's first sight)."""

    def __init__(self, store: Store, name: str) -> None:
        self.store = store
        self.name = name
        self.spans: dict[tuple[str, str], list[Span]] = {}
        """Per island run, the iterations handled as disjoint sorted spans (rows beyond a gap are asked for again)."""
        self._asked: dict[tuple[str, str], tuple[float, int, int]] = {}
        """Per island run: when rows were last asked for, from which iteration, how often without progress."""

    def _spans(self, key: tuple[str, str]) -> list[Span]:
        if key not in self.spans:
            self.spans[key] = self.store.handled(self.name, *key)
        return self.spans[key]

    def stored(self, key: tuple[str, str]) -> int:
        """The last iteration ``k`` of island run ``key`` with rows ``0..k`` all handled (-1: not iteration 0)."""
        spans = self._spans(key)
        return spans[0][1] if spans and spans[0][0] == 0 else -1

    def arrived(self, key: tuple[str, str], first: int, last: int, ask: Callable[[str, str, int], None]) -> None:
        """Track the handled iterations of an island run after rows ``first..last`` arrived; while
        some are missing, ``ask(island, run, since)`` the island for them again."""
        self.spans[key] = merged([*self._spans(key), (first, last)])
        done, now = self.stored(key), time.monotonic()
        asked_at, asked_from, attempts = self._asked.get(key, (-np.inf, -2, 0))
        if done < self.spans[key][-1][1] and now - asked_at >= BACKFILL_EVERY_S:
            attempts = attempts + 1 if asked_from == done else 1
            if attempts <= BACKFILL_ATTEMPTS:  # an island that cannot fill the gap is not asked forever
                self._asked[key] = (now, done, attempts)
                ask(key[0], key[1], done)

    def forget(self) -> None:
        """Forget what is known to be handled (after a rollback it is read from the database again)."""
        self.spans.clear()
