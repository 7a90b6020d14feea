"""A user's own terms: a force law written as a plain function, or as the rate of a state, made a model term.

    def quadratic_damping(x, v, c2):
        return c2 * v * np.abs(v)

    drag = term(quadratic_damping, name="drag", units={"c2": "N s^2/m^2"}, bounds={"c2": (0.0, 1e3)})
    model = build_model("thesis") + drag          # or the model string "thesis+myterms:drag"

* ``term(fn, ...)``: ``fn(x, v, **params)`` is the force (N) at displacement ``x`` (m) and velocity ``v``
  (m/s), numpy arrays of shape ``(P, L, N)`` or ``(1, L, N)`` (candidates, loops, samples), each parameter a
  ``(P, 1, 1)`` array; its result must broadcast to ``(P, L, N)``. The force is no combination of the
  basis features, so the model evaluates it sample by sample as it does a memory term's
  (:meth:`~hysid_model.terms.Term.time_force`, :mod:`hysid_model.sampled`).
* ``term(rate=..., ...)``: a force with memory, a state z (N) with dz/dt = ``rate(z, x, v, **params)``,
  e.g. Dahl's friction dz/dt = sigma v (1 - z sgn(v) / F_c); written elementwise, it is called with ``z``
  ``(P, L)``, ``x`` and ``v`` ``(L,)`` and parameters ``(P, 1)`` at each instant of a cycle (and once with
  arrays of one more axis, the whole cycle at once). The state's periodic solution under each loop's motion,
  z(2 pi) = z(0), is found by the secant method on the cycle map, each cycle integrated in :data:`~hysid_model.user_laws.STEPS`
  exponential Rosenbrock-Euler steps (:class:`~hysid_model.user_laws.RateTerm`: stable however stiff the law), and read at the
  samples by cubic Hermite interpolation with the law's own slopes. Plain integration would reach the
  steady state only after many cycles where the law forgets slowly; the secant method needs two or three.
  This covers a single state that is the force itself; a law of several states (LuGre's bristles and
  velocity terms, a two-element damper) does not fit in one z and is left out.

Either force enters the model less its cycle mean, as every term's does (:mod:`hysid_model.terms`).
A term's parameters are the function's arguments after ``x, v`` (after ``z, x, v`` for a rate), each
with a unit and bounds (hard, never widened: nothing derives them from the data); ``strength`` names
the parameter whose 0 switches the term off, which a diagnosis needs to score it as a candidate. A
lower bound of 0 on it is the effect's physical sign, as on the library's strengths: its physical
range is then [0, inf), so a fit that ends there reads "no such effect", not "search further".
Every mistake is a one-line :class:`HysidInputError` when the term is made: ``fn`` is evaluated at its
bounds' midpoint (and around it) on a probe motion and must return finite forces of the right shape,
row by row the same as for one candidate and one loop alone (vectorized, not mixing them).

A model string names a user's term by ``module:attribute`` (``thesis+myterms:drag``): :func:`resolve`
imports the module (its top-level code runs) and takes the attribute, which must be such a term. A
campaign's islands rebuild its model from that string in their own processes, so the module must be
importable there (on their ``PYTHONPATH`` or installed). In the process that made it, a term is also
known by its name (``thesis+drag``), and a model made of it spells it ``module:attribute`` wherever
the term is an attribute of a module other than ``__main__`` (:attr:`~hysid_model.user_laws.UserTerm.reference`).
"""

from __future__ import annotations

import importlib
import inspect
import math
import re
import sys
import warnings
from collections.abc import Callable, Collection, Iterable, Mapping
from dataclasses import replace
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from hysid_model.effects import EFFECTS
from hysid_model.errors import HysidInputError, HysidWarning
from hysid_model.kinematics import Kinematics
from hysid_model.params import Parameter
from hysid_model.presets import PRESETS
from hysid_model.terms import AmplitudeDependentDamping, AmplitudeDependentFrequency, ModalState, Oscillator, Term, TermGroup
from hysid_model.user_laws import FunctionTerm, RateTerm, UserTerm

NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
MODULE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*\Z")
LIBRARY_PARAMETERS = {p.name: t.id for t in (Oscillator, AmplitudeDependentDamping, AmplitudeDependentFrequency, *EFFECTS.values()) for p in t.params}
"""Parameter name -> the library term that owns it (a user's term, added to the library's, may not reuse one)."""

PROBE_X0 = np.array([1e-3, 2e-3])
PROBE_HZ = np.array([10.0, 20.0])
PROBE_SAMPLES = 24
"""The probe motion a term is checked on when it is made: two loops (1 and 2 mm at 10 and 20 Hz), 24 phases."""

_MADE: dict[str, UserTerm] = {}
"""Every user's term made (or imported) in this process, by name: what a model string's bare name means."""


