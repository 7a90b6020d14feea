"""Campaign messages: round trips, strict rejection of bad input, tags and replays (island/protocol.py, island_messages.py, coordinator_messages.py, sealing.py, wire.py)."""

from __future__ import annotations

import time

import msgpack
import numpy as np
import pytest

from hysid_model.errors import HysidInputError
from hysid_model.synth import synth_loops
from island.config import CampaignConfig, decode_config, encode_config
from island.coordinator_messages import (
    Best,
    Control,
    HistoryQuery,
    MemberState,
    decode_best,
    decode_control,
    decode_history_query,
    encode_best,
    encode_control,
    encode_history_query,
)
from island.handshake import (
    JoinRequest,
    Proof,
    decode_challenge,
    decode_join,
    decode_join_step,
    decode_joined,
    encode_challenge,
    encode_join,
    encode_joined,
    encode_prove,
    proof_holds,
)
from island.island_messages import History, Migrants, decode_history, decode_migrants, encode_history, encode_migrants
from island.migration import Migration, in_neighbours
from island.protocol import decode_signed_config, encode_signed_config
from island.sealing import Credentials, ReplayGuard, check_replay, new_key, public_key, seal
from island.secret import CampaignSecret
from island.wire import MAX_BYTES, PROTOCOL_VERSION, MessageRejected, pack_array

BOUNDS = np.array([[0.0, 0.1], [-10.0, 10.0], [100.0, 500.0], [-1e4, 1e4]])
X = np.array([[0.0042, -0.4, 189.1239, -1256.64], [0.01, 1.0, 200.0, 0.0]])
COORDINATOR_KEY = new_key()
SECRET = CampaignSecret.create("c1", public_key(COORDINATOR_KEY))
GA0 = Credentials("ga-0", "r1", new_key(), SECRET.coordinator)
PSO1 = Credentials("pso-1", "r9", new_key(), SECRET.coordinator)
RUN_KEYS = {("ga-0", "r1"): GA0.public, ("pso-1", "r9"): PSO1.public}
NOW = time.time()


def run_key(sender: str, run: str) -> bytes | None:
    """The roster's view (the coordinator's, and every island's): the public key of each run that joined."""
    return RUN_KEYS.get((sender, run))


def migrants(**change) -> Migrants:
    fields = dict(campaign="c1", island="ga-0", run="r1", iteration=10, x=X, claimed=np.array([1e-6, 2e-3]), sent_at=NOW)
    fields.update(change)
    return Migrants(**fields)


ENVELOPE = ("v", "type", "campaign", "island", "run", "seq")


def raw(msg_type: str = "migrants", **fields) -> bytes:
    """A migrant message of ga-0, correctly tagged, with any envelope or body field replaced (``...``: left out)."""
    base = {
        "v": PROTOCOL_VERSION,
        "type": msg_type,
        "campaign": "c1",
        "island": "ga-0",
        "run": "r1",
        "seq": 0,
        "iteration": 3,
        "x": pack_array(X),
        "claimed": pack_array(np.array([0.1, 0.2])),
        "sent_at": NOW,
    }
    base.update(fields)
    body = {k: v for k, v in base.items() if k not in ENVELOPE and v is not ...}
    packed_body = msgpack.packb(body, use_bin_type=True)
    sealed = msgpack.unpackb(seal("migrants", "c1", "ga-0", "r1", 0, body, GA0.key))
    envelope = {**sealed, "body": packed_body}
    for k in ENVELOPE:
        name = "sender" if k == "island" else k
        if base[k] is ...:
            envelope.pop(name)
        else:
            envelope[name] = base[k]
    return msgpack.packb(envelope, use_bin_type=True)


def reason(data: bytes, **kw) -> str:
    with pytest.raises(MessageRejected) as info:
        decode_migrants(data, "c1", BOUNDS, key_for=run_key, **kw)
    return info.value.reason


def test_migrants_round_trip_keeps_vectors_and_claims():
    m = decode_migrants(encode_migrants(migrants(seq=7), GA0), "c1", BOUNDS, key_for=run_key, sender="ga-0")
    np.testing.assert_array_equal(m.x, X)
    np.testing.assert_array_equal(m.claimed, [1e-6, 2e-3])
    assert (m.island, m.run, m.iteration, m.sent_at, m.seq) == ("ga-0", "r1", 10, NOW, 7)


