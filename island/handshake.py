"""The join handshake's messages (protocol version 5; the rest of the wire format: :mod:`island.protocol`).

A challenge-response on ``join/<id>`` (two queries): ``join`` (the island's id, the member it joins for, its
algorithm, seed, a fresh nonce and the public key its run will sign with) is answered by a ``challenge`` signed by
the coordinator; ``prove`` (the request again with the challenge, an HMAC over both with that member's admission
secret, :mod:`island.secret`, and a signature with the run's key) is answered by a signed ``joined`` holding the run
id, or the refusal. The secret never travels; an island takes answers only with the signature of the coordinator
named in its secret, and the coordinator admits only islands whose proof holds.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from hysid_model.errors import HysidInputError
from island.protocol import COORDINATOR, NONCE_BYTES, _algo
from island.sealing import KEY_BYTES, SIGNATURE_BYTES, prove, proven, seal, sign, unseal, verify
from island.wire import MAX_TEXT, NAME_PATTERN, PROTOCOL_VERSION, MessageRejected, _bytes, _dumps, _get, _int, _name, _text, _unpack


@dataclass(frozen=True)
class JoinRequest:
    """An island asking to join: its id, algorithm and seed, a fresh ``nonce`` every answer echoes,
    ``key``, the public half of the signing key its run will sign with, and ``member``, the member it joins for
    ("": a holder of the campaign's own secret; :mod:`island.secret`)."""

    campaign: str
    island: str
    algo: str
    seed: int
    nonce: bytes
    key: bytes
    member: str = ""

    def transcript(self, challenge: bytes) -> bytes:
        """What the island's proof and signature cover: the request and the coordinator's challenge."""
        return _dumps([PROTOCOL_VERSION, "prove", self.campaign, self.island, self.member, self.algo, int(self.seed), self.nonce, self.key, challenge])


def _request(msg: dict[str, Any], campaign: str, sender: str | None) -> JoinRequest:
    island = _name(msg, "island")
    if sender is not None and island != sender:
        raise MessageRejected("sender", f"join request on the key of {sender!r} names island {island!r}")
    member = _get(msg, "member", str)
    if member and not NAME_PATTERN.match(member):
        raise MessageRejected("schema", "join request names no valid member")
    return JoinRequest(campaign, island, _algo(msg, "algo"), _int(msg, "seed"), _bytes(msg, "nonce", NONCE_BYTES), _bytes(msg, "key", KEY_BYTES), member)


def _request_fields(r: JoinRequest, kind: str) -> dict[str, Any]:
    """The request's fields as both steps of the handshake send them (``kind``: join or prove), in wire order."""
    return {
        "v": PROTOCOL_VERSION,
        "type": kind,
        "campaign": r.campaign,
        "island": r.island,
        "member": r.member,
        "algo": r.algo,
        "seed": int(r.seed),
        "nonce": r.nonce,
        "key": r.key,
    }


def encode_join(r: JoinRequest) -> bytes:
    """The first step of the handshake (``join/<id>``): who asks, for which member, with which key; answered by a challenge."""
    return _dumps(_request_fields(r, "join"))


def decode_join(data: bytes, campaign: str, sender: str | None = None) -> JoinRequest:
    """``sender`` is the island named by the Zenoh key the request was sent to (``join/<id>``)."""
    return _request(_unpack(data, "join", campaign), campaign, sender)


def encode_challenge(campaign: str, island: str, nonce: bytes, challenge: bytes, run: str, key: bytes) -> bytes:
    """The coordinator's answer to a join request: a fresh challenge, signed (so that an island can tell its
    coordinator from a stranger before it proves anything)."""
    return seal("challenge", campaign, COORDINATOR, run, 0, {"island": island, "nonce": nonce, "challenge": challenge}, key)


def decode_challenge(data: bytes, campaign: str, island: str, nonce: bytes, coordinator: bytes) -> bytes:
    """The challenge in the coordinator's answer to our join request ``nonce``."""
    s = unseal(data, "challenge", campaign, key_for=lambda sender, run: coordinator, sender=COORDINATOR)
    if _bytes(s.fields, "nonce", NONCE_BYTES) != nonce or _name(s.fields, "island") != island:
        raise MessageRejected("replay", "a challenge for another join request")
    return _bytes(s.fields, "challenge", NONCE_BYTES)


@dataclass(frozen=True)
class Proof:
    """The second step: the request again with the coordinator's challenge, the proof that the island
    holds the admission secret and its signature with the key it registers (it holds that key too)."""

    request: JoinRequest
    challenge: bytes
    proof: bytes
    signature: bytes


def encode_prove(r: JoinRequest, challenge: bytes, admission: bytes, key: bytes) -> bytes:
    """Proof of the admission secret of the request's member (:func:`island.sealing.prove`) and of the run's private ``key``."""
    transcript = r.transcript(challenge)
    return _dumps({**_request_fields(r, "prove"), "challenge": challenge, "proof": prove(admission, transcript), "sig": sign(key, transcript)})


def decode_join_step(data: bytes, campaign: str, sender: str | None = None) -> JoinRequest | Proof:
    """A message on ``join/<id>``: a request (the first step) or a proof (the second)."""
    msg = _unpack(data, "join", campaign, types=("join", "prove"))
    request = _request(msg, campaign, sender)
    if msg["type"] == "join":
        return request
    return Proof(request, _bytes(msg, "challenge", NONCE_BYTES), _bytes(msg, "proof", KEY_BYTES), _bytes(msg, "sig", SIGNATURE_BYTES))


def proof_holds(p: Proof, admission: bytes) -> bool:
    """Whether ``p`` proves ``admission`` (the admission secret of the member it names) and the private half of the key it registers."""
    transcript = p.request.transcript(p.challenge)
    return proven(admission, transcript, p.proof) and verify(p.request.key, p.signature, transcript)


def encode_joined(campaign: str, nonce: bytes, island: str, run: str, coordinator_run: str, key: bytes, refused: str = "") -> bytes:
    """The coordinator's answer to a proof: the run id it issued, or why it refuses; signed."""
    return seal("joined", campaign, COORDINATOR, coordinator_run, 0, {"island": island, "nonce": nonce, "run": run, "refused": refused[:MAX_TEXT]}, key)


def decode_joined(data: bytes, campaign: str, island: str, nonce: bytes, coordinator: bytes) -> str:
    """The run id in the coordinator's answer to our proof; a refusal (signed: only the coordinator can refuse)
    is a :class:`HysidInputError` with its reason."""
    s = unseal(data, "joined", campaign, key_for=lambda sender, run: coordinator, sender=COORDINATOR)
    if _bytes(s.fields, "nonce", NONCE_BYTES) != nonce or _name(s.fields, "island") != island:
        raise MessageRejected("replay", "answer to another join request")
    refused = _text(s.fields, "refused")
    if refused:
        raise HysidInputError(f"the coordinator of campaign {campaign!r} refused island {island!r}: {refused}")
    return _name(s.fields, "run")
