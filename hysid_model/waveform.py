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
    k = orders(xh)
    amp = xh * (1j * k) ** derivative  # (L, K)
    waves = np.exp(1j * np.asarray(theta)[..., None] * k)  # (..., L, N, K)
    return np.einsum("...lnk,lk->...ln", waves, amp).real


def thd(xh: np.ndarray) -> np.ndarray:
    """Total harmonic distortion: rms of harmonics 2..K over the fundamental, per loop."""
    return np.sqrt(np.sum(np.abs(xh[:, 1:]) ** 2, axis=1)) / np.abs(xh[:, 0])


def _refine_extreme(xh: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Newton on x'(theta) = 0 from ``theta`` (L,)."""
    for _ in range(NEWTON_STEPS):
        d1 = displacement(xh, theta[:, None], 1)[:, 0]
        d2 = displacement(xh, theta[:, None], 2)[:, 0]
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
    x = displacement(xh, np.broadcast_to(grid, (xh.shape[0], GRID)))
    lo = _refine_extreme(xh, grid[np.argmin(x, axis=1)])
    hi = _refine_extreme(xh, grid[np.argmax(x, axis=1)])
    hi = lo + np.mod(hi - lo, 2 * np.pi)
    return lo, hi


def reversal_count(xh: np.ndarray) -> np.ndarray:
    """How often x' changes sign per cycle, per loop (2 for a loop with one loading and one unloading branch)."""
    grid = np.linspace(-np.pi, np.pi, GRID, endpoint=False)
    v = displacement(xh, np.broadcast_to(grid, (xh.shape[0], GRID)), 1)
    return np.count_nonzero(np.sign(v) != np.sign(np.roll(v, 1, axis=1)), axis=1)


def _invert(xh: np.ndarray, targets: np.ndarray, start: np.ndarray, stop: np.ndarray) -> np.ndarray:
    """Phases in [start, stop] (per loop) where x(theta) = targets ``(L, N)``; x is monotonic there."""
    u = np.linspace(0.0, 1.0, GRID)
    theta_grid = start[:, None] + (stop - start)[:, None] * u  # (L, G)
    x_grid = displacement(xh, theta_grid)
    rising = x_grid[:, -1] >= x_grid[:, 0]
    x_mono = np.where(rising[:, None], x_grid, -x_grid)
    x_mono = np.maximum.accumulate(x_mono, axis=1)
    tgt = np.where(rising[:, None], targets, -targets)
    theta = np.stack([np.interp(t, xm, tg) for t, xm, tg in zip(tgt, x_mono, theta_grid)])
    lo, hi = np.minimum(start, stop)[:, None], np.maximum(start, stop)[:, None]
    for _ in range(NEWTON_STEPS):
        x = displacement(xh, theta)
        v = displacement(xh, theta, 1)
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
