"""The Bouc-Wen orbit for any exponent n tabulated per candidate, compiled (numba): what the objective evaluates.

The orbit's two pieces w(sigma), dw/dsigma = 1 - c w^n from w = 0 (climbing, c = -r; relaxing, c = 1;
:mod:`hysid_model.bouc_wen_orbit`, Eq. 2.1b in the units of the yield displacement), are tabulated as
quintic Hermite pieces between nodes whose sigma = T(w) is exact and whose derivatives
w' = 1 - c w^n, w'' = -n c w^(n-1) w' are known (:func:`build_table`): nodes graded towards w = 0
(where w^n is not smooth for a non-integer n; below the first node w = sigma within 1e-10) and
towards the pole of 1 / (1 - c w^n), beyond the last relaxing node (1 - u^n = 1e-8) the exact
exponential tail 1 - u = (eps_M / n) exp(-n (sigma - sigma_M)). Samples along a branch walk the
table; the tail runs through the multiply-add chain of :func:`hysid_model.bouc_wen_kernels._piece`, as the
n = 1 orbit does. Within 1e-9 of z_y of the exact z (:func:`hysid_model.bouc_wen_orbit.bouc_wen_exact`;
the tests compare both, and both with the time integration of Eq. 2.1b).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hysid_model.bouc_wen_kernels import _piece
from hysid_model.bouc_wen_orbit import digamma, orbit, relaxing_travel, travel
from hysid_model.shifted_kernels import _motion, _rotate

TAIL_DEFICIT = 1e-8
"""1 - u^n at the last node of the relaxing table; beyond it u = 1 - (1 - u^n) / n exactly to 1e-16."""
LINEAR_HEAD = 1e-10
"""Relative error of w = sigma below the first node (|c| w^n / (n + 1) there)."""
MAX_NODES = 1024
"""Nodes per table (the grading below needs about 30 to 450, the most for n = 1/2 and r >> 1; a table is cut
short at this size rather than overrun)."""
DEFICIT_NODES = 96
"""Nodes kept for the relaxing table's saturating part (it needs at most about 80)."""
NODE_RATIO = 0.2
"""Largest relative change of w' = 1 - c w^n between neighbouring nodes."""
HEAD_RATIO = 0.15
"""Node steps near w = 0 relative to w, times (max(n, 1)^5 |c| w^n)^(1/6)."""
DEFICIT_RATIO = 0.6
"""Ratio of 1 - u^n between neighbouring nodes of the relaxing table's saturating part."""


@njit(cache=True, nogil=True)
def _node(w: float, x: float, g: float, n: float, nodes: np.ndarray, i: int, sigma: float) -> None:
    """Node i: sigma, w, w' = g = 1 - x, w''/2 = -n x g / (2 w) (x = c w^n)."""
    nodes[i, 0] = sigma
    nodes[i, 1] = w
    nodes[i, 2] = g
    nodes[i, 3] = -0.5 * n * x * g / w


@njit(cache=True, nogil=True, inline="always")
def _node_step(w: float, x: float, n: float) -> float:
    """The step from node w (x = c w^n): w' = 1 - x changes by at most ``NODE_RATIO`` of itself, and
    towards w = 0 (where w^n is not smooth for a non-integer n) the steps grow geometrically as the
    sixth derivative of w(sigma), about max(n, 1)^5 |x| / w^5 while |x| < 1, allows (``HEAD_RATIO``)."""
    m = max(n, 1.0)
    grow = HEAD_RATIO / (m**5 * min(abs(x), 1.0) + 1e-300) ** (1.0 / 6.0)
    return w * min(1.0, grow, NODE_RATIO * abs(1.0 - x) / (m * abs(x) + 1e-300))


