"""Faults with real processes, real Zenoh on loopback and real SQLite: killed and frozen islands,
a killed coordinator, floods of bad messages, forged migrants, two campaigns on one network.

Islands run the asynchronous PSO with a tiny swarm and an endless iteration budget, so a
campaign lasts until the coordinator's budget or time limit stops it.
"""

from __future__ import annotations

import json
import signal
import subprocess
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import msgpack
import numpy as np
import pytest
import zenoh

from coordinator.launch import free_port
from coordinator.store import Store
from hysid_model.synth import TRUE_PARAMS
from island.config import decode_config
from island.protocol import MAX_BYTES, Migrants, encode_migrants, pack_array
from island.session import open_session, session_config
from support import events, hysid, query, rows_of, wait_for

pytestmark = pytest.mark.slow  # processes, kills and restarts: the full suite runs these

ENDLESS = ["--algos", "pso", "--population", "20", "--initial", "40", "--iterations", "10000000", "--interval", "5", "--quiet"]
BOUNDS = np.array([[0.0, 0.1], [-10.0, 10.0], [100.0, 500.0], [-1e4, 1e4]])  # Table 5.4 (the Synth set's bounds)
TRUTH = np.array([TRUE_PARAMS[n] for n in ("xi0", "S_xi", "w0", "S_w")])


