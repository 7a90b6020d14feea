"""Modal and physical quantities at each amplitude, with standard errors (as listed under Table 5.3).

From a parameter vector: the damping ratio xi and natural frequency
fn = wn / 2 pi of the 1-DOF oscillator at an amplitude X0 (Eq. 4.8, 4.9), and
the physical stiffness k = m wn^2, damping coefficient c = 2 m xi wn and mass
m (Eq. 2.4); standard errors follow from the parameter covariance by the delta
method. k and c are also what loops far below a resonance determine best: there
the mass trades off with w0 and xi0, and :func:`combinations` reports them
beside the parameters.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from hysid_model.model import Model, to_physical

DERIVED = ("xi", "fn_hz", "k", "c", "m")
DERIVED_UNITS = {"xi": "1", "fn_hz": "Hz", "k": "N/m", "c": "N s/m", "m": "kg"}
COMBINATIONS = {"k": "meq w0^2", "c": "2 xi0 meq w0"}
"""The oscillator's stiffness and damping coefficient as combinations of its parameters (Eq. 2.4), at zero amplitude."""

Propagate = Callable[[np.ndarray], np.ndarray]
"""Gradients ``(Q, D)`` of Q quantities in the parameters -> their standard errors ``(Q,)`` (the fit's covariance)."""


@dataclass
class AmplitudeResult:
    """Modal and physical quantities at one amplitude level, with standard errors (delta method)."""

    x0: float
    values: dict[str, float]
    stderr: dict[str, float]

    def as_dict(self) -> dict[str, Any]:
        return {"x0_m": self.x0, **self.values, "stderr": self.stderr}


def derived_quantities(model: Model, theta: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """xi, fn (Hz), k (N/m), c (N s/m), m (kg) at each amplitude, shape ``(5, K)`` (Eq. 4.8, 4.9, 2.4)."""
    state = model.modal(theta, x0)
    phys = to_physical(state)
    return np.stack([state.xi, state.wn / (2.0 * np.pi), phys["k"], phys["c"], phys["m"]])


def gradients(quantities: Callable[[np.ndarray], np.ndarray], model: Model, theta: np.ndarray) -> np.ndarray:
    """d quantities / d theta by central differences, ``(*shape, D)``."""
    span = model.bounds[:, 1] - model.bounds[:, 0]
    h = 1e-6 * np.maximum(span, 1e-300)
    return np.stack([(quantities(theta + h[i] * e) - quantities(theta - h[i] * e)) / (2.0 * h[i]) for i, e in enumerate(np.eye(theta.size))], axis=-1)


def derived_table(model: Model, theta: np.ndarray, propagate: Propagate, x0: np.ndarray) -> list[AmplitudeResult]:
    """:func:`derived_quantities` with standard errors from ``propagate`` (the fit's full covariance)."""
    theta = np.asarray(theta, dtype=float).reshape(-1)
    grads = gradients(lambda t: derived_quantities(model, t, x0), model, theta).reshape(len(DERIVED), np.size(x0), theta.size)
    values = derived_quantities(model, theta, x0)
    se = propagate(grads.reshape(-1, theta.size)).reshape(len(DERIVED), np.size(x0))
    return [
        AmplitudeResult(float(a), {q: float(values[i, k]) for i, q in enumerate(DERIVED)}, {q: float(se[i, k]) for i, q in enumerate(DERIVED)})
        for k, a in enumerate(np.atleast_1d(x0))
    ]


def combinations(model: Model, theta: np.ndarray, propagate: Propagate) -> dict[str, tuple[float, float]]:
    """The stiffness k = meq w0^2 and damping coefficient c = 2 xi0 meq w0 (:data:`COMBINATIONS`): value and standard error."""
    theta = np.asarray(theta, dtype=float).reshape(-1)

    def kc(t: np.ndarray) -> np.ndarray:
        return derived_quantities(model, t, np.zeros(1))[2:4, 0]

    se = propagate(gradients(kc, model, theta))
    return {name: (float(v), float(s)) for name, v, s in zip(COMBINATIONS, kc(theta), se)}