@njit(cache=True, nogil=True)
def build_table(c: float, n: float, a: float, psi: float, relaxing: bool, top: float, table: np.ndarray) -> int:
    """Tabulate w(sigma), dw/dsigma = 1 - c w^n, as quintic Hermite pieces: ``table[i]`` = (sigma_i, w_i,
    w'_i, w''_i / 2, and the 3rd, 4th, 5th order coefficients of the piece from node i to i + 1), up to
    the first node at or beyond w = ``top`` (the largest peak state of the orbits to evaluate).
    Returns the number of nodes (0: w = sigma everywhere, within ``LINEAR_HEAD``).

    The climbing piece (``relaxing`` False) ends at w = 1 at the latest (|u| never exceeds 1); the
    relaxing one (c = 1) at 1 - u^n = ``TAIL_DEFICIT`` (past which :func:`has_tail`), graded in
    1 - u^n from 1/2 on."""
    if c == 0.0:
        return 0
    first = (LINEAR_HEAD * (n + 1.0) / abs(c)) ** a
    end = 0.5**a if relaxing else 1.0
    if first >= end and not relaxing:
        return 0
    count = 0
    w = min(first, end)
    while True:
        x = c * w**n
        _node(w, x, 1.0 - x, n, table, count, travel(w, c, n, a, psi))
        count += 1
        if w >= end or w >= top or count == MAX_NODES - DEFICIT_NODES:
            break
        h = _node_step(w, x, n)
        w = end if w + h >= end * (1.0 - 1e-12) else w + h
    if relaxing and w < top:  # the saturating part, in the deficit eps = 1 - u^n
        eps = 0.5
        while eps > TAIL_DEFICIT and w < top and count < MAX_NODES:
            h = _node_step(w, 1.0 - eps, n)
            eps = max(eps * DEFICIT_RATIO, -math.expm1(n * math.log(w + h)), TAIL_DEFICIT)
            w = math.exp(a * math.log1p(-eps))
            _node(w, 1.0 - eps, eps, n, table, count, relaxing_travel(eps, a, psi))
            count += 1
    for i in range(count - 1):
        h = table[i + 1, 0] - table[i, 0]
        w0, d1, half = table[i, 1], table[i, 2], table[i, 3]
        r0 = table[i + 1, 1] - (w0 + h * (d1 + h * half))
        r1 = (table[i + 1, 2] - (d1 + 2.0 * half * h)) * h
        r2 = (table[i + 1, 3] - half) * h * h
        table[i, 4] = (10.0 * r0 - 4.0 * r1 + r2) / h**3
        table[i, 5] = (-15.0 * r0 + 7.0 * r1 - 2.0 * r2) / h**4
        table[i, 6] = (6.0 * r0 - 3.0 * r1 + r2) / h**5
    return count


@njit(cache=True, nogil=True, inline="always")
def _hermite(table: np.ndarray, i: int, sigma: float) -> float:
    """w(sigma) on piece i (Estrin's form of the quintic: a shorter chain of dependent operations than Horner's)."""
    d = sigma - table[i, 0]
    d2 = d * d
    return (table[i, 1] + d * table[i, 2]) + d2 * ((table[i, 3] + d * table[i, 4]) + d2 * (table[i, 5] + d * table[i, 6]))


@njit(cache=True, nogil=True, inline="always")
def has_tail(table: np.ndarray, count: int) -> bool:
    """Whether a :func:`build_table` table ends where the relaxing piece's exponential tail begins."""
    return count > 0 and table[count - 1, 2] <= TAIL_DEFICIT


@njit(cache=True, nogil=True)
def tabulated(table: np.ndarray, count: int, sigma: float, n: float) -> float:
    """w(sigma) from a :func:`build_table` table (bisection for the piece; past the end the relaxing
    piece's tail, else the last node's w: only rounding reaches beyond a table built far enough)."""
    if count == 0 or sigma <= table[0, 0]:
        return sigma
    last = count - 1
    if sigma >= table[last, 0]:
        if has_tail(table, count):
            return 1.0 - TAIL_DEFICIT / n * math.exp(-n * (sigma - table[last, 0]))
        return table[last, 1]
    return _hermite(table, _piece_of(table, last, sigma), sigma)


@njit(cache=True, nogil=True, inline="always")
def _bisect(table: np.ndarray, lo: int, hi: int, sigma: float) -> int:
    """The i in [lo, hi) with table[i, 0] <= sigma < table[i + 1, 0], given table[lo, 0] <= sigma < table[hi, 0]."""
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if table[mid, 0] <= sigma:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True, nogil=True, inline="always")
def _piece_of(table: np.ndarray, last: int, sigma: float) -> int:
    """The i < last with table[i, 0] <= sigma < table[i + 1, 0] (sigma within the table)."""
    return _bisect(table, 0, last, sigma)


@njit(cache=True, nogil=True, inline="always")
def _advance(table: np.ndarray, i: int, last: int, sigma: float) -> int:
    """:func:`_piece_of` for a sigma at or beyond piece i: galloping up from i (samples along a branch may be
    denser or sparser than the nodes)."""
    if table[i + 1, 0] > sigma:
        return i
    lo, step = i + 1, 1
    while lo + step < last and table[lo + step, 0] <= sigma:
        lo += step
        step *= 2
    return _bisect(table, lo, min(lo + step, last), sigma)


