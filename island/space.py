"""The optimizer's coordinates: positive scale parameters on a log scale, the physics' parameters unchanged.

A memory model's parameters span decades within their bounds (a Bouc-Wen yield
displacement from microns to the stroke, a hysteretic stiffness from 0 to ten
times the survey's, a mass over four decades) and trade off along curved
ridges: with z_y well below the amplitude only the yield force k_bw z_y shows,
and with a negligible mass only k = m wn^2 and c = 2 m xi wn do. Uniform draws
in such bounds put almost every candidate at the large end (a yield
displacement of the stroke's order, where the loop shows no hysteresis), and a
least-squares step along the ridge k_bw z_y = const is a curve. In the
optimizer's coordinates

    u = log(theta + s)

for every parameter whose bounds lie in a non-negative physical range and span
at least :data:`LOG_SPAN` (``s`` = 0 for a positive lower bound; else
:data:`ZERO_SHIFT` of the upper bound, so that 0 stays reachable: a friction
force or a hysteretic stiffness that is absent), those ridges become straight
lines (log k_bw + log z_y = const) and uniform draws cover every decade. The
model, its bounds and every result stay in the physics' parameters; only the
search moves in ``u``.

:class:`SearchSpace` maps between the two; :class:`SpaceObjective` is an
objective in ``u`` of an objective in theta with the contract of :class:`hysid_model.objective.Objective`
(``__call__`` on a population, ``weighted_residuals``, ``residual_rows``, ``jacobian``,
``bounds``, ``model``, ``evaluations``), so the optimizers and the polish of
:mod:`island.polish` run on it unchanged. Its Jacobian is a central difference
in ``u`` (a step relative to the value for the log-scaled parameters).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hysid_model.objective import Bounded

LOG_SPAN = 100.0
"""The least ratio (upper + s) / (lower + s) of bounds searched on a log scale."""
ZERO_SHIFT = 1e-6
"""s / upper for a parameter whose lower bound is 0 (an effect's strength, a damping ratio)."""
JACOBIAN_STEP = 1e-6
"""Central-difference step in ``u``, relative to the range of ``u`` (a relative step in theta where logged)."""


class SearchSpace:
    """The map theta <-> u for ``bounds`` ``(D, 2)`` of parameters whose physical lower limits are ``floors``."""

    def __init__(self, bounds: np.ndarray, floors: np.ndarray) -> None:
        self.theta_bounds = np.array(bounds, dtype=float).reshape(-1, 2)
        lower, upper = self.theta_bounds[:, 0], self.theta_bounds[:, 1]
        self.shift = np.where(lower > 0, 0.0, ZERO_SHIFT * upper)
        self.logged = (np.asarray(floors, dtype=float) >= 0) & (lower >= 0) & (upper + self.shift >= LOG_SPAN * (lower + self.shift))
        self.bounds = np.column_stack([self.to_u(lower), self.to_u(upper)])
        """Bounds of ``u``."""

    @classmethod
    def of(cls, model: Any) -> SearchSpace:
        """The space of a :class:`hysid_model.model.Model`'s free parameters (their bounds and physical ranges)."""
        return cls(model.bounds, np.array([p.physical[0] for p in model.parameters]))

    @property
    def dim(self) -> int:
        return self.theta_bounds.shape[0]

    def to_u(self, theta: np.ndarray) -> np.ndarray:
        theta = np.asarray(theta, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.logged, np.log(np.maximum(theta + self.shift, 1e-300)), theta)

    def to_theta(self, u: np.ndarray) -> np.ndarray:
        """theta of ``u`` (any shape ending in D), clipped into the theta bounds (exp's rounding at the ends)."""
        u = np.asarray(u, dtype=float)
        with np.errstate(over="ignore"):
            theta = np.where(self.logged, np.exp(u) - self.shift, u)
        return np.clip(theta, self.theta_bounds[:, 0], self.theta_bounds[:, 1])


class SpaceObjective(Bounded):
    """``objective`` seen in the coordinates ``u`` of :class:`SearchSpace` (module docstring).

    ``evaluations`` counts model evaluations as the benches do: a candidate of a
    population, a residual vector, and each probe of a Jacobian.
    """

    def __init__(self, objective: Any, space: SearchSpace | None = None) -> None:
        self.objective = objective
        self.space = space or SearchSpace.of(objective.model)
        self.evaluations = 0

    @property
    def model(self) -> Any:
        return self.objective.model

    @property
    def bounds(self) -> np.ndarray:
        return self.space.bounds

    def __call__(self, pop: np.ndarray) -> np.ndarray:
        pop = np.atleast_2d(np.asarray(pop, dtype=float))
        self.evaluations += pop.shape[0]
        return self.objective(self.space.to_theta(pop))

    def weighted_residuals(self, u: np.ndarray) -> np.ndarray:
        self.evaluations += 1
        return self.objective.weighted_residuals(self.space.to_theta(np.asarray(u, dtype=float).reshape(-1)))

    def jacobian(self, u: np.ndarray) -> np.ndarray:
        """d(weighted residuals)/du by central differences, probes kept inside the bounds of ``u``: the 2 D
        probes evaluated in one call of the objective's ``residual_rows``."""
        u = np.asarray(u, dtype=float).reshape(-1)
        lower, upper = self.bounds[:, 0], self.bounds[:, 1]
        h = JACOBIAN_STEP * (upper - lower)
        step = np.eye(u.size, dtype=bool)
        up = np.where(step, np.minimum(u + h, upper), u)
        down = np.where(step, np.maximum(u - h, lower), u)
        rows = self.objective.residual_rows(self.space.to_theta(np.concatenate([up, down])))
        self.evaluations += 2 * u.size
        return ((rows[: u.size] - rows[u.size :]) / (np.diag(up) - np.diag(down))[:, None]).T
