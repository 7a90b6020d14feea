"""Compliance frequency response from the loops, and the half-power damping estimate.

Under the prescribed motion x = X0 sin(wt) (Eq. 4.5) the first harmonic of the
measured force, F1 = a_s sin(wt) + a_c cos(wt), gives each loop's compliance
(receptance) |X0 / F1| at its excitation frequency. Grouping the loops by
amplitude gives one compliance FRF per amplitude, as in Figs. 2.8, 4.10 and
6.1, and the half-power ("3 dB") bandwidth method of Eq. 2.7 gives a damping
ratio from each FRF that does not depend on any fitted model:

    xi = (w2 - w1) / (2 w0)                                        (Eq. 2.7)

with w0 the resonance peak and w1, w2 the frequencies where the compliance is
3 dB below it. The measured frequencies are discrete, so the peak and the two
-3 dB points are located by interpolating the inverse power 1/|H|^2 with a
quadratic in w^2 through neighbouring samples: for the 1-DOF oscillator of
Eq. 4.4 at fixed X0, 1/|H|^2 = m^2 [(wn^2 - w^2)^2 + (2 xi wn w)^2] is exactly
such a quadratic, so the interpolation adds no error there. The reported
``resolution`` is what the frequency grid alone guarantees: half the width of
the xi interval allowed when each -3 dB point is only known to lie between its
two bracketing frequencies.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hysid_model.basis import design_matrix, harmonic_names
from hysid_model.kinematics import Kinematics
from hysid_model.loops import LoopSet
from hysid_model.model import Model

MODEL_CYCLE_SAMPLES = 512
"""Phases per cycle at which :func:`model_compliance` samples a model's force."""
AMPLITUDE_RTOL = 0.05
"""Loops whose amplitudes X0 agree within this relative tolerance form one amplitude level."""


FIT_ORDERS = 7
"""Force harmonics fitted together (:func:`force_harmonics`): the orders the extraction keeps."""


def force_harmonics(loops: LoopSet, max_order: int = 1) -> np.ndarray:
    """Complex harmonics a_s + i a_c of each loop's force (N) at orders 1..``max_order``, shape ``(L, K)``.

    Least squares of the force on [1, sin(k wt), cos(k wt)] over both branches, orders up to
    ``max(FIT_ORDERS, max_order)`` fitted together: branch points are not evenly spaced in phase,
    so a harmonic left out of the fit (from a nonlinear force, or a distorted displacement) would
    leak into the ones kept; the constant keeps an offset out of them too.
    """
    fitted = max(FIT_ORDERS, max_order)
    phi = design_matrix(harmonic_names(fitted), loops.phases(), loops.n_samples)
    y = loops.forces()
    coef = np.stack([np.linalg.lstsq(p, f, rcond=None)[0] for p, f in zip(phi, y)])
    return (coef[:, 1::2] + 1j * coef[:, 2::2])[:, :max_order]


def first_harmonic(loops: LoopSet) -> np.ndarray:
    """Complex first harmonic F1 = a_s + i a_c of each loop's force (N), shape ``(L,)``."""
    return force_harmonics(loops, 1)[:, 0]


def compliance(loops: LoopSet) -> np.ndarray:
    """Compliance magnitude |X0 / F1| (m/N) of every loop, shape ``(L,)``."""
    return loops.x0 / np.abs(first_harmonic(loops))


