"""The rows a campaign database holds that the coordinator writes and reads as Python records: the global best
(:class:`StoredBest`), an island run's record (:class:`IslandRecord`), and the spans of iterations of a run's
history (:data:`Span`, joined by :func:`merged`), and a run that joined (:class:`RunInfo`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

Span = tuple[int, int]
"""Iterations ``first..last`` of an island run (both included)."""


def merged(spans: list[Span]) -> list[Span]:
    """Spans of iterations joined where they overlap or touch, in order."""
    out: list[list[int]] = []
    for first, last in sorted(spans):
        if out and first <= out[-1][1] + 1:
            out[-1][1] = max(out[-1][1], last)
        else:
            out.append([first, last])
    return [(a, b) for a, b in out]


@dataclass(frozen=True)
class StoredBest:
    island: str
    x: np.ndarray
    fitness: float
    evaluations: int
    """Total campaign evaluations when this best was found (for the stall rule)."""


@dataclass(frozen=True)
class IslandRecord:
    island: str
    run: str
    algo: str
    seed: int
    iterations: int
    evaluations: int
    best_fitness: float
    best_x: np.ndarray
    sent: int
    received: int
    taken: int
    rejected: int
    final: bool
    unlisted: int = 0
    """Migrant messages it counted as having waited in vain for the roster to list their run (apart from ``rejected``)."""

    def as_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__ if k != "best_x"}


@dataclass(frozen=True)
class RunInfo:
    """A run that joined: the public key it signs with, what it said it runs, when it joined (Unix time) and the
    member it joined for ("": the shared member, of the campaign's shared secret)."""

    key: bytes
    algo: str
    seed: int
    joined: float
    member: str = ""
