"""Campaigns: GA and PSO islands that share their best partial solutions (section 6.1, item 3).

    result = hysid.campaign(loops, "thesis", islands=4)                    # island processes over Zenoh on loopback
    result = hysid.campaign(loops, "thesis", islands=4, single_node=True)  # island threads, migrating in memory

The coordinator (:mod:`coordinator.state`) serves the loop set, records every
island's history in SQLite and stops by its rules (:mod:`coordinator.loop`); :class:`CampaignResult` is
the ``hysid fit`` result of its islands (the global best polished) plus the
islands, migrations and membership events.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from coordinator.interrupt import INTERRUPTED
from coordinator.keys import CampaignKeys
from coordinator.launch import island_specs, run_campaign
from coordinator.outcome import CampaignOutcome, polished
from coordinator.progress import CampaignProgress
from coordinator.state import Coordinator
from coordinator.store import Store
from hysid.fit_result import FitResult
from hysid.motion import MotionChoice, choose_motion, confirm_motion, order_evidence, refit_under_other_reading
from hysid.report import campaign_text, jsondoc, markdown, tables
from hysid_model import notices
from hysid_model.errors import HysidInputError
from hysid_model.harmonics import Harmonics
from hysid_model.loops import LoopSet
from hysid_model.model import Model, build_model
from hysid_model.objective import Objective
from hysid_model.problem import prepare_model
from hysid_model.user_terms import check_importable
from island.config import CampaignConfig, decode_config
from island.memetic import BUDGET, ISLAND_OPTIONS, memetic_search, needs_islands, search_limits
from island.migration import Migration
from island.run import RunResult
from island.secret import secret_path
from island.termination import Termination
from island.wire import MessageRejected, check_name


@dataclass
class CampaignResult:
    """A campaign's :class:`~hysid.fit_result.FitResult` (same report as ``hysid fit``) plus its islands and migrations."""

    fit: FitResult
    islands: list[dict[str, Any]]
    migrations: dict[str, Any]
    members: list[dict[str, Any]]
    stored: dict[str, Any]
    """What the coordinator stored: history rows, rows thinned over capacity (every improvement kept), and the
    migrant messages a newer one superseded before it handled them."""

    @classmethod
    def from_outcome(cls, outcome: CampaignOutcome, *, profiles: bool = True) -> CampaignResult:
        """The result of a campaign's outcome (``profiles``: as :meth:`FitResult.from_runs`)."""
        return cls(
            FitResult.from_runs(outcome.objective, outcome.runs, outcome.settings, profiles=profiles),
            islands=outcome.islands,
            migrations=outcome.migrations,
            members=outcome.members,
            stored=outcome.stored,
        )

    @classmethod
    def from_database(cls, db: str | Path, name: str | None = None) -> CampaignResult:
        """The result of a stored campaign, finished or interrupted, rebuilt from its database alone.

        The database (``db``) is only read: its campaign ``name`` (default: the
        latest) is taken up in an in-memory copy, which re-evaluates every
        island's best and polishes the global best as the campaign did. The loop
        set and the settings come from the stored configuration message.
        """
        store = Store.snapshot(db)
        try:
            name = store.pick_campaign(name)
            dataset, message, _ = store.campaign(name)
            (status, reason), stored, gone = store.state(name), store.result(name), store.gone_since(name)
            try:
                config, loops = decode_config(message, name)
            except MessageRejected as exc:
                raise HysidInputError(f"{db}: campaign {name!r} has an unreadable configuration ({exc})") from None
            settings = (stored or {}).get("settings", {})
            termination = Termination(**settings["stop_rules"]) if "stop_rules" in settings else None
            # nothing is signed or sent: keys of its own, the campaign's stay in their file (the database holds none)
            coordinator = Coordinator(store, config, loops, termination, dataset=dataset, resume=True, keys=CampaignKeys.create(name))
            coordinator.stop_reason = (
                reason
                if status in ("stopped", "interrupted") and reason
                else (f"not finished: the database was left while the campaign was {status}" + (f" ({reason})" if reason else ""))
            )
            result = cls.from_outcome(confirmed(coordinator, coordinator.outcome(polish_best=bool(settings.get("polish", True)))))
        finally:
            store.close()
        if gone is not None:  # the islands it saw alive: nobody knows since
            for island in result.islands:
                island["status"] = "unknown" if island["status"] == "alive" else island["status"]
        return result

    @property
    def params(self) -> dict[str, float]:
        return self.fit.params

    @property
    def stderr(self) -> dict[str, float]:
        return self.fit.stderr

    @property
    def raised(self) -> list[dict[str, str]]:
        """The warnings raised while the campaign ran (its fit's; those of loading the data travel with its loops,
        also into its database, so :meth:`from_database` keeps them)."""
        return self.fit.raised

    @raised.setter
    def raised(self, found: list[dict[str, str]]) -> None:
        self.fit.raised = found

    @property
    def warnings(self) -> list[dict[str, str]]:
        """Every warning about the campaign's result, each ``{"code", "message"}`` (:attr:`FitResult.warnings`)."""
        return self.fit.warnings

    def to_dict(self) -> dict[str, Any]:
        """The ``hysid fit --json`` document plus ``islands``, ``migrations``, membership ``members`` and what was ``stored``."""
        return {**self.fit.to_dict(), "islands": self.islands, "migrations": self.migrations, "members": self.members, "stored": self.stored}

    def tables(self) -> dict[str, list[dict[str, Any]]]:
        """The fit's tables (``parameters``, ``amplitudes``) plus ``islands`` (one row per island run; ``algorithms``:
        what it searched with, in order, ``ga -> pso`` where the share moved it)."""
        return {**self.fit.tables(), "islands": [{**i, "algorithms": " -> ".join(i.get("algorithms") or [i["algo"]])} for i in self.islands]}

    def to_csv(self, out_dir: str | Path) -> dict[str, Path]:
        """Each table of :meth:`tables` as ``<name>.csv`` in ``out_dir`` (a header line, SI units in the column names)."""
        return tables.write_tables(self.tables(), out_dir)

    def to_dataframes(self) -> dict[str, Any]:
        """Each table of :meth:`tables` as a pandas DataFrame (needs pandas, an optional dependency)."""
        return tables.data_frames(self.tables())

    def summary(self) -> str:
        """The fit summary, why the campaign stopped, its migrations and every island."""
        return campaign_text.campaign_summary(self.fit.record(), self.migrations, self.stored, self.islands)

    @property
    def interrupted(self) -> bool:
        """Whether the user stopped the campaign (Ctrl-C), or a database fault or a coordinator gone ended it, not one of its rules."""
        return str(self.fit.settings.get("stop_reason")).startswith(INTERRUPTED)

    def write_report(self, out_dir: str | Path, *, figures: bool = True) -> Path:
        """The ``hysid fit`` report of the campaign; its ``result.json`` holds the campaign document. ``figures=False``
        leaves the figures out, the seconds of drawing them (a campaign stopped by Ctrl-C reports so; a coordinator on a
        server may too), and the report says why; ``hysid report DB`` draws them from the database."""
        db = self.fit.settings.get("db")
        why = "the campaign was interrupted" if self.interrupted else "the report was asked for without figures"
        left_out = None if figures else why + (f" (`hysid report {db}` draws them)" if db and db != ":memory:" else "")
        document, out_dir = self.to_dict(), Path(out_dir)
        self.fit.report = str(out_dir / markdown.REPORT)
        return markdown.write_fit_report(
            self.fit.record(),
            out_dir,
            {**document, "report": self.fit.report},
            None if left_out else self.fit.curves(),
            title=f"hysid campaign{' (interrupted)' if self.interrupted else ''}",
            sections=markdown.campaign_sections(self.migrations, self.fit.settings, self.islands),
            figures_left_out=left_out,
        )

    def _repr_markdown_(self) -> str:
        return markdown.fit_overview(self.fit.record())

    def __repr__(self) -> str:
        return (
            f"<CampaignResult {self.fit.settings.get('campaign')!r}, {self.fit.model.spec} on {self.fit.loops.name}: "
            f"{len(self.islands)} island run(s), fitness {self.fit.fitness:.6g}, {self.fit.settings.get('stop_reason')}>"
        )


