"""Named, bounded model parameters (the lmfit-style 'Parameters' of a model)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Parameter:
    """One identifiable quantity: its name, SI unit, default search bounds and meaning."""

    name: str
    unit: str
    lower: float
    upper: float
    description: str = ""

    def __post_init__(self) -> None:
        if not self.lower < self.upper:
            raise ValueError(f"parameter {self.name}: lower bound {self.lower} must be below upper bound {self.upper}")

    def with_bounds(self, lower: float, upper: float) -> "Parameter":
        return Parameter(self.name, self.unit, float(lower), float(upper), self.description)