@pytest.mark.parametrize(
    "data, expected",
    [
        (b"\xc1\x00\x01", "undecodable"),
        (b"", "undecodable"),
        (msgpack.packb([1, 2, 3]), "schema"),
        (raw(v=1), "version"),
        (raw(campaign="other"), "campaign"),
        (raw(msg_type="history"), "schema"),
        (raw(island="no/slash"), "schema"),
        (raw(island=...), "schema"),
        (raw(iteration=-1), "schema"),
        (raw(iteration=True), "schema"),
        (raw(iteration="7"), "schema"),
        (raw(x=[[0.0042, -0.4, 189.0, -1256.0]]), "schema"),
        (raw(x={"shape": [1, 3], "data": np.zeros(3).tobytes()}), "shape"),
        (raw(x={"shape": [2, 4], "data": np.zeros(7).tobytes()}), "shape"),
        (raw(x={"shape": [0, 4], "data": b""}, claimed=pack_array(np.zeros(0))), "shape"),
        (raw(claimed=pack_array(np.array([0.1]))), "shape"),
        (raw(x=pack_array(np.array([[np.nan, 0.0, 200.0, 0.0]])), claimed=pack_array(np.array([0.0]))), "not_finite"),
        (raw(claimed=pack_array(np.array([np.inf, 0.1]))), "not_finite"),
        (raw(claimed=pack_array(np.array([-1.0, 0.1]))), "schema"),
        (raw(x=pack_array(np.array([[0.2, 0.0, 200.0, 0.0]])), claimed=pack_array(np.array([0.0]))), "out_of_bounds"),
        (raw(x=pack_array(np.array([[0.05, 0.0, 99.0, 0.0]])), claimed=pack_array(np.array([0.0]))), "out_of_bounds"),
        (b"\x00" * (MAX_BYTES["migrants"] + 1), "oversized"),
        (raw(x=msgpack.ExtType(5, b"xx")), "schema"),
        (msgpack.packb({1: 2}), "undecodable"),
        # hostile values that once crashed every receiver
        (raw(x={"shape": [2**62, 4], "data": b""}), "shape"),
        (raw(x={"shape": [2**32, 2**32], "data": b""}), "shape"),
        (raw(x={"shape": [2, 4] * 1000, "data": b""}), "shape"),
        (raw(sent_at=float("nan")), "not_finite"),
        (raw(sent_at=float("inf")), "not_finite"),
        (raw(sent_at=2**63), "schema"),
        # send times no island's clock shows: before 2020, or more than a day ahead
        (raw(sent_at=1e308), "out_of_range"),
        (raw(sent_at=-1e308), "out_of_range"),
        (raw(sent_at=0.0), "out_of_range"),
        (raw(sent_at=-1.0), "out_of_range"),
        (raw(sent_at=NOW + 2 * 86400), "out_of_range"),
        (raw(claimed=pack_array(np.array([1e300, 0.1]))), "out_of_range"),
        (raw(iteration=2**63), "schema"),
        (raw(iteration=2**64 - 1), "schema"),
        (raw(iteration=2**53 + 1), "schema"),
        (raw(claimed=pack_array(np.array([1e300, np.nan]))), "not_finite"),
        (raw(x=pack_array(np.array([[1e300, 0.0, 200.0, 0.0]])), claimed=pack_array(np.array([0.0]))), "out_of_bounds"),
        (raw(seq=-1), "schema"),
        (raw(seq=2**64 - 1), "schema"),
        (raw(run="a" * 65), "schema"),
    ],
)
def test_bad_migrant_messages_are_rejected_with_a_reason(data, expected):
    assert reason(data) == expected


def test_migrants_sent_under_another_islands_key_are_rejected():
    assert reason(encode_migrants(migrants(), GA0), sender="pso-1") == "sender"


def test_a_message_verifies_only_under_its_sender_runs_own_key():
    """Coordinator and islands alike check a migrant message with the public key the roster lists for
    its sender's run: a member cannot sign as another, a stranger's run is unknown, a number cannot be changed."""
    impostor = Credentials("ga-0", "r1", PSO1.key, SECRET.coordinator)  # island ga-0's name and run, pso-1's (a member's) key
    assert reason(encode_migrants(migrants(), impostor)) == "forged"
    assert reason(encode_migrants(migrants(island="stranger", run="s1"), Credentials("stranger", "s1", new_key(), SECRET.coordinator))) == "unjoined"
    tampered = msgpack.unpackb(encode_migrants(migrants(), GA0))
    tampered["seq"] = 2**63 - 1  # the number is under the signature: a replay cannot be renumbered, nor a window pushed
    assert reason(msgpack.packb(tampered)) == "forged"
    tampered["sig"] = b"\x00" * 64
    assert reason(msgpack.packb(tampered)) == "forged"


