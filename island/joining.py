"""How an island comes into a campaign over Zenoh: the campaign's key space (:func:`key_prefix`), the coordinator's
``config`` message (:func:`fetch_config`) and the join handshake (:func:`join`, its messages in
:mod:`island.handshake`). Queries go to every queryable and every answer is checked against the coordinator's key in
the campaign secret (:mod:`island.secret`): a stranger that answers first changes nothing."""

from __future__ import annotations

import secrets
import time
from collections.abc import Callable
from typing import TypeVar

import zenoh

from hysid_model.errors import HysidInputError
from island.handshake import JoinRequest, decode_challenge, decode_joined, encode_join, encode_prove
from island.protocol import decode_signed_config
from island.sealing import Credentials, new_key, public_key
from island.secret import CampaignSecret
from island.wire import MessageRejected, check_name

QUERY_TIMEOUT_S = 5.0


_Answer = TypeVar("_Answer", str, bytes)
"""What an answer to a join step decodes to: the challenge (bytes) or the run id (str)."""


def key_prefix(campaign: str) -> str:
    """The key space of ``campaign``: ``hysid/<campaign>``."""
    return f"hysid/{check_name('campaign', campaign)}"


def replies(session: zenoh.Session, selector: str, timeout: float, payload: bytes | None = None) -> list[bytes]:
    """Every answer to a query, from every queryable (a stranger may answer too: the caller checks each)."""
    got = session.get(selector, payload=payload, timeout=timeout, target=zenoh.QueryTarget.ALL, consolidation=zenoh.ConsolidationMode.NONE)
    return [r.ok.payload.to_bytes() for r in got if r.ok is not None]


def join(
    session: zenoh.Session,
    campaign: str,
    island: str,
    algo: str,
    seed: int,
    secret: CampaignSecret,
    wait_s: float,
    on_reject: Callable[[], None] | None = None,
    key: bytes | None = None,
) -> Credentials:
    """The join handshake on ``join/<id>`` (until the coordinator admits the island or ``wait_s`` passes): ask
    with the public half of the run's signing ``key`` (a fresh one by default), take the challenge signed
    by the coordinator of ``secret``, prove the admission secret, take the signed run id. Answers that
    fail validation (a stranger posing as the coordinator) are counted by ``on_reject``; a refusal by
    the coordinator (e.g. the id is taken) is a :class:`HysidInputError`."""
    key = key if key is not None else new_key()
    where = f"{key_prefix(campaign)}/join/{island}"
    deadline = time.monotonic() + wait_s
    timeout = min(QUERY_TIMEOUT_S, max(wait_s, 0.5))

    def answers(payload: bytes, decode: Callable[[bytes], _Answer]) -> _Answer | None:
        for answer in replies(session, where, timeout, payload):
            try:
                return decode(answer)
            except MessageRejected:
                if on_reject is not None:
                    on_reject()
        return None

    request = JoinRequest(campaign, island, algo, seed, secrets.token_bytes(16), public_key(key), secret.member)  # asked again as it is: one run
    while True:
        challenge = answers(encode_join(request), lambda a: decode_challenge(a, campaign, island, request.nonce, secret.coordinator))
        if challenge is not None:
            proof = encode_prove(request, challenge, secret.admission, key)
            run = answers(proof, lambda a: decode_joined(a, campaign, island, request.nonce, secret.coordinator))
            if run is not None:
                return Credentials(island, str(run), key, secret.coordinator)
        if time.monotonic() >= deadline:
            raise HysidInputError(f"no coordinator admitted island {island!r} on {where} within {wait_s:g} s")
        time.sleep(0.2)


def fetch_config(session: zenoh.Session, secret: CampaignSecret, wait_s: float, on_reject: Callable[[], None] | None = None) -> bytes:
    """The ``config`` message of the campaign of ``secret``, signed by its coordinator (answers of anyone
    else are refused, counted by ``on_reject``), asking until one answers or ``wait_s`` passes."""
    key = f"{key_prefix(secret.campaign)}/config"
    deadline = time.monotonic() + wait_s
    while True:
        for answer in replies(session, key, min(2.0, max(wait_s, 0.1))):
            try:
                return decode_signed_config(answer, secret.campaign, secret.coordinator)
            except MessageRejected:
                if on_reject is not None:
                    on_reject()
        if time.monotonic() >= deadline:
            raise HysidInputError(
                f"no coordinator answered on {key} within {wait_s:g} s (is the coordinator of campaign {secret.campaign!r} running and "
                "reachable, and is this its secret?)"
            )
        time.sleep(0.2)
