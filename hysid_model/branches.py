"""Branch values of a loop from the force samples of its steady cycles (step 4 and 6 of
:mod:`hysid_model.extraction`).

On the grid x_i the loading branch sits at the phase theta_i where the
measured displacement passes x_i rising, the unloading branch where it passes
x_i falling. Each branch value is a local-quadratic least-squares fit of the
force against theta over all cycles, in a phase window around theta_i. The
windows are disjoint (branch values have independent noise) unless a window
must widen (at most ``MAX_WIDEN`` times) to hold 4 distinct sample phases, and
one-sided at the reversals, so loading and unloading samples never mix and a
friction jump at the reversal stays sharp. A record whose samples fall on too
few distinct phases even so (a sample rate locked to the excitation, say 200
samples per cycle for 100 points per branch, or sparse sampling) gets the
force's harmonics below its Nyquist order instead, evaluated at theta_i (exact
for a force without higher content). A local-quadratic fit is unbiased for a
parabola, so the force's curvature leaves no bias; what remains is of order
f^(4) h^4 inside and f^(3) w^3 at the four reversal samples (w = 4h).

Noise: sigma_raw, the std of one raw force sample about the mean cycle, is the
median over windows of the scatter about the local fits (chi-square corrected;
a median, so the few windows on a steep transition do not count). A branch
value is a weighted average of m ~ 1/v_i raw samples with v_i = [(U^T U)^-1]_00,
so its std is sigma_raw sqrt(v_i). A window whose v_i exceeds twice the median
is widened (``VARIANCE_SPREAD``), so that one sigma describes every branch value.
Every step is linear in the record length.
"""

from __future__ import annotations

from math import comb

import numpy as np
from scipy.special import gammaincinv

END_WINDOW = 4.0
"""One-sided window at a reversal, in interior window widths: a local-quadratic fit
at the edge of a window has 4x the variance of one at its centre, so a 4x wider
window gives every branch value the same variance."""
WIDEN = (1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0)
"""Widening factors tried for a window with too few distinct sample phases (up to ``MAX_WIDEN``) and for a reversal
window whose branch value is noisier than the others (:func:`_even_out_variance`)."""
MAX_WIDEN = 2.0
"""Widest window (times its width) a local-quadratic fit may take to find >= 4 distinct sample phases; a record
that needs more (a rate locked to the excitation, sparse sampling) gets the force's harmonics instead, as a
quadratic over a wider window would bias a curved force."""
VARIANCE_SPREAD = 2.0
"""A branch value whose variance exceeds the median one's this many times gets a wider window."""
DISTINCT = 1e-3
"""Sample phases closer than this fraction of a window apart count as one (a rate locked to the excitation repeats them)."""
SNAP = 1e-9
"""Phases (rad) this close to a reversal are at the reversal (a record sampled exactly at its peaks)."""


def harmonic_design(theta: np.ndarray, harmonics: int) -> np.ndarray:
    """Rows 1, sin(k theta), cos(k theta) for k = 1..harmonics, ``(2 harmonics + 1, N)`` (angle-sum recurrence)."""
    design = np.empty((2 * harmonics + 1, theta.size))
    design[0] = 1.0
    np.sin(theta, out=design[1])
    np.cos(theta, out=design[2])
    s1, c1 = design[1], design[2]
    for k in range(2, harmonics + 1):
        s, c = design[2 * k - 3], design[2 * k - 2]
        np.multiply(s, c1, out=design[2 * k - 1])
        design[2 * k - 1] += c * s1
        np.multiply(c, c1, out=design[2 * k])
        design[2 * k] -= s * s1
    return design


