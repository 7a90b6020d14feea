"""Hostile and broken messages for every key of a campaign's key space, generated from a seed.

Each generated message is invalid by construction: it carries at least one
defect that some check must catch (the message alone decides which: its
envelope, its signature, its sender, its body, its plausibility, or a replay). The
defects include the shapes and values that once crashed every receiver
(``[2**62, 4]`` arrays, NaN times, integers of 2**63 and more, 1e300 counts),
times and fitness values no campaign produces (send times of +-1e308, 0 or -1),
join steps of a party without the campaign secret, and messages signed correctly
by a joined but broken island, so that the body checks are reached too.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import msgpack
import numpy as np

from island.coordinator_messages import encode_control
from island.handshake import JoinRequest, encode_join, encode_prove
from island.sealing import Credentials, new_key, public_key, seal
from island.wire import MAX_BYTES, PROTOCOL_VERSION, pack_array

HOSTILE_INTS = [-1, 2**53 + 1, 2**62, 2**63, 2**64 - 1, -(2**63)]
HOSTILE_FLOATS = [float("nan"), float("inf"), -float("inf"), 1e300, -1e300]
HOSTILE_VALUES = [None, True, "7", b"\x00" * 9, [1, 2], {"a": 1}, msgpack.ExtType(5, b"x"), *HOSTILE_INTS, *HOSTILE_FLOATS]
HOSTILE_SHAPES = [[2**62, 4], [2**32, 2**32], [4, 2**62], [-1, 4], [1.5, 4], [1], [1, 4, 1], [2] * 64, "4x4", [True, 4]]


def nested(depth: int) -> list:
    """Lists in lists (msgpack packs up to 511 levels)."""
    value: list = []
    for _ in range(min(depth, 500)):
        value = [value]
    return value


def deep_bytes(depth: int) -> bytes:
    """A msgpack document nested ``depth`` levels deep, beyond what a packer would write."""
    return b"\x91" * depth + b"\x90"


@dataclass
class Hostile:
    """Generates invalid messages for campaign ``campaign`` whose search space has ``bounds``.

    ``broken`` is a joined island that misbehaves (its signatures are valid).
    """

    rng: np.random.Generator
    campaign: str
    bounds: np.ndarray
    broken: Credentials
    seq: Callable[[], int]

    def _x(self, k: int = 1) -> np.ndarray:
        lo, hi = self.bounds[:, 0], self.bounds[:, 1]
        return lo + self.rng.random((k, lo.size)) * (hi - lo)

    def _pick(self, options: list):
        return options[int(self.rng.integers(len(options)))]

    def _seal(self, kind: str, fields: dict, key: bytes | None = None, sender: str | None = None, run: str | None = None) -> bytes:
        c = self.broken
        return seal(kind, self.campaign, sender or c.island, run or c.run, self.seq(), fields, key or c.key)

    # --- bodies with one defect each ---------------------------------------------------------
    def migrant_body(self) -> dict:
        good = {"iteration": 5, "x": pack_array(self._x(2)), "claimed": pack_array(np.zeros(2)), "sent_at": time.time()}
        field = self._pick(["iteration", "x", "claimed", "sent_at", "missing", "nesting"])
        if field == "missing":
            del good[self._pick(list(good))]
        elif field == "nesting":
            good["x"] = nested(int(self.rng.integers(20, 500)))
        elif field == "x":
            spoiled = self._x(2)
            spoiled[int(self.rng.integers(2)), int(self.rng.integers(spoiled.shape[1]))] = self._pick(HOSTILE_FLOATS)
            good["x"] = self._pick(
                [
                    {"shape": self._pick(HOSTILE_SHAPES), "data": b""},
                    {"shape": [2, self.bounds.shape[0]], "data": b"\x00" * 7},
                    pack_array(spoiled),
                    pack_array(self.bounds[:, 1] + 1.0),
                    self._pick(HOSTILE_VALUES),
                ]
            )
        elif field == "claimed":
            good["claimed"] = self._pick(
                [
                    pack_array(np.array([self._pick(HOSTILE_FLOATS[:3]), -1.0])),
                    pack_array(np.zeros(3)),
                    pack_array(np.array([1e300, 0.0])),
                    self._pick(HOSTILE_VALUES),
                ]
            )
        elif field == "iteration":
            good[field] = self._pick([*HOSTILE_INTS, *HOSTILE_FLOATS, None, "x", [1]])
        else:  # a send time no clock shows, or no number
            good[field] = self._pick([*HOSTILE_FLOATS[:3], 1e308, -1e308, 0.0, -1.0, 1e300, 2**63, 2**64 - 1, None, "x", [1]])
        return good

    def history_body(self, algo: str, seed: int, implausible: float) -> dict:
        good = {
            "algo": algo,
            "seed": seed,
            "rows": pack_array(np.array([[0, 5.0, 20, 0.1], [1, 4.0, 45, 0.2]])),
            "best_x": pack_array(self._x(1)[0]),
            "best_f": 1e9,
            "stats": {"sent": 0, "received": 0, "taken": 0, "rejected": 0, "unlisted": 0},
            "final": False,
            "gain": 0.5,
        }
        field = self._pick(["rows", "best_x", "best_f", "stats", "seed", "algo", "final", "gain", "missing", "implausible"])
        if field == "missing":
            del good[self._pick(list(good))]
        elif field == "implausible":
            good["rows"] = pack_array(np.array([[1, 5.0, self._pick([implausible, 2.0**52, 2.0**53]), 0.1]]))
        elif field == "rows":
            col, bad_value = self._pick(
                [
                    *((c, v) for c in (0, 2) for v in (1e300, float("nan"), -1.0, 0.5, 2.0**62, float("inf"))),
                    (1, float("nan")),
                    (1, -1.0),
                    (1, 1e300),
                    (1, float("inf")),
                    (3, float("nan")),
                    (3, -1.0),
                    (3, float("inf")),
                    (3, 1e300),
                ]
            )
            rows = np.array([[0, 5.0, 20, 0.1], [1, 4.0, 45, 0.2]])
            rows[1, col] = bad_value
            good["rows"] = self._pick([pack_array(rows), {"shape": self._pick(HOSTILE_SHAPES), "data": b""}, pack_array(rows[::-1].copy())])
        elif field == "best_x":
            good["best_x"] = self._pick(
                [pack_array(self.bounds[:, 0] - 1.0), {"shape": [2**62], "data": b""}, pack_array(np.full(self.bounds.shape[0], np.nan))]
            )
        elif field == "best_f":
            good["best_f"] = self._pick([float("nan"), -1.0, "1", None])
        elif field == "stats":
            good["stats"] = self._pick([{"sent": 2**63}, {**good["stats"], "taken": -1}, {**good["stats"], "received": 2**64 - 1}, [1, 2], None])
        elif field == "seed":
            good["seed"] = self._pick([2**63, -1, 2**64 - 1, 1.5])
        elif field == "algo":
            good["algo"] = self._pick(["GA", "a" * 17, "de", "", 3])
        elif field == "gain":
            good["gain"] = self._pick([-1.0, float("nan"), float("inf"), 1e7, "1", None])
        else:
            good["final"] = self._pick([1, "yes", None])
        return good

    # --- whole messages ----------------------------------------------------------------------
    def envelope_defect(self, kind: str, fields: dict) -> bytes:
        """A message whose envelope, tag or sender is wrong (the body may be fine)."""
        valid = msgpack.unpackb(self._seal(kind, fields))
        defect = self._pick(["garbage", "truncated", "oversized", "flip", "field", "signature", "unjoined", "sender", "nesting", "signed-garbage"])
        if defect == "garbage":
            return self.rng.bytes(int(self.rng.integers(0, 300)))
        if defect == "truncated":
            data = msgpack.packb(valid)
            return data[: int(self.rng.integers(0, len(data)))]
        if defect == "oversized":
            return b"\x00" * (MAX_BYTES[kind] + 1)
        if defect == "flip":
            body = bytearray(valid["body"])
            body[int(self.rng.integers(len(body)))] ^= 1 << int(self.rng.integers(8))
            return msgpack.packb({**valid, "body": bytes(body)})
        if defect == "field":
            key = self._pick(["v", "type", "campaign", "sender", "run", "seq", "body", "sig"])
            return msgpack.packb({**valid, key: self._pick(HOSTILE_VALUES + ["x" * 300, "no/slash"])})
        if defect == "signature":  # missing, empty, zero, short, or a stranger's
            return msgpack.packb({**valid, "sig": self._pick([b"", b"\x00" * 64, b"x", bytes(self.rng.bytes(64)), None, [1] * 5000])})
        if defect == "unjoined":  # a key nobody registered
            ghost = Credentials(f"ghost-{int(self.rng.integers(1000))}", "deadbeef0000", new_key(), b"h" * 32)
            return self._seal_as(ghost, kind, fields)
        if defect == "sender":
            return msgpack.packb({**valid, "sender": "someone-else"})
        if defect == "nesting":
            return deep_bytes(int(self.rng.integers(100, 100_000)))
        return self._seal(kind, {}) if self.rng.random() < 0.5 else msgpack.packb({**valid, "body": b"\xc1\xc1"})

    def _seal_as(self, c: Credentials, kind: str, fields: dict) -> bytes:
        return seal(kind, self.campaign, c.island, c.run, self.seq(), fields, c.key)

    def migrants(self) -> bytes:
        if self.rng.random() < 0.5:
            return self.envelope_defect("migrants", {"iteration": 5, "x": pack_array(self._x(2)), "claimed": pack_array(np.zeros(2)), "sent_at": time.time()})
        return self._seal("migrants", self.migrant_body())

    def history(self, algo: str, seed: int, implausible: float) -> bytes:
        if self.rng.random() < 0.4:
            return self.envelope_defect("history", self.history_body(algo, seed, implausible))
        return self._seal("history", self.history_body(algo, seed, implausible))

    def join(self, island: str) -> bytes:
        """A join step that must get no answer: a malformed request, or a proof of a party without the
        campaign secret or without a challenge the coordinator issued (a well-formed request would be
        answered with a challenge: anyone may ask)."""
        key = new_key()
        good = {
            "v": PROTOCOL_VERSION,
            "type": "join",
            "campaign": self.campaign,
            "island": island,
            "algo": "pso",
            "seed": 1,
            "nonce": b"n" * 16,
            "key": public_key(key),
        }
        field = self._pick(["island", "algo", "seed", "nonce", "key", "v", "campaign", "garbage", "proof"])
        if field == "garbage":
            return self.rng.bytes(int(self.rng.integers(0, 100)))
        if field == "proof":  # a guessed secret, or the right form with a challenge nobody issued
            request = JoinRequest(self.campaign, island, "pso", 1, self.rng.bytes(16), public_key(key))
            return encode_prove(request, self.rng.bytes(16), self.rng.bytes(32), key)
        good[field] = self._pick(
            {
                "island": ["someone-else", "", "x" * 65, 7],
                "algo": ["GA", 3, "x" * 20],
                "seed": [2**63, -1, 2**64 - 1, "1"],
                "nonce": [b"short", "n" * 16, None],
                "key": [b"short", None, "k" * 32],
                "v": [PROTOCOL_VERSION - 1, PROTOCOL_VERSION + 1, str(PROTOCOL_VERSION)],
                "campaign": ["other", 2],
            }[field]
        )
        return msgpack.packb(good, use_bin_type=True)

    def control(self) -> bytes:
        """A control message every island must refuse: signed by a member (not the coordinator), or malformed."""
        members = [["a", "r1", True, 3, "pso", b"k" * 32]]
        defect = self._pick(["forged", "members", "stop", "envelope"])
        if defect == "forged":
            return seal("control", self.campaign, "coordinator", "c0", self.seq(), {"members": members, "stop": "forged stop"}, self.broken.key)
        if defect == "envelope":
            return self.rng.bytes(int(self.rng.integers(0, 200)))
        fields = {"members": members, "stop": ""}
        if defect == "members":
            fields["members"] = self._pick(
                [
                    [["a", "r1", True, 2**63, "pso", b"k" * 32]],
                    [["a/b", "r1", True, 1, "pso", b"k" * 32]],
                    [[1, 2, 3]],
                    "x",
                    [["a", "r1", "yes", 1, "pso", b"k" * 32]],
                    [["a", "r1", True, 1, "PSO!", b"k" * 32]],
                    [["a", "r1", True, 1, "pso"]],
                    [members[0]] * 5000,
                ]
            )
        else:
            fields["stop"] = "s" * 1000
        return seal("control", self.campaign, "coordinator", "c0", self.seq(), fields, new_key())

    def history_query(self) -> str:
        """Selector parameters of a history query that an island must refuse (none is signed by the coordinator)."""
        return self._pick(
            [
                "since=abc",
                "since=" + "9" * 40,
                "since=-7",
                "since=1e300",
                "since=nan",
                "run=x;since=" + "1" * 17,
                "since=2.5",
                "run=x;since=-1",
                "run=x;since=-1;seq=1;sig=" + "00" * 64,
                f"run=x;since=-1;seq=1;sig={self.rng.bytes(64).hex()}",
            ]
        )


def stream(h: Hostile, n: int, algo: str, seed: int, implausible: float, islands: list[str]) -> Iterator[tuple[str, str, bytes]]:
    """``n`` hostile messages for the coordinator as ``(entry, key or island, payload)``; entry is
    ``msg`` (a publication), ``member`` (a liveliness token of a name that never joined, payload
    empty) or ``join`` (a join request)."""
    prefix = f"hysid/{h.campaign}"
    for _ in range(n):
        r = h.rng.random()
        if r < 0.4:
            yield "msg", f"{prefix}/migrants/{h.broken.island}", h.migrants()
        elif r < 0.8:
            yield "msg", f"{prefix}/history/{h.broken.island}", h.history(algo, seed, implausible)
        elif r < 0.85:
            yield "msg", f"{prefix}/{h._pick(['config', 'best', 'control', 'members', 'join', 'other/x'])}/{h.broken.island}", h.migrants()
        elif r < 0.93:
            yield "join", h._pick(islands + ["someone"]), h.join(h._pick(islands + ["someone"]))
        else:
            yield "member", h._pick([f"ghost-{int(h.rng.integers(10**6))}", "x" * 70, "no.such-island"]), b""


# --- attacks from a party's own Zenoh session (tests/test_attacks.py) ------------------------------
class RogueCoordinator:
    """A stranger posing as the coordinator of ``campaign`` on its own ``session``, with a key of its own:
    it answers join requests (a challenge, then a run), the config query with ``config`` (a loop set of
    its making), the best query, and publishes a stop order every ``every_s``; ``answered`` counts what
    it answered, by key."""

    def __init__(self, session, campaign: str, config: bytes, best_x: np.ndarray, every_s: float = 0.2) -> None:
        import threading

        from island.coordinator_messages import Best, Control, encode_best
        from island.handshake import decode_join_step, encode_challenge, encode_joined
        from island.protocol import encode_signed_config

        self.session, self.campaign, self.key = session, campaign, new_key()
        self.answered: dict[str, int] = {}
        signed_config = encode_signed_config(config, campaign, "rogue", self.key)
        best = encode_best(Best(campaign, "rogue", best_x, 0.0), "rogue", self.key)

        def answer(kind: str, query, payload: bytes) -> None:
            self.answered[kind] = self.answered.get(kind, 0) + 1
            query.reply(query.key_expr, payload)

        def on_join(query) -> None:
            step = decode_join_step(query.payload.to_bytes(), campaign)
            if isinstance(step, JoinRequest):
                answer("challenge", query, encode_challenge(campaign, step.island, step.nonce, b"r" * 16, "rogue", self.key))
            else:
                answer("joined", query, encode_joined(campaign, step.request.nonce, step.request.island, "rogue-run", "rogue", self.key))

        prefix = f"hysid/{campaign}"
        self.entities = [
            session.declare_queryable(f"{prefix}/join/*", on_join),
            session.declare_queryable(f"{prefix}/config", lambda q: answer("config", q, signed_config)),
            session.declare_queryable(f"{prefix}/best", lambda q: answer("best", q, best)),
        ]
        self._stop = threading.Event()
        control = session.declare_publisher(f"{prefix}/control")

        def stop_orders() -> None:
            seq = time.time_ns() // 1000 + 10**12  # ahead of the real coordinator's numbers
            while not self._stop.wait(every_s):
                seq += 1
                control.put(encode_control(Control(campaign, (), "stopped by a stranger", seq), "rogue", self.key))
                self.answered["control"] = self.answered.get("control", 0) + 1

        self._thread = threading.Thread(target=stop_orders, daemon=True)
        self._thread.start()
        self.entities.append(control)

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        for entity in self.entities:
            entity.undeclare()


def join_flood(session, campaign: str, n: int, timeout_s: float = 120.0) -> dict[str, int]:
    """``n`` joins under fresh ids from a party without the campaign secret: each asks, takes the
    coordinator's challenge and sends a proof made with a guessed secret. Returns how many challenges
    and how many runs it got, once every query of both steps ended."""
    import threading

    import zenoh

    got = {"challenges": 0, "runs": 0}
    cond = threading.Condition()
    open_queries = [0]
    key = new_key()

    def ended() -> None:
        with cond:
            open_queries[0] -= 1
            cond.notify_all()

    def ask(request: JoinRequest, payload: bytes, on_reply) -> None:
        with cond:
            open_queries[0] += 1
        session.get(f"hysid/{campaign}/join/{request.island}", zenoh.handlers.Callback(on_reply, ended), payload=payload, timeout=10.0)

    def on_challenge(request: JoinRequest):
        def on_reply(reply) -> None:
            if reply.ok is None:
                return
            fields = msgpack.unpackb(msgpack.unpackb(reply.ok.payload.to_bytes())["body"])  # read unchecked: an attacker trusts anything
            with cond:
                got["challenges"] += 1
            ask(request, encode_prove(request, fields["challenge"], b"guessed secret".ljust(32), key), on_joined)

        return on_reply

    def on_joined(reply) -> None:
        if reply.ok is not None:
            with cond:
                got["runs"] += 1

    for i in range(n):
        request = JoinRequest(campaign, f"fresh-{i}", "pso", i, i.to_bytes(16, "big"), public_key(key))
        ask(request, encode_join(request), on_challenge(request))
    with cond:
        cond.wait_for(lambda: open_queries[0] == 0, timeout=timeout_s)
    return dict(got)
