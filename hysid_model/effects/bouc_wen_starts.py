"""Bouc-Wen parameters read off measured loops: starting points for fits (:meth:`BoucWen.data_starts`).

A saturated Bouc-Wen spring (Eq. 2.1) beside the oscillator's spring, dashpot
and mass leaves its marks on each loop (x_c the loop's centre, X its half span):

* in the loop's centre z sits on its plateau, +-z_y: there the force is linear,
  a0 + k (x - x_c) + c x' + m x'' +- F_h on the loading / unloading branch (F_h
  about k_bw z_y); a least-squares fit over the centre's samples gives the
  linear force everywhere (under the ideal sine x'' is -x and the fit takes
  k - m w^2; under a measured displacement its own x' and x'');
* what is left, H = F - the linear force, is k_bw z: at the turning points
  +-k_bw z_max, about +-F_h; along the loading branch it climbs from -F_h to F_h
  with the travel t from the reversal: monotonic (made so by isotonic
  regression against the noise), it crosses 0 after t_0 = z_y T_-r(1) and F_h / 2,
  9/10 F_h after a further z_y T_1(1/2), z_y T_1(9/10)
  (:func:`hysid_model.bouc_wen_orbit.travel`). The relaxing piece does not
  depend on r: T_1(1/2) gives z_y (0.50 to 0.69 z_y for n >= 1), the ratio
  T_1(9/10) / T_1(1/2) the sharpness of the knee, n (3.3 at n = 1, 2.7 at 2, 1.8
  as n -> inf), and t_0 / z_y the shape r; k_bw = F_h / z_y.

The same reading on the unloading branch (mirrored) is averaged in. Loops
that are not saturated (H still rising over the last fifth of the branch:
z_y is not much below X, the spring merely stiffens the loop) or whose
hysteresis is below the noise tell nothing and are skipped; the medians over
the readable loops make the first start, then variants (r = 0, and n = 1, 2
where n is free).
"""

from __future__ import annotations

import numpy as np

from hysid_model import bouc_wen_orbit
from hysid_model.kinematics import Kinematics
from hysid_model.loops import LoopSet

CENTRE = 0.3
"""Half width (in half spans) of the loop's centre, where z is on its plateau (its samples fit the linear force)."""
SATURATED = 0.1
"""A branch is saturated when its hysteretic force rises by less than this fraction of F_h over its last fifth."""
NOISE = 5.0
"""F_h must exceed this many noise sigmas."""


def _travel(w: float, c: float, n: float) -> float:
    a = 1.0 / n
    return bouc_wen_orbit.travel(w, c, n, a, bouc_wen_orbit.digamma(a))


def _isotonic(y: np.ndarray) -> np.ndarray:
    """The non-decreasing sequence closest to ``y`` in least squares (pool adjacent violators)."""
    values, counts = [], []
    for v in y:
        values.append(float(v))
        counts.append(1)
        while len(values) > 1 and values[-2] > values[-1]:
            total = counts[-2] + counts[-1]
            values[-2] = (values[-2] * counts[-2] + values[-1] * counts[-1]) / total
            counts[-2] = total
            del values[-1], counts[-1]
    return np.repeat(values, counts)


def _crossing(t: np.ndarray, h: np.ndarray, level: float) -> float:
    """The travel where the non-decreasing ``h`` reaches ``level`` (linear between samples), NaN if it does not."""
    above = np.flatnonzero(h >= level)
    if above.size == 0 or above[0] == 0:
        return float("nan")
    i = above[0]
    return float(t[i - 1] + (level - h[i - 1]) * (t[i] - t[i - 1]) / (h[i] - h[i - 1]))


def _branch_reading(t: np.ndarray, h: np.ndarray, f_h: float) -> tuple[float, float, float] | None:
    """(t_0, travel from z = 0 to F_h / 2, to 9/10 F_h) of one branch's hysteretic force ``h`` (rising from -F_h
    to F_h along the travel ``t``), or None if the branch is not saturated."""
    h = _isotonic(h)
    tail = t >= t[-1] - 0.2 * (t[-1] - t[0])
    if h[-1] - h[tail][0] > SATURATED * f_h:
        return None
    zero, half, most = (_crossing(t, h, level * f_h) for level in (0.0, 0.5, 0.9))
    if not np.isfinite([zero, half, most]).all() or not zero < half < most:
        return None
    return zero, half - zero, most - zero


