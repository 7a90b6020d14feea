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
  under a ``_m`` header puts one loop at 1000x);
* unit slips from the physics (:func:`physics`), also when every loop has the
  same slip: the motion X0 sin(wt) needs a peak velocity w X0 and acceleration
  w^2 X0 that no rig delivers beyond ``RIG_VELOCITY`` and ``RIG_ACCELERATION``
  (nor a stroke beyond ``PLAUSIBLE_X0_M``), or the force is far too small for
  the motion (a dynamic stiffness |F1| / X0 below ``SOFTEST``); the warning
  names the slip (mm under ``_m``, kN under ``_n``) and what the factor makes
  of the record;
* swapped columns or a reversed sign: a passive specimen dissipates energy, so
  its force leads the displacement (0 to 180 degrees); loops whose force lags
  generate energy, which swapped columns or a reversed channel make of any
  specimen. Swapped columns are told from a reversed sign by the magnitudes
  (swapped back they are plausible), by the harmonics (the "displacement" then
  carries the force's distortion and the "force" is the shaker's clean sine)
  or by the phase's trend over the frequencies (a passive specimen's phase
  rises with frequency; swapped it falls, reversed it rises from -180 degrees).
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
"""No hysteresis rig strokes a metre (electrodynamic shakers +-25 mm or so, servo-hydraulic actuators +-250 mm)."""
GRID = 4096
SATURATED = 0.01
"""A force channel at the end of its range reads the same value in this share of its samples or more; a signal,
however flat its top, only touches its maximum (``WALL`` of the range decides "the same")."""
WALL = 1e-9
JUMP = 0.5
"""A mean force cycle that changes by more than this share of its range from one phase bin to the next jumps (a
friction force at the reversals); a clipped one rises into its flat top."""
G = 9.80665
RIG_VELOCITY = 3.0
"""Peak velocity (m/s) beyond what test rigs deliver: electrodynamic shakers reach about 2 m/s in sine (the
velocity limit of the sine envelope, besides stroke and acceleration: G. F. Lang and D. Snyder, "Understanding the
physics of electrodynamic shaker performance", Sound and Vibration, Oct. 2001; Data Physics, "Sizing shakers
review, part 1: sine and random", 2024; C. W. de Silva, Vibration: Fundamentals and Practice, whose example shaker
has 5 cm stroke, 1.5 m/s and 100 g), servo-hydraulic actuators 1 to 2 m/s (servovalve flow over piston area). The
thesis' own beam sample 2 went to 0.8 mm at 440 Hz (Tables 5.16 and 5.18): 2.2 m/s; 3 m/s leaves that a margin."""
RIG_ACCELERATION = 1000.0 * G
"""Peak acceleration (m/s^2) beyond what test rigs deliver in steady sine. A shaker's bare table reaches about
100 g (same sources), a light specimen on a small shaker more: the thesis' sample 2 at 0.8 mm and 440 Hz is 620 g.
Beyond 1000 g only shock machines go."""
SOFTEST = 1.0
"""Median dynamic stiffness |F1| / X0 (N/m) below which the force is too small for the motion: a millinewton per
millimetre, far softer than the specimens a rig holds (the thesis' Synth specimen, 40 g at 30 Hz, is 1400 N/m,
and some 10 N/m at resonance, which a median over a sweep does not see)."""
DISPLACEMENT_SLIPS = ((1e-3, "mm"), (1e-6, "um"))
"""Displacement units a file may hold under a ``_m`` header, and the factor to metres."""
ACTIVE_DEG = 2.0
"""A loop whose force lags its displacement by more than this generates energy: no passive specimen does, while a
lag of a degree or so can be a channel delay on a lightly damped one (100 us at 30 Hz)."""
DISTORTED = 0.01
"""The displacement carries the force's distortion when its THD exceeds twice the force's by this much."""


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


CLIP_CAUSES = {"displacement": "a stroke or sensor limit?", "force": "a load cell or its amplifier at the end of its range?",
               "velocity": "a speed limit?"}
CLIP_LEVELS = {"displacement": ("flat at {:+.3g} mm", 1e3), "force": ("flat at {:+.4g} N", 1.0), "velocity": ("flattened at {:.3g} m/s", 1.0)}
"""How a set's summary gives each kind's level: format and factor from the stored level (m, N, m/s)."""


