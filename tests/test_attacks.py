"""Attacks on a running campaign of real processes, each mounted as an attacker would mount it: from its
own Zenoh session on loopback, with or without the campaign secret (tests/hostile.py); and faults that
must end a campaign cleanly (a database locked, deleted, a coordinator killed and resumed, a junk flood
at the end). Default configuration throughout: plain TCP on loopback,
authenticated by the campaign secret only.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import zenoh

from coordinator.launch import free_port
from coordinator.store import Store
from hostile import RogueCoordinator, join_flood
from hysid.cli.campaign import resumed_from
from hysid_model.synth import TRUE_PARAMS
from island.config import decode_config, encode_config
from island.island_messages import History, Migrants, encode_history, encode_migrants
from island.sealing import Credentials
from island.session import open_session, session_config
from support import PSO_ISLANDS, Peer, coordinator_args, events, query, ready, rows_of, secret_file, secret_of, wait_for
from test_faults import BOUNDS, TRUTH, coordinator, finished, interrupted, island

pytestmark = pytest.mark.slow  # processes, floods and waits of seconds

STATS = dict.fromkeys(("sent", "received", "taken", "rejected"), 0)


def stranger(endpoint: str) -> zenoh.Session:
    """An attacker's own Zenoh session, without the campaign secret."""
    return open_session(session_config("client", connect=[endpoint]), endpoint)


def island_value(db: Path, island: str, column: str) -> int:
    found = query(db, f"SELECT max({column}) FROM islands WHERE island = ?", island)
    return found[0][0] or 0 if found else 0


def reasons(db: Path) -> dict[str, int]:
    return dict(query(db, "SELECT reason, sum(n) FROM rejected GROUP BY reason"))


# --- strangers (no campaign secret) --------------------------------------------------------------
def test_a_stranger_posing_as_the_coordinator_is_refused_by_every_island(spawn, tmp_path):
    """It answers every join request (challenge and run) and the config query first, with a loop set of
    its own (forces doubled), answers the best query and sends stop orders, all signed with its own key:
    the islands join the real coordinator, search the real loops (no polish to rescue a wrong answer)
    and stop by its rule only."""
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "r.sqlite"
    # 20,000 evaluations: both islands stand on the real loops' answer from their first iteration (a probe: 5.5e-28 there), and
    # each refuses the stranger's join answers at once and a stop order every 0.2 s for the ~500 iterations each still runs
    coord = coordinator(spawn, endpoint, "rogue", db, "--min-islands", "2", "--budget", "20000", "--no-polish")
    config, loops = decode_config(Store.read_only(db).campaign("rogue")[1], "rogue")
    doubled = replace(loops, top=loops.top * [1.0, 2.0], bottom=loops.bottom * [1.0, 2.0])  # forces doubled
    session = stranger(endpoint)
    rogue = RogueCoordinator(session, "rogue", encode_config(config, doubled), BOUNDS[:, 1].copy())
    try:
        islands = [island(spawn, endpoint, "rogue", name, db) for name in ("a", "b")]
        doc = finished(coord, timeout=120)
        assert all(p.wait(30) == 0 for p in islands)
    finally:
        rogue.close()
        session.close()
    assert rogue.answered["challenge"] >= 2 and rogue.answered["config"] >= 2 and rogue.answered["control"] > 10  # it was heard
    assert doc["settings"]["stop_reason"] == "budget of 20,000 evaluations spent"
    assert {i["island"] for i in doc["islands"]} == {"a", "b"} and all(i["status"] == "left" for i in doc["islands"])
    assert doc["fitness"] < 1e-6 and doc["params"]["w0"] == pytest.approx(TRUE_PARAMS["w0"], rel=1e-3)  # the real loops' answer
    assert all(i["rejected"] >= 2 for i in doc["islands"])  # each refused the stranger's answers and stop orders


