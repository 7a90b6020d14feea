"""The Bouc-Wen orbit for any exponent n (Eq. 2.1b), compiled (numba).

In the units of the yield displacement, u = z / z_y and s = travel / z_y, with
gamma = (1 + r) / (2 z_y^n) and beta = (1 - r) / (2 z_y^n) (so that z saturates at
z_y for every n), Eq. 2.1b on the loading branch (x' > 0, A = 1) is autonomous:
du/ds = 1 - u^n while u >= 0 (relaxing towards 1) and du/ds = 1 + r |u|^n while
u < 0 (climbing to 0); unloading is its mirror image (the orbit is odd). Each
piece is the solution w(sigma) of dw/dsigma = 1 - c w^n from w = 0 (relaxing:
c = 1, w = u, sigma the travel since z = 0; climbing: c = -r, w = |u|, sigma the
travel still to go to z = 0), whose inverse is a quadrature,

    T_c(w) = int_0^w dv / (1 - c v^n) = w L(c w^n),   L(x) = sum_k x^k / (k n + 1),

summed exactly (:func:`travel`): directly for |x| <= 1/2; for x > 1/2 (a = 1/n,
eps = 1 - x) as a c^-a [-log eps - psi(a) - gamma_E - sum_m (1 - a)_m / m! eps^m / m];
for -2 <= x < -1/2 as w a (1 - x)^-a sum_m (a)_m / m! q^m / (m + a), q = -x / (1 - x);
beyond (a large r) from w1 with c w1^n = -2 on in powers of 1 / (-c v^n) <= 1/2.
The peak state u_m of the orbit under a half span S (in z_y) solves
T_-r(u_m) + T_1(u_m) = 2 S (:func:`orbit`): the loading branch climbs from -u_m
to 0 and relaxes from 0 to u_m over the travel 2 S from one reversal to the other.

Two evaluations of z at a travel:

* exact (:func:`bouc_wen_exact`, the reference of :meth:`hysid_model.effects.bouc_wen.BoucWen.time_force`):
  Newton's method on T per point, here;
* tabulated (the compiled objective's :class:`~hysid_model.effects.bouc_wen.BoucWenSampler`): per candidate,
  w(sigma) of both pieces as quintic Hermite pieces between nodes whose sigma = T(w) is exact
  (:mod:`hysid_model.bouc_wen_tables`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

EULER_GAMMA = 0.5772156649015329
NEWTON_STEPS = 100
"""At most this many steps of a safeguarded Newton's method (they converge in about 5)."""
NEWTON_TOLERANCE = 4e-16


@njit(cache=True, nogil=True)
def digamma(x: float) -> float:
    """psi(x) for x > 0: the recurrence up to 10, then the asymptotic series (error < 1e-15)."""
    shift = 0.0
    while x < 10.0:
        shift -= 1.0 / x
        x += 1.0
    f = 1.0 / (x * x)
    tail = f * (1.0 / 12.0 - f * (1.0 / 120.0 - f * (1.0 / 252.0 - f * (1.0 / 240.0 - f * (1.0 / 132.0)))))
    return shift + math.log(x) - 0.5 / x - tail


@njit(cache=True, nogil=True)
def _log_part(eps: float, a: float) -> float:
    """sum_{m >= 1} (1 - a)_m / m! eps^m / m for 0 <= eps <= 1/2."""
    total, coef, power, m = 0.0, 1.0, 1.0, 1
    while True:
        coef *= (m - a) / m
        power *= eps
        total += coef * power / m
        if power < 1e-18:
            return total
        m += 1


@njit(cache=True, nogil=True)
def relaxing_travel(eps: float, a: float, psi: float) -> float:
    """T_1(u) from the deficit eps = 1 - u^n <= 1/2: a (-log eps - psi(a) - gamma_E - sum_m ...) (module docstring)."""
    return a * (-math.log(eps) - psi - EULER_GAMMA - _log_part(eps, a))


