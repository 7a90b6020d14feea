"""Effective stiffness and equivalent damping of the whole fitted model at each amplitude and frequency.

How isolator and damper tests characterise a nonlinear device (ISO 10846,
EN 15129, AASHTO's isolator tests): under a sinusoidal displacement of
amplitude X0 at frequency f,

* the effective stiffness is the slope between the forces at the peak
  displacements, k_eff = (F+ - F-) / (x+ - x-) = (F+ - F-) / (2 X0);
* the equivalent damping ratio is energy-based: the energy dissipated per
  cycle, E_d (the loop's area, the integral of F dx), over 4 pi times the
  stored energy E_s = k_eff X0^2 / 2, so xi_eq = E_d / (2 pi k_eff X0^2).

Both are taken from the model's force with every term (a Bouc-Wen spring, a
friction or a power-law damper as much as the oscillator's spring, dashpot
and inertia: the force the rig measures), under the ideal sine X0 sin(wt),
without the measurement chain (a channel delay or a charge amplifier's
high-pass is the rig's, not the device's). For a linear oscillator they are
k - m w^2 and c w / (2 (k - m w^2)); above a resonance, where the inertia
makes k_eff negative, no energy is stored and xi_eq is not given. Standard errors follow from the
parameters' covariance by the delta method (central differences of the
model, all its parameters moved at once as a population).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from hysid_model.frf import amplitude_levels
from hysid_model.loops import LoopSet
from hysid_model.model import Model
from hysid_model.objective import Objective
from hysid_model.terms import MeasurementTerm

POINTS = 257
"""Samples per branch, evenly spaced in phase (dense at the reversals, where a |v|^alpha law has its cusp)."""
EFFECTIVE = ("k_eff", "xi_eq", "energy")
EFFECTIVE_UNITS = {"k_eff": "N/m", "xi_eq": "1", "energy": "J"}
STEP = 1e-6
"""Central-difference step, relative to max(|theta|, 1e-3 x the bound range)."""


@dataclass
class OperatingPoint:
    """k_eff, xi_eq and the energy dissipated per cycle at one amplitude and frequency, with standard errors."""

    x0: float
    freq_hz: float
    values: dict[str, float]
    stderr: dict[str, float]

    def as_dict(self) -> dict[str, Any]:
        return {"x0_m": self.x0, "freq_hz": self.freq_hz, **self.values, "stderr": self.stderr}


def operating_points(loops: LoopSet) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The loops' distinct amplitude levels and frequencies (repeated tests once): ``(freq_hz, x0, level index)``,
    ordered by level, then frequency; a level's amplitude is its mean (:func:`~hysid_model.frf.amplitude_levels`),
    frequencies within 0.1 % one."""
    levels, index = amplitude_levels(loops.x0)
    freq, x0, level = [], [], []
    for k, amplitude in enumerate(levels):
        f = np.sort(loops.freq_hz[index == k])
        groups = np.split(f, np.flatnonzero(np.diff(f) > 1e-3 * f[1:]) + 1)
        freq += [float(g.mean()) for g in groups]
        x0 += [float(amplitude)] * len(groups)
        level += [k] * len(groups)
    return np.array(freq), np.array(x0), np.array(level, dtype=int)


def device_model(model: Model) -> tuple[Model, np.ndarray]:
    """``model`` without its measurement terms (the device alone), and the indices of its free parameters in ``model``'s."""
    terms = [t for t in model.terms if not isinstance(t, MeasurementTerm)]
    if len(terms) == len(model.terms):
        return model, np.arange(model.dim)
    own = {p.name for t in terms for p in t.params}
    device = Model(terms).vary(*(n for n in model.names if n in own)).fix({n: v for n, v in model.fixed.items() if n in own})
    return device, np.array([model.names.index(n) for n in device.names], dtype=int)


