"""Named, bounded model parameters (the lmfit-style 'Parameters' of a model).

A parameter is either searched within its bounds (``vary=True``) or fixed at a
known ``value`` (``vary=False``), as in lmfit. The known equivalent mass of a
specimen is the fixed parameter ``meq``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from hysid_model.errors import HysidInputError


@dataclass(frozen=True)
class Parameter:
    """One identifiable quantity: its name, SI unit, search bounds, meaning, and a value if it is fixed."""

    name: str
    unit: str
    lower: float
    upper: float
    description: str = ""
    vary: bool = True
    value: float | None = None
    """The fixed value (``vary=False``); None while the parameter is searched."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.lower) and math.isfinite(self.upper) and self.lower < self.upper):
            raise HysidInputError(f"lower bound {self.lower:g} must be finite and below the upper bound {self.upper:g}", param=f"bounds[{self.name!r}]")
        if not self.vary and (self.value is None or not math.isfinite(self.value)):
            raise HysidInputError("a fixed parameter needs a finite value", param=self.name, value=self.value)

    def with_bounds(self, lower: float, upper: float) -> "Parameter":
        return replace(self, lower=float(lower), upper=float(upper))

    def fixed_at(self, value: float) -> "Parameter":
        return replace(self, vary=False, value=float(value))

    def varied(self) -> "Parameter":
        return replace(self, vary=True, value=None)


def on_bounds(bounds: np.ndarray, theta: np.ndarray, rtol: float = 1e-6) -> np.ndarray:
    """Which entries of ``theta`` sit on a bound of ``bounds`` ``(D, 2)`` (within ``rtol`` of the range)."""
    bounds = np.asarray(bounds, dtype=float)
    theta = np.asarray(theta, dtype=float).reshape(-1)
    span = bounds[:, 1] - bounds[:, 0]
    return np.minimum(theta - bounds[:, 0], bounds[:, 1] - theta) <= rtol * span
