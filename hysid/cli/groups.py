"""Options that travel together, declared once: the islands' search, the reading of the loops, the stop rules, the constraints.

A command names a group as one parameter (``search: Search``) and :func:`grouped`
lays the group's options out in its place, in the group's order, with the
flags, defaults and help of :mod:`hysid.cli.options`; the command then receives
the group as one object (``search.migration()``, ``reading.load(dataset)``,
``stop.termination()``). ``hysid campaign --help`` lists the same options as
when each command spelled them out.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import typing
from collections.abc import Callable
from typing import Any

from hysid.cli import options as o
from hysid_model.datasets import load_dataset
from hysid_model.loops import LoopSet
from island.migration import Migration
from island.termination import Termination


@dataclasses.dataclass
class Search:
    """The islands' algorithms, migration and sizes: ``--algos`` ... ``--seed``."""

    algos: str = o.ALGOS
    share: str = o.SHARE
    topology: str = o.TOPOLOGY
    interval: int = o.INTERVAL
    migrants: int = o.MIGRANTS
    random_k: int = o.RANDOM_K
    population: int | None = o.POPULATION
    initial: int | None = o.INITIAL
    iterations: int | None = o.ITERATIONS
    seed: int = o.SEED

    def migration(self) -> Migration:
        return Migration(interval=self.interval, k=self.migrants, topology=self.topology, random_k=self.random_k)

    def algo_list(self) -> list[str]:
        return o.parse_algos(self.algos)


@dataclasses.dataclass
class Reading:
    """How the loops are read: ``--noise``, ``--noise-seed``, ``--points``, ``--skip-rows``."""

    noise: float = o.NOISE
    noise_seed: int = o.NOISE_SEED
    points: int | None = o.POINTS
    skip_rows: int | None = o.SKIP_ROWS

    def load(self, dataset: str) -> LoopSet:
        return load_dataset(dataset, noise_pct=self.noise, noise_seed=self.noise_seed, n_points=self.points, skip_rows=self.skip_rows)


@dataclasses.dataclass
class Stop:
    """When a campaign stops: ``--evaluations``, ``--target``, ``--stall``, ``--time-limit``."""

    budget: int | None = o.BUDGET
    target: float | None = o.TARGET
    stall: int | None = o.STALL
    time_limit: float | None = o.TIME_LIMIT

    def termination(self) -> Termination:
        return Termination(budget=self.budget, target=self.target, stall=self.stall, time_limit_s=self.time_limit)


@dataclasses.dataclass
class Constraints:
    """What the search may not vary: ``--bound``, ``--fix``, ``--displacement``."""

    bound: list[str] | None = o.BOUND
    fix: list[str] | None = o.FIX
    displacement: str = o.DISPLACEMENT

    def bounds(self) -> dict[str, tuple[float, float]]:
        return o.parse_bounds(self.bound)

    def fixed(self) -> dict[str, float]:
        return o.parse_fixed(self.fix)


GROUPS = (Search, Reading, Stop, Constraints)


@dataclasses.dataclass(frozen=True)
class LaidOut:
    """The default of a group's parameter in a command's signature, which :func:`grouped` replaces by the group's
    options: in ``order`` (their names) where given, else in the group's."""

    order: tuple[str, ...] = ()


LAID_OUT: Any = LaidOut()


def laid_out(*order: str) -> Any:
    """A group's options in another ``order`` (as a command listed them before they were a group)."""
    return LaidOut(order)


def grouped(command: Callable[..., Any]) -> Callable[..., Any]:
    """``command`` with each parameter typed as one of :data:`GROUPS` laid out as the group's options (for typer),
    and called with the group made from them."""
    hints = typing.get_type_hints(command)
    groups = {name: hint for name, hint in hints.items() if hint in GROUPS}
    layout: list[inspect.Parameter] = []
    for param in inspect.signature(command).parameters.values():
        if param.name not in groups:
            layout.append(param.replace(annotation=hints.get(param.name, param.annotation)))
            continue
        group = groups[param.name]
        fields = {f.name: f for f in dataclasses.fields(group)}
        hinted = typing.get_type_hints(group)
        names = param.default.order or tuple(fields)
        layout += [inspect.Parameter(n, param.kind, default=fields[n].default, annotation=hinted[n]) for n in names]

    @functools.wraps(command)
    def run(**given: Any) -> Any:
        for name, group in groups.items():
            given[name] = group(**{f.name: given.pop(f.name) for f in dataclasses.fields(group)})
        return command(**given)

    run.__signature__ = inspect.Signature(layout, return_annotation=hints.get("return", inspect.Signature.empty))  # type: ignore[attr-defined]
    run.__annotations__ = {p.name: p.annotation for p in layout}
    return run
