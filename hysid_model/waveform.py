"""The measured displacement of a loop as harmonics of its fundamental: x(theta) = sum_k Re[X_k e^{i k theta}].

The thesis prescribes x = X0 sin(wt) (Eq. 4.5); a real shaker adds harmonics
(5-20 % distortion is common). Referenced to the fundamental's phase,
theta = wt + phi, the displacement is

    x(theta) = sum_{k=1..K} Re[X_k e^{i k theta}],      X_1 = -i X0,

so X0 = |X_1| is the fundamental amplitude and the ideal sine is K = 1. A loop
runs between the displacement's minimum (phase theta_lo) and maximum
(theta_hi): the loading branch is theta_lo -> theta_hi (x' > 0), the unloading
branch theta_hi -> theta_lo + 2 pi. A branch sample at displacement x sits at
the phase where x(theta) = x on its branch; for the ideal sine these are
arcsin(x / X0) and pi - arcsin(x / X0).

Arrays: ``xh`` is ``(L, K)`` complex, one row per loop.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from hysid_model.errors import HysidInputError

GRID = 4096
"""Phases per cycle on which extremes are bracketed and branches inverted before Newton refinement."""
NEWTON_STEPS = 6


def ideal(x0: np.ndarray) -> np.ndarray:
    """The harmonics of x = X0 sin(theta): ``(L, 1)`` with X_1 = -i X0."""
    return (-1j * np.asarray(x0, dtype=float)).reshape(-1, 1)


def orders(xh: np.ndarray) -> np.ndarray:
    return np.arange(1, xh.shape[-1] + 1)


def displacement(xh: np.ndarray, theta: np.ndarray, derivative: int = 0) -> np.ndarray:
    """d^n x / d theta^n at phases ``theta`` ``(L, N)`` (or ``(..., L, N)``), same shape."""
    return _derivatives(xh, theta, (derivative,))[0]


def _derivatives(xh: np.ndarray, theta: np.ndarray, derivatives: tuple[int, ...]) -> list[np.ndarray]:
    """:func:`displacement` for several derivatives at the same phases, the waves e^{ik theta} computed once."""
    k = orders(xh)
    waves = np.exp(1j * np.asarray(theta)[..., None] * k)  # (..., L, N, K)
    return [np.einsum("...lnk,lk->...ln", waves, xh * (1j * k) ** n).real for n in derivatives]


def on_grid(xh: np.ndarray, theta: np.ndarray, derivative: int = 0) -> np.ndarray:
    """:func:`displacement` at many phases ``theta`` ``(L, N)`` at once, e^{ik theta} as powers of e^{i theta}: a
    complex exponential per phase instead of one per phase and order (ten times faster at 4096 phases and 7 orders),
    exact to about k x 1e-16 of the amplitude. For the grids on which extremes are bracketed and branches inverted;
    Newton then refines with :func:`displacement`."""
    z = np.exp(1j * np.asarray(theta, dtype=float))
    amp = xh * (1j * orders(xh)) ** derivative
    power = z.copy()
    total = amp[:, :1] * power
    for k in range(1, xh.shape[1]):
        power *= z
        total += amp[:, k : k + 1] * power
    return total.real


def thd(xh: np.ndarray) -> np.ndarray:
    """Total harmonic distortion: rms of harmonics 2..K over the fundamental, per loop."""
    return np.sqrt(np.sum(np.abs(xh[:, 1:]) ** 2, axis=1)) / np.abs(xh[:, 0])


def _refine_extreme(xh: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Newton on x'(theta) = 0 from ``theta`` (L,)."""
    for _ in range(NEWTON_STEPS):
        d1, d2 = (d[:, 0] for d in _derivatives(xh, theta[:, None], (1, 2)))
        step = np.where(np.abs(d2) > 0, d1 / np.where(d2 == 0, 1.0, d2), 0.0)
        theta = theta - np.clip(step, -np.pi / GRID, np.pi / GRID)
    return theta


