"""Faults with real processes, real Zenoh on loopback and real SQLite: killed and frozen islands,
a killed coordinator, floods of bad messages, forged migrants, two campaigns on one network.

Islands run the asynchronous PSO with a tiny swarm and an endless iteration budget, so a
campaign lasts until the coordinator's budget or time limit stops it.
"""

from __future__ import annotations

import json
import signal
import subprocess
import threading
import time
from pathlib import Path

import msgpack
import numpy as np
import pytest
import zenoh

from coordinator.launch import free_port
from coordinator.store import Store
from hysid_model.synth import TRUE_PARAMS
from island.config import decode_config
from island.island_messages import History, Migrants, encode_history, encode_migrants
from island.joining import fetch_config
from island.node import IslandNode
from island.sealing import Credentials, envelope, seal
from island.session import open_session, session_config
from island.transports import ZenohTransport
from island.wire import MAX_BYTES, MessageRejected, pack_array
from support import PSO_ISLANDS, Peer, coordinator_args, events, query, ready, rows_of, secret_file, secret_of, wait_for

pytestmark = pytest.mark.slow  # processes, kills and restarts: the full suite runs these

ENDLESS = [*PSO_ISLANDS, "--iterations", "10000000", "--interval", "5", "--quiet", "--no-figures"]  # the report, without its seconds of figures
BOUNDS = np.array([[0.0, 0.1], [-10.0, 10.0], [100.0, 500.0], [-1e4, 1e4]])  # Table 5.4 (the Synth set's bounds)
TRUTH = np.array([TRUE_PARAMS[n] for n in ("xi0", "S_xi", "w0", "S_w")])


def finished(p: subprocess.Popen, timeout: float = 90) -> dict:
    out, err = p.communicate(timeout=timeout)
    assert p.returncode == 0, err
    return json.loads(out) if out.strip() else {}


def interrupted(p: subprocess.Popen, timeout: float = 90) -> dict:
    """Ctrl-C on a coordinator process: it stops its campaign, reports it (marked interrupted) and exits 130."""
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=timeout)
    assert p.returncode == 130 and err.endswith("hysid: error: interrupted\n"), err
    doc = json.loads(out)
    assert doc["settings"]["stop_reason"] == "interrupted"
    return doc


def coordinator(spawn, endpoint: str, campaign: str, db: Path, *extra: str) -> subprocess.Popen:
    """A coordinator process, returned once it answers on ``endpoint``."""
    p = spawn(
        "coordinator", "--listen", endpoint, "--campaign", campaign, "--db", str(db), "--out", str(db.parent / f"out-{campaign}"), "--json", *ENDLESS, *extra
    )
    ready(endpoint, campaign)
    return p


def island(spawn, endpoint: str, campaign: str, name: str, db: Path, *extra: str) -> subprocess.Popen:
    """An island process of the coordinator whose database is ``db`` (its secret is beside it)."""
    return spawn("island", "--connect", endpoint, "--campaign", campaign, "--id", name, "--quiet", "--secret-file", secret_file(db, campaign), *extra)


def test_a_killed_island_is_recorded_lost_and_the_campaign_finishes_with_the_rest(spawn, tmp_path):
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "k.sqlite"
    # 30,000 evaluations: at the kill (every island past 20 rows) the three have spent ~2,500, so a and c search on
    # for ~10 times what they had before; the loss is recorded within LEAVE_GRACE_S of the kill
    coord = coordinator(spawn, endpoint, "kill", db, "--min-islands", "3", "--budget", "30000", "--time-limit", "120")
    islands = {name: island(spawn, endpoint, "kill", name, db) for name in ("a", "b", "c")}
    wait_for(lambda: all(rows_of(db, n) > 20 for n in islands), 60, "every island's history")
    islands["b"].send_signal(signal.SIGKILL)
    doc = finished(coord)
    assert events(db, "b") == ["join", "lost"]
    assert events(db, "a") == events(db, "c") == ["join", "left"]
    assert {i["island"]: i["status"] for i in doc["islands"]} == {"a": "left", "b": "lost", "c": "left"}
    assert doc["settings"]["stop_reason"] == "budget of 30,000 evaluations spent"
    assert islands["a"].wait(30) == islands["c"].wait(30) == 0


