"""How a coordinator reaches its islands (:class:`coordinator.server.Link`).

:class:`ZenohLink` declares the coordinator's Zenoh entities; :class:`MemoryLink`
stands in for them when every island is a thread of the coordinator's process
(``single_node`` campaigns).
"""

from __future__ import annotations

import threading

import zenoh

from coordinator.server import Coordinator
from island.node import key_prefix


class ZenohLink:
    """The coordinator's Zenoh entities under ``hysid/<campaign>/``: queryables ``config`` and
    ``best``, subscribers to ``history/*`` and ``migrants/*``, the members' liveliness
    tokens, publications on ``control`` and ``best``."""

    def __init__(self, session: zenoh.Session, coordinator: Coordinator) -> None:
        self.session = session
        self.coordinator = coordinator
        prefix = key_prefix(coordinator.name)
        self.prefix = prefix
        inbox = coordinator.inbox

        def on_sample(sample: zenoh.Sample) -> None:
            inbox.put(("msg", str(sample.key_expr), sample.payload.to_bytes()))

        def on_member(sample: zenoh.Sample) -> None:
            inbox.put(("member", str(sample.key_expr).rsplit("/", 1)[-1], sample.kind == zenoh.SampleKind.PUT))

        def on_config(query: zenoh.Query) -> None:
            query.reply(query.key_expr, coordinator.config_message)

        def on_best(query: zenoh.Query) -> None:
            message = coordinator.best_message
            if message is not None:
                query.reply(query.key_expr, message)

        self._control = session.declare_publisher(f"{prefix}/control", congestion_control=zenoh.CongestionControl.BLOCK)
        self._best = session.declare_publisher(f"{prefix}/best")
        self._entities = [
            session.declare_queryable(f"{prefix}/config", on_config),
            session.declare_queryable(f"{prefix}/best", on_best),
            session.declare_subscriber(f"{prefix}/history/*", on_sample),
            session.declare_subscriber(f"{prefix}/migrants/*", on_sample),
            session.liveliness().declare_subscriber(f"{prefix}/members/*", on_member, history=True),
        ]

    def announce_stop(self, message: bytes) -> None:
        self._control.put(message)

    def publish_best(self, message: bytes) -> None:
        self._best.put(message)

    def request_history(self, island: str, run: str, since: int) -> None:
        inbox = self.coordinator.inbox

        def on_reply(reply: zenoh.Reply) -> None:
            if reply.ok is not None:
                inbox.put(("msg", str(reply.ok.key_expr), reply.ok.payload.to_bytes()))

        self.session.get(f"{self.prefix}/history/{island}?run={run};since={since}", on_reply, timeout=5.0)

    def close(self) -> None:
        for entity in self._entities + [self._control, self._best]:
            entity.undeclare()


class MemoryLink:
    """The coordinator's outputs in a single-node campaign: the stop order is an event."""

    def __init__(self, stop: threading.Event) -> None:
        self.stop = stop

    def announce_stop(self, message: bytes) -> None:
        self.stop.set()

    def publish_best(self, message: bytes) -> None:
        """Islands in one process are all running from the start: nobody joins late."""

    def request_history(self, island: str, run: str, since: int) -> None:
        """Nothing is lost in memory."""