def _phase_windows(theta: np.ndarray, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """Phase windows of the 2n branch samples at phases ``theta`` (``[top(n), bottom(n)]`` order).

    ``lo`` and ``hi`` are the phases of the displacement's minimum and maximum
    (-pi/2 and pi/2 for the ideal sine). Returns (evaluation phase c, window
    start s, window width w, half-cycle limits lo and hi, h): at widening
    factor r the window is ``[c + s r h, c + (s + w) r h)`` clipped to
    ``[lo, hi)``, the sample's own half cycle (loading [lo, hi), unloading
    [hi, lo + 2 pi)). Interior windows are centred (s = -1/2, w = 1); the four
    reversal samples get one-sided windows of width ``END_WINDOW`` on their own
    branch's side. h is the largest width for which the windows at r = 1 are
    disjoint.
    """
    n_points = theta.size // 2
    gaps = np.concatenate([np.diff(theta[:n_points]), -np.diff(theta[n_points:])])
    if n_points == 2:
        h = min(gaps) / (2 * END_WINDOW)
    else:
        edges = np.array([gaps[0], gaps[n_points - 2], gaps[n_points - 1], gaps[-1]])
        inner = np.concatenate([gaps[1 : n_points - 2], gaps[n_points : 2 * n_points - 3]])
        h = min(inner.min() if inner.size else np.inf, edges.min() / (END_WINDOW + 0.5))
    start = np.full(2 * n_points, -0.5)
    width = np.ones(2 * n_points)
    forward = [0, 2 * n_points - 1]  # loading at the minimum, unloading at the maximum
    backward = [n_points - 1, n_points]  # loading at the maximum, unloading at the minimum
    width[forward + backward] = END_WINDOW
    start[forward] = 0.0
    start[backward] = -END_WINDOW
    low = np.repeat([lo, hi], n_points)
    high = np.repeat([hi, lo + 2 * np.pi], n_points)
    return theta, start, width, low, high, float(h)


def _chi2_median_ratio(dof: float) -> float:
    """median(chi2_dof) / dof."""
    return float(2.0 * gammaincinv(0.5 * dof, 0.5) / dof)


def _concatenated_ranges(first: np.ndarray, stop: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(owner, position) of every element of the ranges [first_j, stop_j)."""
    counts = stop - first
    owner = np.repeat(np.arange(first.size), counts)
    position = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts - first, counts)
    return owner, position


def branch_values(
    theta: np.ndarray, force: np.ndarray, sample_phases: np.ndarray, reversal: tuple[float, float], samples_per_cycle: float
) -> tuple[np.ndarray, np.ndarray, float, float, int | None]:
    """Branch values at the 2n ``sample_phases`` (top, then bottom); ``reversal`` = (lo, hi) phases.

    Returns (values, variance factors v, sigma_raw, overlap, harmonics). Local-quadratic fits in
    phase windows, each widened (``WIDEN``, up to ``MAX_WIDEN``) until it holds samples at >= 4
    distinct phases spread over >= 10 % of its width (``harmonics`` None); else, for records whose samples fall on few phases per
    cycle (a rate locked to the excitation, or sparse sampling), the force's harmonics below the
    sample rate's Nyquist order (:func:`_harmonic_branches`). ``overlap`` is how many branch values
    share one independent number (1: independent).
    """
    centre, start, width, half_lo, half_hi, h = _phase_windows(sample_phases, *reversal)
    lo_phase, hi_phase = reversal
    psi = np.mod(theta - lo_phase, 2 * np.pi) + lo_phase
    psi[np.abs(psi - (lo_phase + 2 * np.pi)) < SNAP] = lo_phase  # a sample at a reversal belongs to the branch it starts,
    psi[np.abs(psi - hi_phase) < SNAP] = hi_phase  # whatever the last bits of its phase say
    order = np.argsort(psi, kind="stable")
    ps, ys = psi[order], force[order]
    sums = _PhaseSums(ps, h)
    new_phase = np.concatenate([[1.0], (np.diff(ps) > DISTINCT * h).astype(float)])  # a sample at a phase not seen before
    cum_distinct = np.concatenate([[0.0], np.cumsum(new_phase)])
    lo, hi = np.full(centre.size, np.nan), np.full(centre.size, np.nan)
    chosen_r = np.zeros(centre.size)
    for r in WIDEN[: WIDEN.index(MAX_WIDEN) + 1]:
        todo = np.isnan(lo)
        if not np.any(todo):
            break
        w_lo, w_hi = _window_bounds(centre, start, width, half_lo, half_hi, r * h)
        a, b = np.searchsorted(ps, w_lo), np.searchsorted(ps, w_hi)
        s0, s1, s2 = (c[b] - c[a] for c in sums.cum[:3])
        distinct = cum_distinct[b] - cum_distinct[a] + (a < b) * (1.0 - new_phase[np.minimum(a, ps.size - 1)])
        with np.errstate(divide="ignore", invalid="ignore"):
            spread = np.sqrt(np.maximum(s2 / s0 - (s1 / s0) ** 2, 0.0))
        ok = todo & (distinct >= 4) & (spread >= 0.1 * (w_hi - w_lo))
        lo[ok], hi[ok], chosen_r[ok] = w_lo[ok], w_hi[ok], r
    if np.any(np.isnan(lo)):
        return _harmonic_branches(ps, ys, sample_phases, h, samples_per_cycle)
    _even_out_variance(sums, centre, start, width, half_lo, half_hi, lo, hi, chosen_r)
    win, pos, u, moments, inverse = _window_fits(ps, centre, h, lo, hi)
    y = ys[pos]
    starts = _starts(win)
    yu = y * u
    rhs = np.stack([np.add.reduceat(w, starts) for w in (y, yu, yu * u)], axis=-1)
    coef = np.einsum("wij,wj->wi", inverse, rhs)
    resid = y - coef[win, 0] - coef[win, 1] * u - coef[win, 2] * u * u
    ss = np.add.reduceat(resid * resid, starts)
    dof = moments[0] - 3
    sigma_raw = float(np.sqrt(np.median(ss / dof) / _chi2_median_ratio(float(np.median(dof)))))
    overlap = pos.size / np.count_nonzero(np.bincount(pos))
    return coef[:, 0], inverse[:, 0, 0], sigma_raw, float(overlap), None


def _harmonic_branches(
    ps: np.ndarray, ys: np.ndarray, sample_phases: np.ndarray, h: float, samples_per_cycle: float
) -> tuple[np.ndarray, np.ndarray, float, float, int]:
    """Branch values of a record with few distinct sample phases: the force's harmonics 0..K by least
    squares over every sample (K below the sample rate's Nyquist order and the distinct phases'),
    evaluated at the branch phases.

    Exact for a force without content above order K, whatever the phases; content above K (a
    friction jump) is smoothed, as the samples themselves cannot resolve it. Samples at one phase
    (within ``DISTINCT``) are averaged first, so the cost does not grow with the cycles. The 2n values
    then carry 2K + 1 independent numbers: their variance factors are scaled by 2n / (2K + 1), so
    that the loop's sigma gives chi^2 and the Fisher information of the raw samples.
    """
    key = np.concatenate([[0], np.cumsum(np.diff(ps) > DISTINCT * h)])
    count = np.bincount(key).astype(float)
    phase = np.bincount(key, ps) / count
    mean = np.bincount(key, ys) / count
    k = int(max(1, min((samples_per_cycle - 1) // 2, (count.size - 1) // 2)))
    design = harmonic_design(phase, k)  # (2k + 1, distinct)
    gram_inv = np.linalg.inv((design * count) @ design.T)
    coef = gram_inv @ (design @ (count * mean))
    within = float(np.sum(ys * ys) - np.sum(count * mean * mean))
    between = float(np.sum(count * (mean - coef @ design) ** 2))
    sigma_raw = float(np.sqrt(max(within + between, 0.0) / max(ys.size - (2 * k + 1), 1)))
    at = harmonic_design(sample_phases, k)
    var = np.einsum("in,ij,jn->n", at, gram_inv, at)
    overlap = max(1.0, sample_phases.size / (2 * k + 1))
    return coef @ at, var * overlap, sigma_raw, overlap, k


def _window_bounds(centre: np.ndarray, start: np.ndarray, width: np.ndarray, half_lo: np.ndarray, half_hi: np.ndarray,
                   rh: float) -> tuple[np.ndarray, np.ndarray]:
    """Phase windows at width ``rh`` clipped to their half cycles (see :func:`_phase_windows`)."""
    return np.maximum(centre + start * rh, half_lo), np.minimum(centre + (start + width) * rh, half_hi)


def _window_fits(ps: np.ndarray, centre: np.ndarray, h: float, lo: np.ndarray, hi: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[np.ndarray], np.ndarray]:
    """(window of each used sample, its position in ``ps``, its u = (phase - centre) / h, moments of u^0..u^4,
    inverse Gram matrices ``(W, 3, 3)``) of local-quadratic fits in the windows [lo, hi)."""
    win, pos = _concatenated_ranges(np.searchsorted(ps, lo), np.searchsorted(ps, hi))
    u = (ps[pos] - centre[win]) / h  # in window widths: the normal equations stay well conditioned
    u2 = u * u
    starts = _starts(win)
    moments = [np.diff(np.append(starts, win.size)).astype(float)]
    moments += [np.add.reduceat(w, starts) for w in (u, u2, u2 * u, u2 * u2)]
    gram = np.stack([np.stack([moments[i + j] for j in range(3)], axis=-1) for i in range(3)], axis=-2)
    return win, pos, u, moments, np.linalg.inv(gram)


def _starts(win: np.ndarray) -> np.ndarray:
    """Where each window's run starts in ``win`` (windows in order, none empty)."""
    return np.flatnonzero(np.diff(win, prepend=-1))


class _PhaseSums:
    """Prefix sums of the powers 0..4 of the sorted sample phases: the local-quadratic Gram matrix of any
    window in O(1), to choose windows before the one pass that fits them."""

    def __init__(self, ps: np.ndarray, h: float) -> None:
        self.ps, self.h = ps, h
        self.shift = 0.5 * (ps[0] + ps[-1])  # phases centred: the expansion below loses fewer digits
        q = ps - self.shift
        self.cum = np.empty((5, ps.size + 1))
        self.cum[:, 0] = 0.0
        self.cum[0, 1:] = np.arange(1, ps.size + 1)
        power = q.copy()
        for k in range(1, 5):
            np.cumsum(power, out=self.cum[k, 1:])
            if k < 4:
                power *= q

    def variance(self, centre: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """[(U^T U)^-1]_00 of the windows [lo, hi) about ``centre``: sum (q - c)^p expanded in the prefix sums."""
        a, b = np.searchsorted(self.ps, lo), np.searchsorted(self.ps, hi)
        s = [c[b] - c[a] for c in self.cum]
        c = -(centre - self.shift)
        m = [sum(comb(p, k) * s[k] * c ** (p - k) for k in range(p + 1)) / self.h**p for p in range(5)]
        gram = np.stack([np.stack([m[i + j] for j in range(3)], axis=-1) for i in range(3)], axis=-2)
        return np.linalg.inv(gram)[:, 0, 0]


def _even_out_variance(sums: _PhaseSums, centre: np.ndarray, start: np.ndarray, width: np.ndarray, half_lo: np.ndarray,
                       half_hi: np.ndarray, lo: np.ndarray, hi: np.ndarray, chosen_r: np.ndarray) -> None:
    """Widen (in place) windows whose branch value's variance exceeds ``VARIANCE_SPREAD`` times the median one's.

    On a rate locked to the excitation the samples at a reversal's own phase
    belong to the branch they start, so the branch that ends there
    extrapolates its last value from samples a whole sample interval away;
    widening its window brings its variance back to the others', so that one
    ``sigma`` describes every branch value.
    """
    v = sums.variance(centre, lo, hi)
    limit = VARIANCE_SPREAD * np.median(v)
    for r in WIDEN:
        idx = np.flatnonzero((v > limit) & (r > chosen_r))
        if idx.size == 0:
            continue
        wlo, whi = _window_bounds(centre[idx], start[idx], width[idx], half_lo[idx], half_hi[idx], r * sums.h)
        v_new = sums.variance(centre[idx], wlo, whi)
        better = v_new < v[idx]
        sel = idx[better]
        lo[sel], hi[sel], v[sel], chosen_r[sel] = wlo[better], whi[better], v_new[better], r
