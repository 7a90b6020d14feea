"""Compiled kernels (numba) of the forces at phases shifted per candidate (a channel delay, Eq. 4.1-4.2) at a loop
set's fixed phases: the Bouc-Wen orbit for n = 1 (Eq. 2.1b) driven by the measured displacement, and F sgn(x')
delayed and through a single-pole high-pass, exactly. The displacement x(theta - shift) and dx/dtheta come from
its harmonics (:mod:`hysid_model.waveform`) in real arithmetic.

The numpy reference (:meth:`hysid_model.model.Model.memory_force`) sums the chain's first harmonics;
:class:`hysid_model.sampled.SampledMemory` and :class:`hysid_model.effects.bouc_wen.BoucWenSampler` call these
kernels instead, and the tests compare both.

The kernels compile on first use and are cached on disk (``cache=True``), so a new process (an island, a
command) loads them instead of compiling. numba invalidates a cached kernel when its own file changes, not when a
function it calls from another file does: the helpers a kernel inlines live in its own file.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hysid_model.bouc_wen_kernels import Orbit
from hysid_model.kinematics import REVERSAL_TIE

TWO_PI = 2.0 * math.pi


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


@njit(cache=True, nogil=True, inline="always")
def _state(t: float, z_max: float, run: float, a: float, b: float) -> float:
    """z on the loading branch after travel ``t`` from the reversal (Eq. 2.1b, n = 1): climbing from
    -z_max under dz/dx = 1 - a z up to ``run``, then relaxing under 1 - b z
    (:func:`hysid_model.effects.bouc_wen._loading`)."""
    if t < run:
        if a == 0.0:
            return t - z_max
        e = math.expm1(-a * t)
        return -z_max * (1.0 + e) - e / a
    return -math.expm1(-b * (t - run)) / b


@njit(cache=True, nogil=True)
def bouc_wen_shifted(
    orbit: Orbit,
    shift: np.ndarray,
    xh: np.ndarray,
    waves: np.ndarray,
    x_min: np.ndarray,
    x_max: np.ndarray,
    out: np.ndarray,
) -> None:
    """out[p, l, n] += k_p (z(theta_n - shift[p, l]) - mean[p, l]): the orbit at phases shifted per candidate
    (a channel delay). The displacement ``xh`` (Re, Im) ``(2, L, K)`` is evaluated at the shifted phase from
    ``waves`` (:func:`_motion`); its velocity's sign there is the branch."""
    z_max, run, which, a, b, k, mean = orbit
    xs = np.empty((2, xh.shape[2]))
    for p in range(a.shape[0]):
        for l in range(waves.shape[1]):
            _rotate(xh, l, shift[p, l], xs)
            zm, rn, mn, kp = z_max[p, which[l]], run[p, which[l]], mean[p, l], k[p]
            for n in range(waves.shape[2]):
                x, v = _motion(waves, l, n, xs)
                if v >= 0.0:
                    z = _state(x - x_min[l], zm, rn, a[p], b[p])
                else:
                    z = -_state(x_max[l] - x, zm, rn, a[p], b[p])
                out[p, l, n] += kp * (z - mn)


@njit(cache=True, nogil=True, inline="always")
def _past_jump(offset: float, before: float, after: float) -> float:
    """:func:`hysid_model.waveform.past_jump` for one sample (``offset`` strictly inside its cell)."""
    peak = -0.5 * before if after <= 0.0 else (0.5 * after if before <= 0.0 else 0.0)
    width = 0.5 * (before + after)
    if offset >= peak:
        return (after - offset) ** 2 / (2.0 * (after - peak)) / width
    return 1.0 - (offset + before) ** 2 / (2.0 * (peak + before)) / width


@njit(cache=True, nogil=True, inline="always")
def _jump_in_cell(reversal: float, shift: float, theta: float, before: float, after: float, jump: float, past: bool) -> float:
    """What averaging the jump ``jump`` at ``reversal`` + ``shift`` over the cell of the sample at ``theta``
    adds to its point value (which is past the jump if ``past``): 0 unless the jump is inside the cell."""
    offset = (reversal + shift - theta + math.pi) % TWO_PI - math.pi
    if offset <= -before or offset >= after:
        return 0.0
    return jump * (_past_jump(offset, before, after) - (1.0 if past else 0.0))