def finish(coordinator: Coordinator, outcome: CampaignOutcome, motion: MotionChoice | None = None) -> CampaignResult:
    """The result of a stopped campaign (its displacement reading :func:`confirmed`; after Ctrl-C without a search
    under the other reading, nor the objective's profiles for the errors: the user waits), also kept in its database.
    ``motion``: the choice the campaign started with (None: rebuilt from its configuration)."""
    interrupted = outcome.settings.get("stop_reason") == INTERRUPTED
    result = CampaignResult.from_outcome(confirmed(coordinator, outcome, motion, search=not interrupted), profiles=not interrupted)
    coordinator.store.set_result(coordinator.name, jsondoc.dumps(result.to_dict()))
    return result


MOTION_REASONS = {
    "data": "chosen by the data when the campaign started",
    "user": "as the campaign was configured",
    "none": "the displacement has no harmonics beyond its fundamental",
}
"""The reason a displacement choice rebuilt from a stored configuration gives, by who made it."""


def stored_evidence(loops: LoopSet, config: CampaignConfig) -> list[dict[str, float]]:
    """The order-by-order evidence of a reading the data chose (:func:`hysid.motion.order_evidence`); none
    for any other, or for loops too coarse for harmonics up to order 7 (a stored campaign stays readable)."""
    if config.displacement_by != "data" or loops.x_harmonics is None:
        return []
    try:
        return order_evidence(Harmonics.from_loops(loops))
    except HysidInputError:
        return []


