"""Who takes migrants from whom: the campaign topologies.

Islands publish their ``k`` best candidates every ``interval`` iterations to
everyone; each receiver takes only what its *in-neighbours* sent, so the
topology is a property of the receiver and needs no coordination:

* ``ring``: the members in the order they joined (the coordinator's roster,
  not their names: a name chosen to sort before an island buys no place in
  front of it) form a directed ring; each takes from its predecessor (the
  classic unidirectional island ring);
* ``full``: each takes from every other island;
* ``random``: at every migration each takes from ``random_k`` islands drawn
  anew, reproducibly from the campaign seed, its id and the migration epoch.

Membership is dynamic (islands join, leave, crash): the neighbourhood is worked
out from the members alive at the moment of the migration. What a taken
migrant replaces is the optimizer's migrant policy
(:data:`island.population.MIGRANT_POLICIES`, ``replace_worst`` by default),
always after the receiver has re-evaluated its fitness.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from typing import Any

import numpy as np

from hysid_model.errors import HysidInputError
from island.island_messages import MAX_MIGRANTS

MAX_INTERVAL = 10**9
TOPOLOGIES = ("ring", "full", "random")
"""Migration topologies (who takes migrants from whom)."""


@dataclass(frozen=True)
class Migration:
    """How islands share partial solutions: every ``interval`` iterations (0 = isolated
    islands) each sends its ``k`` best along ``topology``; ``random`` picks ``random_k``
    neighbours anew at every migration."""

    interval: int = 10
    k: int = 2
    topology: str = "ring"
    random_k: int = 2

    def __post_init__(self) -> None:
        if isinstance(self.interval, bool) or not isinstance(self.interval, int) or not 0 <= self.interval <= MAX_INTERVAL:
            raise HysidInputError(f"must be an integer from 0 (isolated islands) to {MAX_INTERVAL:,}", param="interval", value=self.interval)
        for name in ("k", "random_k"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_MIGRANTS:
                raise HysidInputError(f"must be an integer from 1 to {MAX_MIGRANTS}", param=name, value=value)
        if self.topology not in TOPOLOGIES:
            raise HysidInputError(f"must be one of {', '.join(TOPOLOGIES)}", param="topology", value=self.topology)

    def as_dict(self) -> dict[str, Any]:
        return {"interval": self.interval, "k": self.k, "topology": self.topology, "random_k": self.random_k}


def in_neighbours(topology: str, members: list[str], me: str, *, epoch: int, seed: int, random_k: int) -> set[str]:
    """Islands whose migrants ``me`` takes at migration ``epoch``, given the ``members`` alive (in the
    order they joined: the ring's order)."""
    others = sorted(set(members) - {me})
    if not others:
        return set()
    if topology == "full":
        return set(others)
    if topology == "ring":
        ring = list(dict.fromkeys([*members, me]))
        return {ring[ring.index(me) - 1]}
    if topology == "random":
        rng = np.random.default_rng([seed, zlib.crc32(me.encode()), epoch])
        pick = rng.choice(len(others), size=min(random_k, len(others)), replace=False)
        return {others[i] for i in pick}
    raise HysidInputError(f"topology must be one of {', '.join(TOPOLOGIES)}, got {topology!r}")
