"""How a user's term evaluates its force: the term classes that :func:`hysid_model.user_terms.term` makes.

* :class:`FunctionTerm`: a force law ``fn(x, v, **params)`` of the motion alone, evaluated at the
  samples' displacement and velocity (:func:`motion`) less its mean over a cycle;
* :class:`RateTerm`: a force with memory, the periodic orbit of a state z with dz/dt = ``rate(z, x, v,
  **params)``, found by the secant method on the cycle map of :data:`STEPS` exponential
  Rosenbrock-Euler steps and read at the samples by cubic Hermite interpolation.

Both are memory terms to the model (:meth:`~hysid_model.terms.Term.time_force`), and each has a
sampler that prepares the motion at a loop set's fixed phases once (:mod:`hysid_model.sampled`).
What a term is called, how it is checked when made and how another process finds it is
:mod:`hysid_model.user_terms`.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Collection
from itertools import product
from typing import Any

import numpy as np

from hysid_model.effects.bouc_wen import mean_grid
from hysid_model.errors import HysidInputError
from hysid_model.kinematics import Kinematics
from hysid_model.params import Parameter
from hysid_model.terms import ModalState, Term, Values

STEPS = 256
"""Steps per cycle of a rate term's state (a multiple of 4: the ideal sine's reversals fall on their ends)."""
DIFFERENCE = 1e-7
"""Relative step of the forward difference that gives a rate's derivative in the state."""
SECANT_FLOOR = 1e-12
"""A change of z(2 pi) - z(0) between two starts below this times their size is rounding: no secant through it
(a state that drifts by the same amount from every start has no periodic solution, and gets none)."""
MAX_CYCLES = 40
"""Cycles integrated at most while the secant method looks for the periodic orbit."""
ORBIT_RTOL = 1e-9
"""The orbit is periodic once z(2 pi) - z(0) is below this times the range of z over the cycle (not its size: a
state that drifts without bound would pass that)."""
GRID_VALUES = 3
"""Values per shape parameter (every parameter but the strength) on a term's :meth:`~UserTerm.shape_grid`."""


def motion(kin: Kinematics, phase: np.ndarray, n_top: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Displacement (m) and velocity (m/s) at phases ``(L, N)`` or ``(P, L, N)``, each ``(1 or P, L, N)``; where
    ``n_top`` is given, at samples of the loops' branches (:meth:`~hysid_model.kinematics.Kinematics.velocity`:
    each moves in its branch's direction, a sample at a reversal too)."""
    phase = phase if phase.ndim == 3 else phase[None]
    return kin.displacement(phase), kin.velocity(phase, n_top)


def shaped(made: UserTerm, value: Any, shape: tuple[int, ...]) -> np.ndarray:
    """The user's function's result as float ``shape`` (a one-line error where it does not broadcast to it)."""
    out = np.asarray(value, dtype=float)
    try:
        return np.broadcast_to(out, shape)
    except ValueError:
        what = "rate" if isinstance(made, RateTerm) else "fn"
        raise HysidInputError(f"term {made.id!r}: {what} returns shape {out.shape}, which is not {shape} (or broadcastable to it)", param=what) from None


class UserTerm(Term):
    """A term made from a user's function (:func:`term`); see the module docstring."""

    memory = True

    def __init__(self, law: Callable[..., Any], name: str, params: tuple[Parameter, ...], explanation: str, strength: str, modules: tuple[str, ...]) -> None:
        self.id = name
        self.law = law
        self.params = params
        self.explanation = explanation
        self.strength = strength
        self._modules = modules
        self._reference: str | None = None

    @property
    def reference(self) -> str | None:
        """``module:attribute`` by which another process imports this term: the one it was imported by, else
        where it is an attribute of the module that made it or of its function's module; None for a term
        that is none (made in ``__main__``, a notebook, a function's body)."""
        if self._reference is not None:
            return self._reference
        for name in self._modules:
            module = sys.modules.get(name)
            if name == "__main__" or module is None:
                continue
            attribute = next((key for key, value in list(vars(module).items()) if value is self), None)
            if attribute is not None:
                return f"{name}:{attribute}"
        return None

    @property
    def spec(self) -> str:
        """``module:attribute`` (:attr:`reference`) where there is one, else the term's name."""
        return self.reference or self.id

    def shape_grid(self, kin: Kinematics, free: Collection[str] = ()) -> list[dict[str, float]]:
        """:data:`GRID_VALUES` values of each parameter but the strength across its bounds (geometric where the
        bounds are positive and span more than a decade), every combination: what the strength's signature
        is scored at, since at strength 0 nothing shows the others."""
        axes = []
        for p in self.params:
            if p.name == self.strength:
                continue
            at = (np.arange(GRID_VALUES) + 0.5) / GRID_VALUES
            if p.lower > 0.0 and p.upper > 10.0 * p.lower:
                values = p.lower * (p.upper / p.lower) ** at
            else:
                values = p.lower + (p.upper - p.lower) * at
            axes.append([(p.name, float(v)) for v in values])
        return [dict(combo) for combo in product(*axes)]

    def arguments(self, v: Values, extra_axes: int) -> dict[str, np.ndarray]:
        """The term's parameters of candidates ``v`` (each ``(P, 1)``) with ``extra_axes`` more axes."""
        return {p.name: v[p.name].reshape(v[p.name].shape + (1,) * extra_axes) for p in self.params}

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.spec}: {', '.join(p.name for p in self.params)})"