def confirmed(coordinator: Coordinator, outcome: CampaignOutcome, motion: MotionChoice | None = None, *, search: bool = True) -> CampaignOutcome:
    """``outcome`` under the displacement reading its fitted model prefers, by ``hysid fit``'s rule: where the
    data chose the reading (:func:`hysid.motion.choose_motion`, with the linear start) and the polished best
    reads the loops the other way (:func:`hysid.motion.refit_under_other_reading`), the best is searched again
    under that reading from the islands' best (memetic islands on a model with memory, as ``fit``, within the
    campaign's own budget: its evaluations and time limit, :func:`island.memetic.search_limits`; then polished
    and widened as the campaign's best is) and every island run's best is re-evaluated under it; the islands'
    own records stay as they searched. ``settings['displacement_model']`` says which reading and why.
    Without ``search`` the reading stays, its reason saying that the model prefers the other one."""
    config = coordinator.config
    if motion is None:
        motion = MotionChoice(
            config.displacement, config.displacement_by, MOTION_REASONS[config.displacement_by], orders=stored_evidence(coordinator.loops, config)
        )
    outcome.settings["displacement_model"] = motion.as_dict()
    if not outcome.settings.get("polish") or motion.decided_by != "data":
        return outcome
    best = min(outcome.runs, key=lambda r: r.fitness)
    if not search:
        flipped = confirm_motion(coordinator.loops, outcome.objective.model, best.theta, motion)
        if flipped is not None:
            motion.reason += f"; the fitted model reads it as {flipped.displacement}, not searched again (interrupted: hysid report does)"
            outcome.settings["displacement_model"] = motion.as_dict()
        return outcome

    def under(reading: str) -> Objective:
        built = replace(config, objective_kind="closed_form", displacement=reading).objective(coordinator.loops)
        assert isinstance(built, Objective)  # the closed form, as asked
        return built

    def refit(objective: Objective, start: np.ndarray) -> tuple[Objective, RunResult, list[dict[str, Any]]]:
        label = f"refit under the {objective.loops.motion} reading"
        if needs_islands(objective.model):
            budget, seconds = search_limits(coordinator.termination, None)
            found = memetic_search(objective, [start], config.seed, budget=budget, time_limit_s=seconds, label=label)
        else:
            f = float(objective(start[None, :])[0])
            found = RunResult.unpolished(label, "polish", config.seed, start, f, 1, [])
        return polished(objective, found, config.seed)

    again = refit_under_other_reading(coordinator.loops, outcome.objective.model, best.theta, motion, under, refit)
    if again is None:
        return outcome
    flipped, (objective, found, widened) = again
    runs = [replace(r, fitness=float(objective(r.theta[None, :])[0])) for r in outcome.runs]
    flipped.reason += f"; the islands searched under the {motion.displacement} reading, the result is searched again under this one from their best"
    settings = {
        **outcome.settings,
        "displacement": flipped.displacement,
        "displacement_model": flipped.as_dict(),
        "bounds_widened": list(outcome.settings.get("bounds_widened", [])) + widened,
    }
    return replace(outcome, objective=objective, runs=runs + [found], settings=settings)


def islands_until_stopped(termination: Termination | None, options: Mapping[str, Mapping[str, Any]] | None) -> bool:
    """Whether islands search until the stop order by default: the budget is in evaluations or time
    (:attr:`Termination.bounded`) and nobody gave an iteration budget."""
    given = any("iterations" in opts for opts in (options or {}).values())
    return termination is not None and termination.bounded and not given


def default_options(
    loops: LoopSet, model: str | Model, bounds: Mapping[str, tuple[float, float]] | None = None, algos: list[str] | tuple[str, ...] = ("ga", "pso")
) -> dict[str, dict[str, Any]] | None:
    """The islands' settings when none are given: on a model with memory (whose islands refine their best,
    :mod:`island.node`) the small swarms of memetic islands (:data:`island.memetic.ISLAND_OPTIONS`, the PSO
    moving as one swarm), else None (the thesis' settings; a campaign on a memoryless model, Coulomb
    friction's included, searches as before)."""
    if not prepare_model(loops, model, bounds=bounds).has_memory:
        return None
    return {a: {**ISLAND_OPTIONS, **({"synchronous": True} if a == "pso" else {})} for a in algos}