def term(
    fn: Callable[..., Any] | None = None,
    *,
    name: str,
    units: Mapping[str, str],
    bounds: Mapping[str, tuple[float, float]],
    explanation: str = "",
    strength: str | None = None,
    rate: Callable[..., Any] | None = None,
) -> UserTerm:
    """A model term from a force law ``fn(x, v, **params)``, or a force with memory from ``rate(z, x, v, **params)``
    (see the module docstring); ``name`` is how models and reports call it, ``units`` and ``bounds`` give
    every parameter's SI unit and search bounds ``(lower, upper)``, ``explanation`` says what it models
    (default: the function's docstring), ``strength`` names the parameter whose 0 switches it off (default:
    the only parameter, where there is one)."""
    if (fn is None) == (rate is None):
        raise HysidInputError("give a force law fn(x, v, **params) or a rate(z, x, v, **params) of a state, one of them", param="fn")
    law = fn if fn is not None else rate
    what = "fn" if fn is not None else "rate"
    if not callable(law):
        raise HysidInputError(f"must be a function, not {type(law).__name__}", param=what)
    if not isinstance(name, str) or not NAME.match(name):
        raise HysidInputError("a term's name is a Python identifier (letters, digits, underscores)", param="name", value=name)
    if name in PRESETS or name in EFFECTS or name == Oscillator.id:
        raise HysidInputError("is the name of a preset or of a library effect; choose another", param="name", value=name)
    names = law_parameters(law, what, ("z", "x", "v") if rate is not None else ("x", "v"))
    params = parameters(name, what, names, units, bounds)
    strength = check_strength(name, params, strength)
    params = tuple(replace(p, physical=(0.0, math.inf)) if p.name == strength and p.lower == 0.0 else p for p in params)
    if explanation is not None and not isinstance(explanation, str):
        raise HysidInputError("must be a sentence (a string)", param="explanation", value=explanation)
    doc = inspect.getdoc(law) or ""
    text = " ".join((explanation or doc.split("\n\n")[0] or f"a user's term ({getattr(law, '__qualname__', what)})").split())
    caller = sys._getframe(1).f_globals.get("__name__", "")
    modules = tuple(dict.fromkeys(m for m in (caller, getattr(law, "__module__", None)) if isinstance(m, str) and m))
    made: UserTerm = (FunctionTerm if fn is not None else RateTerm)(law, name, params, text, strength, modules)
    probe(made)
    register(made)
    return made


def law_parameters(law: Callable[..., Any], what: str, leading: tuple[str, ...]) -> list[str]:
    """The parameter names of ``law``: its arguments after the ``leading`` ones (x, v; or z, x, v)."""
    try:
        signature = inspect.signature(law)
    except (TypeError, ValueError):
        raise HysidInputError(f"its arguments cannot be read; write it as def {what}({', '.join(leading)}, *params)", param=what) from None
    args = list(signature.parameters.values())
    variadic = [("*" if a.kind == a.VAR_POSITIONAL else "**") + a.name for a in args if a.kind in (a.VAR_POSITIONAL, a.VAR_KEYWORD)]
    if variadic:
        raise HysidInputError(f"name every parameter as an argument, not {variadic[0]}", param=what)
    if (
        len(args) <= len(leading)
        or any(a.kind == a.KEYWORD_ONLY for a in args[: len(leading)])
        or any(a.kind == a.POSITIONAL_ONLY for a in args[len(leading) :])
    ):
        raise HysidInputError(f"takes ({', '.join(leading)}, then its parameters by name), e.g. def {what}({', '.join(leading)}, c2)", param=what)
    return [a.name for a in args[len(leading) :]]


def parameters(name: str, what: str, names: list[str], units: Mapping[str, str], bounds: Mapping[str, tuple[float, float]]) -> tuple[Parameter, ...]:
    """The term's parameters: every name with its unit and bounds, nothing given for a name it does not have."""
    for given, kind in ((units, "units"), (bounds, "bounds")):
        if not isinstance(given, Mapping):
            raise HysidInputError(f"must map each parameter ({', '.join(names)}) to its {kind[:-1]}", param=kind, value=given)
        extra = sorted(set(given) - set(names))
        if extra:
            raise HysidInputError(f"{extra[0]!r} is no parameter of term {name!r} (its parameters: {', '.join(names)})", param=kind)
    out = []
    for n in names:
        if n in LIBRARY_PARAMETERS:
            raise HysidInputError(f"parameter {n!r} of term {name!r} is a parameter of {LIBRARY_PARAMETERS[n]} already; call it otherwise", param=what)
        if n not in units or not isinstance(units[n], str) or not units[n].strip():
            raise HysidInputError(f'give the SI unit of parameter {n!r} ("1" for none)', param="units")
        if n not in bounds:
            raise HysidInputError(f"give the search bounds (lower, upper) of parameter {n!r}", param="bounds")
        pair = bounds[n]
        try:
            lower, upper = (float(b) for b in pair)
        except (TypeError, ValueError):
            raise HysidInputError("must be a pair of numbers (lower, upper)", param=f"bounds[{n!r}]", value=pair) from None
        out.append(Parameter(n, units[n].strip(), lower, upper, f"{n} of {name}"))
    return tuple(out)


