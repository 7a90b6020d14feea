"""A campaign's configuration: everything an island needs besides the loops.

The coordinator serves it with the loop set in the ``config`` message
(:mod:`island.protocol`); every island builds the same objective from it
(:func:`hysid_model.problem.build_objective`): the model string, the loop
weights, the bounds of every free parameter and the fixed values (the known
mass), so coordinator and islands search the same space.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.loops import LoopSet
from hysid_model.model import Model
from hysid_model.objective import WEIGHTS, Objective
from hysid_model.problem import DISPLACEMENTS, OBJECTIVES, build_objective, displaced, prepare_model, resolve_weights, starting_point
from hysid_model.thesis_port import ThesisObjective
from island.algorithms import ALGORITHMS, check_algorithm, make_optimizer
from island.migration import Migration
from island.population import MAX_ITERATIONS
from island.protocol import decode_config as unpack_config
from island.protocol import encode_config as pack_config
from island.share import check_share
from island.termination import Termination
from island.wire import INT64_MAX, MAX_MEMBERS, MessageRejected, check_name

MAX_SEED = 2**62
"""Largest campaign seed (island seeds add up to 2**20 to it and are stored as SQLite integers)."""
DISPLACEMENT_BY = ("data", "user", "none")
"""Who chose a campaign's displacement reading (:attr:`CampaignConfig.displacement_by`)."""


def _plain_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and abs(value) <= INT64_MAX


def _option_value(value: Any) -> bool:
    return (isinstance(value, (str, bool)) and len(str(value)) <= 200) or _plain_number(value)


