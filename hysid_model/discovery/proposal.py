"""A discovered force law as a term of the user's kind, its formula, and the Python module that defines it.

A law is one or two families of :mod:`.features` with their shapes and linear coefficients. As a term
(:func:`hysid_model.user_terms.term`, named ``term_<n>``) it is

    F = c * (phi_1(x, v; shape_1) + r2 * phi_2(x, v; shape_2))

with the strength ``c`` (N) that switches it off, the relative weight ``r2`` of a second family, and the
families' shape parameters (an exponent, a threshold in m, a velocity scale in m/s), each named
``t<n>_<symbol>`` (the second family's with a 2). The same source text defines the force law in the diagnosing
process and in the module written for the user (:func:`module_source`), so that the module is the term that
was fitted: ``--model baseline+proposed:term_1`` and ``--candidates proposed:term_1`` take it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hysid_model.discovery.features import Family
from hysid_model.discovery.memory import compiled_term, is_memory, rate_expression, with_physical
from hysid_model.user_laws import UserTerm
from hysid_model.user_terms import term

MODULE = "proposed"
"""The module a diagnosis writes its proposed terms to (``proposed.py`` in its output folder)."""
WEIGHT_BOUND = 100.0
"""Bounds of a second family's relative weight r2, +-."""
STRENGTH_BOUND = 100.0
"""Bounds of the strength c, +- this times the largest force of the loops."""
SIGNIFICANT = ".10g"
"""Digits of the fitted values in a formula (evaluated by a user's numpy, it must be the fitted force)."""


@dataclass
class Law:
    """One or two families with their shapes (``{symbol: value}`` each) and linear coefficients (N)."""

    families: list[Family]
    shapes: list[dict[str, float]]
    weights: list[float]
    peak_force: float
    """The largest force of the loops (N): the strength's bounds are set from it."""
    bounds: list[dict[str, tuple[float, float]]] = field(default_factory=list)
    """Each family's shape bounds (default: the family's own)."""
    chi2: float = float("nan")
    """What the law leaves of the residual it was fitted to (its whitened sum of squares)."""
    fixed: list[dict[str, float]] = field(default_factory=list)
    """Each family's shapes fixed at a simple value (``{symbol: value}``): written as numbers, not parameters."""

    def __post_init__(self) -> None:
        if not self.bounds:
            self.bounds = [{s.symbol: s.bounds for s in f.shapes} for f in self.families]
        if not self.fixed:
            self.fixed = [{} for _ in self.families]

    @property
    def memory(self) -> bool:
        """A law of the Bouc-Wen state (:mod:`.memory`): its term is the rate of its force, not a force of x and v."""
        return any(is_memory(f) for f in self.families)

    @property
    def n_params(self) -> int:
        return len(self.families) + sum(len(f.shapes) - len(fixed) for f, fixed in zip(self.families, self.fixed))


def names(law: Law, number: int) -> list[dict[str, str]]:
    """Per family, its symbols (``c`` or ``r``, and its shape symbols) -> parameter names."""
    out = []
    for i, family in enumerate(law.families):
        tail = "" if i == 0 else str(i + 1)
        weight = "c" if i == 0 else f"r{tail}"
        free = [s.symbol for s in family.shapes if s.symbol not in law.fixed[i]]
        out.append({weight: f"t{number}_{weight}", **{s: f"t{number}_{s}{tail}" for s in free}})
    return out


def initial_values(law: Law, number: int) -> dict[str, float]:
    """The law's values as the term's parameters."""
    out: dict[str, float] = {}
    c = law.weights[0]
    for i, (mapping, shape) in enumerate(zip(names(law, number), law.shapes)):
        weight = "c" if i == 0 else f"r{i + 1}"
        out[mapping[weight]] = c if i == 0 else law.weights[i] / c if c != 0 else 0.0
        out.update({mapping[s]: v for s, v in shape.items() if s in mapping})
    return out


def _number(value: float, fmt: str = SIGNIFICANT) -> str:
    text = format(float(value), fmt)
    return f"({text})" if text.startswith("-") else text


def expression(law: Law, number: int, values: dict[str, float] | None = None, plain: bool = False) -> str:
    """The term's force as a numpy expression in x and v, in its parameter names, or with ``values`` in place
    (``plain``: in plain notation, four digits); for a law with memory, the rate dz/dt of its force z in z, x and v
    (:func:`hysid_model.discovery.memory.rate_expression`)."""
    fmt, times = (".4g", " ") if plain else (SIGNIFICANT, " * ")
    parts, strength = [], ""
    for i, (family, mapping) in enumerate(zip(law.families, names(law, number))):
        shown = {s: (mapping[s] if values is None else _number(values[mapping[s]], fmt)) for s in mapping}
        shown.update({s: _number(value, fmt) for s, value in law.fixed[i].items()})
        if is_memory(family):
            return rate_expression({**shown, "c": shown["c"] + (" N" if plain and values is not None else "")}, plain)
        phi = family.render(shown, plain)
        if i == 0:
            strength = shown["c"] + (" N" if plain and values is not None else "")
            parts.append(phi)
        else:
            parts.append(shown[f"r{i + 1}"] + times + phi)
    inner = parts[0] if plain and len(parts) == 1 else f"({' + '.join(parts)})"
    return f"{strength}{' x ' if plain else ' * '}{inner}"