def _dwell_ratios(y: np.ndarray, band: float) -> np.ndarray:
    """Time near the maximum and near the minimum of a sampled cycle, relative to a sine's: ``(2,)``."""
    half = 0.5 * (y.max() - y.min())
    if not half > 0:
        return np.ones(2)
    sine = np.arccos(1.0 - band) / np.pi
    return np.array([np.mean(y >= y.max() - band * half), np.mean(y <= y.min() + band * half)]) / sine


def mean_cycle(cycle_phase: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The average cycle of samples ``x`` at ``cycle_phase`` (in cycles; whole cycles), in up to
    ``CLIP_BINS`` phase bins (empty bins, of a sample rate locked to the excitation, left out)."""
    bins = int(max(1, min(CLIP_BINS, x.size // 4)))
    b = (np.mod(cycle_phase, 1.0) * bins).astype(np.int64)
    np.minimum(b, bins - 1, out=b)
    count = np.bincount(b, minlength=bins)
    total = np.bincount(b, weights=x, minlength=bins)
    used = count > 0
    return total[used] / count[used]


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


def _names(labels: list[str], idx: np.ndarray, values: np.ndarray, fmt: str) -> str:
    if idx.size <= NAMED:
        return ", ".join(f"{labels[i]} ({fmt.format(values[i])})" for i in idx)
    low, high = int(idx[np.argmin(values[idx])]), int(idx[np.argmax(values[idx])])
    every = "all" if idx.size == len(labels) else f"{idx.size} of"
    return (f"{every} {len(labels)} records ({fmt.format(values[low])} in {labels[low]} to "
            f"{fmt.format(values[high])} in {labels[high]})")


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
        warnings.warn(HysidWarning(
            f"{where}: displacement THD above {100 * THD_WARN:g} % in {_names(labels, high, 100 * m.x_distortion, '{:.3g} %')}: "
            "the shaker does not impose a pure sine, or the sensor distorts; the loops keep the measured waveform, and fit, "
            "campaign and diagnose decide from the force whether it is the motion (displacement_model)"
        ), stacklevel=3)
    clipped = [i for i, c in enumerate(clips) if c.kind]
    if clipped:
        kinds = [kind for kind in CLIP_CAUSES if any(clips[i].kind == kind for i in clipped)]
        if len(clipped) <= NAMED:
            found = "; ".join(f"{labels[i]}: {clips[i].describe(float(x0[i]))}" for i in clipped)
        else:
            level = np.array([c.level for c in clips])
            found = "; ".join(
                f"{kind} in {_names(labels, np.array([i for i in clipped if clips[i].kind == kind]), level * CLIP_LEVELS[kind][1], CLIP_LEVELS[kind][0])}"
                for kind in kinds
            )
        warnings.warn(HysidWarning(f"{where}: clipped: {found} ({' '.join(CLIP_CAUSES[kind] for kind in kinds)})"), stacklevel=3)
    for k, what in enumerate(("displacement", "force")):
        drifting = np.flatnonzero(m.drift[:, k] > DRIFT_WARN)
        if drifting.size:
            warnings.warn(HysidWarning(
                f"{where}: the {what} amplitude drifts over the steady window by "
                f"{_names(labels, drifting, 100 * m.drift[:, k], '{:.3g} %')}; each loop averages its cycles"
            ), stacklevel=3)
    for message in physics(labels, m, where):
        warnings.warn(HysidWarning(message), stacklevel=3)
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


def _motion(freq_hz: np.ndarray, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(peak velocity m/s, peak acceleration m/s^2, beyond a rig) of the motion x0 sin(2 pi f t), per loop."""
    w = 2 * np.pi * freq_hz
    v, a = w * x0, w * w * x0
    return v, a, (x0 > PLAUSIBLE_X0_M) | (v > RIG_VELOCITY) | (a > RIG_ACCELERATION)


def _most(flags: np.ndarray) -> bool:
    return bool(np.count_nonzero(flags) * 2 > flags.size)


def physics(labels: list[str], m: Measured, where: str) -> list[str]:
    """The warnings (lines) of the physics checks: energy sign, swapped columns, unit slips (see the module docstring)."""
    out = []
    with np.errstate(divide="ignore", invalid="ignore"):
        stiffness = float(np.median(m.force_amplitude / m.x0))
        swapped_stiffness = float(np.median(m.x0 / m.force_amplitude))
    v, a, fast = _motion(m.freq_hz, m.x0)
    soft = not stiffness >= SOFTEST
    phase = (m.phase_deg + 180.0) % 360.0 - 180.0
    active = phase < -ACTIVE_DEG
    if _most(phase < 0):
        sv, sa, swapped_fast = _motion(m.freq_hz, m.force_amplitude)
        implausible = bool(fast.any()) or soft
        back = implausible and not swapped_fast.any() and swapped_stiffness >= SOFTEST
        carried = _most(active) and _most(m.x_distortion > 2 * m.force_distortion + DISTORTED)  # a delay's lag is small
        if back or carried:
            idx = np.arange(m.x0.size)
            why = (f"swapped back, the motion (at most {sv.max():.3g} m/s and {sa.max() / G:.3g} g) and the stiffness "
                   f"({swapped_stiffness:.3g} N/m) are plausible, as they are not now" if back else
                   f"the 'displacement' carries the force's harmonics (THD {100 * np.median(m.x_distortion):.3g} % against "
                   f"{100 * np.median(m.force_distortion):.3g} % in the 'force')")
            out.append(
                f"{where}: displacement and force look swapped in {_names(labels, idx, m.x0, 'X0 = {:.4g} m')}, "
                f"force amplitude {_values(m.force_amplitude, '{:.3g} N')}: the loops generate energy (the force lags "
                f"the displacement by {-np.median(phase):.3g} degrees; a passive specimen's leads it) and {why}; "
                "check the column order"
            )
            return out
        if _most(active):
            out.append(f"{where}: the loops generate energy in {_names(labels, np.flatnonzero(active), -phase, 'a lag of {:.3g} deg')}: "
                       f"a passive specimen's force leads its displacement; {_lag_cause(m.freq_hz[active], phase[active])}")
    if fast.any():
        idx = np.flatnonzero(fast)
        fix = next((f"x {factor:g} ({unit}) makes it at most {(v * factor).max():.3g} m/s and {(a * factor).max() / G:.3g} g "
                    f"(declare displacement_unit = \"{unit}\" in dataset.toml)"
                    for factor, unit in DISPLACEMENT_SLIPS if not _motion(m.freq_hz, m.x0 * factor)[2].any()),
                   "no unit slip makes it plausible: check the displacement channel")
        out.append(
            f"{where}: the displacement moves as no rig does in {_names(labels, idx, v, 'peak velocity {:.3g} m/s')}, "
            f"peak acceleration up to {a[idx].max() / G:.3g} g and X0 up to {m.x0[idx].max():.4g} m; shakers reach about "
            f"2 m/s and some hundred g, servo-hydraulic actuators 1-2 m/s: is the displacement in mm under a _m header? {fix}"
        )
    elif soft:
        out.append(
            f"{where}: the force is too small for the motion: a dynamic stiffness |F1|/X0 of {stiffness:.3g} N/m over the "
            f"loops (median), softer than any specimen a rig holds: is the force in kN under a _n header? x 1000 (kN) makes "
            f"it {stiffness * 1e3:.3g} N/m (declare force_unit = \"kN\" in dataset.toml)"
        )
    return out


def _lag_cause(freq_hz: np.ndarray, phase: np.ndarray) -> str:
    """Which fault the phases over the frequencies point to: a passive specimen's phase rises with frequency, swapped
    columns mirror it (it falls), a reversed sign shifts it by 180 degrees (it still rises)."""
    if freq_hz.size >= 3 and np.ptp(phase) > 10.0 and np.ptp(freq_hz) > 0:
        slope = np.polyfit(np.log(freq_hz), phase, 1)[0]
        if slope < 0:
            return "the lag grows with frequency, a passive specimen's mirrored: force and displacement look swapped (check the column order)"
        return "the phase rises with frequency from -180 degrees, a passive specimen's turned over: the force's (or the displacement's) sign looks reversed"
    return "are force and displacement swapped, or is one channel's sign reversed?"


def _values(values: np.ndarray, fmt: str) -> str:
    if values.size <= NAMED:
        return ", ".join(fmt.format(v) for v in values)
    return f"{fmt.format(values.min())} to {fmt.format(values.max())}"