def island_settings(
    loops: LoopSet,
    model: str | Model,
    bounds: Mapping[str, tuple[float, float]] | None,
    algos: list[str] | tuple[str, ...],
    options: dict[str, dict[str, Any]] | None,
    termination: Termination | None,
    until_stopped: bool | None,
) -> tuple[dict[str, dict[str, Any]] | None, Termination | None, bool]:
    """The islands' settings, stop rules and ``until_stopped`` of a campaign, one rule for Python and the
    command line: what is given, else the defaults. With no ``options`` on a model with memory, memetic
    islands (:func:`default_options`) that search until the stop order, within :data:`island.memetic.BUDGET`
    evaluations unless an evaluation budget or a time limit is given."""
    if options is None and (options := default_options(loops, model, bounds, algos)) is not None and not (termination and termination.bounded):
        termination = replace(termination or Termination(), budget=BUDGET)
    return options, termination, islands_until_stopped(termination, options) if until_stopped is None else until_stopped


@notices.keeps_warnings
def campaign(
    loops: LoopSet,
    model: str | Model = "thesis",
    *,
    islands: int = 4,
    name: str = "campaign",
    bounds: Mapping[str, tuple[float, float]] | None = None,
    fixed: Mapping[str, float] | None = None,
    weights: str | None = None,
    displacement: str = "auto",
    algos: list[str] | tuple[str, ...] = ("ga", "pso"),
    options: dict[str, dict[str, Any]] | None = None,
    migration: Migration | None = None,
    seed: int = 0,
    termination: Termination | None = None,
    single_node: bool = False,
    db: str | Path = ":memory:",
    dataset: str = "",
    polish: bool = True,
    progress: Callable[[CampaignProgress], None] | None = None,
    until_stopped: bool | None = None,
    share: str = "staged",
) -> CampaignResult:
    """Run ``islands`` GA/PSO islands on ``loops`` to a stop rule and report the polished global best of ``model``.

    ``model`` is a string (``"thesis+coulomb_friction"``, ``"baseline+myterms:drag"``) or a
    :class:`~hysid_model.model.Model`, as for :func:`hysid.fit`; every other argument is a keyword.
    Islands are processes connected over Zenoh on loopback (threads of this
    process with ``single_node``, or when Zenoh cannot open a session here, with
    a warning); island i runs ``algos[i % len(algos)]`` with seed ``seed + i``.
    ``options[algo]`` are each algorithm's settings (``population``,
    ``initial_population``, ``iterations``, ...), ``migration`` how islands share
    their best, ``termination`` the coordinator's stop rules. The campaign is
    recorded in the SQLite file ``db`` (in memory by default).

    ``until_stopped``: every island searches (and migrates) until the coordinator's
    stop order, its ``iterations`` off, so that no island leaves early (which
    algorithm each island runs meanwhile is the ``share``'s). By default (None) that holds when ``termination`` has an
    evaluation budget or a time limit and no ``options`` give ``iterations``.

    On a model with memory (Bouc-Wen) the islands are memetic by default: small swarms (:func:`default_options`) whose best each island refines by least
    squares (:mod:`island.node`), within a budget of :data:`island.memetic.BUDGET` evaluations unless
    ``termination`` says otherwise.

    ``share``: with several ``algos``, ``staged`` (default) moves the GA islands to
    the PSO once they have searched one migration interval, ``adaptive`` moves islands to the
    algorithm whose own moves gain more (:mod:`island.share`; the moves are in
    ``result.fit.settings["moves"]``), ``fixed`` keeps every island's algorithm.
    """
    if isinstance(model, int) and not isinstance(model, bool):  # the island count where the model goes (its place before)
        raise HysidInputError(
            "a model is a string such as 'thesis+coulomb_friction' or a hysid Model; "
            f"the number of islands is a keyword: campaign(loops, model, islands={model})",
            param="model",
            value=model,
        )
    check_name("name", name)
    specs = island_specs(islands, list(algos), seed)
    motion = choose_motion(loops, model, displacement, bounds=bounds, fixed=fixed)
    options, termination, until_stopped = island_settings(loops, model, bounds, algos, options, termination, until_stopped)
    config = CampaignConfig.create(
        loops,
        name=name,
        model=model,
        weights=weights,
        bounds=bounds,
        fixed=fixed,
        algos=list(algos),
        options=options,
        migration=migration,
        seed=seed,
        min_islands=islands,
        displacement=motion.displacement,
        displacement_by=motion.decided_by,
        until_stopped=until_stopped,
        share=share,
    )
    if not single_node:
        check_importable(build_model(config.model).terms)
    store = Store(db)
    try:
        coordinator = Coordinator(store, config, loops, termination, dataset=dataset or loops.name)
        if str(db) != ":memory:":
            coordinator.secret.write(secret_path(db, name))
        began = time.perf_counter()
        result = finish(coordinator, run_campaign(coordinator, specs, single_node=single_node, on_progress=progress, polish=polish), motion)
        result.fit.settings["wall_s"] = time.perf_counter() - began
        return result
    finally:
        store.close()
