"""Loop extraction: from a raw time series (t, x, F) or raw branches to a loop.

The thesis (Appendix A, ``PrepareExpData`` with ``getloopdisp``) smooths a
record, picks *one* cycle by hand, splits it at the displacement reversals into
a top (loading) and a bottom (unloading) branch, centres it
(``centercurveloop``) and resamples each branch on 100 points evenly spaced in
x (``reinterpolate``); those samples are what Eq. 3.3 / Fig. 5.1 compares.
:func:`extract_loop` does the same from every steady whole cycle of a record:

1. frequency: peak of the displacement spectrum (:mod:`hysid_model.spectral_peak`), refined by the slope of the
   steady cycles' first-harmonic phases (:func:`hysid_model.steady.phase_slope_frequency`);
   compared with the nominal (manifest) frequency, > 2 % apart is an error;
2. steady window: given (``dataset.toml``; it may reach one sample interval
   past the record) or found automatically (:mod:`hysid_model.steady`: the
   longest run of cycles with steady amplitudes, a slow drift allowed, minus
   leading/trailing transient cycles); all whole cycles inside it are used;
3. reference: x = X0 sin(theta) + harmonics + x_offset with theta = w t + phi
   (the fundamental of Eq. 4.5), by harmonic least squares over those whole
   cycles (harmonics below the Nyquist frequency only);
4. branches: on the grid x_i = linspace(x_min, x_max, n) (``reinterpolate``)
   between the measured displacement's extremes, the loading branch sits at
   the phase theta_i where the measured waveform passes x_i rising, the
   unloading branch where it passes x_i falling (:mod:`hysid_model.waveform`;
   for the ideal sine arcsin(x_i / X0) and pi - arcsin(x_i / X0)), exactly the
   phases :meth:`LoopSet.phases` gives the model.
   Each branch value is a local-quadratic fit of the force over all cycles
   in a phase window around theta_i, widened where its samples do not
   determine the fit (a sample rate that is a ratio of small integers times
   the frequency bunches them on a few phases), or, where the samples fall on
   too few distinct phases, the force's harmonics at theta_i (:mod:`hysid_model.branches`).
   The displacement's harmonics (orders 1-7) are kept with the loop,
   so that the model sees the measured waveform, and their distortion (rms of
   harmonics 2..7 over the fundamental) is reported;
5. centring (cf. ``centercurveloop``): the grid is centred on the fitted
   displacement offset, and the force's time average over the whole cycles is
   removed (the mean, not the mid-range of ``centercurveloop``, so noise
   spikes do not move the loop);
6. noise: sigma_raw, the std of one raw force sample about the mean cycle,
   from the scatter about the local fits (:mod:`hysid_model.branches`); the
   loop's ``sigma`` is sigma_raw sqrt(mean v_i), the noise of the branch
   samples *as stored* (v_i: each value's variance factor, counting the
   samples that overlapping windows share), which maximum-likelihood weights
   and Cramer-Rao bounds need;
7. checks (:mod:`hysid_model.plausibility`): displacement and force
   distortion, clipping of the displacement, the force or the velocity,
   amplitude drift; the set's unit slips and swapped columns are checked
   when every record is extracted. A record no loop can come from (values
   beyond ``LARGEST``, a force that never changes) is an error.

Every step is linear in the record length (no sliding windows over cycles).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np

from hysid_model import plausibility, steady, waveform
from hysid_model.blas import on_one_blas_thread
from hysid_model.branches import branch_values, half_cycle_phases, reversal_guard
from hysid_model.errors import HysidInputError, HysidWarning
from hysid_model.force_harmonics import CHUNK, harmonic_design, smooth_part
from hysid_model.resolution import reversal_steps
from hysid_model.spectral_peak import spectral_frequency

FREQ_TOLERANCE = 0.02
"""Largest relative difference between the nominal and the measured frequency."""
X_HARMONICS = 7
"""Harmonics of w t in the displacement (a real shaker's x is not a pure sine): fitted to refine the
frequency, and kept for the model (:mod:`hysid_model.waveform`)."""
SIGNIFICANT = 4.0
"""A displacement harmonic smaller than this many standard errors is noise (set to 0)."""
DISTORTION_FLOOR = 1e-5
"""...and so is one below 10 ppm of the fundamental (rounding, and leakage from a frequency known to ~1e-6)."""
CYCLE_SLACK = 0.02
"""Fraction of a period by which the whole cycles may overrun a given window."""
LARGEST = 1e100
"""Largest displacement (m) or force (N) a record may hold: squared and summed over millions of samples a larger
value overflows (1e300 did, into NaN cycle counts); no physical record comes anywhere near it."""


@dataclass
class ExtractedLoop:
    """One loop from a raw record; ``top``/``bottom`` are ``(n, 2)`` (x in m, F in N); ``x_harmonics``
    ``(K,)`` the measured displacement's harmonics (:mod:`hysid_model.waveform`)."""

    freq_hz: float
    x0: float
    x_harmonics: np.ndarray
    top: np.ndarray
    bottom: np.ndarray
    sigma: float
    sigma_raw: float
    cycles: int
    phase_deg: float
    force_amplitude: float
    x_offset: float
    x_peak: float
    x_distortion: float
    force_distortion: float
    """THD of the force (rms of its harmonics 2..7 over the first): a check of swapped columns."""
    force_mean: float
    window_s: tuple[float, float]
    samples_per_point: float
    window_overlap: float
    force_harmonics: int | None = None
    """Set where the record's few distinct sample phases made the branches harmonics 0..K of the force."""
    drift: tuple[float, float] = (0.0, 0.0)
    """Relative change of the displacement and force amplitudes over the cycles used."""
    clipping: plausibility.Clipping = field(default_factory=plausibility.Clipping)
    reversal_steps: np.ndarray | None = None
    """The reversal values less their fits on half windows at 1, 2, 4, 8 times the points per branch, in standard
    errors (:func:`hysid_model.resolution.reversal_steps`); None where the force's harmonics gave the branches."""

    def meta(self) -> dict[str, Any]:
        """Per-loop facts kept in ``LoopSet.meta['per_loop']``."""
        return {
            "phase_deg": self.phase_deg,
            "force_amplitude_n": self.force_amplitude,
            "sigma_raw_n": self.sigma_raw,
            "samples_per_point": self.samples_per_point,
            "window_overlap": self.window_overlap,
            "force_harmonics": self.force_harmonics,
            "x_offset_m": self.x_offset,
            "x_peak_m": self.x_peak,
            "x_distortion": self.x_distortion,
            "force_distortion": self.force_distortion,
            "force_mean_n": self.force_mean,
            "steady_t0_s": self.window_s[0],
            "steady_t1_s": self.window_s[1],
            "x_drift": self.drift[0],
            "force_drift": self.drift[1],
            "clipped": self.clipping.kind,
            "clip_level": self.clipping.level if self.clipping.kind else None,
        }


def centre_branches(top: np.ndarray, bottom: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Appendix A ``centercurveloop``: shift x and F so both ranges are symmetric about 0."""
    both = np.concatenate([top, bottom])
    shift = 0.5 * (both.max(axis=0) + both.min(axis=0))
    return top - shift, bottom - shift


def _branch_on_grid(branch: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Linear interpolation with linear extrapolation (``interp1(..., 'linear', 'extrap')``).

    Repeated x values (a sampled branch often has them at the reversals) are averaged.
    """
    xs, inverse = np.unique(branch[:, 0], return_inverse=True)
    fs = np.bincount(inverse, weights=branch[:, 1]) / np.bincount(inverse)
    if xs.size == 1:
        return np.full(grid.size, fs[0])
    out = np.interp(grid, xs, fs)
    lo, hi = grid < xs[0], grid > xs[-1]
    out[lo] = fs[0] + (grid[lo] - xs[0]) * (fs[1] - fs[0]) / (xs[1] - xs[0])
    out[hi] = fs[-1] + (grid[hi] - xs[-1]) * (fs[-1] - fs[-2]) / (xs[-1] - xs[-2])
    return out


def loop_from_branches(top: np.ndarray, bottom: np.ndarray, n_points: int, source: str) -> tuple[float, np.ndarray, np.ndarray]:
    """Raw branches (e.g. the thesis' ``HexpT``/``HexpB``) -> (X0, top, bottom) on the grid.

    Centred (``centercurveloop``), X0 = peak |x| (the thesis' ``Xpk``), both
    branches resampled on ``linspace(-X0, X0, n)`` (``reinterpolate``). The
    loading branch is the one with the larger force at equal x (true for any
    loop that dissipates energy); the branches are swapped if needed.
    """
    for arr, what in ((top, "top"), (bottom, "bottom")):
        if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 2:
            raise HysidInputError(f"{source}: the {what} branch must be an N x 2 array (x, F) with N >= 2, got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise HysidInputError(f"{source}: the {what} branch holds NaN or inf")
    top, bottom = centre_branches(top, bottom)
    x0 = float(max(np.abs(top[:, 0]).max(), np.abs(bottom[:, 0]).max()))
    if not x0 > 0:
        raise HysidInputError(f"{source}: the displacement does not vary (peak |x| = 0)")
    grid = np.linspace(-x0, x0, n_points)
    f_top, f_bot = _branch_on_grid(top, grid), _branch_on_grid(bottom, grid)
    if np.mean(f_top - f_bot) < 0:
        f_top, f_bot = f_bot, f_top
    return x0, np.column_stack([grid, f_top]), np.column_stack([grid, f_bot])


def _check_values(x: np.ndarray, force: np.ndarray, source: str) -> None:
    """Records no loop can come from: a value beyond ``LARGEST`` in size, or a force that never changes."""
    for values, what, unit in ((x, "displacement", "m"), (force, "force", "N")):
        peak = max(abs(float(values.max())), abs(float(values.min()))) if values.size else 0.0
        if peak > LARGEST:
            raise HysidInputError(
                f"{source}: the {what} reaches {peak:.3g} {unit}, beyond any physical {what} and beyond what the fits' "
                "sums of squares keep in floating point (a corrupt file, or a column of another quantity?)"
            )
    if force.size and force.max() == force.min():
        raise HysidInputError(f"{source}: the force is {force[0]:g} N in every sample: no loop to extract (a load cell not connected?)")


def _too_few_cycles(source: str, found: int, of: int) -> HysidInputError:
    return HysidInputError(
        f"{source}: fewer than 2 steady cycles (longest run of steady cycles: {found} of {of}); "
        "give steady_t0_s/steady_t1_s in dataset.toml or record more cycles"
    )


def _auto_window(t: np.ndarray, x: np.ndarray, force: np.ndarray, f0: float, source: str) -> tuple[float, float, float, steady.CycleFits]:
    """(t0, t1, refined frequency, the per-cycle fits on cycles of 1/f0 from t[0]) of the steady whole cycles
    (:mod:`hysid_model.steady`, stages 1 and 2)."""
    n_cycles = int(np.floor((t[-1] - t[0]) * f0 * (1 + 1e-9)))
    if n_cycles < 2:
        raise HysidInputError(f"{source}: fewer than 2 steady cycles: the whole record holds {(t[-1] - t[0]) * f0:.2f} cycles at {f0:.6g} Hz")
    fits = steady.cycle_fits(t, [x, force], t[0], f0, n_cycles)
    sampling = steady.sampling_error(t, [x, force], t[0], f0, n_cycles)
    start, length = steady.steady_run(fits.amplitude, fits.amplitude_noise(), sampling)
    if length < 2:
        raise _too_few_cycles(source, length, n_cycles)
    freq = steady.phase_slope_frequency(fits, f0, start, start + length)
    t_a = t[0] + start / f0
    amp = steady.line_through(fits.amplitude, start, start + length)
    off = steady.line_through(fits.offset, start, start + length)
    length = int(np.floor(length * freq / f0 + CYCLE_SLACK))
    if length < steady.WAVEFORM_MIN_CYCLES:
        return t_a, t_a + length / freq, freq, fits
    index = start + np.arange(length) * (f0 / freq)  # the stage-2 cycles on stage 1's cycle numbers
    trends = [(amp[s, 0] + amp[s, 1] * index, off[s, 0] + off[s, 1] * index) for s in range(2)]
    first, last = steady.waveform_steady(t, [x, force], trends, t_a, freq, length)
    if last - first < 2:
        raise _too_few_cycles(source, max(last - first, 0), n_cycles)
    return t_a + first / freq, t_a + last / freq, freq, fits


def _given_window(t: np.ndarray, window: tuple[float, float], source: str) -> tuple[float, float]:
    """A steady window from ``dataset.toml``, which may reach one sample interval past either end of the record
    (a window written as the nominal end of a record sampled up to one interval before it)."""
    t_a, t_b = window
    dt = (t[-1] - t[0]) / (t.size - 1)
    slack = dt * (1.0 + 1e-6)
    if not (t[0] - slack <= t_a < t_b <= t[-1] + slack):
        raise HysidInputError(f"{source}: steady window [{t_a:g}, {t_b:g}] s is not inside the record [{t[0]:g}, {t[-1]:g}] s")
    return max(t_a, float(t[0])), t_b


def _cycle_mean(t: np.ndarray, y: np.ndarray, t_a: float, t_b: float) -> float:
    """Time average of y over [t_a, t_b] (trapezoid of the linear interpolant, exact end points), a piece at a time
    beyond ``MAX_SAMPLES`` samples.

    A plain sample mean over "whole cycles" is off by up to one sample's share
    of the waveform, which for a 400 N loop sampled 700 times a cycle is
    already a visible 0.05 N offset.
    """
    first, stop = np.searchsorted(t, t_a, side="right"), np.searchsorted(t, t_b, side="left")
    ends = np.interp([t_a, t_b], t, y)
    total = 0.0
    starts = list(range(first, stop, steady.MAX_SAMPLES)) if stop - first > steady.MAX_SAMPLES else [first]
    for a in starts:
        b = stop if a == starts[-1] else a + steady.MAX_SAMPLES
        grid = np.concatenate([[t_a] if a == first else t[a - 1 : a], t[a:b], [t_b] if b == stop else []])
        vals = np.concatenate([ends[:1] if a == first else y[a - 1 : a], y[a:b], ends[1:] if b == stop else []])
        total += float(np.sum(0.5 * (vals[1:] + vals[:-1]) * np.diff(grid)))
    return total / (t_b - t_a)


def _displacement_harmonics(cx: np.ndarray, phi: float, x0: float, stderr: float, source: str) -> tuple[np.ndarray, float]:
    """(the displacement's harmonics referenced to its fundamental ``(1, K)``, their THD): x = sum Re[X_k e^{ik theta}], theta = w t + phi.

    ``cx`` holds [offset, a_1, b_1, a_2, b_2, ...] of x = sum a_k sin(k w t) + b_k cos(k w t);
    X_k = (b_k - i a_k) e^{-i k phi}, so X_1 = -i X0. Harmonics within ``SIGNIFICANT`` standard
    errors (``stderr``, of each coefficient) of zero, or below ``DISTORTION_FLOOR``, are noise and
    set to 0, so a clean sine stays the ideal sine. A waveform that reverses more than twice per cycle
    has no single loading and unloading branch: sub-loops, or the ripple that a few harmonics put on
    a clipped, flat top. The loop then keeps the most harmonics that reverse twice (at least the
    fundamental, the ideal sine), with a warning; the THD is that of all the measured harmonics.
    """
    k = np.arange(1, (cx.size - 1) // 2 + 1)
    xh = ((cx[2::2] - 1j * cx[1::2]) * np.exp(-1j * k * phi))[None, :]
    xh[0, 0] = -1j * x0
    xh[0, 1:][np.abs(xh[0, 1:]) < max(SIGNIFICANT * stderr, DISTORTION_FLOOR * x0)] = 0.0
    thd = float(waveform.thd(xh)[0])
    reverses = int(waveform.reversal_count(xh)[0])
    if reverses == 2:
        return xh, thd
    kept = next(n for n in range(xh.shape[1] - 1, 0, -1) if n == 1 or waveform.reversal_count(xh[:, :n])[0] == 2)
    warnings.warn(
        HysidWarning(
            f"{source}: the displacement reverses {reverses} times per cycle (sub-loops, or a clipped top); "
            + ("the loop is placed on the ideal sine X0 sin(wt)" if kept == 1 else f"the loop keeps its first {kept} harmonics, which reverse twice"),
            "sub_loops",
        ),
        stacklevel=3,
    )
    return xh[:, :kept].copy(), thd


@on_one_blas_thread
def extract_loop(
    t: np.ndarray,
    x: np.ndarray,
    force: np.ndarray,
    *,
    source: str,
    n_points: int = 100,
    nominal_freq_hz: float | None = None,
    steady_window: tuple[float, float] | None = None,
) -> ExtractedLoop:
    """Extract one loop from a raw record (see the module docstring for the method).

    ``t`` (s, strictly increasing), ``x`` (m), ``force`` (N); ``source`` names
    the file in error messages; ``steady_window`` = (t0, t1) in s, else found
    automatically. BLAS runs on one thread: its products here are small, and on a shared machine a second
    thread waiting for a core costs more than it saves (twice the time of the whole extraction, measured under
    a load of 2-5 on 2 cores).
    """
    t, x, force = (np.asarray(a, dtype=float) for a in (t, x, force))
    _check_values(x, force, source)
    f0 = spectral_frequency(t, x, source)
    if steady_window is None:
        t_a, t_b, freq, fits = _auto_window(t, x, force, f0, source)
        origin = float(t[0])
    else:
        t_a, t_b = _given_window(t, steady_window, source)
        n_given = int(np.floor((t_b - t_a) * f0 + CYCLE_SLACK))
        if n_given < 2 or np.searchsorted(t, t_b, side="right") - np.searchsorted(t, t_a) < 8:
            raise HysidInputError(f"{source}: fewer than 2 steady cycles ({(t_b - t_a) * f0:.2f} cycles at {f0:.6g} Hz in [{t_a:g}, {t_b:g}] s)")
        fits, origin = steady.cycle_fits(t, [x, force], t_a, f0, n_given), t_a
        freq = steady.phase_slope_frequency(fits, f0, 0, n_given)
    if nominal_freq_hz is not None and abs(freq / nominal_freq_hz - 1) > FREQ_TOLERANCE:
        raise HysidInputError(
            f"{source}: the data's frequency {freq:.6g} Hz disagrees with the manifest's {nominal_freq_hz:g} Hz "
            f"by {100 * abs(freq / nominal_freq_hz - 1):.1f} % (more than {100 * FREQ_TOLERANCE:g} %)"
        )
    cycles = int(np.floor((t_b - t_a) * freq + CYCLE_SLACK))
    while cycles >= 2 and t_a + cycles / freq > t[-1] + (1 + 1e-6) * (t[-1] - t[0]) / (
        t.size - 1
    ):  # the last sample of a whole cycle is one interval before its end
        cycles -= 1
    if cycles < 2:
        raise HysidInputError(f"{source}: fewer than 2 steady whole cycles at {freq:.6g} Hz in [{t_a:g}, {t_b:g}] s")
    t_end = t_a + cycles / freq
    bounds = steady.cycle_bounds(t, t_a, freq, cycles)
    sampled = steady.sampled_cycles(bounds)  # every cycle, or every k-th of a record longer than MAX_SAMPLES
    span = steady.samples_of(bounds, sampled)
    ts, xs, fs = t[span], x[span], force[span]
    w = 2 * np.pi * freq
    theta = w * (ts - t_a)
    harmonics = max(1, min(X_HARMONICS, int((ts.size / sampled.size - 1) // 2)))  # below the Nyquist frequency
    design = harmonic_design(theta, harmonics)
    gram = design @ design.T
    projection = np.stack([design @ xs, design @ fs], axis=1)
    cx, cf = np.linalg.solve(gram, projection).T
    x0 = float(np.hypot(cx[1], cx[2]))
    phi = float(np.arctan2(cx[2], cx[1]))
    phase = (np.degrees(np.arctan2(cf[2], cf[1]) - phi) + 180.0) % 360.0 - 180.0
    force_mean = _cycle_mean(t, force, t_a, t_end)
    x_residual = xs - cx @ design
    kept = design if ts.size <= CHUNK else None  # a longer record's (2K + 1) x N rows are rebuilt in pieces where needed
    del design
    x_sigma = float(np.sqrt(x_residual @ x_residual / max(xs.size - (2 * harmonics + 1), 1)))
    xh, thd = _displacement_harmonics(cx, phi, x0, x_sigma * np.sqrt(2.0 / xs.size), source)
    lo, hi = (float(r[0]) for r in waveform.reversals(xh))
    x_min, x_max = (float(e[0]) for e in waveform.extremes(xh))
    grid = np.linspace(x_min, x_max, n_points)
    sample_phases = waveform.branch_phases(xh, grid[None], grid[None])[0]
    psi = half_cycle_phases(theta + phi, (lo, hi))
    centred = fs - force_mean
    guard = reversal_guard(xh, (lo, hi), x_sigma, xs.size)
    order = np.argsort(psi, kind="stable")
    values, var, sigma_raw, overlap, force_harmonics = branch_values(
        psi,
        centred,
        sample_phases,
        (lo, hi),
        ts.size / sampled.size,
        guard,
        lambda: smooth_part(
            theta, harmonics, gram, projection[:, 1] - force_mean * gram[0], psi, hi, centred, harmonic_design(sample_phases - phi, harmonics), kept
        ),
        order,
    )
    first = int(round((t_a - origin) * f0))  # the cycles used, on the cycles of the per-cycle fits
    used = fits.amplitude[:, first : first + max(int(round(cycles * f0 / freq)), 1)]
    x_cycle, f_cycle = plausibility.mean_cycles(theta / (2 * np.pi), xs, fs)
    return ExtractedLoop(
        freq_hz=freq,
        x0=x0,
        x_harmonics=xh[0],
        top=np.column_stack([grid, values[:n_points]]),
        bottom=np.column_stack([grid, values[n_points:]]),
        sigma=sigma_raw * float(np.sqrt(var.mean())),
        sigma_raw=sigma_raw,
        cycles=int(sampled.size),
        phase_deg=float(phase),
        force_amplitude=float(np.hypot(cf[1], cf[2])),
        x_offset=float(cx[0]),
        x_peak=float(np.abs(xs - cx[0]).max()),
        x_distortion=thd,
        force_distortion=float(np.sqrt(np.sum(np.hypot(cf[3::2], cf[4::2]) ** 2)) / max(float(np.hypot(cf[1], cf[2])), 1e-300)),
        force_mean=force_mean,
        window_s=(float(t[bounds[0]]), float(t[bounds[-1] - 1])),
        samples_per_point=float(np.mean(1.0 / var)),
        window_overlap=overlap,
        force_harmonics=force_harmonics,
        drift=cast(tuple[float, float], tuple(float(d) for d in plausibility.amplitude_drift(used))),  # (displacement, force)
        clipping=plausibility.clipping(x_cycle, f_cycle, plausibility.saturation(fs), xh, freq),
        reversal_steps=None if force_harmonics is not None else reversal_steps(psi, centred, sample_phases, (lo, hi), guard, sigma_raw, order),
    )
