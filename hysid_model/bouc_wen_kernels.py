"""Compiled kernels (numba) of the Bouc-Wen orbit for n = 1 (Eq. 2.1b) at a loop set's fixed samples: its peak
state, its force and its cycle mean.

The numpy form (:meth:`hysid_model.terms.Term.time_force` of :class:`hysid_model.effects.bouc_wen.BoucWen`)
evaluates a population as arrays of shape ``(P, L, N)``, every branch of a piecewise formula computed everywhere,
with temporaries per step. These kernels walk candidates x loops x samples once, compute only the branch taken and
add into one output array; :class:`hysid_model.effects.bouc_wen.BoucWenSampler` calls them (at phases shifted by a
channel delay: :mod:`hysid_model.shifted_kernels`; any other n: :mod:`hysid_model.bouc_wen_tables`). The numpy
form stays as the reference the tests compare them with.

The kernels compile on first use and are cached on disk (``cache=True``), so a new process (an island, a
command) loads them instead of compiling. numba invalidates a cached kernel when its own file changes, not when a
function it calls from another file does: the helpers a kernel inlines live in its own file.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

NEWTON_STEPS = 60
"""At most this many safeguarded Newton steps for the orbit's peak state (it converges in about 5)."""
EXACT_GRID = 1e-13
"""Largest |c| x spread of a run's offsets from its uniform travel grid below which the offsets
are ignored (they change exp(-c t) by less than this, relative)."""
STEP_TAYLOR = 0.05
"""Largest c dt for which exp(-c dt) between neighbouring mean nodes is its Taylor polynomial to x^8 (error < 1e-16)."""
RECURRENCE_DEVIATION = 1e-4
"""Largest |c d| for which a sample off its group's uniform travel grid by d is corrected to second
order from the grid's exp(-c t) (error (c d)^3 / 6); beyond it the sample gets its own exponential."""

Orbit = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]
"""The Bouc-Wen orbits of a population as the kernels take them: (z_max, run, which, a, b, k, mean) of
:meth:`hysid_model.effects.bouc_wen.BoucWenSampler._orbit` and the loops' ``which``."""


@njit(cache=True, nogil=True)
def bouc_wen_orbit(span: np.ndarray, a: np.ndarray, b: np.ndarray, z_max: np.ndarray, run: np.ndarray) -> None:
    """Peak state ``z_max`` and zero-crossing travel ``run`` ``(P, U)`` of the n = 1 orbit for half spans
    ``span`` ``(U,)`` and rates a = gamma - beta, b = gamma + beta ``(P,)``
    (:func:`hysid_model.effects.bouc_wen.loading_orbit` solves the same condition by bisection).

    With u = log(1 - b z_max) and r = a / b the condition 1 - b z_max = exp(b run - 2 b S),
    run = log(1 + a z_max) / a, reads F(u) = u + 2 b S - log1p(r (1 - e^u)) / r = 0: F rises
    with 1 <= F' <= 1 + 1 / (1 + r) (r >= -0.9), its root lies in
    [-2 b S, -2 b S + log1p(r) / r], and Newton kept inside that bracket converges in a few steps.
    """
    for p in range(a.shape[0]):
        ap, bp = a[p], b[p]
        ratio = ap / bp
        top = 1.0 if ratio == 0.0 else math.log1p(ratio) / ratio
        for i in range(span.shape[0]):
            base = -2.0 * bp * span[i]
            lo, hi = base, min(0.0, base + top)
            u = base
            for _ in range(NEWTON_STEPS):
                y = -math.expm1(u)
                if ratio == 0.0:
                    h, slope = y, 1.0 - y
                else:
                    h, slope = math.log1p(ratio * y) / ratio, (1.0 - y) / (1.0 + ratio * y)
                f = u - base - h
                if f == 0.0:
                    break
                if f > 0.0:
                    hi = u
                else:
                    lo = u
                nxt = u - f / (1.0 + slope)
                if not (lo < nxt < hi):
                    nxt = 0.5 * (lo + hi)
                done = abs(nxt - u) <= 4e-16 * max(1.0, abs(u))
                u = nxt
                if done:
                    break
            zm = -math.expm1(u) / bp
            z_max[p, i] = zm
            run[p, i] = zm if ap == 0.0 else math.log1p(ap * zm) / ap