def test_a_forged_number_cannot_block_the_real_sender():
    """The replay window is only shown messages whose signature verified: a forgery numbered 2**63-1
    under a victim's name is rejected as forged and the victim's next message still counts."""
    guard = ReplayGuard()
    forged = encode_migrants(migrants(seq=2**63 - 1), Credentials("ga-0", "r1", PSO1.key, SECRET.coordinator))
    for data in (forged, encode_migrants(migrants(seq=0), GA0), encode_migrants(migrants(seq=1), GA0)):
        try:
            m = decode_migrants(data, "c1", BOUNDS, key_for=run_key)
        except MessageRejected as exc:
            assert exc.reason == "forged"
            continue
        check_replay(guard, "migrants", m.island, m.run, m.seq)
    assert not guard.fresh(("migrants", "ga-0", "r1"), 1) and guard.fresh(("migrants", "ga-0", "r1"), 2)


def test_replays_are_dropped_also_out_of_order_within_the_window():
    guard = ReplayGuard(window=8)
    assert [guard.fresh(("m", "a", "r"), s) for s in (0, 2, 1, 2, 0)] == [True, True, True, False, False]
    assert guard.fresh(("m", "b", "r"), 0) and guard.fresh(("m", "a", "r2"), 0)  # per sender run
    assert guard.fresh(("m", "a", "r"), 100) and not guard.fresh(("m", "a", "r"), 90)  # older than the window
    with pytest.raises(MessageRejected, match="replay"):
        check_replay(guard, "m", "a", "r", 100)


def test_too_many_migrants_is_oversized_before_anything_else_is_read():
    many = np.tile(X[:1], (300, 1))
    assert reason(encode_migrants(migrants(x=many, claimed=np.zeros(300)), GA0)) == "oversized"


def test_rejection_is_a_one_line_hysid_input_error():
    with pytest.raises(HysidInputError) as info:
        decode_migrants(raw(claimed=pack_array(np.array([np.nan, 1.0]))), "c1", BOUNDS, key_for=run_key)
    assert "\n" not in str(info.value) and "not_finite" in str(info.value)


def history(**change) -> History:
    fields = dict(
        campaign="c1",
        island="pso-1",
        run="r9",
        algo="pso",
        seed=4,
        rows=np.array([[0, 5.0, 100, 0.1], [1, 2.0, 200, 0.2]]),
        best_x=X[0],
        best_f=2.0,
        stats={"sent": 1, "received": 2, "taken": 1, "rejected": 0},
        final=True,
    )
    fields.update(change)
    return History(**fields)


def history_of(h: History) -> History:
    return decode_history(encode_history(h, PSO1), "c1", BOUNDS, key_for=run_key, sender="pso-1")


def test_history_round_trip():
    h = history_of(history())
    np.testing.assert_array_equal(h.rows, [[0, 5.0, 100, 0.1], [1, 2.0, 200, 0.2]])
    assert (h.algo, h.seed, h.final, h.stats["received"]) == ("pso", 4, True, 2)


def test_history_allows_an_infinite_best_only_before_the_first_row_and_no_nan_or_fractional_counts():
    history_of(history(rows=np.zeros((0, 4)), best_f=np.inf))  # an island that has not finished its first iteration
    for rows in ([[0, np.nan, 10, 0.0]], [[0, 1.0, 10.5, 0.0]], [[-1, 1.0, 10, 0.0]]):
        with pytest.raises(MessageRejected):
            history_of(history(rows=np.array(rows)))
    with pytest.raises(MessageRejected, match="out_of_bounds"):
        history_of(history(best_x=np.array([1.0, 0, 200, 0])))