@njit(cache=True, nogil=True, inline="always")
def _retreat(table: np.ndarray, i: int, sigma: float) -> int:
    """:func:`_piece_of` for a sigma at or before the end of piece i (and at or above the first node),
    galloping down from i."""
    if table[i, 0] <= sigma:
        return i
    hi, step = i, 1
    while hi - step > 0 and table[hi - step, 0] > sigma:
        hi -= step
        step *= 2
    return _bisect(table, max(hi - step, 0), hi, sigma)


@njit(cache=True, nogil=True)
def _tabulated_state(t: float, tn: float, climb: np.ndarray, n_climb: int, relax: np.ndarray, n_relax: int, n: float) -> float:
    """u on the loading branch after the travel t (in z_y) from the reversal, from the tables."""
    if t < tn:
        return -tabulated(climb, n_climb, tn - t, n)
    return tabulated(relax, n_relax, t - tn, n)


@njit(cache=True, nogil=True)
def _candidate(
    n: float,
    r: float,
    zy: float,
    span: np.ndarray,
    climb: np.ndarray,
    relax: np.ndarray,
    um: np.ndarray,
    tn: np.ndarray,
    which: np.ndarray,
    mean_nodes: np.ndarray,
    split: np.ndarray,
    mean: np.ndarray,
) -> tuple[int, int]:
    """The orbit of every half span of one candidate and the tables up to its largest peak state, and where
    there are ``mean_nodes`` (M > 0) its cycle means into ``mean`` (:func:`_mean`): returns the table sizes."""
    a = 1.0 / n
    psi = digamma(a)
    top = 0.0
    for i in range(span.shape[0]):
        um[i], tn[i] = orbit(span[i] / zy, n, r, a, psi)
        top = max(top, um[i])
    n_climb, n_relax = build_table(-r, n, a, psi, False, top, climb), build_table(1.0, n, a, psi, True, top, relax)
    if mean_nodes.shape[1] > 0:
        _mean(which, tn, zy, mean_nodes, split, climb, n_climb, relax, n_relax, n, mean)
    return n_climb, n_relax