@njit(cache=True, nogil=True, inline="always")
def _piece(
    out: np.ndarray,
    start: int,
    stride: int,
    first: int,
    last: int,
    travel: np.ndarray,
    deviation: np.ndarray,
    dx: float,
    spread: float,
    origin: float,
    c: float,
    base: float,
    scale: float,
) -> None:
    """out[n] += base + scale expm1(-c (travel[n] - origin)) for n = start + j stride, first <= j < last (one loop's samples).

    On a uniform travel grid (``dx`` not NaN, offsets within ``spread`` small enough) the
    exponential advances by multiply-adds, e(t + i dx) = e(t) q_i + (q_i - 1) with q_i = exp(-i c dx):
    four samples per step of 4 dx; offsets beyond ``EXACT_GRID`` are corrected to second order
    (then in two interleaved chains of step 2 dx)."""
    if first >= last:
        return
    n = start + first * stride
    e = math.expm1(-c * (travel[n] - origin))
    out[n] += base + scale * e
    uniform = not math.isnan(dx) and abs(c) * spread <= RECURRENCE_DEVIATION
    if not uniform:
        for j in range(first + 1, last):
            n = start + j * stride
            out[n] += base + scale * math.expm1(-c * (travel[n] - origin))
        return
    d = math.expm1(-c * dx)
    d2 = d * (2.0 + d)  # expm1 of 2, 3, 4 steps, without cancellation
    r2 = 1.0 + d2
    if abs(c) * spread <= EXACT_GRID:  # four samples per step of 4 dx from one chain value
        d3 = d2 + r2 * d
        d4 = d2 * (2.0 + d2)
        r1, r3, r4 = 1.0 + d, 1.0 + d3, 1.0 + d4
        j = first + 1
        if stride == 1:  # contiguous: the four updates can share vector registers
            while j + 3 < last:
                n = start + j
                out[n] += base + scale * (e * r1 + d)
                out[n + 1] += base + scale * (e * r2 + d2)
                out[n + 2] += base + scale * (e * r3 + d3)
                out[n + 3] += base + scale * (e * r4 + d4)
                e = e * r4 + d4
                j += 4
        else:
            while j + 3 < last:
                n = start + j * stride
                out[n] += base + scale * (e * r1 + d)
                out[n + stride] += base + scale * (e * r2 + d2)
                out[n + 2 * stride] += base + scale * (e * r3 + d3)
                out[n + 3 * stride] += base + scale * (e * r4 + d4)
                e = e * r4 + d4
                j += 4
        while j < last:
            e = e * r1 + d
            out[start + j * stride] += base + scale * e
            j += 1
        return
    odd, even = e * (1.0 + d) + d, e * r2 + d2
    anchor = deviation[n]
    for j in range(first + 1, last, 2):
        n = start + j * stride
        off = c * (deviation[n] - anchor)
        out[n] += base + scale * (odd + (1.0 + odd) * off * (0.5 * off - 1.0))
        if j + 1 < last:
            n = n + stride
            off = c * (deviation[n] - anchor)
            out[n] += base + scale * (even + (1.0 + even) * off * (0.5 * off - 1.0))
        odd, even = odd * r2 + d2, even * r2 + d2


@njit(cache=True, nogil=True, inline="always")
def _bouc_wen_loop(
    out: np.ndarray,
    first_run: int,
    last_run: int,
    runs: np.ndarray,
    step: np.ndarray,
    spread: np.ndarray,
    travel: np.ndarray,
    deviation: np.ndarray,
    zm: float,
    rn: float,
    ap: float,
    bp: float,
    kp: float,
    km: float,
) -> None:
    """out[n] += k (sign z(travel[n])) - km over the runs ``first_run:last_run`` of one loop (see :func:`bouc_wen_samples`)."""
    for r in range(first_run, last_run):
        start, stride, count, ks = runs[r, 1], runs[r, 2], runs[r, 3], kp * runs[r, 4]
        lo, hi = 0, count  # first position on the relaxing piece (travel >= run): bisection
        while lo < hi:
            mid = (lo + hi) // 2
            if travel[start + mid * stride] < rn:
                lo = mid + 1
            else:
                hi = mid
        if ap == 0.0:
            for j in range(lo):
                n = start + j * stride
                out[n] += ks * (travel[n] - zm) - km
        else:
            _piece(out, start, stride, 0, lo, travel, deviation, step[r], spread[r], 0.0, ap, -ks * zm - km, -ks * (zm + 1.0 / ap))
        _piece(out, start, stride, lo, count, travel, deviation, step[r], spread[r], rn, bp, -km, -ks / bp)