def reversals(xh: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Phases (theta_lo, theta_hi) of each loop's displacement minimum and maximum, with theta_lo < theta_hi < theta_lo + 2 pi.

    A loop set's harmonics are fixed data while a fit evaluates its model many times, so the
    result is kept per distinct ``xh`` (:data:`REVERSALS_KEPT` of them)."""
    xh = np.ascontiguousarray(xh, dtype=complex)
    lo, hi = _reversals(xh.tobytes(), xh.shape)
    return lo.copy(), hi.copy()


REVERSALS_KEPT = 64


@lru_cache(maxsize=REVERSALS_KEPT)
def _reversals(data: bytes, shape: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    xh = np.frombuffer(data, dtype=complex).reshape(shape)
    grid = np.linspace(-np.pi, np.pi, GRID, endpoint=False)
    x = on_grid(xh, np.broadcast_to(grid, (xh.shape[0], GRID)))
    lo = _refine_extreme(xh, grid[np.argmin(x, axis=1)])
    hi = _refine_extreme(xh, grid[np.argmax(x, axis=1)])
    hi = lo + np.mod(hi - lo, 2 * np.pi)
    return lo, hi


def reversal_count(xh: np.ndarray) -> np.ndarray:
    """How often x' changes sign per cycle, per loop (2 for a loop with one loading and one unloading branch)."""
    grid = np.linspace(-np.pi, np.pi, GRID, endpoint=False)
    v = on_grid(xh, np.broadcast_to(grid, (xh.shape[0], GRID)), 1)
    return np.count_nonzero(np.sign(v) != np.sign(np.roll(v, 1, axis=1)), axis=1)


def _exact_where_read(xh: np.ndarray, theta_grid: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """x on the grid ``theta_grid`` ``(L, G)`` (:func:`on_grid`), with :func:`displacement`'s own values at both ends and
    at the two grid points on either side of each target, the only ones the bracketing in :func:`_invert` reads: its
    start, and so the phases Newton ends on, are :func:`displacement`'s to the last bit, at a tenth of the cost."""
    x_grid = on_grid(xh, theta_grid)
    rising = (x_grid[:, -1] >= x_grid[:, 0])[:, None]
    mono = np.maximum.accumulate(np.where(rising, x_grid, -x_grid), axis=1)
    found = np.stack([np.searchsorted(m, t) for m, t in zip(mono, np.where(rising, targets, -targets))])
    last = theta_grid.shape[1] - 1
    near = (found[:, :, None] + np.arange(-2, 2)).reshape(found.shape[0], -1)
    read = np.clip(np.concatenate([near, np.broadcast_to([0, last], (found.shape[0], 2))], axis=1), 0, last)
    np.put_along_axis(x_grid, read, displacement(xh, np.take_along_axis(theta_grid, read, axis=1)), axis=1)
    return x_grid


def _invert(xh: np.ndarray, targets: np.ndarray, start: np.ndarray, stop: np.ndarray) -> np.ndarray:
    """Phases in [start, stop] (per loop) where x(theta) = targets ``(L, N)``; x is monotonic there."""
    u = np.linspace(0.0, 1.0, GRID)
    theta_grid = start[:, None] + (stop - start)[:, None] * u  # (L, G)
    x_grid = _exact_where_read(xh, theta_grid, targets)
    rising = x_grid[:, -1] >= x_grid[:, 0]
    x_mono = np.where(rising[:, None], x_grid, -x_grid)
    x_mono = np.maximum.accumulate(x_mono, axis=1)
    tgt = np.where(rising[:, None], targets, -targets)
    theta = np.stack([np.interp(t, xm, tg) for t, xm, tg in zip(tgt, x_mono, theta_grid)])
    lo, hi = np.minimum(start, stop)[:, None], np.maximum(start, stop)[:, None]
    for _ in range(NEWTON_STEPS):
        x, v = _derivatives(xh, theta, (0, 1))
        step = np.where(np.abs(v) > 1e-12 * np.abs(xh[:, :1]), (x - targets) / np.where(v == 0, 1.0, v), 0.0)
        theta = np.clip(theta - step, lo, hi)
    return theta


def branch_phases(xh: np.ndarray, x_top: np.ndarray, x_bottom: np.ndarray) -> np.ndarray:
    """Phases ``(L, 2n)`` of loading samples at displacements ``x_top`` and unloading samples at ``x_bottom`` (each ``(L, n)``).

    Kept per distinct input (:data:`REVERSALS_KEPT` of them), as :func:`reversals`: every objective
    and projection built on a loop set asks again."""
    arrays = [np.ascontiguousarray(xh, dtype=complex), *(np.ascontiguousarray(a, dtype=float) for a in (x_top, x_bottom))]
    return _branch_phases(*((a.tobytes(), a.shape) for a in arrays)).copy()


@lru_cache(maxsize=REVERSALS_KEPT)
def _branch_phases(xh: tuple[bytes, tuple[int, ...]], top: tuple[bytes, tuple[int, ...]], bottom: tuple[bytes, tuple[int, ...]]) -> np.ndarray:
    xh_ = np.frombuffer(xh[0], dtype=complex).reshape(xh[1])
    x_top, x_bottom = (np.frombuffer(b, dtype=float).reshape(shape) for b, shape in (top, bottom))
    lo, hi = reversals(xh_)
    return np.concatenate([_invert(xh_, x_top, lo, hi), _invert(xh_, x_bottom, hi, lo + 2 * np.pi)], axis=1)


def extremes(xh: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(x_min, x_max) of each loop's displacement."""
    lo, hi = reversals(xh)
    return displacement(xh, lo[:, None])[:, 0], displacement(xh, hi[:, None])[:, 0]


CELL_SNAP = 1e-9
"""A sample this close in phase (rad) to a reversal is at it (the end of its branch's cells)."""


def sample_cells(phase: np.ndarray, n_top: int, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How far each sample's cell reaches back and ahead in phase, ``(L, N)`` each: to the neighbouring
    samples of its branch (the first ``n_top`` of ``phase`` ``(L, N)`` loading, ``lo`` -> ``hi``; the rest
    unloading, ``hi`` -> ``lo`` + 2 pi), and at a branch's ends to its reversal (0 for a sample at one).
    Where a delay moves a jump of the force (at a reversal) into a sample's cell, the sample sees it
    averaged with the cell's hat function (:func:`past_jump`), so that the force is continuously
    differentiable in the delay."""
    lo, hi = np.asarray(lo, dtype=float)[:, None], np.asarray(hi, dtype=float)[:, None]
    before, after = np.empty(phase.shape), np.empty(phase.shape)
    for start, length, cols in ((lo, hi - lo, slice(0, n_top)), (hi, 2 * np.pi - (hi - lo), slice(n_top, phase.shape[1]))):
        u = np.mod(phase[:, cols] - start, 2 * np.pi)
        u = np.clip(np.where(u > 0.5 * (length + 2 * np.pi), u - 2 * np.pi, u), 0.0, length)  # rounding before the start
        u = np.where(u < CELL_SNAP, 0.0, np.where(length - u < CELL_SNAP, length, u))
        order = np.argsort(u, axis=1, kind="stable")
        ordered = np.take_along_axis(u, order, axis=1)
        edges = np.concatenate([np.zeros_like(length), ordered, length], axis=1)
        np.put_along_axis(before[:, cols], order, ordered - edges[:, :-2], axis=1)
        np.put_along_axis(after[:, cols], order, edges[:, 2:] - ordered, axis=1)
    return before, after


def past_jump(offset: np.ndarray, before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """The share of a sample's cell past a jump at phase ``offset`` from the sample, weighted by the cell's hat
    function: 0 ``before`` behind and ``after`` ahead of the sample and 1 at its peak, the sample itself, or for
    a sample at a reversal (one side 0) the middle of its one-sided cell, so that a jump leaving the cell over
    the reversal (a delay crossing 0) changes nothing to first order either. 1 for a jump at or before the
    cell's start, 0 at or beyond its end, continuously differentiable in between."""
    peak = np.where(after <= 0.0, -0.5 * before, np.where(before <= 0.0, 0.5 * after, 0.0))
    rise, fall = peak + before, after - peak
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.where(offset >= peak, (after - offset) ** 2 / (2.0 * fall), 0.5 * (before + after) - (offset + before) ** 2 / (2.0 * rise))
        share = share / (0.5 * (before + after))
    return np.where(offset <= -before, 1.0, np.where(offset >= after, 0.0, share))


def velocity_sign_harmonics(xh: np.ndarray, max_order: int) -> np.ndarray:
    """Complex amplitudes A_k (k = 0..max_order-1) of sgn(x'(theta)), ``(L, max_order)``.

    sgn(x') is +1 on (theta_lo, theta_hi) and -1 elsewhere, so A_0 = (hi - lo) / pi - 1 and
    A_k = 2 (e^{-ik lo} - e^{-ik hi}) / (i pi k); for the ideal sine this is the
    square wave (4 / pi k) sin(k pi / 2).
    """
    lo, hi = (a[:, None] for a in reversals(xh))
    k = np.arange(max_order)[None, :]
    safe = np.where(k == 0, 1, k)
    amp = 2.0 * (np.exp(-1j * k * lo) - np.exp(-1j * k * hi)) / (1j * np.pi * safe)
    return np.where(k == 0, (hi - lo) / np.pi - 1.0, amp)


def check(xh: np.ndarray, what: str) -> np.ndarray:
    """``xh`` as an ``(L, K)`` complex array with a non-zero fundamental, else :class:`HysidInputError`."""
    xh = np.asarray(xh, dtype=complex)
    if xh.ndim != 2 or xh.shape[1] < 1 or not np.all(np.isfinite(xh)) or np.any(np.abs(xh[:, 0]) == 0):
        raise HysidInputError(f"{what}: displacement harmonics must be a finite (loops, orders) array with a non-zero fundamental")
    return xh
