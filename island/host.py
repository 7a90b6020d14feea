"""Many islands in one process: each its own id, run, key, algorithm and seed, over one Zenoh session.

An island needs a population and an objective (a few MB); a process of its own
costs about 140 MB more (the interpreter, numpy, numba, Zenoh). :func:`run_islands`
runs any number of islands of one campaign as threads of one process, on one
:class:`island.transports.ZenohHost`: one session, every migrant message and
roster read and checked once for all of them, one heartbeat thread. Each
island joins on its own (its own run id and signing key, registered with the
coordinator), searches, migrates and reports exactly as an island process does,
so a seed gives the same search in either.

* The islands compute ``turns`` at a time (default: :func:`cores`, the cores the
  process may run on), taking turns iteration by iteration in order
  (:class:`island.turns.Turns`): they progress alike, and the threads that speak for all of
  them (control, heartbeats, migrants) never wait behind dozens of computing
  ones for Python's interpreter lock.
* One island's failure (refused by the coordinator, an error in its search)
  ends that island only: it is reported (``notify``) and the others carry on.
* Ctrl-C (``KeyboardInterrupt`` in the calling thread) ends them all cleanly:
  each stops, sends its last history and waits (at most
  :data:`INTERRUPT_CONFIRM_S`) for the coordinator to confirm it; a second
  Ctrl-C leaves at once.

:func:`host_specs` names the islands of a host and gives each its seed and
algorithm; :func:`cores` is how many islands a process may run side by side.
"""

from __future__ import annotations

import os
import threading
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field

import zenoh

from hysid_model.errors import HysidInputError
from hysid_model.loops import LoopSet
from island.config import CampaignConfig
from island.node import HISTORY_EVERY_S, IslandNode
from island.secret import CampaignSecret
from island.transports import ZenohHost, ZenohTransport
from island.turns import Turns
from island.wire import MAX_MEMBERS, check_name

INTERRUPT_CONFIRM_S = 3.0
"""After Ctrl-C, how long each island waits for the coordinator to confirm its last rows (it commits every 0.5 s)."""
SEED_SPREAD = 1 << 20
"""Islands not given a seed draw one from the campaign seed and their id, this far apart at most."""


@dataclass(frozen=True)
class IslandSpec:
    """One island of a campaign: its id, algorithm and seed."""

    id: str
    algo: str
    seed: int


def cores() -> int:
    """The cores this process may run on (``os.sched_getaffinity``: under SLURM, the task's CPUs)."""
    return len(os.sched_getaffinity(0))


def host_specs(base: str, count: int, config: CampaignConfig, algo: str | None = None, seed: int | None = None) -> list[IslandSpec]:
    """The islands of one host: ``base`` alone for one island, else ``base-0`` .. ``base-<count-1>``;
    seeds ``seed``, ``seed+1``, ... (default: from the campaign seed and each id); each island's
    algorithm ``algo`` or the campaign's mix by its seed."""
    if isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= MAX_MEMBERS:
        raise HysidInputError(f"must be from 1 to {MAX_MEMBERS} islands", param="count", value=count)
    ids = [base] if count == 1 else [check_name("island", f"{base}-{k}") for k in range(count)]
    seeds = [config.seed + zlib.crc32(i.encode()) % SEED_SPREAD if seed is None else seed + k for k, i in enumerate(ids)]
    return [IslandSpec(i, algo or config.algo_for(s), s) for i, s in zip(ids, seeds)]


@dataclass
class Hosted:
    """An island of a host once it ended: its node (None if it never started) and why it failed ("" if it did not)."""

    spec: IslandSpec
    node: IslandNode | None = None
    error: BaseException | None = None
    ended: threading.Event = field(default_factory=threading.Event)
    """Set when its thread ended: waited on instead of ``Thread.join``, which CPython 3.11 reports done at once
    after a Ctrl-C interrupted it (the island's last history would go unsent as the process exits)."""


def run_islands(
    session: zenoh.Session,
    secret: CampaignSecret,
    config: CampaignConfig,
    loops: LoopSet,
    specs: list[IslandSpec],
    *,
    wait_s: float = 30.0,
    notify: Callable[[str], None] | None = None,
    history_every_s: float = HISTORY_EVERY_S,
    turns: int | None = None,
) -> list[Hosted]:
    """Run the islands ``specs`` of the campaign of ``config`` (its loop set ``loops``) over ``session``,
    each in a thread, until they end; what became of each (see the module docstring). Ctrl-C in the
    calling thread stops them all, waits for their last history, then raises ``KeyboardInterrupt``. ``turns``:
    how many compute at once (default :func:`cores`)."""
    say = notify or (lambda message: None)
    first = config.objective(loops)  # each island has an objective of its own: nothing is shared between their threads
    host = ZenohHost(session, secret, first.bounds, wait_s, say)
    hosted = [Hosted(spec) for spec in specs]
    computing = Turns(turns or cores())

    def island(h: Hosted) -> None:
        try:
            objective = first if h is hosted[0] else config.objective(loops)
            h.node = IslandNode(h.spec.id, h.spec.algo, h.spec.seed, config, objective, history_every_s=history_every_s, turns=computing)
            transport = ZenohTransport(session, h.node, secret, wait_s, notify=say, host=host)
            try:
                h.node.run(transport)
            finally:
                transport.close()
        except Exception as exc:  # this island ends; the others carry on
            h.error = exc
            if len(hosted) > 1:
                say(f"island {h.spec.id} failed: {describe(exc)}; the other islands of this process carry on")
        finally:
            h.ended.set()

    threads = [threading.Thread(target=island, args=(h,), name=f"island-{h.spec.id}", daemon=True) for h in hosted]
    for t in threads:
        t.start()
    try:
        for h in hosted:
            h.ended.wait()
    except KeyboardInterrupt:
        host.stop("interrupted (Ctrl-C)")
        host.confirm_s = min(wait_s, INTERRUPT_CONFIRM_S)
        say(f"{len(threads)} island(s) of this process interrupted: sending their last history rows (Ctrl-C again to leave at once)")
        for h in hosted:
            h.ended.wait()
        raise
    finally:
        host.close()
    return hosted


def describe(exc: BaseException) -> str:
    """One line for an island's failure: an input error's own message, else the exception's type and text."""
    if isinstance(exc, HysidInputError):
        return str(exc)
    return f"{type(exc).__name__}: {exc}"
