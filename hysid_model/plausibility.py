"""What is suspicious but usable in measured loops: distortion, clipping, drift, unit slips, swapped columns.

The thesis' model assumes an imposed sine (Eq. 4.5) on a specimen measured in
consistent SI units. Real records break that quietly, so hysid measures each
record and warns (:class:`HysidWarning`, the work goes on):

* displacement distortion: THD (rms of harmonics 2-7 over the fundamental)
  above ``THD_WARN``; the loops keep the measured waveform, so the fit uses it;
* clipping: a flat displacement peak (stroke or sensor limit), or a
  flattened velocity (an actuator at its speed limit, which then cannot reach
  the amplitude asked for); see :func:`clipping`. A sine stays within a band
  of relative width b of its extreme for acos(1 - b) / pi of a cycle;
* amplitude drift over the steady window above ``DRIFT_WARN``;
* unit slips: a loop whose amplitude X0, or whose force per displacement
  F1/X0, is ``UNIT_GAP`` times away from every other loop's (mm under a
  ``_m`` header puts one loop at 1000x);
* implausible displacement: X0 above ``PLAUSIBLE_X0_M`` (no hysteresis rig
  strokes a metre); if the force is then smaller than the displacement, the
  two columns look swapped.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from hysid_model import waveform
from hysid_model.errors import HysidWarning

THD_WARN = 0.05
DRIFT_WARN = 0.05
CLIP_BAND = 0.05
CLIP_RATIO = 1.5
VELOCITY_BAND = 0.10
"""A velocity plateau is rounded by the harmonics the waveform keeps, so it is judged in a wider band."""
PLATEAU = 0.8
CLIP_BINS = 256
MIN_CLIP_BINS = 64
"""A mean cycle with fewer distinct phases is too coarse to tell a flat top from a round one."""
UNIT_GAP = 15.0
PLAUSIBLE_X0_M = 1.0
GRID = 4096


@dataclass
class Clipping:
    """``kind`` "" (none), "displacement" or "velocity"; ``level`` the flat top's displacement as recorded (m)
    or the velocity's peak |v| (m/s)."""

    kind: str = ""
    level: float = float("nan")

    def describe(self, x0: float) -> str:
        if self.kind == "displacement":
            return f"displacement flat at {self.level * 1e3:+.3g} mm (a stroke or sensor limit?), X0 = {x0 * 1e3:.3g} mm"
        if self.kind == "velocity":
            return f"velocity flattened at {self.level:.3g} m/s (a speed limit?), the displacement reaching X0 = {x0 * 1e3:.3g} mm"
        return ""


def _dwell_ratios(y: np.ndarray, band: float) -> np.ndarray:
    """Time near the maximum and near the minimum of a sampled cycle, relative to a sine's: ``(2,)``."""
    half = 0.5 * (y.max() - y.min())
    if not half > 0:
        return np.ones(2)
    sine = np.arccos(1.0 - band) / np.pi
    return np.array([np.mean(y >= y.max() - band * half), np.mean(y <= y.min() + band * half)]) / sine


