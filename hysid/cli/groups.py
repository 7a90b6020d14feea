"""Options that travel together, declared once: the islands' search, the reading of the loops, the stop rules, the constraints, the output.

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
from pathlib import Path
from typing import Any

from hysid.cli import options as o
from hysid.cli.directories import report_dir
from hysid.report import jsondoc
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


@dataclasses.dataclass
class Output:
    """Where and how a command reports its result: ``--out``, ``--json``, ``--csv``, ``--quiet``, ``--figures``."""

    out: Path | None = o.OUT
    as_json: bool = o.JSON
    csv: bool = o.CSV
    quiet: bool = o.QUIET
    figures: bool = o.FIGURES

    @property
    def live(self) -> bool:
        """Whether live progress goes to stderr: not with ``--quiet``, nor with ``--json``."""
        return not (self.quiet or self.as_json)

    def directory(self, kind: str) -> Path:
        """The report directory, checked before any work (:func:`hysid.cli.options.report_dir`)."""
        return report_dir(self.out, kind)

    def write(self, result: Any, target: Path, dataset: str | None = None, figures: bool = True) -> dict[str, Path]:
        """The result's report in ``target``, with its figures unless ``--no-figures`` or ``figures=False``
        (``write_report(..., figures=False)``); with ``--csv`` its tables too, returned."""
        drawn = self.figures and figures
        if dataset is None:
            result.write_report(target, figures=drawn)
        else:
            result.write_report(target, dataset, figures=drawn)
        return result.to_csv(target) if self.csv else {}

    def print(self, result: Any, tables: dict[str, Path]) -> None:
        """The result's JSON document (``--json``) or its summary and the ``tables`` written, on stdout."""
        if self.as_json:
            print(jsondoc.dumps(result.to_dict()))
            return
        print(result.summary())
        if tables:
            print(f"tables: {', '.join(str(p) for p in tables.values())}")

    def show(self, result: Any, target: Path, figures: bool = True) -> None:
        """:meth:`write`, then :meth:`print`."""
        self.print(result, self.write(result, target, figures=figures))


GROUPS = (Search, Reading, Stop, Constraints, Output)


@dataclasses.dataclass(frozen=True)
class LaidOut:
    """The default of a group's parameter in a command's signature, which :func:`grouped` replaces by the group's
    options: in ``order`` (their names) where given, else in the group's. A field ``order`` leaves out is no option
    of the command: the group holds its default."""

    order: tuple[str, ...] = ()


LAID_OUT: Any = LaidOut()


def laid_out(*order: str) -> Any:
    """A group's options in another ``order`` (as a command listed them before they were a group), or some of them."""
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
            given[name] = group(**{f.name: given.pop(f.name) if f.name in given else typing.cast(Any, f.default).default for f in dataclasses.fields(group)})
        return command(**given)

    run.__signature__ = inspect.Signature(layout, return_annotation=hints.get("return", inspect.Signature.empty))  # type: ignore[attr-defined]
    run.__annotations__ = {p.name: p.annotation for p in layout}
    return run