@pytest.mark.parametrize(
    "change, expected",
    [
        ({"rows": np.array([[0, 5.0, 1e300, 0.1]])}, "schema"),  # a count no float64 holds exactly
        ({"rows": np.array([[2.0**62, 5.0, 100, 0.1]])}, "schema"),
        ({"rows": np.array([[0, 5.0, 100, np.inf]])}, "not_finite"),
        ({"rows": np.array([[0, np.inf, 100, 0.1]]), "best_f": np.inf}, "out_of_range"),
        ({"rows": np.array([[0, 1e300, 100, 0.1]]), "best_f": 1e300}, "out_of_range"),
        ({"best_f": np.inf}, "out_of_range"),
        ({"rows": np.array([[0, 5.0, 100, 0.2], [1, 4.0, 200, 0.1]])}, "implausible"),  # wall time that falls
        ({"rows": np.array([[1, 5.0, 100, 0.1], [0, 6.0, 50, 0.0]])}, "implausible"),  # iterations must rise
        ({"rows": np.array([[0, 5.0, 100, 0.1], [1, 6.0, 200, 0.2]])}, "implausible"),  # a best that worsens
        ({"rows": np.array([[0, 5.0, 100, 0.1], [1, 4.0, 90, 0.2]])}, "implausible"),  # evaluations that fall
        ({"best_f": float("nan")}, "not_finite"),
        ({"best_f": -1.0}, "schema"),
        ({"seed": 2**63}, "schema"),
        ({"stats": {"sent": 2**63, "received": 0, "taken": 0, "rejected": 0}}, "schema"),
        ({"stats": {"sent": 1, "received": 0, "taken": 0}}, "schema"),
        ({"algo": "GA; DROP TABLE"}, "schema"),
    ],
)
def test_hostile_history_values_are_rejected_not_raised(change, expected):
    data = encode_history(history(**change), PSO1) if "stats" not in change and "seed" not in change else None
    if data is None:  # values the encoder itself would refuse: build the body by hand
        fields = {
            "algo": "pso",
            "seed": 4,
            "rows": pack_array(np.array([[0, 5.0, 100, 0.1]])),
            "best_x": pack_array(X[0]),
            "best_f": 2.0,
            "stats": {"sent": 1, "received": 2, "taken": 1, "rejected": 0},
            "final": True,
            **change,
        }
        data = seal("history", "c1", "pso-1", "r9", 0, fields, PSO1.key)
    with pytest.raises(MessageRejected) as info:
        decode_history(data, "c1", BOUNDS, key_for=run_key, sender="pso-1")
    assert info.value.reason == expected


def test_history_of_a_run_that_never_joined_is_rejected():
    with pytest.raises(MessageRejected, match="unjoined"):
        decode_history(
            encode_history(history(island="ghost", run="g1"), Credentials("ghost", "g1", new_key(), SECRET.coordinator)), "c1", BOUNDS, key_for=run_key
        )


def test_config_round_trip_carries_the_loop_set_and_settings():
    loops = synth_loops(noise_pct=1.0, seed=3, n_points=20)
    config = CampaignConfig(
        name="c1",
        bounds={"xi0": (0.0, 0.1)},
        algos=["pso"],
        options={"pso": {"population": 10, "iterations": 3}},
        migration=Migration(interval=2, k=3, topology="random", random_k=1),
        seed=7,
    )
    got, got_loops = decode_config(encode_config(config, loops), "c1")
    assert got.as_dict() == config.as_dict()
    np.testing.assert_array_equal(got_loops.top, loops.top)
    np.testing.assert_array_equal(got_loops.sigma, loops.sigma)
    assert got_loops.labels == loops.labels and got_loops.meq_kg == loops.meq_kg
    assert got_loops.meta["true_params"] == loops.meta["true_params"]
    objective = got.objective(got_loops)
    assert objective.model.bounds[0].tolist() == [0.0, 0.1]


def test_config_with_a_broken_loop_set_is_rejected():
    loops = synth_loops(n_points=10)
    data = msgpack.unpackb(encode_config(CampaignConfig(name="c1"), loops))
    data["loops"]["x0"] = pack_array(np.full(loops.n_loops, -1.0))
    with pytest.raises(MessageRejected, match="positive amplitude"):
        decode_config(msgpack.packb(data), "c1")
    with pytest.raises(MessageRejected) as info:
        decode_config(encode_config(CampaignConfig(name="c1"), loops), "c2")
    assert info.value.reason == "campaign"


@pytest.mark.parametrize(
    "change",
    [{"name": "bad name"}, {"weights": "nope"}, {"algos": []}, {"algos": ["cmaes"]}, {"options": {"de": {}}}, {"seed": -1}, {"objective_kind": "fast"}],
)
def test_invalid_campaign_settings_raise_input_errors(change):
    with pytest.raises(HysidInputError):
        CampaignConfig(**{"name": "c1", **change})


@pytest.mark.parametrize("change", [{"interval": -1}, {"k": 0}, {"topology": "star"}, {"random_k": 10_000}])
def test_invalid_migration_settings_raise_input_errors(change):
    with pytest.raises(HysidInputError):
        Migration(**change)