@njit(cache=True, nogil=True)
def _scratch(span: np.ndarray, which: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Work space of :func:`_candidate`, used again for every candidate: the two tables, the peak states and
    travel times of the half spans, the loops' cycle means."""
    return np.empty((MAX_NODES, 7)), np.empty((MAX_NODES, 7)), np.empty(span.shape[0]), np.empty(span.shape[0]), np.zeros(which.shape[0])


@njit(cache=True, nogil=True)
def _mean(
    which: np.ndarray,
    tn: np.ndarray,
    zy: float,
    nodes: np.ndarray,
    split: np.ndarray,
    climb: np.ndarray,
    n_climb: int,
    relax: np.ndarray,
    n_relax: int,
    n: float,
    out: np.ndarray,
) -> None:
    """out[l] = the cycle mean of z (m) over loop l's mean nodes (loading travels first, ``split[l]`` of them)."""
    for l in range(nodes.shape[0]):
        total = 0.0
        for j in range(nodes.shape[1]):
            u = _tabulated_state(max(nodes[l, j], 0.0) / zy, tn[which[l]], climb, n_climb, relax, n_relax, n)
            total += u if j < split[l] else -u
        out[l] = zy * total / nodes.shape[1]


@njit(cache=True, nogil=True, fastmath={"contract"})
def _run(
    out: np.ndarray,
    start: int,
    stride: int,
    count: int,
    travel_: np.ndarray,
    deviation: np.ndarray,
    dx: float,
    spread: float,
    tn: float,
    zy: float,
    n: float,
    ks: float,
    km: float,
    climb: np.ndarray,
    n_climb: int,
    relax: np.ndarray,
    n_relax: int,
) -> None:
    """out[start + j stride] += ks u(travel) - km along one run (travel increasing): the climbing piece,
    u = -w(tn - travel / z_y), walks its table down, the relaxing piece, u = w(travel / z_y - tn), up, and the
    relaxing tail goes through :func:`_piece`."""
    inv = 1.0 / zy
    j = 0
    i = -1
    while j < count:
        idx = start + j * stride
        sigma = tn - max(travel_[idx], 0.0) * inv
        if sigma <= 0.0:
            break
        if n_climb == 0 or sigma <= climb[0, 0]:
            u = sigma
        elif sigma >= climb[n_climb - 1, 0]:
            u = climb[n_climb - 1, 1]
        else:
            i = _piece_of(climb, n_climb - 1, sigma) if i < 0 else _retreat(climb, i, sigma)
            u = _hermite(climb, i, sigma)
        out[idx] += -ks * u - km
        j += 1
    last = n_relax - 1
    end = relax[last, 0]
    tail = has_tail(relax, n_relax)
    i = 0
    while j < count:
        idx = start + j * stride
        sigma = max(travel_[idx], 0.0) * inv - tn
        if sigma >= end and tail:
            break
        if sigma >= end:  # rounding past a table that ends before the tail
            u = relax[last, 1]
        elif sigma <= relax[0, 0]:
            u = max(sigma, 0.0)
        else:
            i = _advance(relax, i, last, sigma)
            u = _hermite(relax, i, sigma)
        out[idx] += ks * u - km
        j += 1
    if j < count:  # z = z_y (1 - (eps_M / n) exp(-(n / z_y) (t - z_y (tn + sigma_M))))
        scale = -ks * TAIL_DEFICIT / n
        _piece(out, start, stride, j, count, travel_, deviation, dx, spread, zy * (tn + end), n / zy, ks + scale - km, scale)


@njit(cache=True, nogil=True)
def bouc_wen_samples(
    candidates: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    span: np.ndarray,
    which: np.ndarray,
    travel_: np.ndarray,
    runs: np.ndarray,
    loop_runs: np.ndarray,
    step: np.ndarray,
    spread: np.ndarray,
    deviation: np.ndarray,
    mean_nodes: np.ndarray,
    split: np.ndarray,
    out: np.ndarray,
) -> None:
    """out[p, l, j] += k_p (z - mean) at fixed samples, any exponent: ``candidates`` the columns (exponent, r,
    zy, k) ``(P,)``; the runs as in :func:`hysid_model.bouc_wen_kernels.bouc_wen_samples`; the cycle mean over
    ``mean_nodes`` ``(L, M)`` (M = 0: none)."""
    exponent, r, zy, k = candidates
    climb, relax, um, tn, mean = _scratch(span, which)
    for p in range(exponent.shape[0]):
        n, zp = exponent[p], zy[p]
        n_climb, n_relax = _candidate(n, r[p], zp, span, climb, relax, um, tn, which, mean_nodes, split, mean)
        for l in range(travel_.shape[0]):
            row, km = out[p, l], k[p] * mean[l]
            for q in range(loop_runs[l], loop_runs[l + 1]):
                _run(
                    row,
                    runs[q, 1],
                    runs[q, 2],
                    runs[q, 3],
                    travel_[l],
                    deviation[l],
                    step[q],
                    spread[q],
                    tn[which[l]],
                    zp,
                    n,
                    k[p] * zp * runs[q, 4],
                    km,
                    climb,
                    n_climb,
                    relax,
                    n_relax,
                )


@njit(cache=True, nogil=True)
def bouc_wen_shifted(
    candidates: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    span: np.ndarray,
    which: np.ndarray,
    mean_nodes: np.ndarray,
    split: np.ndarray,
    shift: np.ndarray,
    motion: tuple[np.ndarray, np.ndarray],
    bounds: tuple[np.ndarray, np.ndarray],
    out: np.ndarray,
) -> None:
    """out[p, l, j] += k_p (z(theta_j - shift[p, l]) - mean): the orbit at phases shifted per candidate, any
    exponent (as :func:`hysid_model.shifted_kernels.bouc_wen_shifted`, whose ``xh, waves`` are ``motion`` here and
    ``x_min, x_max`` ``bounds``)."""
    exponent, r, zy, k = candidates
    (xh, waves), (x_min, x_max) = motion, bounds
    climb, relax, um, tn, mean = _scratch(span, which)
    xs = np.empty((2, xh.shape[2]))
    for p in range(exponent.shape[0]):
        n, zp = exponent[p], zy[p]
        n_climb, n_relax = _candidate(n, r[p], zp, span, climb, relax, um, tn, which, mean_nodes, split, mean)
        for l in range(waves.shape[1]):
            _rotate(xh, l, shift[p, l], xs)
            kp, km, t0 = k[p] * zp, k[p] * mean[l], tn[which[l]]
            for j in range(waves.shape[2]):
                x, v = _motion(waves, l, j, xs)
                if v >= 0.0:
                    u = _tabulated_state(max(x - x_min[l], 0.0) / zp, t0, climb, n_climb, relax, n_relax, n)
                else:
                    u = -_tabulated_state(max(x_max[l] - x, 0.0) / zp, t0, climb, n_climb, relax, n_relax, n)
                out[p, l, j] += kp * u - km