def model_compliance(model: Model, theta: np.ndarray, x0: float, freq_hz: np.ndarray) -> np.ndarray:
    """Compliance |X0 / F1| (m/N) the model predicts at amplitude ``x0`` and frequencies ``freq_hz``.

    The model's steady-state force (every feature, memory terms included) is
    sampled over one cycle, loading branch first as in :class:`LoopSet`, and
    projected on sin(wt), cos(wt): for the oscillator this is Eq. 4.6 / 4.10's
    amplitude m X0 sqrt((wn^2 - w^2)^2 + (2 xi wn w)^2).
    """
    freq_hz = np.asarray(freq_hz, dtype=float).reshape(-1)
    kin = Kinematics(x0=np.full(freq_hz.size, float(x0)), omega=2.0 * np.pi * freq_hz)
    pop = np.asarray(theta, dtype=float).reshape(1, -1)
    n = MODEL_CYCLE_SAMPLES // 2
    loading = np.mod(np.linspace(-0.5 * np.pi, 0.5 * np.pi, n, endpoint=False), 2.0 * np.pi)
    unloading = np.linspace(0.5 * np.pi, 1.5 * np.pi, n, endpoint=False)
    cycle = np.concatenate([loading, unloading])
    phase = np.ascontiguousarray(np.broadcast_to(cycle, (freq_hz.size, 2 * n)))
    coefs = model.coefficients(pop, kin)
    names = list(coefs)
    force = np.einsum("lnm,lm->ln", design_matrix(names, phase, n), np.stack([coefs[k][0] for k in names], axis=-1))
    memory = model.memory_force(pop, kin, phase)
    if memory is not None:
        force = force + memory[0]
    f1 = (force @ np.sin(cycle) + 1j * (force @ np.cos(cycle))) / n
    return x0 / np.abs(f1)


def amplitude_levels(x0: np.ndarray, rtol: float = AMPLITUDE_RTOL) -> tuple[np.ndarray, np.ndarray]:
    """Group amplitudes into levels: returns ``(levels (K,), level index of each loop (L,))``.

    Sorted amplitudes start a new level where one differs from the previous
    level's first member by more than ``rtol``; a level's value is its mean.
    """
    x0 = np.asarray(x0, dtype=float).reshape(-1)
    order = np.argsort(x0, kind="stable")
    index = np.empty(x0.size, dtype=int)
    level, start = 0, x0[order[0]]
    for i in order:
        if x0[i] > start * (1.0 + rtol):
            level, start = level + 1, x0[i]
        index[i] = level
    levels = np.array([x0[index == k].mean() for k in range(level + 1)])
    return levels, index


@dataclass(frozen=True)
class HalfPower:
    """Half-power estimate at one amplitude level; ``xi`` is NaN with a ``note`` when unavailable."""

    x0: float
    n_loops: int
    f_peak_hz: float
    f1_hz: float
    f2_hz: float
    xi: float
    resolution: float
    peak_compliance: float
    note: str = ""

    @property
    def ok(self) -> bool:
        return not self.note

    def as_dict(self) -> dict[str, float | int | str]:
        return {
            "x0_m": self.x0,
            "n_loops": self.n_loops,
            "f_peak_hz": self.f_peak_hz,
            "f1_hz": self.f1_hz,
            "f2_hz": self.f2_hz,
            "xi": self.xi,
            "resolution": self.resolution,
            "peak_compliance_m_per_n": self.peak_compliance,
            "note": self.note,
        }