def mean_cycle(cycle_phase: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The average displacement cycle of samples at ``cycle_phase`` (in cycles; whole cycles), in up to
    ``CLIP_BINS`` phase bins (empty bins, of a sample rate locked to the excitation, left out)."""
    bins = int(max(1, min(CLIP_BINS, x.size // 4)))
    b = (np.mod(cycle_phase, 1.0) * bins).astype(np.int64)
    np.minimum(b, bins - 1, out=b)
    count = np.bincount(b, minlength=bins)
    total = np.bincount(b, weights=x, minlength=bins)
    used = count > 0
    return total[used] / count[used]


def clipping(cycle: np.ndarray, xh: np.ndarray, freq: float) -> Clipping:
    """Clipping of a record from its mean displacement cycle and its displacement harmonics ``(1, K)``.

    A displacement extreme is flattened when the cycle stays near it (``CLIP_BAND``) ``CLIP_RATIO``
    times as long as a sine and is flat there: most of that time it is also within ``CLIP_BAND / 5``
    (``PLATEAU``; a sine spends 45 % of it there, a smooth top flattened by harmonics about 60 %, a
    clipped one over 80 %). A velocity is flattened when both its extremes are (a speed limit), in a
    displacement distorted by more than ``THD_WARN``.
    """
    if cycle.size >= MIN_CLIP_BINS:
        wide = _dwell_ratios(cycle, CLIP_BAND)
        narrow = _dwell_ratios(cycle, CLIP_BAND / 5) * (np.arccos(1 - CLIP_BAND / 5) / np.arccos(1 - CLIP_BAND))
        flat = (wide >= CLIP_RATIO) & (narrow >= PLATEAU * wide)
        if flat.any():
            return Clipping("displacement", float(cycle.max() if wide[0] * flat[0] >= wide[1] * flat[1] else cycle.min()))
    if waveform.thd(xh)[0] > THD_WARN:
        theta = np.linspace(-np.pi, np.pi, GRID, endpoint=False)
        v = 2 * np.pi * freq * waveform.displacement(xh, theta[None, :], 1)[0]
        if np.all(_dwell_ratios(v, VELOCITY_BAND) >= CLIP_RATIO):
            return Clipping("velocity", float(np.abs(v).max()))
    return Clipping()


def amplitude_drift(amplitudes: np.ndarray) -> np.ndarray:
    """Per row, the relative change over the cycles of a straight line through its per-cycle amplitudes."""
    n = amplitudes.shape[1]
    if n < 2:
        return np.zeros(amplitudes.shape[0])
    u = np.arange(n) - 0.5 * (n - 1)
    level = np.abs(amplitudes.mean(axis=1))
    change = np.abs(amplitudes @ u / (u @ u)) * (n - 1)
    return np.where(level > 0, change / np.where(level > 0, level, 1.0), 0.0)


def _outliers(values: np.ndarray) -> np.ndarray:
    """Indices outside the largest group of values that lie within ``UNIT_GAP`` of a neighbour (log scale)."""
    order = np.argsort(values)
    logs = np.log10(values[order])
    groups = np.concatenate([[0], np.cumsum(np.diff(logs) > np.log10(UNIT_GAP))])
    if groups[-1] == 0:
        return np.array([], dtype=int)
    main = np.argmax(np.bincount(groups))
    return np.sort(order[groups != main])


NAMED = 5
"""Loops a warning names one by one; beyond that it counts them and gives the range."""


def _names(labels: list[str], idx: np.ndarray, values: np.ndarray, fmt: str) -> str:
    if idx.size <= NAMED:
        return ", ".join(f"{labels[i]} ({fmt.format(values[i])})" for i in idx)
    low, high = int(idx[np.argmin(values[idx])]), int(idx[np.argmax(values[idx])])
    every = "all" if idx.size == len(labels) else f"{idx.size} of"
    return (f"{every} {len(labels)} records ({fmt.format(values[low])} in {labels[low]} to "
            f"{fmt.format(values[high])} in {labels[high]})")


def warn_loops(labels: list[str], x0: np.ndarray, force_amplitude: np.ndarray, thd: np.ndarray, drift: np.ndarray,
               clips: list[Clipping], where: str) -> None:
    """Warn (one line per kind) about the suspicious loops of a set extracted from ``where``; ``drift`` is
    ``(L, 2)`` (displacement, force)."""
    high = np.flatnonzero(thd > THD_WARN)
    if high.size:
        warnings.warn(HysidWarning(
            f"{where}: displacement THD above {100 * THD_WARN:g} % in {_names(labels, high, 100 * thd, '{:.3g} %')}: "
            "the shaker does not impose a pure sine; the loops keep the measured waveform"
        ), stacklevel=3)
    clipped = [i for i, c in enumerate(clips) if c.kind]
    if clipped:
        warnings.warn(HysidWarning(
            f"{where}: clipped: " + "; ".join(f"{labels[i]}: {clips[i].describe(float(x0[i]))}" for i in clipped)
        ), stacklevel=3)
    for k, what in enumerate(("displacement", "force")):
        drifting = np.flatnonzero(drift[:, k] > DRIFT_WARN)
        if drifting.size:
            warnings.warn(HysidWarning(
                f"{where}: the {what} amplitude drifts over the steady window by "
                f"{_names(labels, drifting, 100 * drift[:, k], '{:.3g} %')}; each loop averages its cycles"
            ), stacklevel=3)
    huge = np.flatnonzero(x0 > PLAUSIBLE_X0_M)
    if huge.size:
        swapped = huge[force_amplitude[huge] < x0[huge]]
        if swapped.size:
            warnings.warn(HysidWarning(
                f"{where}: displacement and force look swapped in {_names(labels, swapped, x0, 'X0 = {:.4g} m')} "
                f"(force amplitude {', '.join(f'{force_amplitude[i]:.3g} N' for i in swapped)}): no rig strokes more than "
                f"{PLAUSIBLE_X0_M:g} m while a specimen pushes back less than that in newtons; check the column order"
            ), stacklevel=3)
        rest = np.setdiff1d(huge, swapped)
        if rest.size:
            warnings.warn(HysidWarning(
                f"{where}: displacement amplitude above {PLAUSIBLE_X0_M:g} m in {_names(labels, rest, x0, 'X0 = {:.4g} m')}: "
                "is the displacement in mm under a _m header? (declare displacement_unit in dataset.toml)"
            ), stacklevel=3)
    if x0.size > 1:
        slips = np.union1d(_outliers(x0), _outliers(force_amplitude / x0))
        if slips.size:
            others = np.setdiff1d(np.arange(x0.size), slips)
            span = f"{x0[others].min() * 1e3:.4g}-{x0[others].max() * 1e3:.4g} mm" if others.size else "the others"
            warnings.warn(HysidWarning(
                f"{where}: amplitude or force per displacement far (more than {UNIT_GAP:g}x) from the other loops' in "
                f"{_names(labels, slips, x0 * 1e3, 'X0 = {:.4g} mm')} against X0 = {span}: a unit slip (mm under a _m "
                "header, kN under _n)? declare displacement_unit/force_unit in dataset.toml"
            ), stacklevel=3)