@njit(cache=True, nogil=True, fastmath={"contract"})
def bouc_wen_samples(
    orbit: Orbit,
    travel: np.ndarray,
    runs: np.ndarray,
    loop_runs: np.ndarray,
    step: np.ndarray,
    spread: np.ndarray,
    deviation: np.ndarray,
    out: np.ndarray,
) -> None:
    """out[p, l, n] += k_p (sign z(travel) - mean[p, l]) at fixed samples.

    ``orbit`` is (z_max, run, which, a, b, k, mean) (:data:`Orbit`): the orbit of loop l is column
    ``which[l]`` of ``z_max`` and ``run``; ``a``, ``b``, ``k`` are ``(P,)``; ``travel`` ``(L, N)`` is each sample's travel since the last reversal. The samples
    come in ``runs`` ``(R, 5)``: (loop, first sample, stride, count, sign +1 loading / -1
    unloading), travel increasing along a run, those of loop l at ``loop_runs[l]:loop_runs[l + 1]``.
    Where a run lies on a uniform travel grid (``step[r]``, NaN if not; ``deviation`` ``(L, N)`` each
    sample's offset from it, ``spread[r]`` twice the largest) exp(-c t) follows from the previous
    sample's by one multiply-add, e_{j+1} = e_j q + (q - 1) with e = expm1(-c t), q = exp(-c step).
    On the climbing piece (t < run) z = -z_max - (z_max + 1/a) expm1(-a t) (t - z_max for a = 0),
    on the relaxing piece z = -expm1(-b (t - run)) / b; each piece starts from its own exponential.
    """
    z_max, run, which, a, b, k, mean = orbit
    for p in range(a.shape[0]):
        for l in range(travel.shape[0]):
            _bouc_wen_loop(
                out[p, l],
                loop_runs[l],
                loop_runs[l + 1],
                runs,
                step,
                spread,
                travel[l],
                deviation[l],
                z_max[p, which[l]],
                run[p, which[l]],
                a[p],
                b[p],
                k[p],
                k[p] * mean[p, l],
            )


@njit(cache=True, nogil=True, inline="always")
def _exp_sum(travel: np.ndarray, l: int, first: int, last: int, origin: float, c: float) -> float:
    """sum_j expm1(-c (travel[l, j] - origin)) over j = first..last-1 (travel increasing).

    From one node to the next e = expm1(-c t) advances by the factor exp(-c dt): a Taylor
    polynomial (e_new = e + (1 + e) expm1(-c dt)) while c dt <= STEP_TAYLOR, else its own
    exponential; once exp(-c t) underflows the rest of the nodes add -1 each."""
    if first >= last:
        return 0.0
    e = math.expm1(-c * (travel[l, first] - origin))
    total = e
    for j in range(first + 1, last):
        if e == -1.0:
            return total - (last - j)
        x = c * (travel[l, j] - travel[l, j - 1])
        if abs(x) <= STEP_TAYLOR:
            step = -x * (1.0 - x * (0.5 - x * (1.0 / 6.0 - x * (1.0 / 24.0 - x * (1.0 / 120.0 - x * (1.0 / 720.0 - x * (1.0 / 5040.0 - x / 40320.0)))))))
            e = e + (1.0 + e) * step
        else:
            e = math.expm1(-c * (travel[l, j] - origin))
        total += e
    return total


@njit(cache=True, nogil=True)
def bouc_wen_mean(
    z_max: np.ndarray,
    run: np.ndarray,
    which: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    travel: np.ndarray,
    split: np.ndarray,
    out: np.ndarray,
) -> None:
    """out[p, l] = mean of z over the nodes of loop l (a uniform phase grid: the cycle mean).

    ``travel`` ``(L, M)`` holds the loading nodes' travels (the first ``split[l]``), then the
    unloading ones', each increasing; z = +-z(travel) (:func:`hysid_model.shifted_kernels._state`), summed piece by piece."""
    nodes = travel.shape[1]
    for p in range(a.shape[0]):
        ap, bp = a[p], b[p]
        for l in range(travel.shape[0]):
            zm, rn = z_max[p, which[l]], run[p, which[l]]
            total = 0.0
            for g in range(2):
                first = 0 if g == 0 else split[l]
                last = split[l] if g == 0 else nodes
                lo, hi = first, last  # first node on the relaxing piece: bisection
                while lo < hi:
                    mid = (lo + hi) // 2
                    if travel[l, mid] < rn:
                        lo = mid + 1
                    else:
                        hi = mid
                part = 0.0
                if ap == 0.0:
                    for j in range(first, lo):
                        part += travel[l, j] - zm
                else:
                    part += -zm * (lo - first) - (zm + 1.0 / ap) * _exp_sum(travel, l, first, lo, 0.0, ap)
                part -= _exp_sum(travel, l, lo, last, rn, bp) / bp
                total += part if g == 0 else -part
            out[p, l] = total / nodes