def test_a_frozen_island_is_lost_within_3_s_and_back_after_sigcont(spawn, tmp_path):
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "s.sqlite"
    coord = coordinator(spawn, endpoint, "freeze", db, "--min-islands", "2", "--time-limit", "120")
    a, b = island(spawn, endpoint, "freeze", "a", db), island(spawn, endpoint, "freeze", "b", db)
    wait_for(lambda: rows_of(db, "a") > 20 and rows_of(db, "b") > 20, 60, "both islands' history")
    b.send_signal(signal.SIGSTOP)
    lost_after = wait_for(lambda: events(db, "b")[-1:] == ["lost"], 10, "the frozen island to be marked lost")
    assert lost_after < 3.0
    rows_frozen = rows_of(db, "b")
    b.send_signal(signal.SIGCONT)
    wait_for(lambda: events(db, "b")[-1:] == ["back"], 20, "the island to come back")
    wait_for(lambda: rows_of(db, "b") > rows_frozen + 20, 20, "new history after SIGCONT")
    doc = interrupted(coord)  # Ctrl-C: the campaign stops and reports
    assert doc["settings"]["stop_reason"] == "interrupted"
    assert events(db, "b") == ["join", "lost", "back", "stopped"] and events(db, "a") == ["join", "stopped"]  # by the user
    assert a.wait(30) == b.wait(30) == 0


def bad_messages(n: int, evil: Peer) -> list[tuple[str, bytes, str]]:
    """``n`` bad migrant messages of a joined but broken island (key suffix, payload, expected
    reason), cycling through kinds; sealed with its own keys, so that each reaches the check it fails."""
    cred = evil.credentials
    good = {"iteration": 1, "x": pack_array(TRUTH[None, :]), "claimed": pack_array(np.zeros(1)), "sent_at": time.time()}

    def variant(envelope: dict | None = None, **change) -> bytes:
        body = {k: v for k, v in {**good, **change}.items() if v is not ...}
        sealed = msgpack.unpackb(seal("migrants", "flood", "evil", cred.run, evil.seq(), body, cred.key))
        return msgpack.packb({**sealed, **(envelope or {})}, use_bin_type=True)

    kinds = [
        (lambda: b"\xc1garbage", "undecodable"),
        (lambda: b"\x00" * (MAX_BYTES["migrants"] + 10), "oversized"),
        (lambda: variant(x="not an array"), "schema"),
        (lambda: variant(claimed=...), "schema"),
        (lambda: variant(x=pack_array(np.array([[np.nan, 0.0, 200.0, 0.0]]))), "not_finite"),
        (lambda: variant(x=pack_array(np.array([[0.5, 0.0, 200.0, 0.0]]))), "out_of_bounds"),
        (lambda: variant(x=pack_array(np.zeros((1, 7)))), "shape"),
        (lambda: variant({"campaign": "other"}), "campaign"),
        (lambda: variant({"v": 99}), "version"),
        (lambda: variant({"sender": "someone-else"}), "sender"),
    ]
    return [("evil", kinds[i % len(kinds)][0](), kinds[i % len(kinds)][1]) for i in range(n)]


def test_a_thousand_bad_migrant_messages_are_each_rejected_and_counted(spawn, tmp_path):
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "f.sqlite"
    coord = coordinator(spawn, endpoint, "flood", db, "--time-limit", "120")
    target = island(spawn, endpoint, "flood", "target", db)
    wait_for(lambda: rows_of(db, "target") > 20, 60, "the island's history")
    evil = Peer(endpoint, "flood", "evil", secret=secret_of(db, "flood"))  # joined: a broken island, not an outsider
    evil.token()  # as an island holds one: its leaving is seen at once
    messages = bad_messages(1000, evil)
    try:
        publisher = evil.publisher("migrants")
        for _, payload, _ in messages:
            publisher.put(payload)
        wait_for(lambda: query(db, "SELECT count(*) FROM rejected")[0][0] >= 1000, 60, "the coordinator to reject all")
        wait_for(lambda: query(db, "SELECT max(rejected) FROM islands WHERE island = 'target'")[0][0] == 1000, 60, "the island to count all")
        rows = rows_of(db, "target")
        wait_for(lambda: rows_of(db, "target") > rows + 20, 30, "the island to keep going")
    finally:
        evil.close()
    assert target.poll() is None and coord.poll() is None
    expected: dict[str, int] = {}
    for _, _, reason in messages:
        expected[reason] = expected.get(reason, 0) + 1
    assert dict(query(db, "SELECT reason, count(*) FROM rejected GROUP BY reason")) == expected
    assert query(db, "SELECT count(*) FROM migrations WHERE island = 'evil'")[0][0] == 0
    assert interrupted(coord)["migrations"]["rejected_reasons"] == expected