@njit(cache=True, nogil=True)
def travel(w: float, c: float, n: float, a: float, psi: float) -> float:
    """T_c(w) = int_0^w dv / (1 - c v^n) for w >= 0, c w^n < 1 (a = 1/n, psi = psi(a); module docstring)."""
    if w <= 0.0:
        return 0.0
    x = c * w**n
    if abs(x) <= 0.5:
        total, power, k = 0.0, 1.0, 0
        while True:
            total += power / (k * n + 1.0)
            if abs(power) < 1e-18:
                return w * total
            k += 1
            power *= x
    if x > 0.5:
        return a * c ** (-a) * (-math.log1p(-x) - psi - EULER_GAMMA - _log_part(1.0 - x, a))
    if x < -2.0:  # T_c(w1) at c w1^n = -2, then the integrand 1 / (1 - c v^n) in powers of 1 / (-c v^n) <= 1/2
        w1 = (-2.0 / c) ** a
        span, total, k = math.log(w / w1), 0.0, 0
        while True:
            e = 1.0 - n * (k + 1)
            term = 0.5 ** (k + 1) * (span if e == 0.0 else math.expm1(e * span) / e)
            total += -term if k % 2 else term
            if abs(term) < 1e-17 * abs(total):
                return _euler(w1, -2.0, a) + w1 * total
            k += 1
    return _euler(w, x, a)


@njit(cache=True, nogil=True)
def _euler(w: float, x: float, a: float) -> float:
    """T_c(w) = w a (1 - x)^-a sum_m (a)_m / m! q^m / (m + a), q = -x / (1 - x), for x = c w^n < 0."""
    q = -x / (1.0 - x)
    total, coef, m = 0.0, 1.0, 0
    while True:
        term = coef / (m + a)
        total += term
        if m > a + 2.0 and term < 1e-17 * total:
            return w * a * (1.0 - x) ** (-a) * total
        m += 1
        coef *= (a + m - 1.0) / m * q


@njit(cache=True, nogil=True, inline="always")
def _safeguard(x: float, newton: float, lo: float, hi: float) -> tuple[float, bool]:
    """The next iterate of a safeguarded Newton's method, the Newton step ``newton`` or, outside the
    bracket [lo, hi], the bisection, and whether it has converged (a step or bracket of 2 ulps)."""
    if abs(newton - x) <= NEWTON_TOLERANCE * abs(x):
        return newton, True
    if not lo <= newton <= hi:
        newton = 0.5 * (lo + hi)
    return newton, hi - lo <= NEWTON_TOLERANCE * abs(hi)


@njit(cache=True, nogil=True)
def _relaxing_at(lam: float, a: float, psi: float) -> tuple[float, float, float]:
    """u, T_1(u) and dT_1/dlambda at lambda = -log(1 - u^n) >= log 2."""
    eps = math.exp(-lam)
    u = math.exp(a * math.log1p(-eps))
    return u, a * (lam - psi - EULER_GAMMA - _log_part(eps, a)), a * (1.0 - eps) ** (a - 1.0)


@njit(cache=True, nogil=True)
def orbit(span: float, n: float, r: float, a: float, psi: float) -> tuple[float, float]:
    """Peak state u_m and the travel T_-r(u_m) from a reversal to z = 0, both in z_y, of the orbit
    under the half span ``span`` (in z_y): the root of T_-r(u) + T_1(u) = 2 span.

    Safeguarded Newton's method in u while 1 - u^n >= 1/2, else in lambda = -log(1 - u^n)
    (where T_1 is nearly linear and u may round to 1)."""
    target = 2.0 * span
    knee = 0.5**a
    mid = travel(knee, -r, n, a, psi) + relaxing_travel(0.5, a, psi) - target
    if mid >= 0.0:
        lo, hi = 0.0, knee
        u = min(span, knee)
        for _ in range(NEWTON_STEPS):
            un = u**n
            f = travel(u, -r, n, a, psi) + travel(u, 1.0, n, a, psi) - target
            if f > 0.0:
                hi = u
            else:
                lo = u
            u, done = _safeguard(u, u - f / (1.0 / (1.0 + r * un) + 1.0 / (1.0 - un)), lo, hi)
            if done:
                break
        return u, travel(u, -r, n, a, psi)
    lo = math.log(2.0)
    hi = n * (target + abs(psi) + 10.0)
    while True:
        u, tp, _ = _relaxing_at(hi, a, psi)
        if travel(u, -r, n, a, psi) + tp > target:
            break
        hi *= 2.0
    lam = min(max(n * (target - travel(1.0, -r, n, a, psi)) + psi + EULER_GAMMA, lo), hi)
    for _ in range(NEWTON_STEPS):
        u, tp, slope = _relaxing_at(lam, a, psi)
        eps = math.exp(-lam)
        f = travel(u, -r, n, a, psi) + tp - target
        if f > 0.0:
            hi = lam
        else:
            lo = lam
        du = a * u * eps / (1.0 - eps)
        lam, done = _safeguard(lam, lam - f / (slope + du / (1.0 + r * u**n)), lo, hi)
        if done:
            break
    u, _, _ = _relaxing_at(lam, a, psi)
    return u, travel(u, -r, n, a, psi)


