"""Named, bounded model parameters (the lmfit-style 'Parameters' of a model).

A parameter is either searched within its bounds (``vary=True``) or fixed at a
known ``value`` (``vary=False``), as in lmfit. The known equivalent mass of a
specimen is the fixed parameter ``meq``.

Bounds are *soft* when hysid derived them from the data or took a term's
default that the physics does not set (they may be widened when a fit ends on
one) and hard when a user or a dataset gave them; no bound
ever leaves the parameter's ``physical`` range (a damping ratio is not
negative, a mass is positive).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from hysid_model.errors import HysidInputError


def _range(physical: tuple[float, float]) -> str:
    lo, hi = physical
    return f"[{lo:g}, {hi:g}]" if math.isfinite(hi) else f"[{lo:g}, inf)"


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
    soft: bool = False
    """The bounds were derived from the data (or are a term's default) and may be widened."""
    physical: tuple[float, float] = (-math.inf, math.inf)
    """Values outside this range mean nothing (bounds are never widened past it)."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.lower) and math.isfinite(self.upper) and self.lower < self.upper):
            raise HysidInputError(f"lower bound {self.lower:g} must be finite and below the upper bound {self.upper:g}", param=f"bounds[{self.name!r}]")
        if not self.vary and (self.value is None or not math.isfinite(self.value)):
            raise HysidInputError("a fixed parameter needs a finite value", param=self.name, value=self.value)
        lo, hi = self.physical
        if not self.vary and not lo <= self.value <= hi:  # type: ignore[operator]
            raise HysidInputError(
                f"{self.value:g}{'' if self.unit == '1' else ' ' + self.unit} is outside the physical range {_range(self.physical)} of {self.description or self.name}",
                param=self.name,
            )
        if self.lower < lo or self.upper > hi:
            raise HysidInputError(
                f"bounds {self.lower:g}:{self.upper:g} reach outside the physical range {_range(self.physical)} of {self.description or self.name}",
                param=f"bounds[{self.name!r}]",
            )

    def with_bounds(self, lower: float, upper: float, soft: bool = False) -> Parameter:
        return replace(self, lower=float(lower), upper=float(upper), soft=soft)

    def widened(self, lower: bool, upper: bool) -> Parameter:
        """These soft bounds widened on the given sides, within the physical range: by a decade away from 0 (a
        stiffness, a frequency, an upper shape bound of 3 to 30), else by one more range width."""
        lo, hi = self.lower, self.upper
        span = hi - lo
        if lower:
            lo = lo / 10.0 if lo > 0 and self.physical[0] >= 0 else lo * 10.0 if lo < 0 else lo - span
        if upper:
            hi = hi * 10.0 if hi > 0 else hi + span
        return replace(self, lower=max(lo, self.physical[0]), upper=min(hi, self.physical[1]))

    def fixed_at(self, value: float) -> Parameter:
        return replace(self, vary=False, value=float(value))

    def varied(self) -> Parameter:
        return replace(self, vary=True, value=None)


def on_bounds(bounds: np.ndarray, theta: np.ndarray, rtol: float = 1e-6) -> np.ndarray:
    """Which entries of ``theta`` sit on a bound of ``bounds`` ``(D, 2)`` (within ``rtol`` of the range)."""
    bounds = np.asarray(bounds, dtype=float)
    theta = np.asarray(theta, dtype=float).reshape(-1)
    span = bounds[:, 1] - bounds[:, 0]
    return np.minimum(theta - bounds[:, 0], bounds[:, 1] - theta) <= rtol * span