def forged(forger: Peer, x: np.ndarray, claimed: float) -> bytes:
    seq = forger.seq()
    return encode_migrants(Migrants("forge", "forger", forger.credentials.run, 1, x[None, :], np.array([claimed]), time.time(), seq), forger.credentials)


def test_a_forged_migrant_claiming_fitness_zero_becomes_the_best_only_if_it_earns_it(spawn, tmp_path):
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "g.sqlite"
    coord = coordinator(spawn, endpoint, "forge", db, "--topology", "full", "--time-limit", "120")
    target = island(spawn, endpoint, "forge", "target", db)
    wait_for(lambda: rows_of(db, "target") > 0, 60, "the island's history")
    config, loops = decode_config(Store(db).campaign("forge")[1], "forge")
    objective = config.objective(loops)  # the coordinator's own objective
    bad = BOUNDS[:, 1].copy()
    forger = Peer(endpoint, "forge", "forger", secret=secret_of(db, "forge"))  # joined: a member the island takes from
    forger.token()
    try:
        publisher = forger.publisher("migrants")
        for _ in range(40):
            publisher.put(forged(forger, bad, 0.0))
        wait_for(lambda: query(db, "SELECT count(*) FROM migrations WHERE island = 'forger'")[0][0] == 40, 20, "all forgeries seen")
        wait_for(lambda: query(db, "SELECT max(received) FROM islands WHERE island = 'target'")[0][0] > 0, 20, "the island to re-evaluate some")
        ((best_x, best_f),) = query(db, "SELECT x, fitness FROM best")
        x = np.frombuffer(best_x, dtype="<f8")
        assert best_f > 0 and not np.allclose(x, bad)
        assert best_f == pytest.approx(objective(x[None, :])[0], rel=1e-12)  # the coordinator's own evaluation
        assert query(db, "SELECT max(taken), min(best_fitness) > 0 FROM islands WHERE island = 'target'")[0] == (0, 1)
        for _ in range(5):  # the truth (fitness ~1e-30, beyond what the young island has found) under the same lie
            publisher.put(forged(forger, TRUTH, 0.0))
        earned: list[tuple] = []  # the island, evolving around the truth, may beat it by rounding soon after: catch the moment
        truth_f = objective(TRUTH[None, :])[0]

        def truth_arrived() -> bool:
            rows = query(db, "SELECT island, x, fitness FROM best")
            earned.extend(row for row in rows if row[0] == "forger")
            # within one commit window the island may take the truth in and beat it by rounding: then the
            # forger's moment as the best is never committed, and the island's best came from the truth
            return bool(earned) or (rows[0][2] <= truth_f and query(db, "SELECT max(taken) FROM islands WHERE island = 'target'")[0][0] > 0)

        wait_for(truth_arrived, 60, "the earned best")
        wait_for(lambda: query(db, "SELECT max(taken) FROM islands WHERE island = 'target'")[0][0] > 0, 20, "the island to take it")
        for _, best_x, best_f in earned:  # whenever the forger held the best, it held it with the truth, evaluated here
            np.testing.assert_array_equal(np.frombuffer(best_x, dtype="<f8"), TRUTH)
            assert best_f == truth_f
    finally:
        forger.close()
    assert target.poll() is None
    doc = interrupted(coord)
    assert doc["fitness"] <= objective(TRUTH[None, :])[0]


