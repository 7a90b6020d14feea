"""Branch values of a loop from the force samples of its steady cycles (step 4 and 6 of
:mod:`hysid_model.extraction`).

On the grid x_i the loading branch sits at the phase theta_i where the
measured displacement passes x_i rising, the unloading branch where it passes
x_i falling. Each branch value is a local-quadratic least-squares fit of the
force against theta over all cycles, in a phase window around theta_i. The
windows are disjoint (branch values have independent noise) and one-sided at
the reversals, so loading and unloading samples never mix and a friction jump
at the reversal stays sharp; samples too close to a reversal for the measured
displacement to tell their branch are left out (``GUARD_SIGMAS``).

A window is used as it is when its samples determine the quadratic about as
well as evenly spread samples would (:mod:`hysid_model.phase_sums`), else it
widens (``WIDEN``) until they do. Counting distinct phases is not enough: a
sample rate that is a ratio of small integers times the frequency (2048 Hz at
20 Hz: 102.4 samples per cycle) puts its samples on a few hundred phases,
each smeared by the frequency's small error, and a window then holds two or
three tight bunches of samples; a quadratic through them extrapolates the noise
into spikes and a noise estimate 50 times too large. A window widened until
it overlaps its neighbours shares their samples, and its value's variance
counts that (:func:`_shared_variance`). Windows that widen, or records that
need the harmonics below, first have the force's smooth part taken out
(:func:`hysid_model.force_harmonics.smooth_part`: harmonics 0..K and a jump at the reversals), so a wide
window is biased only by what that part misses. A record whose samples fall on
too few phases even for a window ``MAX_WIDTH`` wide (sparse sampling, or fewer
than about 25 distinct phases per cycle) gets the force's harmonics below its
Nyquist order instead, evaluated at theta_i (exact for a force without higher
content). A local-quadratic fit is unbiased for a parabola, so the force's
curvature leaves no bias; what remains is of order f^(4) w^4 inside and f^(3) w^3
at the four reversal samples.

Noise: sigma_raw, the std of one raw force sample about the mean cycle, is the
median over windows of the scatter about the local fits (chi-square corrected;
a median, so the few windows on a steep transition do not count). A branch
value is a weighted average of m ~ 1/v_i raw samples with v_i = [(U^T U)^-1]_00,
so its std is sigma_raw sqrt(v_i). A window whose v_i exceeds twice the median
is widened (``VARIANCE_SPREAD``), so that one sigma describes every branch value.
Every step is linear in the record length.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import cast

import numpy as np

from hysid_model import waveform
from hysid_model.force_harmonics import harmonic_branches
from hysid_model.phase_sums import PhaseSums, concatenated_ranges

END_WINDOW = 4.0
"""One-sided window at a reversal, in interior window widths: a local-quadratic fit
at the edge of a window has 4x the variance of one at its centre, so a 4x wider
window gives every branch value the same variance."""
WIDEN = tuple(float(r) for r in np.round(2.0 ** (np.arange(25) / 4), 3))
"""Widening factors tried for a window whose samples do not determine a local quadratic well (``CONDITION``) and
for a window whose branch value is noisier than the others (:func:`_even_out_variance`)."""
MAX_WIDEN = 2.0
"""Any window may widen this much..."""
MAX_WIDTH = np.pi / 4
"""...and beyond that up to this phase width (rad), three distinct phases of a rate locked to the excitation at 24
samples per cycle: a local quadratic over a wider window would bias what the smooth part leaves of a curved force
(by about f^(4) w^4 / 4500 inside and f^(3) w^3 / 120 at a reversal). A record whose samples need more (sparse
sampling, or fewer distinct phases per cycle) gets the force's harmonics instead."""
VARIANCE_SPREAD = 2.0
"""A branch value whose variance exceeds the median one's this many times gets a wider window."""
SNAP = 1e-9
"""Phases (rad) this close to a reversal are at the reversal (a record sampled exactly at its peaks)."""
GUARD_SIGMAS = 6.0
"""Samples closer to a reversal than this many standard errors of its phase are left out: the measured displacement
cannot tell on which branch they are, and one force sample of the other branch (a friction jump away) at the edge
of a reversal's one-sided window throws its extrapolated value off by a fraction of the jump."""


