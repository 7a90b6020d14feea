"""Compiled kernel (numba) of an objective's sums of squares: each candidate's residual per loop, its linear
features' force plus its memory force less the measured force, squared and summed (Eq. 3.3).

:class:`hysid_model.sampled.SampledMemory` calls it where a model has memory terms or a measurement chain;
compiled on first use and cached on disk (``cache=True``).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, fastmath=True, inline="always")
def _square_sum(residual: np.ndarray) -> float:
    """sum of residual^2 (``fastmath``: in vector lanes, a few ulps from the sequential sum)."""
    total = 0.0
    for n in range(residual.shape[0]):
        total += residual[n] * residual[n]
    return total


@njit(cache=True, nogil=True, fastmath=True)
def sum_of_squares(coef: np.ndarray, features: np.ndarray, memory: np.ndarray, y: np.ndarray, out: np.ndarray) -> None:
    """out[p, l] = sum_n (sum_m coef[p, l, m] features[l, m, n] + memory[p, l, n] - y[l, n])^2.

    ``features`` is feature-major ``(L, M, N)`` so that each pass over the samples is one
    contiguous vector loop (``fastmath`` lets the final sum run in vector lanes: its rounding
    differs from a sequential sum by a few ulps; a non-finite force still sums to a non-finite value).
    """
    n_pop, n_loops, n_features = coef.shape
    n_samples = y.shape[1]
    residual = np.empty(n_samples)
    for l in range(n_loops):  # loop-major: the loop's features and data stay in cache across candidates
        for p in range(n_pop):
            for n in range(n_samples):
                residual[n] = memory[p, l, n] - y[l, n]
            for m in range(n_features):
                a = coef[p, l, m]
                for n in range(n_samples):
                    residual[n] += a * features[l, m, n]
            out[p, l] = _square_sum(residual)