@dataclass
class CampaignConfig:
    """Model, weights, bounds, fixed values, algorithms and migration of one campaign.

    ``options[algo]`` are keyword options of that algorithm's constructor (e.g.
    population size and iterations); ``algos`` is the mix islands are assigned
    from when they are not told their algorithm.
    """

    name: str
    model: str = "thesis"
    weights: str = "thesis"
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)
    soft: list[str] = field(default_factory=list)
    """Parameters whose bounds were derived from the data (the final refit may widen them)."""
    fixed: dict[str, float] = field(default_factory=dict)
    start: list[float] | None = None
    """A starting point every island adds to its initial population (the survey's linear estimate)."""
    algos: list[str] = field(default_factory=lambda: ["ga", "pso"])
    options: dict[str, dict[str, Any]] = field(default_factory=dict)
    migration: Migration = field(default_factory=Migration)
    seed: int = 0
    objective_kind: str = "closed_form"
    displacement: str = "measured"
    """The displacement the model sees: each loop's measured waveform, or the ideal sine (Eq. 4.5)."""
    displacement_by: str = "user"
    """Who chose :attr:`displacement`: ``data`` (``auto``, :func:`hysid.motion.choose_motion`; the campaign's
    result confirms it with the fitted model, as ``hysid fit`` does), ``user`` or ``none``."""
    min_islands: int = 1
    """Islands wait (up to :data:`island.node.START_TIMEOUT_S`) until this many are members before
    they start, so that islands launched together also search together."""
    until_stopped: bool = False
    """Islands search until the coordinator's stop order (their own iteration budget is off): with a
    campaign budget in evaluations or time, fast (GA) and slow (PSO) islands search, and migrate,
    until the campaign stops instead of the fast ones leaving early (which algorithm each runs
    meanwhile is the :attr:`share`'s)."""
    share: str = "staged"
    """How the islands are shared between :attr:`algos` (:mod:`island.share`): ``staged`` moves the
    exploring (GA) islands to the converging algorithm (PSO) after their first migration interval, ``adaptive``
    moves islands to the algorithm whose own moves gain more, ``fixed`` keeps each island's algorithm."""
    stop_rules: dict[str, Any] = field(default_factory=dict)
    """The coordinator's :class:`~island.termination.Termination` as plain data (kept with the
    campaign, so that ``--resume`` stops by the same rules)."""

    def __post_init__(self) -> None:
        check_name("campaign", self.name)
        if self.weights not in WEIGHTS:
            raise HysidInputError(f"must be one of {', '.join(WEIGHTS)}", param="weights", value=self.weights)
        if not self.algos:
            raise HysidInputError(f"give a non-empty list of {', '.join(ALGORITHMS)}", param="algos", value=self.algos)
        for algo in self.algos:
            check_algorithm(algo, "algos")
        unknown = sorted(set(self.options) - set(ALGORITHMS))
        if unknown:
            raise HysidInputError(f"options given for unknown algorithm(s) {', '.join(map(str, unknown))}")
        for algo, opts in self.options.items():
            if not isinstance(opts, dict) or not all(isinstance(k, str) and _option_value(v) for k, v in opts.items()):
                raise HysidInputError(f"{algo} options must map names to finite numbers, short strings or booleans")
        if not isinstance(self.until_stopped, bool):
            raise HysidInputError("must be true or false", param="until_stopped", value=self.until_stopped)
        check_share(self.share)
        if not isinstance(self.stop_rules, dict) or not set(self.stop_rules) <= set(Termination().as_dict()):
            raise HysidInputError("must map Termination's fields to values", param="stop_rules", value=self.stop_rules)
        Termination(**self.stop_rules)
        for algo in self.algos:  # every island's settings are checked here, before any island starts
            make_optimizer(algo, np.array([[0.0, 1.0]]), 0, self.island_options(algo))
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or not 0 <= self.seed <= MAX_SEED:
            raise HysidInputError("must be an integer from 0 to 2**62", param="seed", value=self.seed)
        try:
            self.bounds = {str(k): (float(v[0]), float(v[1])) for k, v in self.bounds.items()}
        except (TypeError, ValueError, IndexError, KeyError, OverflowError):
            raise HysidInputError("bounds must map parameter names to (lower, upper)", param="bounds", value=self.bounds) from None
        if not all(math.isfinite(lo) and math.isfinite(hi) for lo, hi in self.bounds.values()):
            raise HysidInputError("bounds must be finite numbers", param="bounds", value=self.bounds)
        if not isinstance(self.soft, list) or not all(isinstance(n, str) and n in self.bounds for n in self.soft):
            raise HysidInputError("soft must list parameters that have bounds", param="soft", value=self.soft)
        if self.start is not None and (
            not isinstance(self.start, list) or len(self.start) != len(self.bounds) or not all(_plain_number(v) and np.isfinite(v) for v in self.start)
        ):
            raise HysidInputError("start must hold one finite number per parameter", param="start", value=self.start)
        if not all(_plain_number(v) for v in self.fixed.values()):
            raise HysidInputError("fixed values must be finite numbers", param="fixed", value=self.fixed)
        self.fixed = {str(k): float(v) for k, v in self.fixed.items()}
        if isinstance(self.min_islands, bool) or not isinstance(self.min_islands, int) or not 1 <= self.min_islands <= MAX_MEMBERS:
            raise HysidInputError(f"must be an integer from 1 to {MAX_MEMBERS}", param="min_islands", value=self.min_islands)
        if self.objective_kind not in OBJECTIVES:
            raise HysidInputError(f"must be one of {', '.join(OBJECTIVES)}", param="objective", value=self.objective_kind)
        if self.displacement not in DISPLACEMENTS:
            raise HysidInputError(f"must be one of {', '.join(DISPLACEMENTS)}", param="displacement", value=self.displacement)
        if self.displacement_by not in DISPLACEMENT_BY:
            raise HysidInputError(f"must be one of {', '.join(DISPLACEMENT_BY)}", param="displacement_by", value=self.displacement_by)
        if self.displacement_by == "data" and self.displacement not in ("measured", "fundamental"):
            raise HysidInputError("the data choose between measured and fundamental only", param="displacement", value=self.displacement)
        if self.objective_kind == "thesis_port" and (self.model != "thesis" or self.weights != "thesis"):
            raise HysidInputError("the thesis_port objective is the thesis model with the thesis weights only")

    @classmethod
    def create(
        cls,
        loops: LoopSet,
        *,
        name: str,
        model: str | Model = "thesis",
        weights: str | None = None,
        bounds: Mapping[str, tuple[float, float]] | None = None,
        fixed: Mapping[str, float] | None = None,
        algos: list[str] | None = None,
        options: dict[str, dict[str, Any]] | None = None,
        migration: Migration | None = None,
        seed: int = 0,
        min_islands: int = 1,
        objective_kind: str = "closed_form",
        displacement: str = "measured",
        displacement_by: str = "user",
        until_stopped: bool = False,
        share: str = "staged",
    ) -> CampaignConfig:
        """The configuration of a campaign on ``loops``: the bounds and fixed values ``hysid fit`` would use."""
        m = prepare_model(displaced(loops, displacement), model, bounds=bounds, fixed=fixed)
        return cls(
            name=name,
            model=m.spec,
            weights=resolve_weights(loops, weights),
            bounds={p.name: (p.lower, p.upper) for p in m.parameters},
            soft=[p.name for p in m.parameters if p.soft],
            fixed=m.fixed,
            start=[float(v) for v in starting_point(displaced(loops, displacement), m)],
            algos=list(algos or ["ga", "pso"]),
            options=dict(options or {}),
            migration=migration or Migration(),
            seed=seed,
            min_islands=min_islands,
            objective_kind=objective_kind,
            displacement=displacement,
            displacement_by=displacement_by,
            until_stopped=until_stopped,
            share=share,
        )

    def objective(self, loops: LoopSet) -> Objective | ThesisObjective:
        """The campaign objective (Eq. 3.3 with the configured weights) on ``loops``."""
        hard = {n: b for n, b in self.bounds.items() if n not in self.soft}
        soft = {n: b for n, b in self.bounds.items() if n in self.soft}
        return build_objective(
            loops,
            self.model,
            weights=self.weights,
            bounds=hard,
            derived=soft,
            fixed=self.fixed,
            kind=self.objective_kind,
            displacement=self.displacement,
        )

    def island_options(self, algo: str) -> dict[str, Any]:
        """The constructor options of an island running ``algo``: ``options[algo]``, and with
        :attr:`until_stopped` no iteration budget of its own (the coordinator's stop order ends it)."""
        options = dict(self.options.get(algo, {}))
        if self.until_stopped:
            options["iterations"] = MAX_ITERATIONS
        return options

    def algo_for(self, seed: int) -> str:
        """The algorithm of an island that was not told one: the mix, cycled by seed."""
        return self.algos[seed % len(self.algos)]

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "model": self.model,
            "weights": self.weights,
            "bounds": {k: list(v) for k, v in self.bounds.items()},
            "soft": list(self.soft),
            "fixed": dict(self.fixed),
            "start": None if self.start is None else list(self.start),
            "algos": list(self.algos),
            "options": {k: dict(v) for k, v in self.options.items()},
            "migration": self.migration.as_dict(),
            "seed": self.seed,
            "objective": self.objective_kind,
            "displacement": self.displacement,
            "displacement_by": self.displacement_by,
            "min_islands": self.min_islands,
            "until_stopped": self.until_stopped,
            "share": self.share,
            "stop_rules": dict(self.stop_rules),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> CampaignConfig:
        try:
            bounds = {k: (v[0], v[1]) for k, v in d["bounds"].items()}
            return cls(
                name=d["name"],
                model=d["model"],
                weights=d["weights"],
                bounds=bounds,
                soft=list(d["soft"]),
                fixed=dict(d["fixed"]),
                start=None if d["start"] is None else list(d["start"]),
                algos=list(d["algos"]),
                options=d["options"],
                migration=Migration(**d["migration"]),
                seed=d["seed"],
                objective_kind=d["objective"],
                displacement=d["displacement"],
                min_islands=d["min_islands"],
                until_stopped=d.get("until_stopped", False),
                stop_rules=d.get("stop_rules", {}),  # absent in campaigns stored before them
                share=d.get("share", "fixed"),
                displacement_by=d.get("displacement_by", "user"),
            )
        except HysidInputError:
            raise
        except (KeyError, TypeError, ValueError, AttributeError, IndexError, OverflowError) as exc:
            raise HysidInputError(f"campaign configuration is malformed ({type(exc).__name__}: {exc})") from None


def encode_config(config: CampaignConfig, loops: LoopSet) -> bytes:
    """The ``config`` message of a campaign."""
    return pack_config(config.name, config.as_dict(), loops)


def decode_config(data: bytes, campaign: str) -> tuple[CampaignConfig, LoopSet]:
    """A ``config`` message as configuration and loop set; anything invalid is a :class:`MessageRejected`."""
    settings, loops = unpack_config(data, campaign)
    try:
        config = CampaignConfig.from_dict(settings)
    except HysidInputError as exc:
        raise MessageRejected("schema", f"configuration invalid: {exc}") from None
    if config.name != campaign:
        raise MessageRejected("campaign", f"configuration names campaign {config.name!r}")
    return config, loops