@njit(cache=True, nogil=True)
def velocity_sign_chain(
    amplitude: np.ndarray,
    shift: np.ndarray,
    rho: np.ndarray,
    xh: np.ndarray,
    waves: np.ndarray,
    phase: np.ndarray,
    x0: np.ndarray,
    theta_lo: np.ndarray,
    theta_hi: np.ndarray,
    n_top: int,
    before: np.ndarray,
    after: np.ndarray,
    out: np.ndarray,
) -> None:
    """out[p, l, n] += amplitude[p, l] y(theta_n - shift[p, l]): sgn(x') delayed by ``shift`` and, where
    ``rho[p, l]`` = w_c / w > 0, through the single-pole high-pass G = s / (s + w_c) (Eq. 4.1-4.2).

    sgn(x') is +1 from the reversal theta_lo to theta_hi (a phase T1) and -1 for the rest of the
    cycle (T2). The high-pass's periodic response to it is exact: it jumps by +-2 at the
    reversals and decays as exp(-rho (theta - reversal)) in between, from
    A = 2 (1 - E2) / (1 - E1 E2) after the jump up and -B = -2 (1 - E1) / (1 - E1 E2) after the
    jump down, E_i = exp(-rho T_i). Where the velocity at the shifted phase vanishes
    (|x'| < REVERSAL_TIE X0: the sample is at a reversal) the branch is the sample's own, loading for the
    first ``n_top`` samples, as :meth:`hysid_model.model.Model.memory_force` decides. A jump of +-2 that
    the shift moves into a sample's cell (``before`` and ``after`` it, ``(L, N)``:
    :func:`hysid_model.waveform.sample_cells`) is averaged over the cell (:func:`_jump_in_cell`), as the
    reference does.
    """
    xs = np.empty((2, xh.shape[2]))
    for p in range(amplitude.shape[0]):
        for l in range(waves.shape[1]):
            _rotate(xh, l, shift[p, l], xs)
            t1 = theta_hi[l] - theta_lo[l]
            t2 = TWO_PI - t1
            rh, f = rho[p, l], amplitude[p, l]
            if -math.expm1(-rh * TWO_PI) <= 0.0:  # a cut-off so low that no decay over the cycle is representable: none
                rh = 0.0
            up = down = 1.0
            if rh > 0.0:
                whole = -math.expm1(-rh * TWO_PI)  # 1 - E1 E2, exact where rho is tiny
                up, down = 2.0 * -math.expm1(-rh * t2) / whole, 2.0 * -math.expm1(-rh * t1) / whole
            for n in range(waves.shape[2]):
                _, v = _motion(waves, l, n, xs)
                tie = abs(v) < REVERSAL_TIE * x0[l]
                loading = (n < n_top) if tie else v > 0.0
                theta, b, a = phase[l, n], before[l, n], after[l, n]
                cell = _jump_in_cell(theta_lo[l], shift[p, l], theta, b, a, 2.0, loading)
                cell += _jump_in_cell(theta_hi[l], shift[p, l], theta, b, a, -2.0, not loading)
                out[p, l, n] += f * cell
                if rh <= 0.0:
                    out[p, l, n] += f if loading else -f
                    continue
                phi = (phase[l, n] - shift[p, l] - theta_lo[l]) % TWO_PI
                if tie:  # at a reversal: the side of the jump is the branch's
                    near_lo = min(phi, TWO_PI - phi) < abs(phi - t1)
                    if loading:
                        elapsed = 0.0 if near_lo else t1
                    else:
                        elapsed = t2 if near_lo else 0.0
                elif loading:
                    elapsed = phi if phi <= t1 else phi - TWO_PI
                else:
                    elapsed = phi - t1 if phi >= t1 else phi - t1 + TWO_PI
                if loading:
                    out[p, l, n] += f * up * math.exp(-rh * elapsed)
                else:
                    out[p, l, n] -= f * down * math.exp(-rh * elapsed)