def test_two_campaigns_on_one_network_do_not_cross_talk(spawn, tmp_path):
    port_a, port_b = free_port(), free_port()
    ep_a, ep_b = f"tcp/127.0.0.1:{port_a}", f"tcp/127.0.0.1:{port_b}"
    db_a, db_b = tmp_path / "a.sqlite", tmp_path / "b.sqlite"
    coord_a = coordinator(spawn, ep_a, "alpha", db_a, "--budget", "20000", "--time-limit", "120")
    coord_b = coordinator(spawn, ep_b, "beta", db_b, "--connect", ep_a, "--noise", "5", "--budget", "20000", "--time-limit", "120")
    session = open_session(session_config("client", connect=[ep_a]), ep_a)
    try:  # one network, before either island starts: beta's coordinator answers a query sent to alpha's router
        wait_for(lambda: any(r.ok is not None for r in session.get("hysid/beta/config", timeout=2)), 30, "beta reachable via alpha")
    finally:
        session.close()
    island(spawn, ep_a, "alpha", "same-name", db_a)  # the two islands start together and search side by side
    island(spawn, ep_b, "beta", "same-name", db_b)
    doc_a, doc_b = finished(coord_a), finished(coord_b)
    for db, doc in ((db_a, doc_a), (db_b, doc_b)):
        assert [i["island"] for i in doc["islands"]] == ["same-name"]  # one run each: nothing from the other campaign
        assert query(db, "SELECT count(*) FROM rejected")[0][0] == 0, query(db, "SELECT key, reason, detail FROM rejected")
        assert events(db, "same-name") == ["join", "left"]
    assert doc_a["dataset"]["name"] != doc_b["dataset"]["name"]
    (a_from, a_to), (b_from, b_to) = (query(db, "SELECT min(t), max(t) FROM history")[0] for db in (db_a, db_b))
    assert a_from < b_to and b_from < a_to  # the two searched side by side


# --- attacks, durability and the end of a campaign (issue: hardening) --------------------------------
def migrations_are_unique(db: Path) -> bool:
    return query(db, "SELECT count(*) = count(DISTINCT island || '/' || run || '/' || seq) FROM migrations")[0][0] == 1


