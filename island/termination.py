"""When a search ends: one set of rules for a single-node fit and for a campaign's coordinator.

Any rule that is set can end the search: a budget of objective evaluations, a
target fitness, a stall (evaluations since the best last improved) or a wall
time limit. An optimizer's own iteration budget (section 5.1: 18 iterations)
ends its run as well, unless a campaign lets its islands search until its
coordinator's stop order (:attr:`island.config.CampaignConfig.until_stopped`,
the default when the budget is in evaluations or time: :attr:`Termination.bounded`);
a coordinator adds "every island finished".
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from hysid_model.errors import HysidInputError


@dataclass(frozen=True)
class Termination:
    """Stop rules (None: the rule is off); ``stall`` counts evaluations without improvement."""

    budget: int | None = None
    target: float | None = None
    stall: int | None = None
    time_limit_s: float | None = None

    def __post_init__(self) -> None:
        for name in ("budget", "stall"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
                raise HysidInputError("must be a positive number of evaluations", param=name, value=value)
        if self.target is not None and not (isinstance(self.target, (int, float)) and math.isfinite(self.target) and self.target >= 0):
            raise HysidInputError("must be a finite fitness >= 0", param="target", value=self.target)
        if self.time_limit_s is not None and not (isinstance(self.time_limit_s, (int, float)) and self.time_limit_s > 0):
            raise HysidInputError("must be a positive number of seconds", param="time_limit_s", value=self.time_limit_s)

    @property
    def bounded(self) -> bool:
        """A rule that surely fires is set (an evaluation budget or a time limit): a campaign can let
        its islands search until its stop order instead of each spending an iteration budget."""
        return self.budget is not None or self.time_limit_s is not None

    def reason(self, *, evaluations: int, best: float, best_at: int, elapsed_s: float) -> str | None:
        """Why the search ends now, or None: ``best`` is the best fitness so far, found after ``best_at`` evaluations."""
        if self.budget is not None and evaluations >= self.budget:
            return f"budget of {self.budget:,} evaluations spent"
        if self.target is not None and best <= self.target:
            return f"target fitness {self.target:g} reached"
        if self.stall is not None and math.isfinite(best) and evaluations - best_at >= self.stall:
            return f"no improvement in {self.stall:,} evaluations"
        if self.time_limit_s is not None and elapsed_s >= self.time_limit_s:
            return f"time limit of {self.time_limit_s:g} s"
        return None

    def as_dict(self) -> dict[str, Any]:
        return {"budget": self.budget, "target": self.target, "stall": self.stall, "time_limit_s": self.time_limit_s}