def units(law: Law, number: int) -> dict[str, str]:
    out = {}
    for i, (family, mapping) in enumerate(zip(law.families, names(law, number))):
        out[mapping["c" if i == 0 else f"r{i + 1}"]] = "N" if i == 0 else "1"
        out.update({mapping[s.symbol]: s.unit for s in family.shapes if s.symbol in mapping})
    return out


def term_bounds(law: Law, number: int) -> dict[str, tuple[float, float]]:
    out = {}
    for i, (bounds, mapping) in enumerate(zip(law.bounds, names(law, number))):
        limit = STRENGTH_BOUND * law.peak_force if i == 0 else WEIGHT_BOUND
        out[mapping["c" if i == 0 else f"r{i + 1}"]] = (-float(limit), float(limit))
        out.update({mapping[s]: (float(lo), float(hi)) for s, (lo, hi) in bounds.items() if s in mapping})
    return out


def function_name(law: Law, number: int) -> str:
    """The name of the ``def`` of :func:`function_source`: the force's, or with memory the rate's."""
    return f"term_{number}_{'rate' if law.memory else 'force'}"


def function_source(law: Law, number: int) -> str:
    """The force law's ``def`` (what the module defines and the diagnosing process executes); for a law with
    memory, the rate of its force z, ``def term_<n>_rate(z, x, v, ...)`` (given to ``hysid.term`` as ``rate=``)."""
    params = [n for mapping in names(law, number) for n in mapping.values()]
    plain = expression(law, number, plain=True).replace('"', "'")
    head = plain if law.memory else f"F = {plain}"
    return (
        f"def {function_name(law, number)}({'z, ' if law.memory else ''}x, v, {', '.join(params)}):\n"
        f'    """{head}: proposed from the data, not a library effect."""\n'
        f"    return {expression(law, number)}\n"
    )


def term_call(law: Law, number: int) -> str:
    """The ``hysid.term(...)`` arguments after the law, as source."""
    return f"name={f'term_{number}'!r}, units={units(law, number)!r}, bounds={term_bounds(law, number)!r}, strength={names(law, number)[0]['c']!r}"


_NUMBERS: dict[str, int] = {}
"""The number of every law made a term in this process, by its source and bounds: a law met again keeps its
number (and the same term), a new one takes the next."""


def number_of(law: Law) -> int:
    """The number of ``law``'s term in this process (1 for the first law a process proposes)."""
    key = function_source(law, 0) + repr(term_bounds(law, 0))
    return _NUMBERS.setdefault(key, len(_NUMBERS) + 1)


def make_term(law: Law, number: int) -> UserTerm:
    """The law as a term of this process, ``term_<number>``, its force defined by :func:`function_source`."""
    namespace: dict = {"np": np, "__name__": MODULE}
    exec(compile(function_source(law, number), f"<{MODULE}.term_{number}>", "exec"), namespace)
    law_fn = namespace[function_name(law, number)]
    made = term(
        None if law.memory else law_fn,
        rate=law_fn if law.memory else None,
        name=f"term_{number}",
        units=units(law, number),
        bounds=term_bounds(law, number),
        strength=names(law, number)[0]["c"],
        explanation=f"proposed from the data, not a library effect: {expression(law, number, plain=True)}",
    )
    if not law.memory:
        return made
    made.params = with_physical(made.params, names(law, number)[0])
    shown: dict[str, str | float] = {**names(law, number)[0], **law.fixed[0]}
    return compiled_term(made, str(shown["c"]), shown["zy"], shown["n"])


def module_source(entries: list[tuple[Law, int, str]], dataset: str) -> str:
    """The module ``proposed.py``: every ``(law, number, fitted text)`` as ``term_<number>`` with ``hysid.term``."""
    doc = [
        f"Force terms proposed by hysid diagnose from the data of {dataset}: proposed from the data, not library effects.",
        "",
        "Each term_<n> is a term of your own (hysid.term): put this folder on the path and give it to a fit or a diagnosis,",
        "  PYTHONPATH=<this folder> hysid fit DATA --model baseline+proposed:term_1",
        "  PYTHONPATH=<this folder> hysid diagnose DATA --candidates proposed:term_1",
        "",
    ]
    for law, number, fitted in entries:
        doc += [f"term_{number}: {'' if law.memory else 'F = '}{expression(law, number, plain=True)}", f"  fitted: {fitted}"]
    quotes = '"' * 3
    text = "\n".join(doc).replace("\\", "/").replace(quotes, "'")
    memory = any(law.memory for law, _, _ in entries)
    lines = [quotes + text + "\n" + quotes, "", "import numpy as np", "", "import hysid"]
    lines += ["from hysid_model.discovery.memory import with_physical", ""] if memory else [""]
    for law, number, _ in entries:
        fn = f"{'rate=' if law.memory else ''}{function_name(law, number)}"
        lines += ["", function_source(law, number), "", f"term_{number} = hysid.term({fn}, {term_call(law, number)})", ""]
        if law.memory:  # its rate is defined for z_y > 0 and n >= 1 only: a fit widens a bound it ends on within those
            lines[-1:] = [f"term_{number}.params = with_physical(term_{number}.params, {names(law, number)[0]!r})", ""]
    return "\n".join(lines)