def test_outsiders_and_a_broken_island_cannot_steer_a_campaign(spawn, tmp_path):
    """Forged history of an invented island (2**52 evaluations, never final), a fake liveliness token,
    migrants under another island's id, replays of real messages and a decoy flood that would rewire
    the ring: the campaign still ends because its islands finished, with their own numbers only."""
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "st.sqlite"
    coord = spawn(
        *coordinator_args(endpoint, "steer", db, tmp_path / "out"),
        "--json",
        *PSO_ISLANDS,
        "--iterations",
        "2500",
        "--interval",
        "5",
        "--min-islands",
        "2",
        "--budget",
        "100000000",
        "--quiet",
        "--no-figures",
    )  # islands run long enough to hear every attack (sent by their ~50th iteration) and the 5 s a decoy's message may wait
    ready(endpoint, "steer")
    islands = {name: island(spawn, endpoint, "steer", name, db) for name in ("a", "c")}
    outsider = Peer(endpoint, "steer", "ghost")  # without the secret: a stranger
    mallory = Peer(endpoint, "steer", "mallory", secret=secret_of(db, "steer"))  # joined: an island that lies
    captured: list[bytes] = []
    outsider.entities.append(outsider.session.declare_subscriber("hysid/steer/migrants/a", lambda s: captured.append(s.payload.to_bytes())))
    try:
        # both islands search before the attacks (mallory's join makes two members: island a may start before c has joined)
        wait_for(lambda: rows_of(db, "a") > 10 and rows_of(db, "c") > 10 and len(captured) >= 3, 120, "both islands' history and a's migrants")
        ghost = Credentials.issue("ghost", b"k" * 32)  # a key nobody registered
        outsider.put(
            "history",
            encode_history(
                History(
                    "steer",
                    "ghost",
                    ghost.run,
                    "pso",
                    0,
                    np.array([[0, 0.0, 2.0**52, 1.0]]),
                    TRUTH,
                    0.0,
                    dict.fromkeys(("sent", "received", "taken", "rejected"), 0),
                ),
                ghost,
            ),
        )
        outsider.token("ghost")  # a member only by its token: never joined
        outsider.token("b")  # the decoy sorts between a and c: the ring would make it c's predecessor
        decoy = outsider.publisher("migrants", "b")
        for i in range(300):
            decoy.put(encode_migrants(Migrants("steer", "b", "r", 5, TRUTH[None, :], np.zeros(1), time.time(), i), Credentials.issue("b", b"y" * 32)))
        a_run = query(db, "SELECT run FROM islands WHERE island = 'a'")[0][0]
        mallory.put(
            "migrants",
            encode_migrants(
                Migrants("steer", "a", a_run, 5, TRUTH[None, :], np.zeros(1), time.time(), 10**6),
                Credentials("a", a_run, mallory.credentials.key, mallory.credentials.coordinator),
            ),
            key_island="a",
        )
        replays = outsider.publisher("migrants", "a")
        for message in captured[:3] * 30:
            replays.put(message)
        assert not query(db, "SELECT 1 FROM islands WHERE final = 1")  # every attack went out while both islands ran
        doc = finished(coord, timeout=120)
    finally:
        outsider.close()
        mallory.close()
    assert doc["settings"]["stop_reason"] == "every island finished"
    assert {i["island"] for i in doc["islands"]} == {"a", "c"} and doc["evaluations"] < 10**6
    reasons = doc["migrations"]["rejected_reasons"]
    # each of the 87 replays (the first three may be the originals) rejected as one, or, where the coordinator's inbox
    # was crowded (a loaded machine), superseded by a newer message of a before it was handled (coordinator.inbox)
    superseded = query(db, "SELECT coalesce(sum(messages), 0) FROM superseded WHERE island = 'a'")[0][0]
    assert reasons["unjoined"] >= 300 + 3 and reasons["forged"] >= 1 and reasons["replay"] + superseded >= 87, (reasons, superseded)
    assert migrations_are_unique(db) and not query(db, "SELECT 1 FROM migrations WHERE island IN ('b', 'ghost', 'mallory')")
    assert {e for (e,) in query(db, "SELECT DISTINCT island FROM members")} == {"a", "c", "mallory"}
    a_doc, c_doc = (next(i for i in doc["islands"] if i["island"] == name) for name in ("a", "c"))
    assert c_doc["rejected"] >= 1  # the decoy's flood: never listed, so never checked, and rejected once it waited in vain
    assert 0 < c_doc["received"] <= 2 * a_doc["sent"] + 1  # c kept taking from its real predecessor a, and only from a
    assert all(p.wait(30) == 0 for p in islands.values())


def test_a_killed_coordinator_loses_at_most_its_commit_window(spawn, tmp_path):
    """A steady stream of history rows; SIGKILL; what was committed is at most COMMIT_EVERY_S old."""
    from coordinator.loop import COMMIT_EVERY_S

    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "kl.sqlite"
    coord = coordinator(spawn, endpoint, "loss", db)
    feeder = Peer(endpoint, "loss", "feeder", secret=secret_of(db, "loss"))  # joined as pso with seed 0, population 20 + 15 per iteration
    config, loops = decode_config(Store(db).campaign("loss")[1], "loss")
    x = config.objective(loops).bounds.mean(axis=1)
    f = float(config.objective(loops)(x[None, :])[0])
    stats = dict.fromkeys(("sent", "received", "taken", "rejected"), 0)
    publisher = feeder.publisher("history")
    sent: list[tuple[float, int]] = []  # (time sent, rows so far)
    per_message, every_s = 10, 0.02
    try:
        it, start = 0, time.time()
        while time.time() - start < 4.0 or not rows_of(db, "feeder"):
            rows = np.array([[i, f, 40 + 35 * i, 0.0] for i in range(it, it + per_message)], dtype=float)
            publisher.put(encode_history(History("loss", "feeder", feeder.credentials.run, "pso", 0, rows, x, f, stats, seq=feeder.seq()), feeder.credentials))
            it += per_message
            sent.append((time.time(), it))
            time.sleep(every_s)
        killed_at = time.time()
        coord.send_signal(signal.SIGKILL)
        coord.communicate(timeout=30)
    finally:
        feeder.close()
    stored = rows_of(db, "feeder")
    committed = query(db, "SELECT t FROM commits")[0][0]
    sent_before_kill = max(n for t, n in sent if t <= killed_at)
    lost_rows, lost_s = sent_before_kill - stored, killed_at - committed
    print(f"kill loss: {lost_rows} rows ({lost_rows / per_message * every_s:.2f} s of the stream), last commit {lost_s:.2f} s before the kill")
    assert history_contiguous(db, "feeder") == stored - 1  # what is stored has no hole
    assert lost_s <= COMMIT_EVERY_S + 1.0, lost_s  # the commit window, plus scheduling slack on a loaded machine
    assert lost_rows <= (COMMIT_EVERY_S + 1.0) / every_s * per_message, lost_rows