@pytest.fixture
def spawn() -> Iterator[Callable[..., subprocess.Popen]]:
    """Start processes; whatever is still running at the end is killed (only ours, by pid)."""
    started: list[subprocess.Popen] = []

    def start(*args: str) -> subprocess.Popen:
        p = subprocess.Popen(hysid(*args), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        started.append(p)
        return p

    yield start
    for p in started:
        if p.poll() is None:
            p.send_signal(signal.SIGCONT)
            p.kill()
        p.communicate(timeout=30)


def finished(p: subprocess.Popen, timeout: float = 90) -> dict:
    out, err = p.communicate(timeout=timeout)
    assert p.returncode == 0, err
    return json.loads(out) if out.strip() else {}


def coordinator(spawn, endpoint: str, campaign: str, db: Path, *extra: str) -> subprocess.Popen:
    return spawn("coordinator", "--listen", endpoint, "--campaign", campaign, "--db", str(db), "--out", str(db.parent / f"out-{campaign}"),
                 "--json", *ENDLESS, *extra)


def island(spawn, endpoint: str, campaign: str, name: str) -> subprocess.Popen:
    return spawn("island", "--connect", endpoint, "--campaign", campaign, "--id", name, "--quiet")


def test_a_killed_island_is_recorded_lost_and_the_campaign_finishes_with_the_rest(spawn, tmp_path):
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "k.sqlite"
    coord = coordinator(spawn, endpoint, "kill", db, "--min-islands", "3", "--budget", "150000", "--time-limit", "120")
    islands = {name: island(spawn, endpoint, "kill", name) for name in ("a", "b", "c")}
    wait_for(lambda: all(rows_of(db, n) > 20 for n in islands), 60, "every island's history")
    islands["b"].send_signal(signal.SIGKILL)
    doc = finished(coord)
    assert events(db, "b") == ["join", "lost"]
    assert events(db, "a") == events(db, "c") == ["join", "left"]
    assert {i["island"]: i["status"] for i in doc["islands"]} == {"a": "left", "b": "lost", "c": "left"}
    assert doc["settings"]["stop_reason"] == "budget of 150,000 evaluations spent"
    assert islands["a"].wait(30) == islands["c"].wait(30) == 0


def test_a_frozen_island_is_lost_within_3_s_and_back_after_sigcont(spawn, tmp_path):
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "s.sqlite"
    coord = coordinator(spawn, endpoint, "freeze", db, "--min-islands", "2", "--time-limit", "120")
    a, b = island(spawn, endpoint, "freeze", "a"), island(spawn, endpoint, "freeze", "b")
    wait_for(lambda: rows_of(db, "a") > 20 and rows_of(db, "b") > 20, 60, "both islands' history")
    b.send_signal(signal.SIGSTOP)
    lost_after = wait_for(lambda: events(db, "b")[-1:] == ["lost"], 10, "the frozen island to be marked lost")
    assert lost_after < 3.0
    rows_frozen = rows_of(db, "b")
    b.send_signal(signal.SIGCONT)
    wait_for(lambda: events(db, "b")[-1:] == ["back"], 20, "the island to come back")
    wait_for(lambda: rows_of(db, "b") > rows_frozen + 20, 20, "new history after SIGCONT")
    coord.send_signal(signal.SIGINT)  # Ctrl-C: the campaign stops and reports
    doc = finished(coord)
    assert doc["settings"]["stop_reason"] == "interrupted"
    assert events(db, "b") == ["join", "lost", "back", "left"] and events(db, "a") == ["join", "left"]
    assert a.wait(30) == b.wait(30) == 0


def contiguous(db: Path) -> dict[str, list[int]]:
    got: dict[str, list[int]] = {}
    for isl, it in query(db, "SELECT island, iteration FROM history ORDER BY island, iteration"):
        got.setdefault(isl, []).append(it)
    return got


def test_a_killed_coordinator_resumes_from_sqlite_without_losing_history(spawn, tmp_path):
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "r.sqlite"
    first = coordinator(spawn, endpoint, "resume", db, "--min-islands", "2")
    islands = [island(spawn, endpoint, "resume", n) for n in ("a", "b")]
    wait_for(lambda: rows_of(db, "a") > 30 and rows_of(db, "b") > 30, 60, "both islands' history")
    first.send_signal(signal.SIGKILL)
    first.communicate(timeout=30)
    before = contiguous(db)
    time.sleep(1.5)  # the islands go on iterating with nobody to hear them
    second = spawn("coordinator", "--listen", endpoint, "--campaign", "resume", "--db", str(db), "--resume",
                   "--out", str(tmp_path / "out2"), "--json", "--quiet", "--time-limit", "12")
    doc = finished(second)
    after = contiguous(db)
    for name in ("a", "b"):
        assert after[name][: len(before[name])] == before[name]  # nothing stored before the crash was lost
        assert after[name] == list(range(len(after[name])))  # and the rows missed while down were fetched
        assert len(after[name]) > len(before[name]) + 50
        assert events(db, name) == ["join", "join", "left"]  # joined, seen again by the resumed coordinator, left
    assert {i["island"] for i in doc["islands"]} == {"a", "b"}
    assert doc["evaluations"] >= sum(i["evaluations"] for i in doc["islands"])
    assert all(p.wait(30) == 0 for p in islands)


def bad_messages(n: int) -> list[tuple[str, bytes, str]]:
    """``n`` bad migrant messages (key suffix, payload, expected reason), cycling through kinds."""
    good = {"v": 1, "type": "migrants", "campaign": "flood", "island": "evil", "run": "r", "iteration": 1,
            "x": pack_array(TRUTH[None, :]), "claimed": pack_array(np.zeros(1)), "sent_at": 0.0}

    def variant(**change) -> bytes:
        return msgpack.packb({**good, **change}, use_bin_type=True)

    kinds = [
        (b"\xc1garbage", "undecodable"),
        (b"\x00" * (MAX_BYTES["migrants"] + 10), "oversized"),
        (variant(x="not an array"), "schema"),
        (msgpack.packb({k: v for k, v in good.items() if k != "claimed"}), "schema"),
        (variant(x=pack_array(np.array([[np.nan, 0.0, 200.0, 0.0]]))), "not_finite"),
        (variant(x=pack_array(np.array([[0.5, 0.0, 200.0, 0.0]]))), "out_of_bounds"),
        (variant(x=pack_array(np.zeros((1, 7)))), "shape"),
        (variant(campaign="other"), "campaign"),
        (variant(v=99), "version"),
        (variant(island="someone-else"), "sender"),
    ]
    return [("evil", *kinds[i % len(kinds)]) for i in range(n)]


def test_a_thousand_bad_migrant_messages_are_each_rejected_and_counted(spawn, tmp_path):
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "f.sqlite"
    coord = coordinator(spawn, endpoint, "flood", db, "--time-limit", "120")
    target = island(spawn, endpoint, "flood", "target")
    wait_for(lambda: rows_of(db, "target") > 20, 60, "the island's history")
    messages = bad_messages(1000)
    session = open_session(session_config("client", connect=[endpoint]), endpoint)
    try:
        publisher = session.declare_publisher("hysid/flood/migrants/evil", congestion_control=zenoh.CongestionControl.BLOCK)
        for _, payload, _ in messages:
            publisher.put(payload)
        wait_for(lambda: query(db, "SELECT count(*) FROM rejected")[0][0] >= 1000, 60, "the coordinator to reject all")
        wait_for(lambda: query(db, "SELECT max(rejected) FROM islands WHERE island = 'target'")[0][0] == 1000, 60, "the island to count all")
        rows = rows_of(db, "target")
        wait_for(lambda: rows_of(db, "target") > rows + 20, 30, "the island to keep going")
    finally:
        session.close()
    assert target.poll() is None and coord.poll() is None
    expected: dict[str, int] = {}
    for _, _, reason in messages:
        expected[reason] = expected.get(reason, 0) + 1
    assert dict(query(db, "SELECT reason, count(*) FROM rejected GROUP BY reason")) == expected
    assert query(db, "SELECT count(*) FROM migrations WHERE island = 'evil'")[0][0] == 0
    coord.send_signal(signal.SIGINT)
    assert finished(coord)["migrations"]["rejected_reasons"] == expected


def forged(x: np.ndarray, claimed: float) -> bytes:
    return encode_migrants(Migrants("forge", "forger", "f", 1, x[None, :], np.array([claimed]), 0.0))


def test_a_forged_migrant_claiming_fitness_zero_becomes_the_best_only_if_it_earns_it(spawn, tmp_path):
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "g.sqlite"
    coord = coordinator(spawn, endpoint, "forge", db, "--topology", "full", "--time-limit", "120")
    target = island(spawn, endpoint, "forge", "target")
    wait_for(lambda: rows_of(db, "target") > 0, 60, "the island's history")
    config, loops = decode_config(Store(db).campaign("forge")[1], "forge")
    objective = config.objective(loops)  # the coordinator's own objective
    bad = BOUNDS[:, 1].copy()
    session = open_session(session_config("client", connect=[endpoint]), endpoint)
    token = session.liveliness().declare_token("hysid/forge/members/forger")  # a member: the island takes from it
    try:
        publisher = session.declare_publisher("hysid/forge/migrants/forger", congestion_control=zenoh.CongestionControl.BLOCK)
        for _ in range(40):
            publisher.put(forged(bad, 0.0))
        wait_for(lambda: query(db, "SELECT count(*) FROM migrations WHERE island = 'forger'")[0][0] == 40, 20, "all forgeries seen")
        wait_for(lambda: query(db, "SELECT max(received) FROM islands WHERE island = 'target'")[0][0] > 0, 20, "the island to re-evaluate some")
        (best_x, best_f), = query(db, "SELECT x, fitness FROM best")
        x = np.frombuffer(best_x, dtype="<f8")
        assert best_f > 0 and not np.allclose(x, bad)
        assert best_f == pytest.approx(objective(x[None, :])[0], rel=1e-12)  # the coordinator's own evaluation
        assert query(db, "SELECT max(taken), min(best_fitness) > 0 FROM islands WHERE island = 'target'")[0] == (0, 1)
        for _ in range(5):  # the truth (fitness ~1e-30, beyond what the young island has found) under the same lie
            publisher.put(forged(TRUTH, 0.0))
        wait_for(lambda: query(db, "SELECT island FROM best")[0][0] == "forger", 20, "the earned best")
        wait_for(lambda: query(db, "SELECT max(taken) FROM islands WHERE island = 'target'")[0][0] > 0, 20, "the island to take it")
        (holder, best_x, best_f), = query(db, "SELECT island, x, fitness FROM best")
        x = np.frombuffer(best_x, dtype="<f8")
        assert best_f == objective(x[None, :])[0] <= objective(TRUTH[None, :])[0]  # earned, by the coordinator's count
        if holder == "forger":  # else the island, having taken the truth, has since polished it further
            np.testing.assert_array_equal(x, TRUTH)
    finally:
        token.undeclare()
        session.close()
    assert target.poll() is None
    coord.send_signal(signal.SIGINT)
    doc = finished(coord)
    assert doc["fitness"] <= objective(TRUTH[None, :])[0]


def test_two_campaigns_on_one_network_do_not_cross_talk(spawn, tmp_path):
    port_a, port_b = free_port(), free_port()
    ep_a, ep_b = f"tcp/127.0.0.1:{port_a}", f"tcp/127.0.0.1:{port_b}"
    db_a, db_b = tmp_path / "a.sqlite", tmp_path / "b.sqlite"
    coord_a = coordinator(spawn, ep_a, "alpha", db_a, "--budget", "60000", "--time-limit", "120")
    coord_b = coordinator(spawn, ep_b, "beta", db_b, "--connect", ep_a, "--noise", "5", "--budget", "60000", "--time-limit", "120")
    island(spawn, ep_a, "alpha", "same-name")
    island(spawn, ep_b, "beta", "same-name")
    session = open_session(session_config("client", connect=[ep_a]), ep_a)
    try:  # one network: beta's coordinator answers a query sent to alpha's router
        wait_for(lambda: any(r.ok is not None for r in session.get("hysid/beta/config", timeout=2)), 30, "beta reachable via alpha")
    finally:
        session.close()
    doc_a, doc_b = finished(coord_a), finished(coord_b)
    for db, doc in ((db_a, doc_a), (db_b, doc_b)):
        assert [i["island"] for i in doc["islands"]] == ["same-name"]  # one run each: nothing from the other campaign
        assert query(db, "SELECT count(*) FROM rejected")[0][0] == 0
        assert events(db, "same-name") == ["join", "left"]
    assert doc_a["dataset"]["name"] != doc_b["dataset"]["name"]
