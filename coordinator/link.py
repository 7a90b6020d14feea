"""What a coordinator sends out: the :class:`Link` it needs (:mod:`coordinator.links` has the Zenoh one and the
in-process one of single-node campaigns)."""

from __future__ import annotations

from typing import Protocol


class Link(Protocol):
    """What the coordinator sends out (Zenoh publications, or in-process for single-node campaigns)."""

    def publish_control(self, message: bytes, stop: bool) -> None:
        """The sealed roster and stop order (``stop``: it carries the stop order)."""

    def publish_best(self, message: bytes) -> None: ...

    def request_history(self, island: str, run: str, since: int) -> None:
        """Ask an island for its rows after ``since``; the answer arrives in the inbox as a history message."""

    def unfollow_migrants(self) -> None:
        """Stop the delivery of migrant messages (:data:`coordinator.intake.FOLLOWS_MIGRANTS_UP_TO`)."""
