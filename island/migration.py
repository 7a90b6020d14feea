"""Who takes migrants from whom: the campaign topologies.

Islands publish their ``k`` best candidates every ``interval`` iterations to
everyone; each receiver takes only what its *in-neighbours* sent, so the
topology is a property of the receiver and needs no coordination:

* ``ring``: islands sorted by id form a directed ring; each takes from its
  predecessor (the classic unidirectional island ring);
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

import numpy as np

from island.protocol import TOPOLOGIES


def in_neighbours(topology: str, members: list[str], me: str, *, epoch: int, seed: int, random_k: int) -> set[str]:
    """Islands whose migrants ``me`` takes at migration ``epoch``, given the ``members`` alive."""
    others = sorted(set(members) - {me})
    if not others:
        return set()
    if topology == "full":
        return set(others)
    if topology == "ring":
        ring = sorted(set(others) | {me})
        return {ring[ring.index(me) - 1]}
    if topology == "random":
        rng = np.random.default_rng([seed, zlib.crc32(me.encode()), epoch])
        pick = rng.choice(len(others), size=min(random_k, len(others)), replace=False)
        return {others[i] for i in pick}
    raise ValueError(f"unknown topology {topology!r}; choose one of {', '.join(TOPOLOGIES)}")
