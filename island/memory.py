"""Islands as threads of one process, exchanging migrants in memory: :class:`MemoryBus` and each island's
:class:`MemoryTransport` (an :class:`island.transport.Transport`), in lock step at every epoch so that a single-node
campaign is reproducible (over Zenoh: :mod:`island.transports`)."""

from __future__ import annotations

import secrets
import threading
from collections.abc import Callable

from hysid_model.errors import HysidInputError
from island.joining import key_prefix
from island.sealing import Credentials, new_key, public_key
from island.wire import MAX_MEMBERS

Admit = Callable[[str, str, int, bytes], str]
"""``admit(island, algo, seed, public key)``: the run id the coordinator issues an in-process island."""


class MemoryBus:
    """In-process migration between island threads, in lock step per epoch.

    At epoch ``e`` every island posts its migrants and waits until each island
    still running has posted for ``e`` (or finished), so the exchange does not
    depend on thread timing and a seeded single-node campaign is reproducible.
    ``admit`` registers each island's signing key and issues its run (the
    coordinator's, in a single-node campaign; by default the bus' own);
    ``assigned(island)`` is the algorithm the coordinator tells an island to run
    (None: not said).
    """

    def __init__(
        self,
        campaign: str,
        islands: list[str],
        deliver: Callable[[str, bytes], object],
        stop: threading.Event,
        admit: Admit | None = None,
        assigned: Callable[[str], str | None] | None = None,
        coordinator: bytes = b"",
    ) -> None:
        self.prefix = key_prefix(campaign)
        self.islands = sorted(islands)
        if len(self.islands) > MAX_MEMBERS:
            raise HysidInputError(f"at most {MAX_MEMBERS} islands", param="islands", value=len(self.islands))
        self.deliver = deliver
        """Receives every publication as ``(key, message)``, as the coordinator's subscribers would."""
        self.stop = stop
        self.coordinator = coordinator
        """The coordinator's public key (in one process nothing it sends goes through the bus)."""
        self.admit = admit or (lambda island, algo, seed, key: secrets.token_hex(6))
        self.assigned = assigned or (lambda island: None)
        self._keys: dict[tuple[str, str], bytes] = {}
        self._active = set(islands)
        self._posts: dict[int, dict[str, bytes]] = {}
        self._cond = threading.Condition()

    def transport(self, island: str, algo: str = "", seed: int = 0) -> MemoryTransport:
        key = new_key()
        run = self.admit(island, algo, seed, public_key(key))
        with self._cond:
            self._keys[(island, run)] = public_key(key)
        return MemoryTransport(self, island, Credentials(island, run, key, self.coordinator))

    def key_for(self, island: str, run: str) -> bytes | None:
        with self._cond:
            return self._keys.get((island, run))

    def exchange(self, island: str, epoch: int, payload: bytes) -> list[tuple[str, bytes]]:
        self.deliver(f"{self.prefix}/migrants/{island}", payload)
        with self._cond:
            posts = self._posts.setdefault(epoch, {})
            posts[island] = payload
            self._cond.notify_all()
            self._cond.wait_for(lambda: self._active <= set(posts) or self.stop.is_set())
            return [(sender, data) for sender, data in sorted(posts.items()) if sender != island]

    def leave(self, island: str) -> None:
        with self._cond:
            self._active.discard(island)
            self._cond.notify_all()


class MemoryTransport:
    """One island's view of a :class:`MemoryBus`."""

    silent_s: float | None = None
    """In lock step every member posts at every epoch."""
    arrivals = None
    """Each island keeps its own (:class:`island.arrivals.Arrivals`)."""

    def __init__(self, bus: MemoryBus, island: str, credentials: Credentials) -> None:
        self.bus = bus
        self.island = island
        self.credentials = credentials

    def exchange(self, epoch: int, payload: bytes) -> list[tuple[str, bytes]]:
        return self.bus.exchange(self.island, epoch, payload)

    def publish_history(self, payload: bytes) -> None:
        self.bus.deliver(f"{self.bus.prefix}/history/{self.island}", payload)

    def members(self) -> list[str]:
        return list(self.bus.islands)

    def key_for(self, island: str, run: str) -> bytes | None:
        return self.bus.key_for(island, run)

    def stop_requested(self) -> bool:
        return self.bus.stop.is_set()

    def stop_reason(self) -> str:
        return "stopped by the coordinator"

    def global_best(self) -> list[bytes]:
        return []

    def assigned_algo(self) -> str | None:
        return self.bus.assigned(self.island)

    def wait_for_members(self, n: int, timeout_s: float) -> None:
        """Every island of the bus exists from the start."""

    def confirm(self, iteration: int) -> bool:
        """The coordinator is in this process: what was delivered is in its queue."""
        return True

    def close(self) -> None:
        self.bus.leave(self.island)