def test_best_and_stop_round_trip_and_validate():
    b = decode_best(encode_best(Best("c1", "ga-0", X[0], 1e-9), "coord", COORDINATOR_KEY), "c1", BOUNDS, SECRET.coordinator)
    assert b.fitness == 1e-9 and b.island == "ga-0"
    with pytest.raises(MessageRejected):
        decode_best(encode_best(Best("c1", "ga-0", X[0], np.nan), "coord", COORDINATOR_KEY), "c1", BOUNDS, SECRET.coordinator)
    with pytest.raises(MessageRejected, match="forged"):  # a best from anyone but the coordinator
        decode_best(encode_best(Best("c1", "ga-0", X[0], 1e-9), "coord", GA0.key), "c1", BOUNDS, SECRET.coordinator)
    control = Control(
        "c1", (MemberState("ga-0", "r1", True, 41, "ga", GA0.public), MemberState("pso-1", "r9", False, -1, "pso", PSO1.public)), "budget spent", 5
    )
    message = encode_control(control, "coord", COORDINATOR_KEY)
    assert decode_control(message, "c1", SECRET.coordinator) == control
    with pytest.raises(MessageRejected):
        decode_control(message, "c2", SECRET.coordinator)
    with pytest.raises(MessageRejected, match="forged"):  # a stop order only counts with the coordinator's signature: no member's
        decode_control(encode_control(control, "coord", GA0.key), "c1", SECRET.coordinator)


def test_config_is_taken_only_with_the_coordinators_signature():
    message = encode_config(CampaignConfig(name="c1"), synth_loops(n_points=10))
    assert decode_signed_config(encode_signed_config(message, "c1", "coord", COORDINATOR_KEY), "c1", SECRET.coordinator) == message
    with pytest.raises(MessageRejected, match="forged"):
        decode_signed_config(encode_signed_config(message, "c1", "coord", new_key()), "c1", SECRET.coordinator)
    with pytest.raises(MessageRejected):  # unsigned, as a stranger would serve it
        decode_signed_config(message, "c1", SECRET.coordinator)


def test_join_handshake_is_a_challenge_response_that_proves_the_secret_without_sending_it():
    key = new_key()
    request = JoinRequest("c1", "ga-0", "ga", 3, b"n" * 16, public_key(key))
    assert decode_join(encode_join(request), "c1", sender="ga-0") == request == decode_join_step(encode_join(request), "c1", "ga-0")
    with pytest.raises(MessageRejected, match="sender"):
        decode_join(encode_join(request), "c1", sender="pso-1")
    challenge = decode_challenge(
        encode_challenge("c1", "ga-0", request.nonce, b"c" * 16, "coord", COORDINATOR_KEY), "c1", "ga-0", request.nonce, SECRET.coordinator
    )
    with pytest.raises(MessageRejected, match="forged"):  # a stranger answering the request
        decode_challenge(encode_challenge("c1", "ga-0", request.nonce, b"c" * 16, "coord", new_key()), "c1", "ga-0", request.nonce, SECRET.coordinator)
    with pytest.raises(MessageRejected, match="replay"):  # the answer to another request
        decode_challenge(encode_challenge("c1", "ga-0", b"o" * 16, b"c" * 16, "coord", COORDINATOR_KEY), "c1", "ga-0", request.nonce, SECRET.coordinator)
    proof = encode_prove(request, challenge, SECRET.admission, key)
    assert SECRET.admission not in proof and SECRET.admission.hex().encode() not in proof
    step = decode_join_step(proof, "c1", "ga-0")
    assert isinstance(step, Proof) and step.request == request and step.challenge == challenge and proof_holds(step, SECRET.admission)
    assert not proof_holds(decode_join_step(encode_prove(request, challenge, b"w" * 32, key), "c1"), SECRET.admission)  # not the secret
    assert not proof_holds(decode_join_step(encode_prove(request, challenge, SECRET.admission, new_key()), "c1"), SECRET.admission)  # not its key
    answer = encode_joined("c1", request.nonce, "ga-0", "r1", "coord", COORDINATOR_KEY)
    assert decode_joined(answer, "c1", "ga-0", request.nonce, SECRET.coordinator) == "r1"
    with pytest.raises(MessageRejected, match="replay"):  # an answer to another request
        decode_joined(answer, "c1", "ga-0", b"o" * 16, SECRET.coordinator)
    with pytest.raises(MessageRejected, match="forged"):  # credentials from a stranger posing as the coordinator
        decode_joined(encode_joined("c1", request.nonce, "ga-0", "r1", "coord", new_key()), "c1", "ga-0", request.nonce, SECRET.coordinator)
    with pytest.raises(HysidInputError, match="refused island 'ga-0': id taken"):
        decode_joined(
            encode_joined("c1", request.nonce, "ga-0", "x", "coord", COORDINATOR_KEY, refused="id taken"), "c1", "ga-0", request.nonce, SECRET.coordinator
        )