def history_contiguous(db: Path, island: str) -> int:
    its = [it for (it,) in query(db, "SELECT iteration FROM history WHERE island = ? ORDER BY iteration", island)]
    return next((i - 1 for i, it in enumerate(its) if it != i), len(its) - 1)


def test_rows_sent_while_the_coordinator_was_down_arrive_when_it_returns_and_the_campaign_ends(spawn, tmp_path):
    """An island finishes while its coordinator is dead; it waits, the resumed coordinator fetches what it
    missed, confirms, and, nothing being left to do, ends with its report."""
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "down.sqlite"
    first = spawn(
        *coordinator_args(endpoint, "down", db, tmp_path / "out1"),
        *PSO_ISLANDS,
        "--iterations",
        "1200",
        "--interval",
        "0",
        "--quiet",
    )
    ready(endpoint, "down")
    session = open_session(session_config("client", connect=[endpoint]), endpoint)
    secret = secret_of(db, "down")
    config, loops = decode_config(fetch_config(session, secret, 30), "down")
    node = IslandNode("solo", "pso", 3, config, config.objective(loops), history_every_s=0.05)
    transport = ZenohTransport(session, node, secret, wait_s=60)
    worker = threading.Thread(target=lambda: (node.run(transport), transport.close()))
    worker.start()
    try:
        wait_for(lambda: rows_of(db, "solo") > 10, 60, "the first rows")
        first.send_signal(signal.SIGKILL)
        first.communicate(timeout=30)
        stored_before = rows_of(db, "solo")
        wait_for(lambda: node.finished, 120, "the island to finish its budget with nobody listening")
        assert len(node.rows) == 1201 > stored_before and worker.is_alive()  # it waits for a confirmation
        second = spawn(
            "coordinator",
            "--listen",
            endpoint,
            "--campaign",
            "down",
            "--db",
            str(db),
            "--resume",
            "--out",
            str(tmp_path / "out2"),
            "--json",
            "--quiet",
            "--no-figures",
        )
        doc = finished(second, timeout=90)
        worker.join(30)
    finally:
        session.close()
    assert not worker.is_alive() and node.confirmed is True
    assert history_contiguous(db, "solo") == 1200 == rows_of(db, "solo") - 1  # every row, none twice
    assert doc["settings"]["stop_reason"] == "every island finished"
    assert [i["final"] for i in doc["islands"]] == [True] and (tmp_path / "out2" / "report.md").is_file()


def waits_in_vain(payload: bytes, broken: Credentials) -> bool:
    """Whether an island takes a migrant message of the broken island for one of a run the roster does not list yet: its
    envelope is well formed, from the broken island, of another run (it waits for the roster, in vain)."""
    try:
        return envelope(payload, "migrants", "zf", broken.island).run != broken.run
    except MessageRejected:
        return False


