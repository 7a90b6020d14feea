"""Compiled helpers (numba) for the measured displacement at phases shifted per candidate (a channel delay):
x(theta - shift) and dx/dtheta from its harmonics (:mod:`hysid_model.waveform`), in real arithmetic.

:mod:`hysid_model.bouc_wen_kernels`, :mod:`hysid_model.bouc_wen_tables` and :mod:`hysid_model.chain_kernels`
evaluate the motion through them; cached on disk (``cache=True``) as they are.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


def motion_tables(xh: np.ndarray, phase: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The displacement harmonics ``xh`` ``(L, K)`` as (Re, Im) ``(2, L, K)`` and (cos k theta, sin k theta)
    ``(2, L, N, K)`` at ``phase`` ``(L, N)``: what :func:`_motion` evaluates x(theta - shift) from."""
    k = np.arange(1, xh.shape[1] + 1)
    angle = phase[..., None] * k
    return np.ascontiguousarray(np.stack([xh.real, xh.imag]), dtype=float), np.ascontiguousarray(np.stack([np.cos(angle), np.sin(angle)]))


@njit(cache=True, nogil=True, inline="always")
def _rotate(xh: np.ndarray, l: int, shift: float, out: np.ndarray) -> None:
    """out[0, k], out[1, k] = Re, Im of X_k e^{-ik shift}: the harmonics of x(theta - shift) (``xh`` = (Re, Im) ``(2, L, K)``)."""
    for i in range(xh.shape[2]):
        c, s = math.cos((i + 1) * shift), math.sin((i + 1) * shift)
        out[0, i] = xh[0, l, i] * c + xh[1, l, i] * s
        out[1, i] = xh[1, l, i] * c - xh[0, l, i] * s


@njit(cache=True, nogil=True, inline="always")
def _motion(waves: np.ndarray, l: int, n: int, xs: np.ndarray) -> tuple[float, float]:
    """x and dx/dtheta at sample n of loop l from harmonics ``xs`` (:func:`_rotate`) and ``waves``
    = (cos k theta_n, sin k theta_n) ``(2, L, N, K)``: x = sum_k Re[X_k e^{ik theta}] (real arithmetic:
    numba's complex product checks for infinities and is ~20 times slower)."""
    x = 0.0
    v = 0.0
    for i in range(xs.shape[1]):
        c, s = waves[0, l, n, i], waves[1, l, n, i]
        x += xs[0, i] * c - xs[1, i] * s
        v -= (i + 1) * (xs[0, i] * s + xs[1, i] * c)
    return x, v
