"""Sparse selection of candidate columns by FROLS, and the refinement of their shapes by nonlinear least squares.

Forward regression with orthogonal least squares (Billings' FROLS): at each step every remaining column w_k,
orthogonalised against the columns selected so far, would remove (w_k . r)^2 / (w_k . w_k) of the squared
target r left (its error-reduction ratio is that over the target's sum of squares); the column that removes
the most is selected while it removes more than the step's ``threshold`` (an information criterion or a
significance level, the caller's rule), and the target and the other columns are orthogonalised against it.
Here the target is the whitened harmonic residual of the best library model and the columns are the candidate
forces in the same coordinates with what the model's own parameters (its spring, dashpot, mass, effects)
already absorb projected out: what a column removes is what a new term could explain that the model cannot.

Written with numpy and scipy alone: PySINDy and SysIdentPy select terms of an ODE's derivative (or of a
NARX model's next sample) from time series, whereas here the target is a force residual on loop branches in
whitened harmonic coordinates with the model's absorption projected out; the selection itself is some
thirty lines, not worth a dependency with its own data conventions.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

COLLINEAR = 1e-3
"""A column whose norm, orthogonalised against those selected (and the model), falls below this fraction of
its own is nothing new: it is not selected."""


@dataclass
class Selected:
    """One column selected by :func:`frols`."""

    index: int
    removed: float
    """Squared target it removes after the ones selected before it."""
    err: float
    """Its error-reduction ratio: ``removed`` over the target's sum of squares."""


def frols(
    columns: np.ndarray, target: np.ndarray, threshold: Callable[[list[int], int], float], max_terms: int, cost: np.ndarray | None = None
) -> list[Selected]:
    """Columns of ``columns`` ``(N, K)`` selected to explain ``target`` ``(N,)``, in order; after the columns
    ``chosen`` (their indices), column ``k`` is selected only if it removes more than ``threshold(chosen, k)``
    (infinite: never); at most ``max_terms``. Of those that may be selected, the one that removes the most less
    its ``cost`` (``(K,)``, e.g. its parameters' ln N: the information criterion's choice; default none)."""
    w = np.array(columns, dtype=float, copy=True)
    r = np.array(target, dtype=float, copy=True)
    own = np.maximum(np.sum(w**2, axis=0), 1e-300)
    total = float(r @ r)
    chosen: list[Selected] = []
    for _ in range(max_terms):
        norms = np.sum(w**2, axis=0)
        usable = norms > COLLINEAR**2 * own
        removed = np.where(usable, (r @ w) ** 2 / np.where(usable, norms, 1.0), -1.0)
        taken = [s.index for s in chosen]
        removed[taken] = -1.0
        limits = np.array([threshold(taken, k) for k in range(removed.size)])
        net = removed - (0.0 if cost is None else cost)
        k = int(np.argmax(np.where(removed > limits, net, -np.inf)))
        if removed[k] <= limits[k]:
            break
        chosen.append(Selected(k, float(removed[k]), float(removed[k] / max(total, 1e-300))))
        q = w[:, k] / np.sqrt(norms[k])
        w -= np.outer(q, q @ w)
        r -= q * (q @ r)
    return chosen


@dataclass
class Refined:
    """Shapes and linear coefficients of the selected columns at the least-squares optimum."""

    shapes: np.ndarray
    coefficients: np.ndarray
    chi2: float


def coefficients(g: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The coefficients c minimising |target + g c|^2 (the target is a model-minus-data residual, the new
    force subtracts it) and the residual left."""
    c = np.linalg.lstsq(g, -target, rcond=None)[0]
    return c, target + g @ c


def refine(make: Callable[[np.ndarray], np.ndarray], target: np.ndarray, start: np.ndarray, bounds: tuple[np.ndarray, np.ndarray]) -> Refined:
    """The shape parameters (``start`` within ``bounds``) that minimise what ``make(shapes)`` ``(N, k)`` leaves of
    ``target`` with its coefficients at their least squares (variable projection), by scipy's bounded
    ``least_squares`` from the selection's grid point; without shape parameters, the least squares alone."""
    from scipy.optimize import least_squares  # on first use: a fast CLI and island start

    start = np.clip(np.asarray(start, dtype=float), bounds[0], bounds[1])
    if start.size:
        span = bounds[1] - bounds[0]

        def left(s: np.ndarray) -> np.ndarray:
            g = make(s)
            if not np.all(np.isfinite(g)):
                return np.full(target.shape, 1e150)
            return coefficients(g, target)[1]

        found = least_squares(left, start, bounds=bounds, x_scale=np.where(span > 0, span, 1.0), max_nfev=200, diff_step=1e-4)
        better = float(found.fun @ found.fun) < float(left(start) @ left(start))
        start = found.x if better else start
    c, rest = coefficients(make(start), target)
    return Refined(start, c, float(rest @ rest))