def check_strength(name: str, params: tuple[Parameter, ...], strength: str | None) -> str:
    """The strength parameter (given, or the only parameter): its bounds must hold 0, where the term is off."""
    if strength is None:
        if len(params) != 1 or not params[0].lower <= 0.0 <= params[0].upper:
            return ""
        strength = params[0].name
    chosen = next((p for p in params if p.name == strength), None)
    if chosen is None:
        raise HysidInputError(f"is no parameter of term {name!r} ({', '.join(p.name for p in params)})", param="strength", value=strength)
    if not chosen.lower <= 0.0 <= chosen.upper:
        raise HysidInputError(f"its bounds {chosen.lower:g}:{chosen.upper:g} must hold 0, where the term is off", param="strength", value=strength)
    return strength


def probe_kinematics() -> Kinematics:
    return Kinematics(x0=PROBE_X0, omega=2.0 * np.pi * PROBE_HZ)


def probe(made: UserTerm) -> None:
    """Evaluate ``made`` on the probe motion at its bounds' midpoint and at a second point (30 % up each range):
    finite forces of shape ``(P, L, N)``, each candidate and loop the same as alone (vectorized), zero at
    strength 0."""
    kin = probe_kinematics()
    phase = np.broadcast_to(np.linspace(0.0, 2.0 * np.pi, PROBE_SAMPLES, endpoint=False), (PROBE_X0.size, PROBE_SAMPLES))
    mid = {p.name: 0.5 * (p.lower + p.upper) for p in made.params}
    other = {p.name: p.lower + 0.3 * (p.upper - p.lower) for p in made.params}
    what = "rate" if isinstance(made, RateTerm) else "fn"

    def force(rows: list[dict[str, float]], loops: slice = slice(None)) -> np.ndarray:
        v = {n: np.array([[row[n]] for row in rows]) for n in mid}
        at = ", ".join(f"{k}={x:g}" for k, x in rows[-1].items())
        sub = Kinematics(x0=kin.x0[loops], omega=kin.omega[loops])
        try:
            with warnings.catch_warnings(), np.errstate(all="ignore"):
                warnings.simplefilter("error", np.exceptions.ComplexWarning)
                out = made.time_force(v, ModalState(xi=np.zeros(1), wn=np.zeros(1), m=np.zeros(1)), sub, phase[loops])
        except HysidInputError:
            raise
        except Exception as exc:  # the user's function, whatever it raises, is named in one line
            detail = " ".join(str(exc).split())[:200]
            raise HysidInputError(f"term {made.id!r}: {what} fails on the probe motion at {at} ({type(exc).__name__}: {detail})", param=what) from None
        bad = [row for row, finite in zip(rows, np.isfinite(out).all(axis=(1, 2))) if not finite]
        if bad:
            why = " (no periodic solution within the cycles tried, or a non-finite rate)" if what == "rate" else ""
            values = ", ".join(f"{k}={x:g}" for k, x in bad[0].items())
            raise HysidInputError(f"term {made.id!r}: {what} gives non-finite forces at {values}{why}", param=what)
        return out

    alone = np.concatenate([force([mid], slice(0, 1)), force([mid], slice(1, 2))], axis=1)
    both = force([mid, other])
    if not np.allclose(both[:1], alone, rtol=1e-9, atol=1e-12 * max(np.abs(alone).max(), 1e-300)):
        raise HysidInputError(f"term {made.id!r}: {what} must be vectorized: each candidate's and each loop's force must not depend on the others'", param=what)
    if made.strength:
        scale = max(np.abs(both).max(), 1e-300)
        off = force([{**mid, made.strength: 0.0}])
        if np.abs(off).max() > 1e-9 * scale:
            raise HysidInputError(
                f"term {made.id!r}: at {made.strength} = 0 its force is not zero, so {made.strength} cannot be its strength",
                param="strength",
                value=made.strength,
            )


def register(made: UserTerm) -> None:
    """Make ``made`` known by its name in this process (a term of the same name made before is replaced; a
    different law under that name is warned about)."""
    before = _MADE.get(made.id)
    if before is not None and before is not made and getattr(before.law, "__qualname__", None) != getattr(made.law, "__qualname__", None):
        warnings.warn(
            HysidWarning(
                f"term {made.id!r} now means the one made from {getattr(made.law, '__qualname__', 'a new law')}, "
                f"not the earlier one from {getattr(before.law, '__qualname__', 'another law')}"
            ),
            stacklevel=3,
        )
    _MADE[made.id] = made