def loop_readings(loops: LoopSet) -> list[dict[str, float]]:
    """Per readable loop: F_h (N), t_0 and the travels to F_h / 2 and 9/10 F_h after it (m), X (m)."""
    kin = Kinematics(loops.x0, loops.omega, loops.x_harmonics)
    phase = loops.phases()
    motion = [kin.displacement(phase, d) for d in (0, 1, 2)]
    n = loops.n_samples
    out = []
    for j in range(loops.n_loops):
        x, velocity, acceleration = (m[j] for m in motion)
        force = loops.forces()[j]
        x_min, x_max = float(x.min()), float(x.max())
        half_span, centre = 0.5 * (x_max - x_min), 0.5 * (x_max + x_min)
        branch = np.where(np.arange(2 * n) < n, 1.0, -1.0)
        inner = np.abs(x - centre) <= CENTRE * half_span
        if inner.sum() < 6 or half_span <= 0:
            continue
        design = np.column_stack([np.ones(2 * n), x - centre, velocity, acceleration, branch])
        coef = np.linalg.lstsq(design[inner], force[inner], rcond=None)[0]
        hysteretic = force - design[:, :4] @ coef[:4]
        ends = [np.argmin(x[:n]), np.argmax(x[:n]), n + np.argmax(x[n:]), n + np.argmin(x[n:])]
        f_h = 0.25 * float(np.dot(hysteretic[ends], [-1.0, 1.0, 1.0, -1.0]))
        sigma = loops.sigma[j] if np.isfinite(loops.sigma[j]) else 0.0
        if not f_h > max(NOISE * sigma, 0.0):
            continue
        readings = []
        for sign, part in ((1.0, slice(0, n)), (-1.0, slice(n, 2 * n))):
            order = np.argsort(sign * x[part])
            t = (x[part] - x_min if sign > 0 else x_max - x[part])[order]
            reading = _branch_reading(t, sign * hysteretic[part][order], f_h)
            if reading is not None:
                readings.append(reading)
        if readings:
            zero, half, most = np.mean(readings, axis=0)
            out.append({"f_h": f_h, "zero": zero, "half": half, "most": most, "span": half_span})
    return out


def knee_exponent(ratio: float) -> float:
    """n with T_1(9/10) / T_1(1/2) = ``ratio``, within [1/2, 60]."""

    def excess(n: float) -> float:
        return _travel(0.9, 1.0, n) / _travel(0.5, 1.0, n) - ratio

    from scipy.optimize import brentq  # on first use: a fast CLI and island start

    lo, hi = 0.5, 60.0
    if excess(lo) <= 0.0:
        return lo
    if excess(hi) >= 0.0:
        return hi
    return float(brentq(excess, lo, hi, xtol=1e-6))


def shape_from_run(ratio: float, n: float) -> float:
    """r with T_-r(1) = ``ratio`` (the travel from a reversal to z = 0 in z_y), within [-0.9, 30]."""

    def excess(r: float) -> float:
        return _travel(1.0, -r, n) - ratio

    from scipy.optimize import brentq  # on first use: a fast CLI and island start

    lo, hi = -0.9, 30.0
    if excess(lo) <= 0.0:
        return lo
    if excess(hi) >= 0.0:
        return hi
    return float(brentq(excess, lo, hi, xtol=1e-6))


def read_starts(loops: LoopSet, exponent_free: bool) -> list[dict[str, float]]:
    """Starting points (bw_k, bw_zy, bw_r and, if ``exponent_free``, bw_n) read off ``loops`` (module
    docstring): the medians over the readable loops first, then variants; none when no loop is readable."""
    readings = loop_readings(loops)
    if not readings:
        return []
    f_h, zero, half, most = (float(np.median([r[key] for r in readings])) for key in ("f_h", "zero", "half", "most"))
    exponents = [knee_exponent(most / half), 1.0, 2.0] if exponent_free else [1.0]
    starts = []
    for n in exponents:
        zy = half / _travel(0.5, 1.0, n)
        for r in (shape_from_run(zero / zy, n), 0.0):
            start = {"bw_k": f_h / zy, "bw_zy": zy, "bw_r": r}
            if exponent_free:
                start["bw_n"] = n
            if start not in starts:
                starts.append(start)
    return starts
