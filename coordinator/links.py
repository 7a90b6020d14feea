"""How a coordinator reaches its islands (:class:`coordinator.link.Link`).

:class:`ZenohLink` declares the coordinator's Zenoh entities; :class:`MemoryLink`
stands in for them when every island is a thread of the coordinator's process
(``single_node`` campaigns).
"""

from __future__ import annotations

import threading

import zenoh

from coordinator.state import Coordinator
from island.joining import key_prefix


class ZenohLink:
    """The coordinator's Zenoh entities under ``hysid/<campaign>/``: queryables ``config``,
    ``best`` and ``join/*``, subscribers to ``history/*`` and (while it follows them:
    :data:`coordinator.intake.FOLLOWS_MIGRANTS_UP_TO`) ``migrants/*``, the members'
    liveliness tokens, publications on ``control`` and ``best``, history queries (everything it
    sends signed, :mod:`island.protocol`).

    The callbacks only queue what arrives (:meth:`Coordinator.receive` and its
    siblings, bounded, with back-pressure); the coordinator's thread handles it.
    """

    def __init__(self, session: zenoh.Session, coordinator: Coordinator) -> None:
        self.session = session
        self.coordinator = coordinator
        prefix = key_prefix(coordinator.name)
        self.prefix = prefix

        def on_sample(sample: zenoh.Sample) -> None:
            coordinator.receive(str(sample.key_expr), sample.payload.to_bytes())

        def on_member(sample: zenoh.Sample) -> None:
            coordinator.member(str(sample.key_expr).rsplit("/", 1)[-1], sample.kind == zenoh.SampleKind.PUT)

        def on_join(query: zenoh.Query) -> None:
            key = query.key_expr
            payload = b"" if query.payload is None else query.payload.to_bytes()
            coordinator.join_request(str(key).rsplit("/", 1)[-1], payload, lambda answer: query.reply(key, answer))

        def on_config(query: zenoh.Query) -> None:
            query.reply(query.key_expr, coordinator.config_signed)

        def on_best(query: zenoh.Query) -> None:
            message = coordinator.best_message
            if message is not None:
                query.reply(query.key_expr, message)

        self._control = session.declare_publisher(f"{prefix}/control", congestion_control=zenoh.CongestionControl.BLOCK)
        self._best = session.declare_publisher(f"{prefix}/best")
        self._entities: list[zenoh.Queryable | zenoh.Subscriber] = [
            session.declare_queryable(f"{prefix}/config", on_config),
            session.declare_queryable(f"{prefix}/best", on_best),
            session.declare_queryable(f"{prefix}/join/*", on_join),
            session.declare_subscriber(f"{prefix}/history/*", on_sample),
            session.liveliness().declare_subscriber(f"{prefix}/members/*", on_member, history=True),
        ]
        self._migrants = session.declare_subscriber(f"{prefix}/migrants/*", on_sample) if coordinator.follows_migrants else None

    def publish_control(self, message: bytes, stop: bool) -> None:
        self._control.put(message)

    def publish_best(self, message: bytes) -> None:
        self._best.put(message)

    def request_history(self, island: str, run: str, since: int) -> None:
        coordinator = self.coordinator

        def on_reply(reply: zenoh.Reply) -> None:
            if reply.ok is not None:
                coordinator.receive(str(reply.ok.key_expr), reply.ok.payload.to_bytes())

        self.session.get(
            f"{self.prefix}/history/{island}?{coordinator.history_query(island, run, since)}",
            on_reply,
            timeout=5.0,
            target=zenoh.QueryTarget.ALL,
            consolidation=zenoh.ConsolidationMode.NONE,
        )  # a stranger's queryable cannot take it

    @property
    def follows_migrants(self) -> bool:
        """Whether the coordinator's subscriber to ``migrants/*`` is declared."""
        return self._migrants is not None

    def unfollow_migrants(self) -> None:
        """Undeclare the subscriber to ``migrants/*``: Zenoh no longer brings them to this session."""
        if self._migrants is not None:
            self._migrants.undeclare()
            self._migrants = None

    def close(self) -> None:
        self.unfollow_migrants()
        for entity in self._entities + [self._control, self._best]:
            entity.undeclare()


class MemoryLink:
    """The coordinator's outputs in a single-node campaign: the stop order is an event."""

    def __init__(self, stop: threading.Event) -> None:
        self.stop = stop

    def publish_control(self, message: bytes, stop: bool) -> None:
        """In one process the islands are the bus' members; only the stop order matters."""
        if stop:
            self.stop.set()

    def publish_best(self, message: bytes) -> None:
        """Islands in one process are all running from the start: nobody joins late."""

    def request_history(self, island: str, run: str, since: int) -> None:
        """Nothing is lost in memory."""

    def unfollow_migrants(self) -> None:
        """The islands' migrant messages still reach :meth:`Coordinator.receive`, which lets them pass."""
