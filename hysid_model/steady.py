"""The steady part of a raw record: which whole cycles a loop is extracted from.

The thesis (Appendix A, ``PrepareExpData``) picks one steady cycle by hand.
hysid uses every steady whole cycle, found in two stages, both linear in the
record length:

1. amplitude (:func:`steady_run`): first-harmonic amplitudes of x and F in
   every cycle (:func:`cycle_fits`, one batched 3-term least squares over
   exactly one period each, its ends interpolated between samples); the
   steady cycles are the longest run whose amplitudes lie within a band
   (but for a few isolated cycles: scatter) around a straight line through them: +-``STEADY_TOLERANCE`` of the line
   or ``NOISE_SIGMAS`` robust standard deviations of the cycle-to-cycle
   scatter, or what sampling a jumping force may put on an amplitude
   (:func:`sampling_error`), whichever is wider, with the line changing by at most
   ``DRIFT_LIMIT`` over the run and bending by at most ``CURVATURE`` (a
   settling transient is curved, a drift straight). The reference is the run itself, not the
   largest amplitude, so the start-up overshoot and beating of a lightly
   damped specimen are left out, and a slow drift (heating, creep) keeps its
   cycles. A tapered sine's ramps change far faster than the band allows.
2. waveform (:func:`waveform_steady`, runs of at least
   ``WAVEFORM_MIN_CYCLES``): leading and trailing cycles whose samples differ
   from the median cycle significantly more than the typical cycle's do
   (transients that hardly change the first harmonic) are dropped. Each cycle
   is compared after the amplitude and offset trends of stage 1 are divided
   out, so a drift is not taken for a transient. The median cycle is the
   median of the samples in phase bins of about two samples per cycle,
   interpolated between the bins' centres (the bin edges sit between the
   phases of a sample rate locked to the excitation, so every cycle is
   compared with the same reference).

The first-harmonic phases of the cycles also give the frequency
(:func:`phase_slope_frequency`): a frequency error delta makes the phase
advance by 2 pi delta per second, a straight line through the cycles' phases.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import numpy as np

STEADY_TOLERANCE = 0.01
"""Half-width of the steady band, relative to the amplitude (or ``NOISE_SIGMAS`` stds of its scatter, if wider)."""
NOISE_SIGMAS = 4.0
CURVATURE = 0.0025
"""Largest departure of the amplitude from a straight line that a curve through the run may show: a start-up
transient settles along a curve, a drift does not."""
DRIFT_LIMIT = 0.10
"""Largest relative change of the amplitude over the steady run (a slow drift); faster changes are ramps."""
WAVEFORM_MIN_CYCLES = 5
"""Fewer steady cycles cannot tell a transient from cycle-to-cycle scatter; then only stage 1 applies."""
WAVEFORM_TOLERANCE = 1e-3
"""A cycle whose samples differ from the median cycle by less than 0.1 % of the signal's std is steady whatever the noise."""
OUTLIERS = 0.05
"""Isolated cycles outside the band (scatter, not a transient) allowed in a steady run, as a fraction of it."""
MAD_TO_STD = 1.4826
PIECE = 1 << 18
"""Samples (whole cycles) taken at once by the passes over every sample of a record, so that their memory is that of
a piece, not of the record (a 7.2 M-sample record's per-cycle fits took 14 copies of it at once)."""
MAX_SAMPLES = 1 << 19
"""Most samples the steps that need their samples together use: the median cycle (:func:`waveform_steady`) and the
branch values (:func:`hysid_model.extraction.extract_loop`) of a longer record are those of every k-th cycle, evenly
over it (524,288 samples: 52 s at 10 kHz; a longer record has its own loop's noise to a fraction of a percent)."""


@dataclass
class CycleFits:
    """First-harmonic fits y = a sin(theta) + b cos(theta) + c per cycle, theta = 2 pi f (t - t_a).

    ``z`` ``(S, n)`` is a + i b (|z| the amplitude, arg z the phase of the sine),
    ``offset`` ``(S, n)`` c, ``resid_var`` ``(S, n)`` the residual variance of a
    sample, ``count`` ``(n,)`` samples per cycle, ``t_mid`` ``(n,)`` their mean time.
    """

    z: np.ndarray
    offset: np.ndarray
    resid_var: np.ndarray
    count: np.ndarray
    t_mid: np.ndarray

    @property
    def amplitude(self) -> np.ndarray:
        return np.abs(self.z)

    def amplitude_noise(self) -> np.ndarray:
        """Std of one cycle's amplitude from the samples' residual scatter, per signal (an upper bound:
        harmonics count as scatter)."""
        return np.sqrt(np.median(self.resid_var, axis=1) * 2.0 / max(float(np.median(self.count)), 1.0))