@njit(cache=True, nogil=True)
def _invert(sigma: float, c: float, top: float, n: float, a: float, psi: float) -> float:
    """w in [0, top] with T_c(w) = sigma (safeguarded Newton's method, T_c' = 1 / (1 - c w^n))."""
    if sigma <= 0.0:
        return 0.0
    lo, hi = 0.0, top
    w = min(sigma, top)
    for _ in range(NEWTON_STEPS):
        f = travel(w, c, n, a, psi) - sigma
        if f > 0.0:
            hi = w
        else:
            lo = w
        w, done = _safeguard(w, w - f * (1.0 - c * w**n), lo, hi)
        if done:
            break
    return w


@njit(cache=True, nogil=True)
def relaxed(sigma: float, n: float, a: float, psi: float) -> float:
    """u on the relaxing piece after the travel ``sigma`` (in z_y) from z = 0, exactly."""
    knee = 0.5**a
    if sigma <= relaxing_travel(0.5, a, psi):
        return _invert(sigma, 1.0, knee, n, a, psi)
    lo, hi = math.log(2.0), n * (sigma + abs(psi) + 10.0)
    lam = min(max(n * sigma + psi + EULER_GAMMA, lo), hi)
    for _ in range(NEWTON_STEPS):
        _, tp, slope = _relaxing_at(lam, a, psi)
        f = tp - sigma
        if f > 0.0:
            hi = lam
        else:
            lo = lam
        lam, done = _safeguard(lam, lam - f / slope, lo, hi)
        if done:
            break
    return _relaxing_at(lam, a, psi)[0]


@njit(cache=True, nogil=True)
def exact_state(t: float, um: float, tn: float, n: float, r: float, a: float, psi: float) -> float:
    """u on the loading branch after the travel ``t`` (in z_y) from the reversal where u = -u_m; ``tn`` the
    travel to z = 0 (:func:`orbit`)."""
    if t < tn:
        return -_invert(tn - t, -r, um, n, a, psi)
    return relaxed(t - tn, n, a, psi)


@njit(cache=True, nogil=True)
def bouc_wen_exact(
    exponent: np.ndarray,
    r: np.ndarray,
    zy: np.ndarray,
    span: np.ndarray,
    which: np.ndarray,
    travel_: np.ndarray,
    sign: np.ndarray,
    out: np.ndarray,
) -> None:
    """out[p, l, j] = z (m) at travel ``travel_[p, l, j]`` (m) since the last reversal, on the loading
    (``sign`` +1) or unloading (-1) branch, exactly (:func:`exact_state`), for candidates of exponent n,
    shape r and yield displacement z_y ``(P,)``; loop l has the half span ``span[which[l]]`` (m)."""
    for p in range(exponent.shape[0]):
        n, rp, zp = exponent[p], r[p], zy[p]
        a = 1.0 / n
        psi = digamma(a)
        for i in range(span.shape[0]):
            um, tn = orbit(span[i] / zp, n, rp, a, psi)
            for l in range(which.shape[0]):
                if which[l] != i:
                    continue
                for j in range(travel_.shape[2]):
                    t = max(travel_[p, l, j], 0.0) / zp
                    out[p, l, j] = sign[p, l, j] * zp * exact_state(t, um, tn, n, rp, a, psi)
