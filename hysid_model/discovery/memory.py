"""Memory candidates of discovery: the Bouc-Wen internal variable of each loop's own displacement history.

A force with memory is no function of the instantaneous x and v (:mod:`.features`): on a loop it depends on
the travel since the last reversal. The family here is the internal variable of the Bouc-Wen law (Eq. 2.1b)
with A = 1, gamma = 1 / z_y^n and beta = 0 (r = (gamma - beta) / (gamma + beta) = 1),

    dz/dt = v - |v| |z|^(n - 1) z / z_y^n,

read in units of its yield displacement, u = z / z_y in (-1, 1), on the steady periodic orbit of each loop
(the orbit of :mod:`hysid_model.bouc_wen_orbit`, compiled: its exact evaluation per point, with the loop's
extremes as the reversals). A term made of it is ``c * u``: a hysteretic force that saturates at c (N) with
an initial stiffness c / z_y, between a spring (z_y >> X), Dahl's friction (n = 1, dF/dx = sigma (1 - F / F_c
sgn v)) and an elastic-perfectly plastic (Jenkins) element with a slip force c and a stiffness c / z_y
(n -> infinity). Its shapes are the yield displacement z_y, on a grid of fractions of the reference amplitude
X, and the exponent n, the sharpness of the knee; beta = 0 keeps the law one parameter short of the library's
``bouc_wen`` (which frees r), so that it is a term of its own where the library's is taken already or a
different shape is wanted beside it.

As a term of the user's kind the law is the rate of its force F = c u (:func:`hysid_model.user_terms.term`
with ``rate=``): dF/dt = c / z_y (v - |v| |F / c|^n sgn(F / c)), whose periodic orbit the user's rate terms
find by their own integration (:class:`hysid_model.user_laws.RateTerm`); the proposal writes that rate
(:func:`rate_expression`) in the module. In the diagnosing process the same term (the same rate, name and
parameters) takes its orbit from the compiled exact solver instead (:class:`StateTerm`): integrating the rate
in Python, 256 steps a cycle, made the refits of a diagnosis with discovery six times as long as one without.
The two differ by the integration's error, about 1 % of c at a sharp knee on the largest loop (0.1-0.4 % RMS);
a fit with the module's term starts that close to the diagnosis' and ends where the rate term's orbit puts it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from hysid_model.discovery.features import Family, Shape
from hysid_model.effects.bouc_wen import mean_grid, travels
from hysid_model.kinematics import Kinematics
from hysid_model.params import Parameter
from hysid_model.terms import ModalState, Values
from hysid_model.user_laws import RateSampler, RateTerm, UserTerm
from hysid_model.user_terms import register

SHAPE_R = 1.0
"""The Bouc-Wen shape r of the family (beta = 0: the state relaxes at the same rate on both sides of zero)."""
YIELD_FRACTIONS = (0.03, 0.1, 0.3, 1.0)
"""Yield displacements z_y the selection tries, as fractions of the reference amplitude X."""
EXPONENTS = (1.0, 2.0, 4.0)
"""Knee exponents n the selection tries (1: Dahl's friction; 4: nearly a Jenkins element)."""
EXPONENT_BOUNDS = (1.0, 12.0)
"""Where the refinement and the refit may take n: from Dahl's (below 1 the rate's slope in z is infinite at
z = 0, which the rate term's steps cannot take, :class:`hysid_model.effects.bouc_wen.BoucWen`) to a knee within
a few per cent of the elastic-plastic corner."""
PHYSICAL = {"zy": (0.0, math.inf), "n": (EXPONENT_BOUNDS[0], 10.0 * EXPONENT_BOUNDS[1])}
"""The physical ranges of the shapes, within which a fit that ends on a search bound widens it (a user's term's
parameters have none: its rate is not defined for n <= 0, nor for z_y <= 0; and the module's rate term, integrated,
holds the orbit to 0.2 % of c at n = 120 but overflows at 1200, where the knee is a Jenkins slider's either way)."""
RATE = "{c} / {zy} * (v - np.abs(v) * np.abs(z / {s}) ** {n} * np.sign(z / {s}))"
"""The rate dF/dt of the force F = z (N) as a numpy expression in z, x and v; ``{s}`` is c where it may be 0."""
RATE_NOTATION = "dF/dt = {c} / {zy} (v - |v| |F / {c}|^{n} sgn(F / {c})), F the force"


@dataclass(frozen=True)
class MemoryFamily(Family):
    """The Bouc-Wen internal variable u = z / z_y of loops whose displacement runs between ``x_min`` and ``x_max``
    (m, one each), as a family of discovery (module docstring): :meth:`evaluate` is its orbit at the loops' samples."""

    x_min: tuple[float, ...] = ()
    x_max: tuple[float, ...] = ()

    def evaluate(self, x: np.ndarray, v: np.ndarray, shape: dict[str, float]) -> np.ndarray:
        """u at ``x``, ``v`` ``(L, N)`` (loop l's samples on row l) on each loop's periodic orbit: the travel since the
        last reversal is x - x_min where v >= 0 (loading), x_max - x elsewhere."""
        lo, hi = np.array(self.x_min)[:, None], np.array(self.x_max)[:, None]
        loading = np.asarray(v) >= 0.0
        travel = np.clip(np.where(loading, x - lo, hi - x), 0.0, hi - lo)
        return state(np.array([float(shape["zy"])]), np.array([float(shape["n"])]), 0.5 * (hi - lo)[:, 0], travel[None], np.where(loading, 1.0, -1.0)[None])[0]


def state(zy: np.ndarray, n: np.ndarray, spans: np.ndarray, travel: np.ndarray, sign: np.ndarray) -> np.ndarray:
    """u = z / z_y ``(P, L, N)`` of candidates of yield displacement ``zy`` and exponent ``n`` ``(P,)`` on the orbits
    of loops of half spans ``spans`` ``(L,)``, at the ``travel`` since the last reversal on the branch ``sign``
    ``(L, N)`` or ``(P or 1, L, N)``: :func:`hysid_model.bouc_wen_orbit.bouc_wen_exact` with r = :data:`SHAPE_R`."""
    from hysid_model.bouc_wen_orbit import bouc_wen_exact  # compiled: on first use, a fast CLI and island start

    if travel.ndim == 2 and zy.size > 1:  # one motion for all: each distinct (z_y, n) once (a Jacobian's rows share most)
        unique, inverse = np.unique(np.column_stack([zy, n]), axis=0, return_inverse=True)
        if unique.shape[0] < zy.size:
            return state(unique[:, 0], unique[:, 1], spans, travel, sign)[inverse.reshape(-1)]
    shape = (zy.size,) + travel.shape[-2:]
    out = np.empty(shape)
    bouc_wen_exact(
        np.ascontiguousarray(n, dtype=float),
        np.full(zy.size, SHAPE_R),
        np.ascontiguousarray(zy, dtype=float),
        np.ascontiguousarray(spans, dtype=float),
        np.arange(spans.size, dtype=np.int64),
        np.ascontiguousarray(np.broadcast_to(travel, shape), dtype=float),
        np.ascontiguousarray(np.broadcast_to(sign, shape), dtype=float),
        out,
    )
    return out / zy[:, None, None]


class StateTerm(RateTerm):
    """A memory law's term in the diagnosing process: the rate term the module defines (its law, name and parameters),
    its orbit from the compiled exact solver (module docstring). ``shape`` names the strength c, and z_y and n by
    their parameters' names or, fixed, their values."""

    def __init__(self, made: UserTerm, shape: tuple[str, str | float, str | float]) -> None:
        super().__init__(made.law, made.id, made.params, made.explanation, made.strength, made._modules)
        self.shape = shape

    def time_force(self, v: Values, state_: ModalState, kin: Kinematics, phase: np.ndarray, n_top: int | None = None) -> np.ndarray:
        """c u on each loop's orbit at ``phase`` ``(L, N)`` or ``(P, L, N)``, less its mean over a cycle (rate
        independent: the travel since the last reversal decides, so ``n_top`` changes nothing)."""
        size = next(iter(v.values())).shape[0]
        c, zy, n = (v[s][:, 0] if isinstance(s, str) else np.full(size, float(s)) for s in self.shape)
        x_min, x_max = kin.extremes

        def u(at: np.ndarray) -> np.ndarray:
            travel, sign = travels(kin, at)
            return state(zy, n, 0.5 * (x_max - x_min), np.clip(travel, 0.0, (x_max - x_min)[:, None]), sign)

        with np.errstate(all="ignore"):
            return c[:, None, None] * (u(phase) - u(mean_grid(kin.x0.size)).mean(axis=-1, keepdims=True))

    def sampler(self, kin: Kinematics, phase: np.ndarray, n_top: int | None = None) -> StateSampler:
        return StateSampler(self, kin, phase)


class StateSampler(RateSampler):
    """:meth:`StateTerm.time_force` at fixed phases ``(L, N)`` (shifted per candidate where a delay asks): no cycle to
    integrate, unlike the rate term's sampler it stands in for."""

    def __init__(self, term: StateTerm, kin: Kinematics, phase: np.ndarray) -> None:
        self.state_term, self.kin, self.phase = term, kin, phase

    def add(self, v: Values, shift: np.ndarray | None, out: np.ndarray) -> None:
        at = self.phase if shift is None else self.phase[None] - shift[:, :, None]
        out += self.state_term.time_force(v, ModalState(xi=np.zeros(1), wn=np.zeros(1), m=np.zeros(1)), self.kin, at)


def compiled_term(made: UserTerm, strength: str, zy: str | float, n: str | float) -> StateTerm:
    """``made`` (checked and registered by :func:`hysid_model.user_terms.term`) as a :class:`StateTerm`, registered in
    its place under its name."""
    fast = StateTerm(made, (strength, zy, n))
    register(fast)
    return fast


def memory_families(x_ref: float, x_min: np.ndarray, x_max: np.ndarray) -> list[Family]:
    """The memory family for loops between ``x_min`` and ``x_max`` (m, per loop) of reference amplitude ``x_ref`` (m)."""
    zy = Shape("zy", "m", (1e-3 * x_ref, 10.0 * x_ref), tuple(x_ref * f for f in YIELD_FRACTIONS), "yield displacement")
    n = Shape("n", "1", EXPONENT_BOUNDS, EXPONENTS, "knee exponent")
    lo, hi = (tuple(float(e) for e in np.ravel(a)) for a in (x_min, x_max))
    return [MemoryFamily("bouc_wen_state", RATE, RATE_NOTATION, (zy, n), lo, hi)]


def is_memory(family: Family) -> bool:
    return isinstance(family, MemoryFamily)


def rate_expression(shown: dict[str, str], plain: bool = False) -> str:
    """The rate of a memory term's force with its strength ``c`` and shapes ``zy``, ``n`` shown as ``shown`` (names or
    numbers, as text): numpy in z, x, v (``plain``: the notation). The scale ``s`` under |F / c| is c itself where c is
    a number, ``np.where(c == 0.0, 1.0, c)`` where it is a name (the term at strength 0 has F = 0, and no rate); in the
    notation a yield displacement given as a number is in m."""
    c, zy = shown["c"], shown["zy"]
    scale = c if plain or not c.isidentifier() else f"np.where({c} == 0.0, 1.0, {c})"
    return (RATE_NOTATION if plain else RATE).format(c=c, zy=zy + (" m" if plain and not zy.isidentifier() else ""), n=shown["n"], s=scale)


def with_physical(params: tuple[Parameter, ...], mapping: dict[str, str]) -> tuple[Parameter, ...]:
    """A memory term's parameters with its shapes' :data:`PHYSICAL` ranges; ``mapping`` takes a shape's symbol to its
    parameter's name."""
    ranges = {mapping[s]: bounds for s, bounds in PHYSICAL.items() if s in mapping}
    return tuple(replace(p, physical=ranges[p.name]) if p.name in ranges else p for p in params)