def test_joins_without_the_secret_take_no_run_slot_and_an_honest_late_island_still_joins(spawn, tmp_path):
    """4,200 joins under fresh ids (each answers the real challenge, with a guessed secret): no run is
    admitted, every proof is refused with its reason, and an island with the secret joins afterwards."""
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "j.sqlite"
    coord = coordinator(spawn, endpoint, "slots", db, "--time-limit", "180")
    first = island(spawn, endpoint, "slots", "first", db)
    wait_for(lambda: rows_of(db, "first") > 10, 60, "the first island's history")
    session = stranger(endpoint)
    try:
        got = join_flood(session, "slots", 4200)
    finally:
        session.close()
    assert got["runs"] == 0 and got["challenges"] > 0
    late = island(spawn, endpoint, "slots", "late", db)
    wait_for(lambda: rows_of(db, "late") > 10, 90, "the late island's history")
    assert query(db, "SELECT island FROM runs ORDER BY joined") == [("first",), ("late",)]
    doc = interrupted(coord)
    assert doc["migrations"]["rejected_reasons"].get("forged", 0) + doc["migrations"]["rejected_reasons"].get("overflow", 0) >= got["challenges"]
    assert first.wait(30) == late.wait(30) == 0


def test_a_token_held_by_a_stranger_neither_keeps_a_campaign_open_nor_hides_a_loss(spawn, tmp_path):
    """Tokens under both islands' names, declared before they start: the killed island is lost once it
    is silent, the other leaves with its final history, and the campaign ends as if nobody held them."""
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "t.sqlite"
    coord = spawn(
        *coordinator_args(endpoint, "held", db, tmp_path / "out"),
        "--json",
        *PSO_ISLANDS,
        "--iterations",
        "300",  # 15 times the 20 rows b has when it is killed; a's end and b's loss may come in either order
        "--interval",
        "5",
        "--min-islands",
        "2",
        "--quiet",
        "--no-figures",
    )
    ready(endpoint, "held")
    session = stranger(endpoint)
    tokens = [session.liveliness().declare_token(f"hysid/held/members/{name}") for name in ("a", "b")]
    try:
        a, b = island(spawn, endpoint, "held", "a", db), island(spawn, endpoint, "held", "b", db)
        wait_for(lambda: rows_of(db, "b") > 20, 60, "the islands' history")
        b.send_signal(signal.SIGKILL)
        doc = finished(coord, timeout=120)  # its tokens still held
        assert a.wait(30) == 0
    finally:
        for token in tokens:
            token.undeclare()
        session.close()
    assert doc["settings"]["stop_reason"] == "every island finished or was lost"
    assert events(db, "a") == ["join", "left"] and events(db, "b") == ["join", "lost"]


def test_history_is_answered_only_to_the_coordinator(spawn, tmp_path):
    """A stranger asks an island for its history, unsigned, and replays the coordinator's own signed
    queries (which its queryable under history/* also received, and answered with junk): no row goes
    to it, each query is counted as rejected, and the coordinator still gets its rows."""
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "h.sqlite"
    coord = coordinator(spawn, endpoint, "hq", db, "--time-limit", "180")
    session = stranger(endpoint)
    captured: list[str] = []
    spy = session.declare_queryable("hysid/hq/history/*", lambda q: (captured.append(str(q.selector)), q.reply(q.key_expr, b"junk")))
    try:
        a = island(spawn, endpoint, "hq", "a", db)
        wait_for(lambda: rows_of(db, "a") > 20 and captured, 60, "the island's history and a query of the coordinator")
        run = query(db, "SELECT run FROM runs WHERE island = 'a'")[0][0]
        before = island_value(db, "a", "rejected")
        selectors = [f"hysid/hq/history/a?run={run};since=-1", "hysid/hq/history/a", *captured]
        answers = [r for selector in selectors for r in session.get(selector, timeout=3.0) if r.ok is not None]
        assert answers == [] or all(r.ok.payload.to_bytes() == b"junk" for r in answers)  # its own spy's, never the island's
        wait_for(lambda: island_value(db, "a", "rejected") >= before + len(selectors), 30, "the island to count every query")
        rows = rows_of(db, "a")
        wait_for(lambda: rows_of(db, "a") > rows + 20, 30, "the island to keep going")
        doc = interrupted(coord)
        assert a.wait(30) == 0
    finally:
        spy.undeclare()
        session.close()
    assert doc["migrations"]["rejected_reasons"].get("undecodable", 0) >= 1  # the spy's junk answers, refused