def cycle_bounds(t: np.ndarray, t_a: float, freq: float, n_cycles: int) -> np.ndarray:
    """``(n_cycles + 1,)`` sample indices: cycle k holds samples bounds[k]:bounds[k+1], t in [t_a + k/f, t_a + (k+1)/f)."""
    return np.searchsorted(t, t_a + np.arange(n_cycles + 1) / freq)


def per_cycle_sums(rows: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """Sums over each cycle of ``rows`` ``(R, n + 1)``: the samples bounds[0]:bounds[-1] then one zero column
    (reduceat's indices must lie inside the array, also for empty last cycles); 0 for an empty cycle."""
    sums = np.add.reduceat(rows, bounds[:-1] - bounds[0], axis=1)
    sums[:, np.diff(bounds) == 0] = 0.0
    return sums


def _fit_rows(t: np.ndarray, signals: list[np.ndarray], index: np.ndarray | slice, t_a: float, freq: float) -> np.ndarray:
    """``(6 + 4 S, m + 1)``: sin, cos, their products and t, then y, y sin, y cos, y^2 per signal, at the samples
    ``index`` (theta = 2 pi f (t - t_a)), and one zero column (:func:`per_cycle_sums`)."""
    ts = t[index]
    m = ts.size
    rows = np.empty((6 + 4 * len(signals), m + 1))
    rows[:, m] = 0.0
    sin, cos = rows[0, :m], rows[1, :m]
    np.multiply(2 * np.pi * freq, ts - t_a, out=rows[2, :m])
    np.sin(rows[2, :m], out=sin)
    np.cos(rows[2, :m], out=cos)
    np.multiply(sin, sin, out=rows[2, :m])
    np.multiply(sin, cos, out=rows[3, :m])
    np.multiply(cos, cos, out=rows[4, :m])
    rows[5, :m] = ts
    for k, y in enumerate(signals):
        yk = rows[6 + 4 * k, :m]
        yk[:] = y[index]
        np.multiply(yk, sin, out=rows[7 + 4 * k, :m])
        np.multiply(yk, cos, out=rows[8 + 4 * k, :m])
        np.multiply(yk, yk, out=rows[9 + 4 * k, :m])
    return rows


def _exact_ends(t: np.ndarray, signals: list[np.ndarray], bounds: np.ndarray, t_a: float, freq: float, sums: np.ndarray) -> np.ndarray:
    """Turn the per-cycle sums of the samples in [T_k, T_k+1) into trapezoid sums over exactly that period (in place;
    returns each cycle's weight in samples).

    A cycle of a sample rate that is a ratio of small integers times the frequency holds one sample more every few
    cycles (102.4 samples per cycle: 103 every fifth); a plain sum over its samples then covers 1 % more than a
    period, and a force with strong harmonics leaks a few percent into that cycle's first harmonic, a pattern
    repeating every few cycles that looks like an unsteady amplitude. With the ends of each period interpolated
    between the samples on either side (alpha: where T_k falls between them), sample j before T_k moves
    (1 - alpha)^2 / 2 of its row to the cycle after, sample j + 1 moves alpha^2 / 2 to the cycle before.
    """
    n = bounds.size - 1
    before, after = np.clip(bounds - 1, 0, t.size - 1), np.clip(bounds, 0, t.size - 1)  # samples j and j + 1
    t_k = t_a + np.arange(n + 1) / freq
    inside = before < after
    alpha = np.where(bounds == 0, 1.0, 0.0)  # no sample before the record's start: T_k is the first sample; none after: the last
    alpha[inside] = np.clip((t_k[inside] - t[before[inside]]) / (t[after[inside]] - t[before[inside]]), 0.0, 1.0)
    both = _fit_rows(t, signals, np.concatenate([before, after]), t_a, freq)[:, :-1]
    move = 0.5 * (1 - alpha) ** 2 * both[:, : n + 1] - 0.5 * alpha**2 * both[:, n + 1 :]  # from cycle k - 1 to cycle k
    sums[:, :n] -= move[:, 1:]
    sums[:, :n] += move[:, :-1]
    return np.diff(bounds) + (0.5 - alpha[:-1]) - (0.5 - alpha[1:])


def pieces(bounds: np.ndarray) -> list[tuple[int, int]]:
    """The cycles ``bounds`` delimits in runs ``(first, stop)`` of whole cycles of about ``PIECE`` samples (at least one
    cycle each)."""
    cuts = [0]
    while cuts[-1] < bounds.size - 1:
        stop = int(np.searchsorted(bounds, bounds[cuts[-1]] + PIECE, side="right")) - 1
        cuts.append(min(max(stop, cuts[-1] + 1), bounds.size - 1))
    return list(pairwise(cuts))


def cycle_fits(t: np.ndarray, signals: list[np.ndarray], t_a: float, freq: float, n_cycles: int) -> CycleFits:
    """One 3-term least-squares fit per cycle [t_a + k/f, t_a + (k+1)/f), k < ``n_cycles``, of every signal (batched),
    each over exactly its period (:func:`_exact_ends`); the sums are taken a piece of cycles at a time (:func:`pieces`)."""
    bounds = cycle_bounds(t, t_a, freq, n_cycles)
    sums = np.empty((6 + 4 * len(signals), n_cycles))
    for first, stop in pieces(bounds):
        part = bounds[first : stop + 1]
        sums[:, first:stop] = per_cycle_sums(_fit_rows(t, signals, slice(part[0], part[-1]), t_a, freq), part)
    weight = _exact_ends(t, signals, bounds, t_a, freq, sums)
    count = np.diff(bounds).astype(float)
    s, c, ss, sc, cc = sums[:5]
    gram = np.stack([np.stack([weight, s, c], axis=-1), np.stack([s, ss, sc], axis=-1), np.stack([c, sc, cc], axis=-1)], axis=-2)
    few = count < 4  # a cycle cut short by the end of the record: no fit
    gram[few] = np.eye(3)
    t_mid = sums[5] / np.where(few, 1.0, weight)
    z, offset, resid = [], [], []
    for k in range(len(signals)):
        rhs = sums[6 + 4 * k : 9 + 4 * k].T
        coef = np.linalg.solve(gram, rhs[:, :, None])[:, :, 0]
        coef[few] = 0.0
        ss_res = sums[9 + 4 * k] - np.sum(coef * rhs, axis=1)
        z.append(coef[:, 1] + 1j * coef[:, 2])
        offset.append(coef[:, 0])
        resid.append(np.where(few, 0.0, np.maximum(ss_res, 0.0) / np.maximum(weight - 3.0, 1.0)))
    return CycleFits(np.array(z), np.array(offset), np.array(resid), count, t_mid)


def phase_slope_frequency(fits: CycleFits, freq: float, first: int, stop: int) -> float:
    """The frequency from the phases of cycles ``first..stop-1`` (fitted at ``freq``) of signal 0:
    a weighted straight line through the unwrapped phases against time (weights: the inverse phase variances)."""
    z = fits.z[0, first:stop]
    tau = fits.t_mid[first:stop]
    weight = np.abs(z) ** 2 * fits.count[first:stop]
    if z.size < 2 or not np.any(weight > 0):
        return freq
    psi = np.unwrap(np.angle(z))
    w = weight / weight.sum()
    tc = tau - w @ tau
    den = w @ (tc * tc)
    return freq if den <= 0 else float(freq + (w @ (tc * psi)) / den / (2 * np.pi))


def sampling_error(t: np.ndarray, signals: list[np.ndarray], t_a: float, freq: float, n_cycles: int) -> np.ndarray:
    """``(S,)``: the most that sampling puts on one cycle's first-harmonic amplitude of each signal.

    A cycle's amplitude is a quadrature over its samples (:func:`cycle_fits`), exact to O(dt^2) for a smooth
    signal but not for one that jumps (a friction force at each reversal): the jump J falls somewhere between two
    samples, and where it falls moves the amplitude by up to J / (samples per cycle) per jump. When the samples'
    phases drift slowly against the excitation (a rate near a multiple of the frequency) that error is a slow
    sawtooth over the cycles, which the band and curvature tests would take for a transient. J is the typical
    cycle's largest second difference (a median over the cycles, so that one glitch does not count).
    """
    bounds = cycle_bounds(t, t_a, freq, n_cycles)
    per_cycle = (bounds[-1] - bounds[0]) / max(n_cycles, 1)
    out = np.zeros(len(signals))
    size = bounds[-1] - bounds[0] - 2  # second differences of the samples of the cycles
    if size < 1:
        return out
    starts = np.minimum(bounds[:-1] - bounds[0], size - 1)
    for k, y in enumerate(signals):
        peaks = np.empty(n_cycles)
        for first, stop in pieces(bounds):
            lo = starts[first]
            hi = size if stop == n_cycles else min(starts[stop] + 1, size)  # one past the piece: a cycle with no sample
            part = y[bounds[0] + lo : bounds[0] + hi + 2]
            second = np.abs(np.diff(part, 2))
            cut = starts[first:stop] - lo
            if stop < n_cycles and hi > starts[stop]:
                cut = np.append(cut, starts[stop] - lo)  # ends the piece's last cycle before the sample past it
            peaks[first:stop] = np.maximum.reduceat(second, cut)[: stop - first]
        out[k] = 2.0 * float(np.median(peaks)) / per_cycle
    return out


def line_through(values: np.ndarray, start: int, stop: int) -> np.ndarray:
    """``(S, 2)``: each row's least-squares line (alpha, beta) through its cycles start..stop-1 (value alpha + beta k)."""
    v = values[:, start : max(stop, start + 1)]
    k = np.arange(start, start + v.shape[1], dtype=float)
    u = k - k.mean()
    beta = v @ u / (u @ u) if v.shape[1] > 1 else np.zeros(v.shape[0])
    return np.stack([v.mean(axis=1) - beta * k.mean(), beta], axis=1)


def steady_run(amp: np.ndarray, noise: np.ndarray, sampling: np.ndarray | None = None) -> tuple[int, int]:
    """(start, length) of the longest run of cycles whose amplitudes ``amp`` ``(S, n)`` are steady (stage 1).

    ``noise`` ``(S,)`` is a first guess of each amplitude's cycle-to-cycle std;
    it is re-estimated from the run found (robust std of successive
    differences), and the run searched again, until it no longer changes.
    ``sampling`` ``(S,)`` bounds what the sampling itself puts on an amplitude
    (:func:`sampling_error`); departures within it are neither scatter nor a transient.
    """
    sampling = np.zeros(amp.shape[0]) if sampling is None else sampling
    start, length = _longest_band_run(amp, noise, sampling)
    for _ in range(3):
        if length < WAVEFORM_MIN_CYCLES:
            break
        run = amp[:, start : start + length]
        scatter = MAD_TO_STD * np.median(np.abs(np.diff(run, axis=1)), axis=1) / np.sqrt(2.0)
        found = _longest_band_run(amp, scatter, sampling)
        if found == (start, length):
            break
        start, length = found
    return start, length


def _longest_band_run(amp: np.ndarray, noise: np.ndarray, sampling: np.ndarray) -> tuple[int, int]:
    """Longest window of cycles that is steady: within the band around its line, drifting at most ``DRIFT_LIMIT``,
    and not curved (a settling transient is curved, a drift is straight); the compiled search of
    :func:`hysid_model.steady_band.longest_band_run`."""
    from hysid_model.steady_band import longest_band_run  # numba loads with the first record extracted (hysid --help and an island never do)

    amp = np.ascontiguousarray(amp, dtype=float)
    spread = NOISE_SIGMAS * np.asarray(noise, dtype=float)
    sampling = np.asarray(sampling, dtype=float)
    limits = np.array([STEADY_TOLERANCE, DRIFT_LIMIT, CURVATURE, OUTLIERS])
    start, length = longest_band_run(amp, np.maximum(spread, sampling), spread, sampling, limits, WAVEFORM_MIN_CYCLES)
    return int(start), int(length)


def _bin_medians(phase: np.ndarray, y: np.ndarray, bins: int) -> tuple[np.ndarray, np.ndarray]:
    """(centre phase, median of y) of the non-empty phase bins [(j - 1/4)/bins, (j + 3/4)/bins)."""
    b = np.floor(phase * bins + 0.25).astype(np.int64) % bins
    order = np.argsort(b.astype(np.int16 if bins <= np.iinfo(np.int16).max else np.int32), kind="stable")  # int16: a radix sort
    counts = np.bincount(b, minlength=bins)
    width = int(counts.max())
    table = np.full((bins, width), np.inf)
    table.ravel()[np.repeat(np.arange(bins) * width - (np.cumsum(counts) - counts), counts) + np.arange(b.size)] = y[order]  # bin, rank
    table.sort(axis=1)  # numpy's vectorised sort beats a partition at the middle ranks (3x at 14 samples a bin, 1.6x at 5,000)
    used = np.flatnonzero(counts)
    c = counts[used]
    rows = table[used]
    median = 0.5 * (rows[np.arange(used.size), (c - 1) // 2] + rows[np.arange(used.size), c // 2])
    return (used + 0.25) / bins, median


def _periodic_interp(phase: np.ndarray, centre: np.ndarray, value: np.ndarray) -> np.ndarray:
    """Linear interpolation in a phase of period 1."""
    xp = np.concatenate([[centre[-1] - 1.0], centre, [centre[0] + 1.0]])
    fp = np.concatenate([[value[-1]], value, [value[0]]])
    return np.interp(phase, xp, fp)


def _excess(phase: np.ndarray, y: np.ndarray, bounds: np.ndarray, centre: np.ndarray, median: np.ndarray) -> np.ndarray:
    """Per cycle of ``bounds`` (the samples ``y`` at ``phase``), the mean squared difference from the median cycle."""
    sq = np.empty((1, y.size + 1))
    sq[0, -1] = 0.0
    np.square(y - _periodic_interp(phase, centre, median), out=sq[0, :-1])
    return per_cycle_sums(sq, bounds)[0] / np.maximum(np.diff(bounds), 1)


def sampled_cycles(bounds: np.ndarray, limit: int = MAX_SAMPLES) -> np.ndarray:
    """The cycles of ``bounds`` to use where at most about ``limit`` samples may be: all of them, or every k-th."""
    n_cycles = bounds.size - 1
    step = max(1, -(-int(bounds[-1] - bounds[0]) // limit))
    return np.arange(0, n_cycles, step)


def samples_of(bounds: np.ndarray, cycles: np.ndarray) -> np.ndarray | slice:
    """The sample indices of ``cycles`` (increasing; a slice when they follow one another)."""
    if cycles[-1] - cycles[0] + 1 == cycles.size:
        return slice(int(bounds[cycles[0]]), int(bounds[cycles[-1] + 1]))
    first, stop = bounds[cycles], bounds[cycles + 1]
    counts = stop - first
    return np.repeat(first - np.cumsum(counts) + counts, counts) + np.arange(int(counts.sum()))


def _normalized(
    t: np.ndarray, y: np.ndarray, bounds: np.ndarray, cycles: np.ndarray, t_a: float, freq: float, offset: np.ndarray, scale: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(phase in [0, 1), ``y`` less its offset trend, times its amplitude's ``scale``) of the samples of ``cycles``."""
    index = samples_of(bounds, cycles)
    cycle = np.repeat(cycles, bounds[cycles + 1] - bounds[cycles])
    return (t[index] - t_a) * freq - cycle, (y[index] - offset[cycle]) * scale[cycle]


def waveform_steady(
    t: np.ndarray, signals: list[np.ndarray], trends: list[tuple[np.ndarray, np.ndarray]], t_a: float, freq: float, n_cycles: int
) -> tuple[int, int]:
    """(first, stop) of the steady cycles after leading and trailing transients are dropped (stage 2).

    ``trends`` gives each signal's amplitude and offset per cycle (``(n,)``
    each), divided out before the comparison. The median cycle is that of at most ``MAX_SAMPLES`` samples
    (:func:`sampled_cycles`); every cycle is compared with it a piece at a time (:func:`pieces`).
    """
    bounds = cycle_bounds(t, t_a, freq, n_cycles)
    per_cycle = (bounds[-1] - bounds[0]) / n_cycles
    sampled = sampled_cycles(bounds)
    runs = pieces(bounds)
    steady = np.ones(n_cycles, dtype=bool)
    for y, (amplitude, offset) in zip(signals, trends):
        scale = np.where(amplitude > 0, np.mean(amplitude) / np.where(amplitude > 0, amplitude, 1.0), 1.0)

        phase, yk = _normalized(t, y, bounds, sampled, t_a, freq, offset, scale)
        centre, median = _bin_medians(phase, yk, max(4, int(per_cycle // 2)))
        spread = np.std(yk)
        if sampled.size == n_cycles and len(runs) == 1:  # the median cycle's samples are every cycle's, in one piece
            excess = _excess(phase, yk, bounds, centre, median)
        else:
            del phase, yk
            excess = np.empty(n_cycles)
            for first, stop in runs:
                phase, yk = _normalized(t, y, bounds, np.arange(first, stop), t_a, freq, offset, scale)
                excess[first:stop] = _excess(phase, yk, bounds[first : stop + 1], centre, median)
        limit = max(np.median(excess) * (1.0 + NOISE_SIGMAS * np.sqrt(2.0 / per_cycle)), (WAVEFORM_TOLERANCE * spread) ** 2)
        steady &= excess <= limit
    if not steady.any():
        return 0, 0
    return int(np.argmax(steady)), n_cycles - int(np.argmax(steady[::-1]))
