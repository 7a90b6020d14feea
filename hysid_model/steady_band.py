"""The steady band search of :func:`hysid_model.steady.steady_run`, compiled (numba).

The search tries a few windows of cycles per cycle of a record, each a handful of sums over two amplitude series
of a few hundred cycles: as numpy calls, their fixed cost was most of the extraction of a short record (a 9 s record
at 2048 Hz: 40 % of it). Compiled, a window costs its arithmetic. The kernels are cached on disk (``cache=True``),
so a new process loads them instead of compiling.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def band_fits(amp: np.ndarray, floor: np.ndarray, spread: np.ndarray, sampling: np.ndarray, i: int, j: int, limits: np.ndarray, min_cycles: int) -> bool:
    """Whether cycles ``i..j-1`` of the amplitudes ``amp`` ``(S, n)`` are steady (:func:`hysid_model.steady.steady_run`):
    each series within its band around its least-squares line (``limits[0]`` of the line or its ``floor``, but for
    isolated cycles: at most ``limits[3]`` of the window, never its first or last), its line changing by at most
    ``limits[1]`` of its level over the window, and, from ``min_cycles`` cycles on, the best parabola's largest
    departure from the line at most ``limits[2]`` of the level or what the noise (``spread``) or the sampling allow.
    ``limits``: (tolerance, drift, curvature, outliers)."""
    tolerance, drift, curvature, outliers = limits[0], limits[1], limits[2], limits[3]
    series, n = amp.shape[0], j - i
    centre = 0.5 * (n - 1)
    uu = 0.0
    for k in range(n):
        uu += (k - centre) * (k - centre)
    level = np.empty(series)
    beta = np.zeros(series)
    for s in range(series):
        total, slope = 0.0, 0.0
        for k in range(n):
            total += amp[s, i + k]
            slope += amp[s, i + k] * (k - centre)
        level[s] = total / n
        if n > 1:
            beta[s] = slope / uu
        if abs(beta[s]) * (n - 1) > drift * abs(level[s]):
            return False
    outside, previous = 0, False
    for k in range(n):
        out = False
        for s in range(series):
            line = level[s] + beta[s] * (k - centre)
            if abs(amp[s, i + k] - line) > max(tolerance * abs(line), floor[s]):
                out = True
        if out:  # an isolated cycle outside the band is scatter; a transient is a run of them, or the window's end
            if k == 0 or k == n - 1 or previous:
                return False
            outside += 1
        previous = out
    if outside > max(1.0, outliers * n):
        return False
    if n < min_cycles:
        return True
    qq, top, mean_square = 0.0, 0.0, uu / n
    for k in range(n):
        q = (k - centre) * (k - centre) - mean_square  # orthogonal to 1 and k - centre
        qq += q * q
        top = max(top, abs(q))
    for s in range(series):
        bend = 0.0
        for k in range(n):
            q = (k - centre) * (k - centre) - mean_square
            bend += (amp[s, i + k] - level[s] - beta[s] * (k - centre)) * q
        bend = abs(bend) / qq * top  # the largest departure of the best parabola from the line
        if not bend <= max(curvature * abs(level[s]), max(spread[s] * top / math.sqrt(qq), sampling[s])):
            return False
    return True


@njit(cache=True, nogil=True)
def longest_band_run(amp: np.ndarray, floor: np.ndarray, spread: np.ndarray, sampling: np.ndarray, limits: np.ndarray, min_cycles: int) -> tuple[int, int]:
    """(start, length) of the longest window of cycles that passes :func:`band_fits`. A window that passes holds only
    windows that pass, so a window that never shrinks, slid over the cycles and grown by galloping, finds it."""
    n = amp.shape[1]
    if n <= 1 or band_fits(amp, floor, spread, sampling, 0, n, limits, min_cycles):
        return 0, n
    best_start, best_length, i = 0, 1, 0
    while i + best_length < n:
        j = i + best_length + 1  # a window one cycle longer than the best so far
        if not band_fits(amp, floor, spread, sampling, i, j, limits, min_cycles):
            i += 1
            continue
        step = 1
        while j + step <= n and band_fits(amp, floor, spread, sampling, i, j + step, limits, min_cycles):  # gallop, then bisect
            j += step
            step *= 2
        bad = min(j + step, n + 1)
        while bad - j > 1:
            mid = (j + bad) // 2
            if band_fits(amp, floor, spread, sampling, i, mid, limits, min_cycles):
                j = mid
            else:
                bad = mid
        best_start, best_length = i, j - i
        i += 1
    return best_start, best_length