def phase_windows(theta: np.ndarray, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
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
    from scipy.special import gammaincinv  # on first use: a fast CLI and island start

    return float(2.0 * gammaincinv(0.5 * dof, 0.5) / dof)


def half_cycle_phases(theta: np.ndarray, reversal: tuple[float, float]) -> np.ndarray:
    """Phases ``theta`` in [lo, lo + 2 pi): the loading half cycle [lo, hi), the unloading one [hi, lo + 2 pi)
    (``reversal`` = (lo, hi)); a sample at a reversal belongs to the branch it starts, whatever the last bits of its
    phase say (``SNAP``)."""
    lo, hi = reversal
    psi = np.mod(theta - lo, 2 * np.pi) + lo
    psi[np.abs(psi - (lo + 2 * np.pi)) < SNAP] = lo
    psi[np.abs(psi - hi) < SNAP] = hi
    return psi


def reversal_guard(xh: np.ndarray, reversal: tuple[float, float], x_sigma: float, samples: int) -> float:
    """``GUARD_SIGMAS`` standard errors of the reversal phases of the displacement harmonics ``xh`` ``(1, K)`` fitted to
    ``samples`` samples with residual std ``x_sigma``: the error of x'(theta_r) over x''(theta_r)."""
    k = np.arange(1, xh.shape[1] + 1)
    slope_sd = x_sigma * np.sqrt(2.0 * np.sum(k * k) / samples)
    curvature = np.abs(waveform.displacement(xh, np.array([reversal]), 2)[0])
    return float(GUARD_SIGMAS * slope_sd / max(float(curvature.min()), 1e-300))


def branch_values(
    psi: np.ndarray,
    force: np.ndarray,
    sample_phases: np.ndarray,
    reversal: tuple[float, float],
    samples_per_cycle: float,
    guard: float,
    smooth: Callable[[], tuple[np.ndarray, np.ndarray]],
    order: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, float, float, int | None]:
    """Branch values at the 2n ``sample_phases`` (top, then bottom) of the force samples at half-cycle phases ``psi``
    (:func:`half_cycle_phases`); ``reversal`` = (lo, hi) phases, samples within ``guard`` of them left out
    (:func:`reversal_guard`). Where a window must widen, or the force's harmonics take over, the branches
    are those of the force less its smooth part, plus that part (``smooth``: :func:`hysid_model.force_harmonics.smooth_part` of
    ``force``); a record whose windows all keep their width (the usual one) does not need it. ``order``: the
    stable argsort of ``psi`` (:func:`hysid_model.resolution.reversal_steps` sorts the same samples).

    Returns (values, variance factors v, sigma_raw, overlap, harmonics). Local-quadratic fits in
    phase windows, each widened (``WIDEN``, up to ``MAX_WIDEN`` or ``MAX_WIDTH``) until its samples
    determine the quadratic well (``CONDITION``, ``MIN_SAMPLES``; ``harmonics`` None); else, for
    records whose samples fall on few phases per cycle (a rate locked to the excitation, or sparse
    sampling), the force's harmonics below the sample rate's Nyquist order
    (:func:`hysid_model.force_harmonics.harmonic_branches`). ``overlap`` is how many branch values share one independent number
    (1: independent); where windows overlap, each value's v counts its samples' shares
    (:func:`_shared_variance`).
    """
    centre, start, width, half_lo, half_hi, h = phase_windows(sample_phases, *reversal)
    guard = min(guard, 0.5 * h)  # a displacement too noisy to place its reversals better keeps most of its windows
    half_lo, half_hi = half_lo + guard, half_hi - guard
    ps = psi[order]
    sums = PhaseSums(ps, h)
    widest = np.maximum(MAX_WIDEN, MAX_WIDTH / (width * h))
    lo, hi = np.full(centre.size, np.nan), np.full(centre.size, np.nan)
    chosen_r, v = np.zeros(centre.size), np.full(centre.size, np.inf)
    for r in WIDEN:
        todo = np.flatnonzero(np.isnan(lo) & (r <= widest))
        if todo.size == 0:
            break
        w_lo, w_hi = _window_bounds(centre[todo], start[todo], width[todo], half_lo[todo], half_hi[todo], r * h)
        ok, v_todo = sums.conditioned(centre[todo], w_lo, w_hi)
        done = todo[ok]
        lo[done], hi[done], chosen_r[done], v[done] = w_lo[ok], w_hi[ok], r, v_todo[ok]
    harmonics = bool(np.any(np.isnan(lo)))
    if not harmonics:
        _even_out_variance(sums, centre, start, width, half_lo, half_hi, lo, hi, chosen_r, widest, v)
    del sums  # its prefix sums are five copies of the record
    at_branches = np.zeros(centre.size)
    if harmonics or np.any(chosen_r > 1.0):
        force, at_branches = smooth()
    ys = force[order]
    if harmonics:
        lo_phase, hi_phase = reversal
        keep = (ps >= lo_phase + guard) & (np.abs(ps - hi_phase) >= guard) & (ps <= lo_phase + 2 * np.pi - guard)
        values, var, sigma_raw, overlap, k = harmonic_branches(ps[keep], ys[keep], sample_phases, h, samples_per_cycle)
        return values + at_branches, var, sigma_raw, overlap, k
    value, v, ss, dof = _local_fits(ps, ys, centre, h, lo, hi)
    sigma_raw = float(np.sqrt(np.median(ss / dof) / _chi2_median_ratio(float(np.median(dof)))))
    shared, overlap = _shared_variance(ps, lo, hi)
    return value + at_branches, v * shared, sigma_raw, overlap, None


def _local_fits(
    ps: np.ndarray, ys: np.ndarray, centre: np.ndarray, h: float, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(value at the centre, variance factor v, residual sum of squares, degrees of freedom) of the local-quadratic
    fit in each window [lo, hi), windows taken in groups that hold about as many samples as the record (widened
    windows overlap, and their samples would otherwise be copied many times over)."""
    size = np.searchsorted(ps, hi) - np.searchsorted(ps, lo)
    group = np.cumsum(size) // max(ps.size, int(size.max()))
    out = []
    for g in np.split(np.arange(centre.size), np.flatnonzero(np.diff(group)) + 1):
        win, pos, u, moments, inverse = _window_fits(ps, centre[g], h, lo[g], hi[g])
        y = ys[pos]
        starts = _starts(win)
        yu = y * u
        rhs = np.stack([np.add.reduceat(w, starts) for w in (y, yu, yu * u)], axis=-1)
        coef = np.einsum("wij,wj->wi", inverse, rhs)
        resid = y - coef[win, 0] - coef[win, 1] * u - coef[win, 2] * u * u
        out.append((coef[:, 0], inverse[:, 0, 0], np.add.reduceat(resid * resid, starts), moments[0] - 3))
    return cast(tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], tuple(np.concatenate(parts) for parts in zip(*out)))


def _shared_variance(ps: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, float]:
    """(per window, the mean number of windows its samples belong to; that number over all samples used).

    Windows widened until they overlap share their samples: the 2n values then carry fewer independent
    numbers than 2n, and a value's variance times this factor is the variance that the raw samples'
    information gives it (as the force's harmonics' values are scaled, :func:`hysid_model.force_harmonics.harmonic_branches`), so that
    the loop's sigma gives chi^2 and the Fisher information of the samples used, not of each one counted
    several times. 1 for disjoint windows. Each window is a range of the sorted samples, so the count per
    sample is a running sum of the windows' starts and ends.
    """
    a, b = np.searchsorted(ps, lo), np.searchsorted(ps, hi)
    shares = np.cumsum(np.bincount(a, minlength=ps.size + 1) - np.bincount(b, minlength=ps.size + 1))[:-1]
    total = np.concatenate([[0.0], np.cumsum(shares, dtype=float)])
    return (total[b] - total[a]) / (b - a), float(np.sum(b - a) / np.count_nonzero(shares))


def _window_bounds(
    centre: np.ndarray, start: np.ndarray, width: np.ndarray, half_lo: np.ndarray, half_hi: np.ndarray, rh: float
) -> tuple[np.ndarray, np.ndarray]:
    """Phase windows at width ``rh`` clipped to their half cycles (see :func:`phase_windows`)."""
    return np.maximum(centre + start * rh, half_lo), np.minimum(centre + (start + width) * rh, half_hi)


def _window_fits(
    ps: np.ndarray, centre: np.ndarray, h: float, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[np.ndarray], np.ndarray]:
    """(window of each used sample, its position in ``ps``, its u = (phase - centre) / h, moments of u^0..u^4,
    inverse Gram matrices ``(W, 3, 3)``) of local-quadratic fits in the windows [lo, hi)."""
    win, pos = concatenated_ranges(np.searchsorted(ps, lo), np.searchsorted(ps, hi))
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


def _even_out_variance(
    sums: PhaseSums,
    centre: np.ndarray,
    start: np.ndarray,
    width: np.ndarray,
    half_lo: np.ndarray,
    half_hi: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    chosen_r: np.ndarray,
    widest: np.ndarray,
    v: np.ndarray,
) -> None:
    """Widen (in place) windows whose branch value's variance (``v``, :meth:`PhaseSums.variance` of the windows
    [lo, hi)) exceeds ``VARIANCE_SPREAD`` times the median one's.

    On a rate locked to the excitation the samples at a reversal's own phase
    belong to the branch they start, so the branch that ends there
    extrapolates its last value from samples a whole sample interval away;
    widening its window brings its variance back to the others', so that one
    ``sigma`` describes every branch value.
    """
    limit = VARIANCE_SPREAD * np.median(v)
    for r in WIDEN:
        wider = (v > limit) & (r <= widest)
        if not wider.any():  # a window's v only falls, and r only grows: none will widen
            break
        idx = np.flatnonzero(wider & (r > chosen_r))
        if idx.size == 0:
            continue
        wlo, whi = _window_bounds(centre[idx], start[idx], width[idx], half_lo[idx], half_hi[idx], r * sums.h)
        v_new = sums.variance(centre[idx], wlo, whi)
        better = v_new < v[idx]
        sel = idx[better]
        lo[sel], hi[sel], v[sel], chosen_r[sel] = wlo[better], whi[better], v_new[better], r