# --- members that lie (they hold the campaign secret) --------------------------------------------
def test_a_forged_migrant_numbered_2_63_cannot_block_its_victim(spawn, tmp_path):
    """A member signs a migrant message as island a (a's name and run, number 2**63-1) with its own key:
    it is refused as forged everywhere, and a's real migrants keep being taken."""
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "m.sqlite"
    coord = coordinator(spawn, endpoint, "victim", db, "--topology", "full", "--min-islands", "2", "--time-limit", "180")
    islands = {name: island(spawn, endpoint, "victim", name, db) for name in ("a", "b")}
    mallory = Peer(endpoint, "victim", "mallory", secret=secret_of(db, "victim"))
    mallory.token()  # a member as an island is: its leaving is seen at once
    try:
        wait_for(lambda: island_value(db, "b", "received") > 4, 60, "b to take a's migrants")
        a_run = query(db, "SELECT run FROM runs WHERE island = 'a'")[0][0]
        as_a = Credentials("a", a_run, mallory.credentials.key, mallory.credentials.coordinator)
        mallory.put("migrants", encode_migrants(Migrants("victim", "a", a_run, 5, TRUTH[None, :], np.zeros(1), time.time(), 2**63 - 1), as_a), "a")
        wait_for(lambda: reasons(db).get("forged", 0) >= 1, 30, "the coordinator to refuse the forgery")
        received, migrations = island_value(db, "b", "received"), query(db, "SELECT count(*) FROM migrations WHERE island = 'a'")[0][0]
        wait_for(lambda: island_value(db, "b", "received") > received + 4, 60, "b to keep taking a's migrants")
        assert query(db, "SELECT count(*) FROM migrations WHERE island = 'a'")[0][0] > migrations
        mallory.close()
        doc = interrupted(coord)
    finally:
        mallory.close()
    assert next(i for i in doc["islands"] if i["island"] == "b")["rejected"] >= 1
    assert all(p.wait(30) == 0 for p in islands.values())


def test_a_silent_member_cannot_starve_its_successor_in_the_ring(spawn, tmp_path):
    """A member that joins between two islands, keeps itself alive with signed heartbeats and sends no
    migrants is skipped by the island after it in the ring, which takes from the one before instead."""
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "s.sqlite"
    coord = coordinator(spawn, endpoint, "ring", db, "--topology", "ring", "--time-limit", "180")
    a = island(spawn, endpoint, "ring", "a", db)
    wait_for(lambda: rows_of(db, "a") > 5, 60, "the first island's history")
    silent = Peer(endpoint, "ring", "aa-silent", secret=secret_of(db, "ring"))  # joins second: the predecessor of the next one
    silent.token()
    stop = threading.Event()

    def heartbeats() -> None:
        publisher = silent.publisher("history")
        x = BOUNDS.mean(axis=1)
        while not stop.wait(0.5):
            publisher.put(
                encode_history(
                    History("ring", silent.island, silent.credentials.run, "pso", 0, np.zeros((0, 4)), x, np.inf, STATS, seq=silent.seq()), silent.credentials
                )
            )

    beating = threading.Thread(target=heartbeats)
    beating.start()
    try:
        b = island(spawn, endpoint, "ring", "b", db)
        wait_for(lambda: island_value(db, "b", "received") >= 10, 90, "b to take migrants past the silent member")
        assert events(db, "aa-silent") == ["join"]  # alive all along, by its signed heartbeats
        stop.set()
        beating.join()
        silent.close()
        interrupted(coord)
    finally:
        stop.set()
        beating.join()
        silent.close()
    assert a.wait(30) == b.wait(30) == 0