def sine_loops(freq_hz: ArrayLike, x0: ArrayLike, points: int = POINTS) -> LoopSet:
    """Empty loops under the ideal sine X0 sin(wt), both branches sampled evenly in phase (x ascending on each)."""
    freq_hz, x0 = np.asarray(freq_hz, dtype=float).reshape(-1), np.asarray(x0, dtype=float).reshape(-1)
    s = np.sin(np.linspace(-0.5 * np.pi, 0.5 * np.pi, points))
    x = x0[:, None] * s[None, :]
    branch = np.stack([x, np.zeros_like(x)], axis=-1)
    return LoopSet(name="sine", freq_hz=freq_hz, x0=x0, top=branch, bottom=branch.copy(), sigma=np.ones(freq_hz.size))


def effective_values(model: Model, pop: np.ndarray, loops: LoopSet) -> np.ndarray:
    """k_eff, xi_eq and E_d of each parameter vector of ``pop`` ``(P, D)`` on each loop of :func:`sine_loops`, ``(P, 3, L)``."""
    force = Objective(loops, model, weights="ml").predict(np.atleast_2d(pop))
    n = loops.n_samples
    top, bottom = force[..., :n], force[..., n:]
    x = loops.top[:, :, 0]
    k_eff = (top[..., -1] - bottom[..., 0]) / (2.0 * loops.x0)
    energy = np.trapezoid(top - bottom, x, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        xi_eq = np.where(k_eff > 0.0, energy / (2.0 * np.pi * k_eff * loops.x0**2), np.nan)
    return np.stack([k_eff, xi_eq, energy], axis=1)


def loop_effective(loops: LoopSet, energy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each measured loop's own k_eff and xi_eq, read off it as a test reads them: the forces at the ends of its
    loading branch (largest displacement) and of its unloading branch (smallest), and its area ``energy`` (J)."""
    k_eff = (loops.top[:, -1, 1] - loops.bottom[:, 0, 1]) / (loops.top[:, -1, 0] - loops.bottom[:, 0, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        xi_eq = np.where(k_eff > 0.0, energy / (2.0 * np.pi * k_eff * loops.x0**2), np.nan)
    return k_eff, xi_eq


def effective_table(
    model: Model, theta: np.ndarray, propagate: Callable[[np.ndarray], np.ndarray], freq_hz: np.ndarray, x0: np.ndarray
) -> list[OperatingPoint]:
    """:func:`effective_values` at each pair of ``freq_hz`` and ``x0`` with standard errors: ``propagate(grads)``
    turns gradients ``(Q, D)`` in ``model``'s parameters into standard errors (the fit's covariance)."""
    device, index = device_model(model)
    loops = sine_loops(freq_hz, x0)
    theta = np.asarray(theta, dtype=float).reshape(-1)
    local = theta[index]
    span = device.bounds[:, 1] - device.bounds[:, 0] if device.dim else np.zeros(0)
    h = STEP * np.maximum(np.abs(local), 1e-3 * span)
    up = np.minimum(local + h, device.bounds[:, 1]) if device.dim else local
    down = np.maximum(local - h, device.bounds[:, 0]) if device.dim else local
    eye = np.eye(device.dim, dtype=bool)
    pop = np.concatenate([local[None, :], np.where(eye, up, local), np.where(eye, down, local)])
    values = effective_values(device, pop, loops)
    grads = np.zeros((len(EFFECTIVE), loops.n_loops, model.dim))
    if device.dim:
        grads[..., index] = ((values[1 : 1 + device.dim] - values[1 + device.dim :]) / (up - down)[:, None, None]).transpose(1, 2, 0)
    se = propagate(grads.reshape(-1, model.dim)).reshape(len(EFFECTIVE), loops.n_loops)
    return [
        OperatingPoint(
            float(loops.x0[j]),
            float(loops.freq_hz[j]),
            {q: float(values[0, i, j]) for i, q in enumerate(EFFECTIVE)},
            {q: float(se[i, j]) for i, q in enumerate(EFFECTIVE)},
        )
        for j in range(loops.n_loops)
    ]