def test_ten_thousand_hostile_messages_over_zenoh_leave_coordinator_and_islands_running_with_the_right_answer(spawn, tmp_path):
    """tests/hostile.py over real Zenoh, under every key: publications (migrants, history and keys
    nobody serves), join requests, liveliness tokens of names that never joined, control messages to
    the islands and history queries to them. Each is rejected and counted where it lands; the
    coordinator and both islands keep going, and the campaign ends with the right answer."""
    from hostile import Hostile, stream

    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "zf.sqlite"
    coord = coordinator(spawn, endpoint, "zf", db, "--min-islands", "2", "--time-limit", "300")
    islands = {name: island(spawn, endpoint, "zf", name, db) for name in ("a", "b")}
    wait_for(lambda: rows_of(db, "a") > 20 and rows_of(db, "b") > 20, 60, "both islands' history")
    broken = Peer(endpoint, "zf", "broken", secret=secret_of(db, "zf"))  # a joined island that sends nothing but junk
    broken.token()
    hostile = Hostile(np.random.default_rng(2026), "zf", BOUNDS, broken.credentials, broken.seq)
    publishers: dict[str, object] = {}
    to_coordinator = to_islands = unlisted = 0
    queries = {"a": 0, "b": 0}
    tokens = 0
    try:
        implausible = 1e15
        for entry, where, payload in stream(hostile, 8500, "pso", 0, implausible, ["a", "b", "broken"]):
            if entry == "msg":
                kind = where.split("/")[2]
                if where not in publishers:
                    publishers[where] = broken.session.declare_publisher(where, congestion_control=zenoh.CongestionControl.BLOCK)
                    if kind in ("migrants", "history"):  # a put before the publisher matches its subscribers is dropped
                        wait_for(lambda: publishers[where].matching_status.matching, 30, f"subscribers of {where}")  # noqa: B023 (called within this iteration)
                publishers[where].put(payload)
                to_coordinator += kind in ("migrants", "history")
                if kind == "migrants":  # a well-formed envelope of a run nobody listed waits for the roster in vain: counted apart
                    unlisted += waits_in_vain(payload, broken.credentials)
                    to_islands += 1
            elif entry == "join":
                broken.session.get(f"hysid/zf/join/{where}", lambda reply: None, payload=payload, timeout=2.0)
                to_coordinator += 1
            else:
                broken.token(f"ghost-{tokens}" if tokens % 3 else f"{'x' * 70}{tokens}")
                tokens += 1
                to_coordinator += 2  # its arrival and, at the end, its departure
        controls = broken.session.declare_publisher("hysid/zf/control", congestion_control=zenoh.CongestionControl.BLOCK)
        wait_for(lambda: controls.matching_status.matching, 30, "the islands' control subscriptions")
        for _ in range(1000):
            controls.put(hostile.control())
        for k in range(500):
            target = "ab"[k % 2]
            broken.session.get(f"hysid/zf/history/{target}?{hostile.history_query()}", lambda reply: None, timeout=2.0)
            queries[target] += 1
        assert 8500 + 1000 + 500 >= 10_000
        for entity in broken.entities[1:]:  # the ghosts leave; the broken island's own token stays
            entity.undeclare()
        del broken.entities[1:]
        recorded = lambda: query(db, "SELECT coalesce(sum(n), 0) FROM rejected")[0][0]
        wait_for(lambda: recorded() >= to_coordinator, 120, f"the coordinator to count {to_coordinator} rejects")
        rows = {name: rows_of(db, name) for name in islands}
        wait_for(lambda: all(rows_of(db, n) > rows[n] + 20 for n in islands), 60, "both islands to keep going")
        counted = lambda: dict(query(db, "SELECT island, sum(rejected) + sum(unlisted) FROM islands WHERE campaign = 'zf' GROUP BY island"))
        sent = {name: to_islands + 1000 + queries[name] for name in islands}  # each island reads its queue at its own pace
        wait_for(lambda: all(counted().get(n, 0) >= sent[n] for n in islands), 120, f"the islands to count {sent} messages")
        assert coord.poll() is None and all(p.poll() is None for p in islands.values())
        doc = interrupted(coord)
    finally:
        broken.close()
    assert doc["migrations"]["rejected"] == to_coordinator
    assert doc["fitness"] < 1e-20 and all(doc["params"][k] == pytest.approx(v, rel=1e-6) for k, v in TRUE_PARAMS.items())
    got = {i["island"]: (i["rejected"], i["unlisted"]) for i in doc["islands"]}  # every migrant and control message, its queries: exactly
    assert got == {name: (to_islands - unlisted + 1000 + queries[name], unlisted) for name in ("a", "b")}, (got, to_islands, unlisted, queries)
    assert all(p.wait(30) == 0 for p in islands.values())