def test_a_members_impossible_claims_are_refused_with_their_reasons_and_spend_no_budget(spawn, tmp_path):
    """434 million evaluations in its first seconds (what its iterations alone would allow), a wall
    time of 1e300 s, an infinite best, send times of +-1e308, 0 and -1: each refused with its reason,
    nothing stored, and the campaign's budget of 2e8 evaluations is not spent."""
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "e.sqlite"
    coord = coordinator(spawn, endpoint, "effort", db, "--budget", "200000000", "--time-limit", "180")
    a = island(spawn, endpoint, "effort", "a", db)
    liar = Peer(endpoint, "effort", "liar", secret=secret_of(db, "effort"))
    liar.token()  # a member as an island is: its leaving is seen at once
    config, loops = decode_config(Store.read_only(db).campaign("effort")[1], "effort")
    f = float(config.objective(loops)(TRUTH[None, :])[0])
    try:
        wait_for(lambda: rows_of(db, "a") > 10, 60, "the island's history")
        lies = [np.array([[175_000, f, 434e6, 1.0]]), np.array([[0, f, 40, 1e300]]), np.array([[0, np.inf, 40, 0.5]])]
        for rows in lies:
            liar.put(
                "history", encode_history(History("effort", "liar", liar.credentials.run, "pso", 0, rows, TRUTH, f, STATS, seq=liar.seq()), liar.credentials)
            )
        for sent_at in (1e308, -1e308, 0.0, -1.0):
            liar.put(
                "migrants",
                encode_migrants(Migrants("effort", "liar", liar.credentials.run, 5, TRUTH[None, :], np.zeros(1), sent_at, liar.seq()), liar.credentials),
            )
        wait_for(lambda: reasons(db).get("out_of_range", 0) >= 5 and reasons(db).get("implausible", 0) >= 1, 30, "every lie to be refused")
        rows = rows_of(db, "a")
        wait_for(lambda: rows_of(db, "a") > rows + 20, 30, "the campaign to go on")
        liar.close()
        doc = interrupted(coord)
    finally:
        liar.close()
    assert doc["settings"]["stop_reason"] == "interrupted" and doc["evaluations"] < 10**7
    assert rows_of(db, "liar") == 0 and query(db, "SELECT count(*) FROM migrations WHERE island = 'liar'")[0][0] == 0
    assert a.wait(30) == 0


# --- faults ------------------------------------------------------------------------------------------
def test_a_resumed_campaign_carries_its_time_on_instead_of_starting_it_again(spawn, tmp_path):
    """A 10 s campaign killed after 5 s or more and resumed decides to stop at 10 s of campaign time,
    not 10 s after the resume."""
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "t.sqlite"
    first = coordinator(spawn, endpoint, "timed", db, "--time-limit", "10")
    a = spawn("island", "--connect", endpoint, "--campaign", "timed", "--id", "a", "--quiet", "--wait", "60", "--secret-file", secret_file(db, "timed"))
    elapsed = lambda: (query(db, "SELECT elapsed_s FROM commits") or [(0.0,)])[0][0]
    wait_for(lambda: elapsed() >= 5.0, 60, "5 s of campaign time")
    first.send_signal(signal.SIGKILL)
    first.communicate(timeout=30)
    at_kill = elapsed()
    second = coordinator(spawn, endpoint, "timed", db, "--resume")
    seen: list[tuple[str, float]] = []  # (status, campaign time of the last commit), as another process reads them

    def stopping() -> bool:
        ((status,),) = query(db, "SELECT status FROM campaigns")
        seen.append((status, elapsed()))
        return status != "running"

    wait_for(stopping, 60, "the resumed campaign to decide to stop", step=0.02)
    doc = finished(second)
    decided_at = seen[-1][1]  # campaign time when another process first sees it stopping: within a commit window or two of the decision
    assert doc["settings"]["stop_reason"] == "time limit of 10 s" and at_kill >= 5.0
    assert 10.0 - 1.5 <= decided_at < 10.0 + 1.5, (at_kill, seen[-3:])  # not 10 s after the resume (that would be at_kill + 10 >= 15)
    assert a.wait(30) == 0


