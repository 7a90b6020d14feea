"""Local polish of a GA/PSO result by bounded least squares (the calculus-based refinement of section 3.1).

The thesis notes that a GA "may be also used to identify an initial guess for
calculus-based optimization techniques, in order to locally refine the
search". The objective of Eq. 3.3 with the loop weights of Appendix A is a
sum of squares of ``objective.weighted_residuals``, so the refinement is a
bounded trust-region least-squares fit (``scipy.optimize.least_squares``,
method ``trf``) started at the heuristic's best, with the objective's own
Jacobian and tight tolerances: on a noiseless data set it reaches the true
parameters to about 1e-9 relative.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hysid_model.blas import one_blas_thread

MEMORY_NFEV = 2000
"""Residual calls of a polish on a model with memory by default: scipy's 100 D ran out before convergence
on a real MR damper ("maximum number of function evaluations exceeded")."""
TOLERANCE = 1e-15
"""ftol, xtol and gtol of the least-squares solver: stop only at convergence to machine precision."""


@dataclass
class PolishResult:
    """The polished parameters, their objective value and the cost of getting there."""

    theta: np.ndarray
    fitness: float
    evaluations: int
    """Residual-vector calls plus Jacobian probes (2 D model evaluations per Jacobian)."""
    success: bool
    message: str


def polish(objective: Any, theta0: np.ndarray, *, max_nfev: int | None = None) -> PolishResult:
    """Refine ``theta0`` within ``objective.bounds``; never returns a worse point than the start.

    ``objective`` needs ``weighted_residuals(theta)`` (whose sum of squares is
    the fitness), ``jacobian(theta)`` and ``bounds`` (D, 2), as
    :class:`hysid_model.objective.Objective` provides. ``max_nfev`` caps the
    residual calls (when None: :data:`MEMORY_NFEV` on a model with memory, else scipy's default, 100 D).
    """
    from scipy.optimize import least_squares  # on first use: a fast CLI and island start

    bounds = np.asarray(objective.bounds, dtype=float)
    if max_nfev is None and getattr(getattr(objective, "model", None), "has_memory", False):
        max_nfev = MEMORY_NFEV
    start = np.clip(np.asarray(theta0, dtype=float).reshape(-1), bounds[:, 0], bounds[:, 1])
    r0 = objective.weighted_residuals(start)
    f0 = float(r0 @ r0)
    if not np.isfinite(f0):
        return PolishResult(start, np.inf, 1, False, "the objective cannot be computed at the start point")
    probes_per_jacobian = 2 * start.size
    calls = {"residuals": 0}

    def residuals(theta: np.ndarray) -> np.ndarray:
        calls["residuals"] += 1
        return objective.weighted_residuals(theta)

    def jacobian(theta: np.ndarray) -> np.ndarray:
        # A probe that leaves the computable region (e.g. a memory term that
        # diverges) carries no slope information: treat it as flat.
        jac = objective.jacobian(theta)
        return np.where(np.isfinite(jac), jac, 0.0)

    try:
        with one_blas_thread():  # the solver's decompositions are a few columns wide
            result = least_squares(
                residuals,
                start,
                jac=jacobian,
                bounds=(bounds[:, 0], bounds[:, 1]),
                method="trf",
                x_scale="jac",
                ftol=TOLERANCE,
                xtol=TOLERANCE,
                gtol=TOLERANCE,
                max_nfev=max_nfev,
            )
    except ValueError as exc:
        return PolishResult(start, f0, 1 + calls["residuals"], False, f"least squares stopped: {exc}")
    evaluations = 1 + int(result.nfev) + probes_per_jacobian * int(result.njev or 0)
    fitness = float(result.fun @ result.fun)
    if not fitness <= f0:
        return PolishResult(start, f0, evaluations, False, f"least squares ended worse than its start ({result.message})")
    return PolishResult(np.asarray(result.x, dtype=float), fitness, evaluations, bool(result.success), str(result.message))