def made_terms() -> list[UserTerm]:
    """Every user's term made or imported in this process so far, by name."""
    return [_MADE[n] for n in sorted(_MADE)]


def resolve(spec: str) -> UserTerm:
    """The user's term a model string names: ``module:attribute`` (imported) or the name of a term made in this process."""
    if ":" not in spec:
        if spec in _MADE:
            return _MADE[spec]
        raise HysidInputError(f"unknown effect {spec!r}; known: {', '.join(sorted(EFFECTS))}, or a term of your own as module:attribute")
    module_name, _, attribute = spec.partition(":")
    if not MODULE.match(module_name) or not NAME.match(attribute):
        raise HysidInputError(f"{spec!r}: a term of your own is named module:attribute (e.g. myterms:drag)")
    module = import_user_module(module_name, f"{spec!r}: ")
    found = getattr(module, attribute, None)
    if found is None:
        raise HysidInputError(f"{spec!r}: module {module_name!r} has no attribute {attribute!r}")
    if not isinstance(found, UserTerm):
        raise HysidInputError(f"{spec!r}: is a {type(found).__name__}, not a term made by hysid.term")
    if module_name != "__main__":
        found._reference = spec
    register(found)
    return found


def import_user_module(module_name: str, where: str = "") -> ModuleType:
    """The module ``module_name`` imported (its top-level code runs: every term it makes becomes known); a
    one-line error (prefixed ``where``) when it is not on the path or its import fails."""
    if not MODULE.match(module_name):
        raise HysidInputError(f"{where}{module_name!r} is not a module name (e.g. myterms or lab.terms)")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name is not None and (module_name == exc.name or module_name.startswith(exc.name + ".")):
            here = Path.cwd() / f"{module_name.split('.')[0]}.py"
            hint = f" ({here.name} is in the working directory, which is not on the path: PYTHONPATH=. puts it there)" if here.is_file() else ""
            raise HysidInputError(f"{where}no module {module_name!r} on this Python's path{hint}") from None
        raise HysidInputError(f"{where}importing module {module_name!r} failed (ModuleNotFoundError: {exc})") from None
    except Exception as exc:  # the user's module, whatever its top-level code raises, is named in one line
        raise HysidInputError(f"{where}importing module {module_name!r} failed ({type(exc).__name__}: {' '.join(str(exc).split())[:200]})") from None
    return module


def user_terms_of(terms: Iterable[Term]) -> list[UserTerm]:
    """The user's terms among ``terms``."""
    return [t for t in terms if isinstance(t, UserTerm)]


def check_importable(terms: Iterable[Term]) -> None:
    """A one-line error unless every user's term among ``terms`` (a model's) has a ``module:attribute`` another
    process can import."""
    for t in user_terms_of(terms):
        if t.reference is None:
            raise HysidInputError(
                f"term {t.id!r} is no attribute of an importable module (made in __main__, a notebook or a function): island "
                "processes import a term by module:attribute; define it in a module on their path (e.g. myterms.py), or run single_node",
                param="model",
            )


def module_roots(terms: Iterable[Term]) -> list[str]:
    """The directories from which the modules of the user's terms among ``terms`` (a model's) are imported (what
    an island process on this machine needs on its ``PYTHONPATH``)."""
    roots = []
    for t in user_terms_of(terms):
        reference = t.reference
        module = sys.modules.get(reference.partition(":")[0]) if reference else None
        origin = getattr(module, "__file__", None)
        if origin:
            depth = reference.partition(":")[0].count(".") + (Path(origin).name == "__init__.py")  # type: ignore[union-attr]
            roots.append(str(Path(origin).resolve().parents[depth]))
    return list(dict.fromkeys(roots))


def specs_of(items: Term | TermGroup | str | Collection[Term | TermGroup | str], param: str) -> tuple[str, ...]:
    """The model-string names of terms given as terms, groups of terms or model strings (``myterms:drag``)."""
    if isinstance(items, (Term, TermGroup, str)):
        items = [items]
    out: list[str] = []
    for item in items:
        if isinstance(item, TermGroup):
            out += [t.spec for t in item]
        elif isinstance(item, UserTerm) or (isinstance(item, Term) and item.id in EFFECTS):
            out.append(item.spec)
        elif isinstance(item, str):
            out.append(item if item in EFFECTS else resolve(item).spec)
        else:
            raise HysidInputError(f"give terms (hysid.term, hysid.effects) or their names (module:attribute), not {type(item).__name__}", param=param)
    return tuple(dict.fromkeys(out))