def test_a_database_locked_by_another_process_ends_the_campaign_within_seconds(spawn, tmp_path):
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "l.sqlite"
    coord = coordinator(spawn, endpoint, "locked", db, "--time-limit", "180")
    a = island(spawn, endpoint, "locked", "a", db, "--wait", "3")  # it waits that long for a confirmation no coordinator will send
    wait_for(lambda: rows_of(db, "a") > 10, 60, "the island's history")
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            f"import sqlite3, sys; c = sqlite3.connect({str(db)!r}, isolation_level=None); "
            "c.execute('BEGIN IMMEDIATE'); print('held', flush=True); sys.stdin.read()",
        ],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "held"
        locked_at = time.monotonic()
        _, err = coord.communicate(timeout=60)
        took = time.monotonic() - locked_at
    finally:
        holder.kill()
        holder.wait()
    errors = [line for line in err.splitlines() if line.startswith("hysid: error:")]
    assert coord.returncode == 2 and len(errors) == 1 and "Traceback" not in err, err
    assert "campaign 'locked' stopped: cannot write the campaign database" in errors[0] and "database is locked" in errors[0]
    assert "it could not be marked interrupted" in errors[0]  # the lock still held: the record says 'running'
    assert took < 20.0  # found within seconds (a 2 s wait for the lock, the islands told, one more try to mark it)
    assert a.wait(30) == 0  # told to stop; it did
    assert query(db, "SELECT status FROM campaigns") == [("running",)]
    gone = "interrupted (its coordinator is gone (last heartbeat "  # its process ended: no lease to wait for
    watched = subprocess.run([sys.executable, "-m", "hysid", "watch", "--once", str(db)], capture_output=True, text=True, timeout=60)
    assert watched.returncode == 0 and f"campaign 'locked' on synth: {gone}" in watched.stdout, watched.stdout
    reported = subprocess.run(
        [sys.executable, "-m", "hysid", "report", str(db), "--out", str(tmp_path / "report")], capture_output=True, text=True, timeout=120
    )
    assert reported.returncode == 0 and "stopped because interrupted: its coordinator is gone (last heartbeat " in reported.stdout, reported.stderr
    store = Store(db)
    try:
        assert resumed_from(store, "locked").startswith(f"hysid: resuming campaign 'locked', {gone}")
    finally:
        store.close()


def test_a_database_deleted_mid_run_ends_the_campaign_with_one_line(spawn, tmp_path):
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "d.sqlite"
    coord = coordinator(spawn, endpoint, "deleted", db, "--time-limit", "180")
    a = island(spawn, endpoint, "deleted", "a", db, "--wait", "3")  # it waits that long for a confirmation no coordinator will send
    wait_for(lambda: rows_of(db, "a") > 10, 60, "the island's history")
    for suffix in ("", "-wal", "-shm"):
        Path(f"{db}{suffix}").unlink(missing_ok=True)
    _, err = coord.communicate(timeout=30)
    errors = [line for line in err.splitlines() if line.startswith("hysid: error:")]
    assert coord.returncode == 2 and len(errors) == 1 and err.endswith(errors[0] + "\n"), err
    assert "the file was deleted" in errors[0] and "nothing to resume" in errors[0]
    assert a.wait(30) == 0 and not db.exists()


def test_a_junk_flood_around_the_end_does_not_keep_the_coordinator_alive(spawn, tmp_path):
    """A stranger floods every key with junk, blocking, from before the islands finish until well after:
    the coordinator reports and exits while the flood goes on."""
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "f.sqlite"
    coord = spawn(
        *coordinator_args(endpoint, "junk", db, tmp_path / "out"),
        "--json",
        *PSO_ISLANDS,
        "--iterations",
        "300",  # the flood starts at the island's ~10th row: ~290 iterations under it before the end
        "--interval",
        "5",
        "--quiet",
        "--no-figures",
    )
    ready(endpoint, "junk")
    a = island(spawn, endpoint, "junk", "a", db)
    session = stranger(endpoint)
    stop = threading.Event()
    sent = [0]

    def flood() -> None:
        publishers = [
            session.declare_publisher(f"hysid/junk/{kind}/ghost-{k}", congestion_control=zenoh.CongestionControl.BLOCK)
            for kind in ("migrants", "history")
            for k in range(4)
        ]
        junk = np.random.default_rng(1).bytes(60_000)
        deadline = time.monotonic() + 120.0  # bounded whatever happens
        while not stop.is_set() and time.monotonic() < deadline:
            publishers[sent[0] % len(publishers)].put(junk)
            sent[0] += 1

    flooding = threading.Thread(target=flood)
    try:
        wait_for(lambda: rows_of(db, "a") > 10, 60, "the island's history")
        flooding.start()
        doc = finished(coord, timeout=90)  # it exits while the flood goes on
        assert flooding.is_alive()
    finally:
        stop.set()
        flooding.join()
        session.close()
    assert doc["settings"]["stop_reason"] == "every island finished" and sent[0] > 100
    assert a.wait(30) == 0