def _quadratic(u: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Coefficients (highest first) of the quadratic through three points (u, q), u scaled by u[1]."""
    return np.polyfit(u / u[1], q, 2)


def _crossing(u: np.ndarray, q: np.ndarray, i: int, j: int, level: float) -> float:
    """w^2 in [u_i, u_j] (adjacent samples) where the interpolated 1/|H|^2 equals ``level``.

    Uses the quadratic through i, j and the neighbour of j towards the peak
    (``2 j - i``); falls back to linear interpolation if its root leaves the bracket.
    """
    k = 2 * j - i
    pts = np.array([i, j, k])
    scale = u[j]
    coef = _quadratic(u[pts], q[pts])
    coef[-1] -= level
    lo, hi = sorted((u[i], u[j]))
    roots = [r.real * scale for r in np.roots(coef) if abs(r.imag) < 1e-12 * max(abs(r.real), 1.0)]
    inside = [r for r in roots if lo <= r <= hi]
    if inside:
        return float(inside[0])
    return float(u[i] + (level - q[i]) * (u[j] - u[i]) / (q[j] - q[i]))


def half_power(freq_hz: np.ndarray, comp: np.ndarray, x0: float = float("nan")) -> HalfPower:
    """Eq. 2.7 on one compliance FRF (frequencies in Hz, compliance in m/N)."""
    freq_hz = np.asarray(freq_hz, dtype=float).reshape(-1)
    comp = np.asarray(comp, dtype=float).reshape(-1)
    f, inverse = np.unique(freq_hz, return_inverse=True)
    h = np.bincount(inverse, weights=comp) / np.bincount(inverse)
    nan = float("nan")

    def unavailable(note: str, f_peak: float = nan, peak: float = nan) -> HalfPower:
        return HalfPower(x0, freq_hz.size, f_peak, nan, nan, nan, nan, peak, note)

    if f.size < 3:
        return unavailable(f"needs at least 3 frequencies, has {f.size}")
    if not np.all(np.isfinite(h) & (h > 0)):
        return unavailable("a loop's compliance is zero or infinite (no displacement or no force)")
    u = (2.0 * np.pi * f) ** 2
    q = 1.0 / h**2
    k = int(np.argmin(q))
    if k == 0 or k == f.size - 1:
        return unavailable("resonance peak at the edge of the frequency sweep", f[k], h[k])
    coef = _quadratic(u[k - 1 : k + 2], q[k - 1 : k + 2])
    u_peak, q_peak = u[k], q[k]
    if coef[0] > 0:
        vertex = -coef[1] / (2.0 * coef[0]) * u[k]
        refined = float(np.polyval(coef, vertex / u[k]))
        if u[k - 1] <= vertex <= u[k + 1] and refined > 0:  # a parabola through a sharp peak may dip below 0
            u_peak, q_peak = vertex, refined
    level = 2.0 * q_peak
    below = np.flatnonzero(q[:k] >= level)
    above = np.flatnonzero(q[k + 1 :] >= level) + k + 1
    if below.size == 0:
        return unavailable("no -3 dB point below the peak (sweep starts too close to resonance)", f[k], h[k])
    if above.size == 0:
        return unavailable("no -3 dB point above the peak (sweep ends too close to resonance)", f[k], h[k])
    i1, i2 = int(below[-1]), int(above[0])
    w1 = np.sqrt(max(_crossing(u, q, i1, i1 + 1, level), 0.0))
    w2 = np.sqrt(max(_crossing(u, q, i2, i2 - 1, level), 0.0))
    w_peak = np.sqrt(u_peak)
    if not (np.isfinite(w2) and w1 < w_peak < w2):
        return unavailable("the -3 dB points do not bracket the peak (too few frequencies across the resonance)", f[k], h[k])
    f_peak = w_peak / (2.0 * np.pi)
    resolution = ((f[i1 + 1] - f[i1]) + (f[i2] - f[i2 - 1])) / (4.0 * f_peak)
    return HalfPower(
        x0=x0,
        n_loops=freq_hz.size,
        f_peak_hz=float(f_peak),
        f1_hz=float(w1 / (2.0 * np.pi)),
        f2_hz=float(w2 / (2.0 * np.pi)),
        xi=float((w2 - w1) / (2.0 * w_peak)),
        resolution=float(resolution),
        peak_compliance=float(1.0 / np.sqrt(q_peak)),
    )


def half_power_by_amplitude(loops: LoopSet, rtol: float = AMPLITUDE_RTOL) -> list[HalfPower]:
    """The half-power estimate of Eq. 2.7 at each amplitude level of the loop set (Fig. 6.1)."""
    comp = compliance(loops)
    levels, index = amplitude_levels(loops.x0, rtol)
    return [half_power(loops.freq_hz[index == k], comp[index == k], float(level)) for k, level in enumerate(levels)]
