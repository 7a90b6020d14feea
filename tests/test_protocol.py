"""Campaign messages: round trips and strict rejection of bad input (island/protocol.py)."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest

from hysid_model.errors import HysidInputError
from hysid_model.synth import synth_loops
from island.config import CampaignConfig, decode_config, encode_config
from island.migration import Migration, in_neighbours
from island.protocol import (
    MAX_BYTES,
    Best,
    History,
    MessageRejected,
    Migrants,
    decode_best,
    decode_history,
    decode_migrants,
    decode_stop,
    encode_best,
    encode_history,
    encode_migrants,
    encode_stop,
    pack_array,
)

BOUNDS = np.array([[0.0, 0.1], [-10.0, 10.0], [100.0, 500.0], [-1e4, 1e4]])
X = np.array([[0.0042, -0.4, 189.1239, -1256.64], [0.01, 1.0, 200.0, 0.0]])


def migrants(**change) -> Migrants:
    fields = dict(campaign="c1", island="ga-0", run="r1", iteration=10, x=X, claimed=np.array([1e-6, 2e-3]), sent_at=1.5)
    fields.update(change)
    return Migrants(**fields)


def raw(msg_type: str = "migrants", **fields) -> bytes:
    base = {"v": 1, "type": msg_type, "campaign": "c1", "island": "ga-0", "run": "r1", "iteration": 3,
            "x": pack_array(X), "claimed": pack_array(np.array([0.1, 0.2])), "sent_at": 0.0}
    base.update(fields)
    return msgpack.packb({k: v for k, v in base.items() if v is not ...}, use_bin_type=True)


def reason(data: bytes, **kw) -> str:
    with pytest.raises(MessageRejected) as info:
        decode_migrants(data, "c1", BOUNDS, **kw)
    return info.value.reason


def test_migrants_round_trip_keeps_vectors_and_claims():
    m = decode_migrants(encode_migrants(migrants()), "c1", BOUNDS, sender="ga-0")
    np.testing.assert_array_equal(m.x, X)
    np.testing.assert_array_equal(m.claimed, [1e-6, 2e-3])
    assert (m.island, m.run, m.iteration, m.sent_at) == ("ga-0", "r1", 10, 1.5)


@pytest.mark.parametrize(
    "data, expected",
    [
        (b"\xc1\x00\x01", "undecodable"),
        (b"", "undecodable"),
        (msgpack.packb([1, 2, 3]), "schema"),
        (raw(v=2), "version"),
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
        (msgpack.packb({"v": 1, "type": "migrants", "campaign": "c1", "x": msgpack.ExtType(5, b"xx")}), "schema"),
        (msgpack.packb({1: 2}), "undecodable"),
    ],
)
def test_bad_migrant_messages_are_rejected_with_a_reason(data, expected):
    assert reason(data) == expected


def test_migrants_sent_under_another_islands_key_are_rejected():
    assert reason(encode_migrants(migrants()), sender="pso-1") == "sender"


def test_too_many_migrants_is_oversized_before_anything_else_is_read():
    many = np.tile(X[:1], (300, 1))
    assert reason(encode_migrants(migrants(x=many, claimed=np.zeros(300)))) == "oversized"


def test_rejection_is_a_one_line_hysid_input_error():
    with pytest.raises(HysidInputError) as info:
        decode_migrants(raw(claimed=pack_array(np.array([np.nan, 1.0]))), "c1", BOUNDS)
    assert "\n" not in str(info.value) and "not_finite" in str(info.value)


def history(**change) -> History:
    fields = dict(
        campaign="c1", island="pso-1", run="r9", algo="pso", seed=4,
        rows=np.array([[0, 5.0, 100, 0.1], [1, 2.0, 200, 0.2]]), best_x=X[0], best_f=2.0,
        stats={"sent": 1, "received": 2, "taken": 1, "rejected": 0}, final=True,
    )
    fields.update(change)
    return History(**fields)


def test_history_round_trip():
    h = decode_history(encode_history(history()), "c1", BOUNDS, sender="pso-1")
    np.testing.assert_array_equal(h.rows, [[0, 5.0, 100, 0.1], [1, 2.0, 200, 0.2]])
    assert (h.algo, h.seed, h.final, h.stats["received"]) == ("pso", 4, True, 2)


def test_history_allows_an_infinite_best_but_not_nan_or_fractional_counts():
    decode_history(encode_history(history(rows=np.array([[0, np.inf, 10, 0.0]]), best_f=np.inf)), "c1", BOUNDS)
    for rows in ([[0, np.nan, 10, 0.0]], [[0, 1.0, 10.5, 0.0]], [[-1, 1.0, 10, 0.0]]):
        with pytest.raises(MessageRejected):
            decode_history(encode_history(history(rows=np.array(rows))), "c1", BOUNDS)
    with pytest.raises(MessageRejected, match="out_of_bounds"):
        decode_history(encode_history(history(best_x=np.array([1.0, 0, 200, 0]))), "c1", BOUNDS)


def test_config_round_trip_carries_the_loop_set_and_settings():
    loops = synth_loops(noise_pct=1.0, seed=3, n_points=20)
    config = CampaignConfig(
        name="c1", bounds={"xi0": (0.0, 0.1)}, algos=["pso"], options={"pso": {"population": 10, "iterations": 3}},
        migration=Migration(interval=2, k=3, topology="random", random_k=1), seed=7,
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
    b = decode_best(encode_best(Best("c1", "ga-0", X[0], 1e-9)), "c1", BOUNDS)
    assert b.fitness == 1e-9 and b.island == "ga-0"
    with pytest.raises(MessageRejected):
        decode_best(encode_best(Best("c1", "ga-0", X[0], np.nan)), "c1", BOUNDS)
    assert decode_stop(encode_stop("c1", "budget spent"), "c1") == "budget spent"
    with pytest.raises(MessageRejected):
        decode_stop(encode_stop("c2", "budget spent"), "c1")


def test_ring_takes_from_the_predecessor_and_survives_departures():
    members = ["a", "b", "c", "d"]
    assert [in_neighbours("ring", members, m, epoch=1, seed=0, random_k=1) for m in members] == [{"d"}, {"a"}, {"b"}, {"c"}]
    assert in_neighbours("ring", ["a", "c", "d"], "c", epoch=1, seed=0, random_k=1) == {"a"}
    assert in_neighbours("ring", ["b"], "b", epoch=1, seed=0, random_k=1) == set()


def test_full_and_random_topologies():
    members = [f"i{k}" for k in range(6)]
    assert in_neighbours("full", members, "i2", epoch=0, seed=0, random_k=2) == set(members) - {"i2"}
    draws = [in_neighbours("random", members, "i2", epoch=e, seed=5, random_k=2) for e in range(20)]
    assert all(len(d) == 2 and "i2" not in d for d in draws)
    assert len({frozenset(d) for d in draws}) > 1, "random neighbours must change between migrations"
    assert draws == [in_neighbours("random", members, "i2", epoch=e, seed=5, random_k=2) for e in range(20)]
