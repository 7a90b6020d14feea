"""What is suspicious but usable in measured loops: distortion, clipping, drift, unit slips, swapped columns.

The thesis' model assumes an imposed sine (Eq. 4.5) on a passive specimen
measured in consistent SI units. Real records break that quietly, so hysid
measures each record and warns (:class:`HysidWarning`, the work goes on):

* displacement distortion: THD (rms of harmonics 2-7 over the fundamental)
  above ``THD_WARN``; the loops keep the measured waveform, and the fits decide
  from the force whether it is the motion or the sensor's (``hysid.motion``);
* clipping: a flat displacement peak (stroke or sensor limit), a flat force
  peak (a load cell or its amplifier at the end of its range), or a
  flattened velocity (an actuator at its speed limit, which then cannot reach
  the amplitude asked for); see :func:`clipping`. A sine stays within a band
  of relative width b of its extreme for acos(1 - b) / pi of a cycle;
* amplitude drift over the steady window above ``DRIFT_WARN``;
* unit slips between loops: a loop whose amplitude X0, or whose force per
  displacement F1/X0, is ``UNIT_GAP`` times away from every other loop's (mm
  under a ``_m`` header puts one loop at 1000x).

The slips every loop shares (swapped columns, a reversed sign, a unit slip of the
whole set) show only in the physics: :mod:`hysid_model.slips`. Each warning carries
its code (:data:`hysid_model.notices.CODES`).
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
GRID = 4096
SATURATED = 0.01
"""A force channel at the end of its range reads the same value in this share of its samples or more; a signal,
however flat its top, only touches its maximum (``WALL`` of the range decides "the same")."""
WALL = 1e-9
JUMP = 0.5
"""A mean force cycle that changes by more than this share of its range from one phase bin to the next jumps (a
friction force at the reversals); a clipped one rises into its flat top."""


@dataclass
class Clipping:
    """``kind`` "" (none), "displacement", "force" or "velocity"; ``level`` the flat top's displacement (m) or force
    (N) as recorded, or the velocity's peak |v| (m/s)."""

    kind: str = ""
    level: float = float("nan")

    def describe(self, x0: float) -> str:
        if self.kind == "displacement":
            return f"displacement flat at {self.level * 1e3:+.3g} mm, X0 = {x0 * 1e3:.3g} mm"
        if self.kind == "force":
            return f"force flat at {self.level:+.4g} N"
        if self.kind == "velocity":
            return f"velocity flattened at {self.level:.3g} m/s, the displacement reaching X0 = {x0 * 1e3:.3g} mm"
        return ""


CLIP_CAUSES = {"displacement": "a stroke or sensor limit?", "force": "a load cell or its amplifier at the end of its range?", "velocity": "a speed limit?"}
CLIP_LEVELS = {"displacement": ("flat at {:+.3g} mm", 1e3), "force": ("flat at {:+.4g} N", 1.0), "velocity": ("flattened at {:.3g} m/s", 1.0)}
"""How a set's summary gives each kind's level: format and factor from the stored level (m, N, m/s)."""


def _dwell_ratios(y: np.ndarray, band: float) -> np.ndarray:
    """Time near the maximum and near the minimum of a sampled cycle, relative to a sine's: ``(2,)``."""
    half = 0.5 * (y.max() - y.min())
    if not half > 0:
        return np.ones(2)
    sine = np.arccos(1.0 - band) / np.pi
    return np.array([np.mean(y >= y.max() - band * half), np.mean(y <= y.min() + band * half)]) / sine


