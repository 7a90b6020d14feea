"""The :class:`Transport` an island node needs: how its messages travel (bytes in, bytes out).

:class:`island.node.IslandNode` takes any object of this shape; :mod:`island.transports` (``ZenohTransport``,
islands over Zenoh, any number per process) and :mod:`island.memory` (``MemoryTransport``, islands as threads of
one process) provide it. The node stands below them: it imports this contract, never them.
"""

from __future__ import annotations

from typing import Protocol

from island.arrivals import Arrivals
from island.sealing import Credentials


class Transport(Protocol):
    """How an island's messages travel (bytes in, bytes out)."""

    credentials: Credentials
    """The island run's identity: issued when it joined."""

    @property
    def arrivals(self) -> Arrivals | None:
        """The migrant messages this island takes from, if the transport shares them between the islands of a
        process (None: the island keeps its own)."""

    silent_s: float | None
    """A ring member that sent no migrants for this long is skipped (None: every member sends at every epoch)."""

    def exchange(self, epoch: int, payload: bytes) -> list[tuple[str, bytes]]:
        """Publish this island's migrants; return ``(sender, message)`` pairs the node should still
        :meth:`IslandNode.receive` (a transport may hand them over as they arrive instead)."""

    def publish_history(self, payload: bytes) -> None: ...

    def members(self) -> list[str]:
        """Islands currently alive in the campaign, in the order they joined."""

    def key_for(self, island: str, run: str) -> bytes | None:
        """The public key of a member's run (None: the roster does not list it)."""

    def stop_requested(self) -> bool:
        """The coordinator ordered the stop, or (Zenoh) it has been silent for longer than the island waits."""

    def global_best(self) -> list[bytes]:
        """Answers to the question for the coordinator's current best (asked once, when the island starts)."""

    def stop_reason(self) -> str:
        """Why :meth:`stop_requested` holds."""

    def wait_for_members(self, n: int, timeout_s: float) -> None:
        """Return once ``n`` islands have joined (or after ``timeout_s``, or on a stop order)."""

    def confirm(self, iteration: int) -> bool:
        """Wait (bounded) until the coordinator has committed this run's rows up to ``iteration``."""

    def assigned_algo(self) -> str | None:
        """The algorithm the coordinator tells this run to run (None: it has not said)."""
