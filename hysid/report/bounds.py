"""Search bounds in words: the parameters on one, and the bounds a fit widened (fit, campaign and diagnose alike)."""

from __future__ import annotations

from typing import Any


def bounds_sentence(kinds: dict[str, str]) -> str:
    """The parameters on a bound, each with which (:meth:`hysid_model.model.Model.bound_kinds`), in one sentence."""
    return (
        "on a bound: "
        + "; ".join(f"{name} on its {kind}" for name, kind in kinds.items())
        + (" (a physical limit is an answer, e.g. no damping of that kind; any other bound means the optimum may lie beyond it)")
    )


def widened_sentence(widened: list[dict[str, Any]]) -> str:
    """The search bounds a fit ended on and widened (``param``, ``from``, ``to`` as each widening is recorded), from the
    first to the last, in one sentence; empty where none was."""
    first: dict[str, list[float]] = {}
    last: dict[str, list[float]] = {}
    for w in widened:
        first.setdefault(w["param"], w["from"])
        last[w["param"]] = w["to"]
    if not first:
        return ""
    parts = [f"{name} [{first[name][0]:g}, {first[name][1]:g}] -> [{last[name][0]:g}, {last[name][1]:g}]" for name in first]
    return "search bounds widened within the physical ranges, each after an optimum on one, and the model fitted again: " + "; ".join(parts)


def widenings(start: Any, final: Any) -> list[dict[str, Any]]:
    """Each free parameter of the model ``final`` whose soft bounds differ from those of ``start`` (the same model as
    :func:`hysid_model.problem.prepare_model` makes it), as one widening ``param``, ``from``, ``to``."""
    before = dict(zip(start.names, start.bounds.tolist()))
    return [
        {"param": p.name, "from": before[p.name], "to": [p.lower, p.upper]}
        for p in final.parameters
        if p.soft and p.name in before and before[p.name] != [p.lower, p.upper]
    ]
