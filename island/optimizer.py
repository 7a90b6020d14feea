"""The ask/tell contract every optimizer in hysid follows (as in cma, pymoo, Nevergrad).

An optimizer is a seedable state machine. It does no I/O, knows nothing of
Zenoh or of the objective: the caller loops

    while not opt.done:
        x = opt.ask()               # (k, D) candidates
        opt.tell(x, objective(x))   # their fitness, lower is better

and between steps may hand it external candidates (migrants) with
``inject(x, f)`` where ``f`` is the fitness the caller evaluated itself.
``state_dict()`` returns plain data (numbers, lists, bytes, nested dicts) that
msgpack can serialize; ``from_state`` restores an identical optimizer, random
generator included, so a checkpointed run resumes bit for bit.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np


class AskTell(ABC):
    """Base class of GA, PSO and any other island algorithm."""

    name: str = ""

    @abstractmethod
    def ask(self) -> np.ndarray:
        """Candidates to evaluate next, shape ``(k, D)``."""

    @abstractmethod
    def tell(self, x: np.ndarray, f: np.ndarray) -> None:
        """Fitness of the candidates returned by the last ``ask``."""

    @abstractmethod
    def inject(self, x: np.ndarray, f: np.ndarray) -> int:
        """Take in external candidates with locally evaluated fitness; returns how many were taken."""

    @property
    @abstractmethod
    def done(self) -> bool:
        """True once the iteration budget is spent."""

    @property
    @abstractmethod
    def iteration(self) -> int:
        """Completed iterations (0 after the initial population)."""

    @abstractmethod
    def best(self, k: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """The ``k`` best candidates known and their fitness, best first."""

    @abstractmethod
    def state_dict(self) -> dict[str, Any]:
        """Everything needed to resume, as msgpack-serializable plain data."""

    @classmethod
    @abstractmethod
    def from_state(cls, state: dict[str, Any]) -> AskTell:
        """Restore an optimizer from ``state_dict()`` output."""
