"""Modal and physical quantities at each amplitude, with standard errors (as listed under Table 5.3).

From a parameter vector: the damping ratio xi and natural frequency
fn = wn / 2 pi of the 1-DOF oscillator at an amplitude X0 (Eq. 4.8, 4.9), and
the physical stiffness k = m wn^2, damping coefficient c = 2 m xi wn and mass
m (Eq. 2.4); standard errors follow from the parameter covariance by the delta
method.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hysid_model.model import Model, to_physical

DERIVED = ("xi", "fn_hz", "k", "c", "m")
DERIVED_UNITS = {"xi": "1", "fn_hz": "Hz", "k": "N/m", "c": "N s/m", "m": "kg"}


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


def derived_table(model: Model, theta: np.ndarray, cov: np.ndarray, x0: np.ndarray) -> list[AmplitudeResult]:
    """:func:`derived_quantities` with standard errors from the parameter covariance (central differences)."""
    span = model.bounds[:, 1] - model.bounds[:, 0]
    h = 1e-6 * span
    grads = np.stack([
        (derived_quantities(model, theta + h[i] * e, x0) - derived_quantities(model, theta - h[i] * e, x0)) / (2.0 * h[i])
        for i, e in enumerate(np.eye(theta.size))
    ], axis=-1).reshape(len(DERIVED), np.size(x0), theta.size)
    values = derived_quantities(model, theta, x0)
    var = np.einsum("qkd,de,qke->qk", grads, cov, grads)
    se = np.sqrt(np.clip(var, 0.0, None))
    return [
        AmplitudeResult(float(a), {q: float(values[i, k]) for i, q in enumerate(DERIVED)}, {q: float(se[i, k]) for i, q in enumerate(DERIVED)})
        for k, a in enumerate(np.atleast_1d(x0))
    ]