def test_history_queries_are_taken_only_with_the_coordinators_signature():
    query = HistoryQuery("c1", "ga-0", "r1", 20, 7)
    params = dict(p.split("=", 1) for p in encode_history_query(query, COORDINATOR_KEY).split(";"))
    assert decode_history_query(params, "c1", "ga-0", SECRET.coordinator) == query
    for change in ({"since": "-1"}, {"seq": "8"}, {"run": "r2"}, {"sig": "00" * 64}, {"sig": "zz"}, {"since": "1e300"}, {"run": "a/b"}):
        with pytest.raises(MessageRejected):
            decode_history_query({**params, **change}, "c1", "ga-0", SECRET.coordinator)
    with pytest.raises(MessageRejected, match="forged"):  # the same query, for another island
        decode_history_query(params, "c1", "pso-1", SECRET.coordinator)


def test_the_campaign_secret_round_trips_as_one_line_and_bad_ones_are_one_line_errors(tmp_path):
    path = SECRET.write(tmp_path / "c.secret")
    assert oct(path.stat().st_mode & 0o777) == "0o600" and len(path.read_text().splitlines()) == 1
    assert CampaignSecret.read(path) == SECRET == CampaignSecret.parse(SECRET.text(), "env")
    for text, words in (
        ("", "not a hysid campaign secret"),
        ("hysid-secret 9 c1 00 00", "format '9'"),
        (SECRET.text()[:-2], "32 bytes"),
        (SECRET.text().replace(" c1 ", " a/b "), "no valid campaign"),
    ):
        with pytest.raises(HysidInputError, match=words):
            CampaignSecret.parse(text, "env")
    with pytest.raises(HysidInputError, match="campaign 'c1''s, not 'c2''s"):
        SECRET.check_campaign("c2", "env")


def test_config_with_hostile_metadata_or_labels_is_rejected():
    loops = synth_loops(n_points=10)
    good = msgpack.unpackb(encode_config(CampaignConfig(name="c1"), loops))
    nested: list = []
    for _ in range(60):
        nested = [nested]
    for change in (
        {"meta": {"deep": nested}},
        {"labels": [nested] * loops.n_loops},
        {"meq_kg": float("nan")},
        {"meq_kg": 2**64 - 1},
        {"cycles": [2**64 - 1] * loops.n_loops},
        {"meta": {"x": float("inf")}},
    ):
        data = msgpack.unpackb(msgpack.packb(good))
        data["loops"].update(change)
        with pytest.raises(MessageRejected):
            decode_config(msgpack.packb(data), "c1")


def test_ring_takes_from_the_predecessor_and_survives_departures():
    members = ["a", "b", "c", "d"]
    assert [in_neighbours("ring", members, m, epoch=1, seed=0, random_k=1) for m in members] == [{"d"}, {"a"}, {"b"}, {"c"}]
    assert in_neighbours("ring", ["a", "c", "d"], "c", epoch=1, seed=0, random_k=1) == {"a"}
    assert in_neighbours("ring", ["b"], "b", epoch=1, seed=0, random_k=1) == set()
    assert in_neighbours("ring", ["c", "a", "b"], "a", epoch=1, seed=0, random_k=1) == {"c"}  # the order they joined in, not by name


def test_full_and_random_topologies():
    members = [f"i{k}" for k in range(6)]
    assert in_neighbours("full", members, "i2", epoch=0, seed=0, random_k=2) == set(members) - {"i2"}
    draws = [in_neighbours("random", members, "i2", epoch=e, seed=5, random_k=2) for e in range(20)]
    assert all(len(d) == 2 and "i2" not in d for d in draws)
    assert len({frozenset(d) for d in draws}) > 1, "random neighbours must change between migrations"
    assert draws == [in_neighbours("random", members, "i2", epoch=e, seed=5, random_k=2) for e in range(20)]