def mean_cycles(cycle_phase: np.ndarray, *signals: np.ndarray) -> list[np.ndarray]:
    """The average cycle of each of the ``signals`` sampled at ``cycle_phase`` (in cycles; whole cycles), in up to
    ``CLIP_BINS`` phase bins (empty bins, of a sample rate locked to the excitation, left out); the bins found once
    for all the signals."""
    bins = int(max(1, min(CLIP_BINS, cycle_phase.size // 4)))
    b = (np.mod(cycle_phase, 1.0) * bins).astype(np.int64)
    np.minimum(b, bins - 1, out=b)
    count = np.bincount(b, minlength=bins)
    used = count > 0
    return [np.bincount(b, weights=x, minlength=bins)[used] / count[used] for x in signals]


def saturation(y: np.ndarray) -> np.ndarray:
    """``(2,)``: the share of the samples ``y`` at their maximum and at their minimum (within ``WALL`` of the range)."""
    span = float(y.max() - y.min())
    return np.array([np.mean(y >= y.max() - WALL * span), np.mean(y <= y.min() + WALL * span)])


def _flat_extremes(cycle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(whether the maximum and the minimum of a mean cycle are flat ``(2,)``, their dwell ratios ``(2,)``).

    An extreme is flattened when the cycle stays near it (``CLIP_BAND``) ``CLIP_RATIO`` times as long as a sine
    and is flat there: most of that time it is also within ``CLIP_BAND / 5`` (``PLATEAU``; a sine spends 45 % of
    it there, a smooth top flattened by harmonics about 60 %, a clipped one over 80 %)."""
    wide = _dwell_ratios(cycle, CLIP_BAND)
    narrow = _dwell_ratios(cycle, CLIP_BAND / 5) * (np.arccos(1 - CLIP_BAND / 5) / np.arccos(1 - CLIP_BAND))
    return (wide >= CLIP_RATIO) & (narrow >= PLATEAU * wide), wide


def clipping(cycle: np.ndarray, force_cycle: np.ndarray, force_wall: np.ndarray, xh: np.ndarray, freq: float) -> Clipping:
    """Clipping of a record from its mean displacement and force cycles, the share of its force samples at their
    extremes (``force_wall``, :func:`saturation`) and its displacement harmonics ``(1, K)``.

    A displacement extreme is clipped when it is flat (:func:`_flat_extremes`). A force extreme is clipped when
    it is flat and either the force reads its extreme value in ``SATURATED`` of the samples (a converter at
    its limit) or the force does not jump between its extremes: a friction force's square wave is flat too,
    but it jumps at the reversals (more than ``JUMP`` of its range from one phase bin to the next), while a
    clipped force rises into its flat top along the specimen's curve. A velocity is flattened when both its
    extremes are (a speed limit), in a displacement distorted by more than ``THD_WARN``.
    """
    if cycle.size >= MIN_CLIP_BINS:
        flat, wide = _flat_extremes(cycle)
        if flat.any():
            return Clipping("displacement", float(cycle.max() if wide[0] * flat[0] >= wide[1] * flat[1] else cycle.min()))
    if force_cycle.size >= MIN_CLIP_BINS:
        flat, wide = _flat_extremes(force_cycle)
        jumps = np.abs(np.diff(force_cycle, append=force_cycle[:1])).max() > JUMP * np.ptp(force_cycle)
        hard = flat & ((force_wall >= SATURATED) | (not jumps))
        if hard.any():
            return Clipping("force", float(force_cycle.max() if wide[0] * hard[0] >= wide[1] * hard[1] else force_cycle.min()))
    if waveform.thd(xh)[0] > THD_WARN:
        theta = np.linspace(-np.pi, np.pi, GRID, endpoint=False)
        v = 2 * np.pi * freq * waveform.on_grid(xh, theta[None, :], 1)[0]
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
    logs = np.log10(np.maximum(values[order], np.finfo(float).tiny))
    groups = np.concatenate([[0], np.cumsum(np.diff(logs) > np.log10(UNIT_GAP))])
    if groups[-1] == 0:
        return np.array([], dtype=int)
    main = np.argmax(np.bincount(groups))
    return np.sort(order[groups != main])


NAMED = 5
"""Loops a warning names one by one; beyond that it counts them and gives the range."""


def names(labels: list[str], idx: np.ndarray, values: np.ndarray, fmt: str) -> str:
    if idx.size <= NAMED:
        return ", ".join(f"{labels[i]} ({fmt.format(values[i])})" for i in idx)
    low, high = int(idx[np.argmin(values[idx])]), int(idx[np.argmax(values[idx])])
    every = "all" if idx.size == len(labels) else f"{idx.size} of"
    return f"{every} {len(labels)} records ({fmt.format(values[low])} in {labels[low]} to {fmt.format(values[high])} in {labels[high]})"


@dataclass
class Measured:
    """What the checks read of each loop of a set: ``(L,)`` arrays, ``drift`` ``(L, 2)`` (displacement, force);
    ``phase_deg`` is the force's first harmonic's lead over the displacement's."""

    freq_hz: np.ndarray
    x0: np.ndarray
    force_amplitude: np.ndarray
    phase_deg: np.ndarray
    x_distortion: np.ndarray
    force_distortion: np.ndarray
    drift: np.ndarray


def warn_loops(labels: list[str], m: Measured, clips: list[Clipping], where: str) -> None:
    """Warn (one line per kind) about the suspicious loops of a set extracted from ``where``."""
    x0, force_amplitude = m.x0, m.force_amplitude
    high = np.flatnonzero(m.x_distortion > THD_WARN)
    if high.size:
        warnings.warn(
            HysidWarning(
                f"{where}: displacement THD above {100 * THD_WARN:g} % in {names(labels, high, 100 * m.x_distortion, '{:.3g} %')}: "
                "the shaker does not impose a pure sine, or the sensor distorts; the loops keep the measured waveform, and fit, "
                "campaign and diagnose decide from the force whether it is the motion (displacement_model)",
                "distortion",
            ),
            stacklevel=3,
        )
    clipped = [i for i, c in enumerate(clips) if c.kind]
    if clipped:
        kinds = [kind for kind in CLIP_CAUSES if any(clips[i].kind == kind for i in clipped)]
        if len(clipped) <= NAMED:
            found = "; ".join(f"{labels[i]}: {clips[i].describe(float(x0[i]))}" for i in clipped)
        else:
            level = np.array([c.level for c in clips])
            found = "; ".join(
                f"{kind} in {names(labels, np.array([i for i in clipped if clips[i].kind == kind]), level * CLIP_LEVELS[kind][1], CLIP_LEVELS[kind][0])}"
                for kind in kinds
            )
        warnings.warn(HysidWarning(f"{where}: clipped: {found} ({' '.join(CLIP_CAUSES[kind] for kind in kinds)})", "clipping"), stacklevel=3)
    for k, what in enumerate(("displacement", "force")):
        drifting = np.flatnonzero(m.drift[:, k] > DRIFT_WARN)
        if drifting.size:
            warnings.warn(
                HysidWarning(
                    f"{where}: the {what} amplitude drifts over the steady window by "
                    f"{names(labels, drifting, 100 * m.drift[:, k], '{:.3g} %')}; each loop averages its cycles",
                    "drift",
                ),
                stacklevel=3,
            )
    if x0.size > 1:
        moved = _outliers(x0)  # a displacement slip moves X0 and F1/X0 apart, a force slip only F1/X0
        for what, slipped, unit in (
            ("displacement", moved, "mm under a _m header, or m under _mm"),
            ("force", np.setdiff1d(_outliers(force_amplitude / x0), moved), "kN under a _n header, or N under _kn"),
        ):
            if slipped.size:
                others = np.setdiff1d(np.arange(x0.size), slipped)
                span = f"{x0[others].min() * 1e3:.4g}-{x0[others].max() * 1e3:.4g} mm" if others.size else "the others"
                key = "amplitude" if what == "displacement" else "force per displacement"
                warnings.warn(
                    HysidWarning(
                        f"{where}: {key} far (more than {UNIT_GAP:g}x) from the other loops' in "
                        f"{names(labels, slipped, x0 * 1e3, 'X0 = {:.4g} mm')} against X0 = {span}: a unit slip of the {what} ({unit})? "
                        f"correct those records ({what}_unit in dataset.toml would change every record)",
                        f"unit_slip_{what}",
                    ),
                    stacklevel=3,
                )