class FunctionTerm(UserTerm):
    """A force ``fn(x, v, **params)`` of the displacement and velocity alone."""

    def forces(self, v: Values, x: np.ndarray, vel: np.ndarray) -> np.ndarray:
        """The law at ``x``, ``vel`` ``(1 or P, L, N)`` for candidates ``v``: ``(P, L, N)``."""
        shape = (next(iter(v.values())).shape[0],) + x.shape[1:]
        return shaped(self, self.law(x, vel, **self.arguments(v, 1)), shape)

    def centred(self, v: Values, at: tuple[np.ndarray, np.ndarray], grid: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        """The force at the motion ``at`` less its mean over the uniform phases of ``grid``."""
        return self.forces(v, *at) - self.forces(v, *grid).mean(axis=-1, keepdims=True)

    def time_force(self, v: Values, state: ModalState, kin: Kinematics, phase: np.ndarray, n_top: int | None = None) -> np.ndarray:
        return self.centred(v, motion(kin, phase, n_top), motion(kin, mean_grid(kin.x0.size)))

    def sampler(self, kin: Kinematics, phase: np.ndarray, n_top: int | None = None) -> FunctionSampler:
        return FunctionSampler(self, kin, phase, n_top)


class FunctionSampler:
    """:meth:`FunctionTerm.time_force` at fixed phases ``(L, N)``, the motion there and on the mean's grid computed once."""

    def __init__(self, term: FunctionTerm, kin: Kinematics, phase: np.ndarray, n_top: int | None = None) -> None:
        self.term, self.kin, self.phase, self.n_top = term, kin, phase, n_top
        self.at = motion(kin, phase, n_top)
        self.grid = motion(kin, mean_grid(kin.x0.size))

    def add(self, v: Values, shift: np.ndarray | None, out: np.ndarray) -> None:
        at = self.at if shift is None else motion(self.kin, self.phase[None] - shift[:, :, None])  # delayed: the motion's own direction
        out += self.term.centred(v, at, self.grid)


class Cycle:
    """A loop set's motion over one cycle of :data:`STEPS` steps: at their middles (what a step sees) and at their
    ends (where the orbit is interpolated from), and each loop's time step."""

    def __init__(self, kin: Kinematics) -> None:
        theta = np.broadcast_to(np.arange(2 * STEPS + 1) * (np.pi / STEPS), (kin.x0.size, 2 * STEPS + 1))
        x, vel = motion(kin, theta)
        self.x, self.v = x[0, :, 1::2].T.copy(), vel[0, :, 1::2].T.copy()
        """``(STEPS, L)``: x and v in the middle of each step."""
        self.ends = (x[0, :, ::2], vel[0, :, ::2])
        """``(L, STEPS + 1)``: x and v at the steps' ends."""
        self.omega = kin.omega
        self.dt = 2.0 * np.pi / (STEPS * kin.omega)
        """Each loop's time step, ``(L,)``."""


def phi1(a: np.ndarray) -> np.ndarray:
    """(exp(a) - 1) / a, 1 at a = 0."""
    small = np.abs(a) < 1e-8
    return np.where(small, 1.0 + 0.5 * a, np.expm1(a) / np.where(small, 1.0, a))


class RateTerm(UserTerm):
    """A force with memory: the periodic orbit of a state z (N) with dz/dt = ``rate(z, x, v, **params)``.

    Each step of a cycle is an exponential Rosenbrock-Euler step at the step's middle,
    z += dt phi1(dt J) f, with f and J = df/dz (a forward difference) taken at the motion of the middle of
    the step: exact where the law is linear in z (Dahl's friction, a Maxwell element, Bouc-Wen's n = 1 on
    each branch), second order otherwise, and stable however stiff the law (a friction law that
    saturates within a small fraction of a step's travel settles onto its saturation instead of
    oscillating, as an explicit Runge-Kutta step would).
    """

    def cycle_map(self, z0: np.ndarray, cycle: Cycle, params: dict[str, np.ndarray], nodes: np.ndarray | None = None) -> np.ndarray:
        """z after one cycle from ``z0`` ``(P, L)``; z at the start of every step and at the end written to ``nodes``
        ``(STEPS + 1, P, L)`` if given. The law is called as it is (the probe checked it when the term was made):
        this loop is the term's cost."""
        z, dt, rate = z0, cycle.dt, self.law
        for j in range(STEPS):
            if nodes is not None:
                nodes[j] = z
            x, vel = cycle.x[j], cycle.v[j]
            f = rate(z, x, vel, **params)
            dz = DIFFERENCE * (np.abs(z) + np.abs(f) * dt) + 1e-300
            jac = (rate(z + dz, x, vel, **params) - f) / dz
            z = z + dt * phi1(dt * jac) * f
        if nodes is not None:
            nodes[STEPS] = z
        return z

    def orbit(self, v: Values, cycle: Cycle) -> tuple[np.ndarray, np.ndarray]:
        """The periodic orbit of candidates ``v``: z at the steps' ends ``(P, L, STEPS + 1)`` and dz/d(wt) there (the
        law, at once on the whole orbit); NaN where none was found within :data:`MAX_CYCLES` cycles (the
        candidate's force is then undefined, its fitness infinite).

        The secant method finds the periodic solution z(2 pi) = z(0) whether it attracts (the steady state of a
        law that forgets, within a strength's physical bounds) or repels (e.g. a friction's stiffness below 0):
        it is smooth across, as the finite differences of a polish and of the standard errors at a bound of 0
        need."""
        params = self.arguments(v, 0)
        n_pop, n_loops = next(iter(v.values())).shape[0], cycle.dt.size
        with np.errstate(all="ignore"):
            z_prev = np.zeros((n_pop, n_loops))
            g_prev = self.cycle_map(z_prev, cycle, params) - z_prev
            z = z_prev + g_prev
            nodes = np.empty((STEPS + 1, n_pop, n_loops))
            for _ in range(MAX_CYCLES):
                g = self.cycle_map(z, cycle, params, nodes) - z
                span = np.ptp(nodes, axis=0)
                done = np.abs(g) <= ORBIT_RTOL * span
                if done.all():
                    break
                change = g - g_prev  # a secant step where g changed beyond rounding, else a plain cycle's
                secant = np.abs(change) > SECANT_FLOOR * (np.abs(z) + np.abs(z_prev) + span)
                step = np.where(secant, -g * (z - z_prev) / np.where(secant, change, 1.0), g)
                z_prev, g_prev, z = z, g, z + step
            orbit = np.where(done[:, :, None], nodes.transpose(1, 2, 0), np.nan)
            rates = shaped(self, self.law(orbit, *(a[None] for a in cycle.ends), **self.arguments(v, 1)), orbit.shape)
        return orbit, rates / cycle.omega[None, :, None]

    def centred(self, orbit: tuple[np.ndarray, np.ndarray], phase: np.ndarray) -> np.ndarray:
        """The orbit at ``phase`` ``(L, N)`` or ``(P, L, N)`` less its cycle mean: cubic Hermite between the steps'
        ends, each slope limited to 3 times the step's change where it has its sign (monotone where the orbit
        is: a state that saturates within a step does not overshoot)."""
        z, slope = orbit
        h = 2.0 * np.pi / STEPS
        where = np.mod(phase, 2.0 * np.pi) / h
        j = np.broadcast_to(np.minimum(where.astype(np.int64), STEPS - 1), z.shape[:1] + phase.shape[-2:])
        t = where - j
        z0, z1 = np.take_along_axis(z, j, axis=-1), np.take_along_axis(z, j + 1, axis=-1)
        change = z1 - z0
        s0, s1 = (np.take_along_axis(slope, i, axis=-1) * h for i in (j, j + 1))
        s0, s1 = (np.where(s * change > 0.0, np.sign(s) * np.minimum(np.abs(s), 3.0 * np.abs(change)), s) for s in (s0, s1))
        t2, t3 = t * t, t * t * t
        at = (2 * t3 - 3 * t2 + 1) * z0 + (t3 - 2 * t2 + t) * s0 + (-2 * t3 + 3 * t2) * z1 + (t3 - t2) * s1
        return at - z[..., :STEPS].mean(axis=-1, keepdims=True)

    def time_force(self, v: Values, state: ModalState, kin: Kinematics, phase: np.ndarray, n_top: int | None = None) -> np.ndarray:
        return self.centred(self.orbit(v, Cycle(kin)), phase)  # the orbit is continuous at a reversal: no side to take

    def sampler(self, kin: Kinematics, phase: np.ndarray, n_top: int | None = None) -> RateSampler:
        return RateSampler(self, kin, phase)


class RateSampler:
    """:meth:`RateTerm.time_force` at fixed phases ``(L, N)``, the cycle's motion computed once."""

    def __init__(self, term: RateTerm, kin: Kinematics, phase: np.ndarray) -> None:
        self.term, self.cycle, self.phase = term, Cycle(kin), phase

    def add(self, v: Values, shift: np.ndarray | None, out: np.ndarray) -> None:
        out += self.term.centred(self.term.orbit(v, self.cycle), self.phase if shift is None else self.phase[None] - shift[:, :, None])
