"""A coordinator that dies and comes back, islands that wait for it, and budgets that keep GA and PSO
islands together: real processes, real Zenoh on loopback, real SQLite.

The three broken outcomes of a SIGKILLed and resumed coordinator (issue 13) each have a check here:
(a) an island that died with the coordinator listed alive forever and the campaign never ending;
(b) the resumed coordinator stopping at once with no members; (c) the campaign split in two (the
survivors' history after the crash never stored, the new island cut off from them).
"""

from __future__ import annotations

import json
import signal
import subprocess
from pathlib import Path

import pytest

from coordinator.launch import free_port
from hysid_model.synth import TRUE_PARAMS
from support import Lines, events, query, ready, rows_of, secret_file, wait_for

pytestmark = pytest.mark.slow  # processes, kills and restarts

SMALL = ["--population", "20", "--initial", "40", "--interval", "5"]


def start_coordinator(spawn, endpoint: str, campaign: str, db: Path, out: Path, *extra: str) -> subprocess.Popen:
    p = spawn("coordinator", "--listen", endpoint, "--campaign", campaign, "--db", str(db), "--out", str(out), "--json", "--quiet", "--no-figures", *extra)
    ready(endpoint, campaign, process=p)  # an island started before it may end its campaign before the first look
    return p


def start_island(spawn, endpoint: str, campaign: str, name: str, db: Path, *extra: str) -> tuple[subprocess.Popen, Lines]:
    """An island process (its summary line on) of the coordinator of database ``db``, and its stderr as it comes."""
    p = spawn("island", "--connect", endpoint, "--campaign", campaign, "--id", name, "--secret-file", secret_file(db, campaign), *extra)
    return p, Lines(p.stderr)


def finished(p: subprocess.Popen, timeout: float = 180) -> dict:
    out, err = p.communicate(timeout=timeout)
    assert p.returncode == 0, err
    return json.loads(out)


def iterations(db: Path, island: str) -> list[int]:
    return [it for (it,) in query(db, "SELECT iteration FROM history WHERE island = ? ORDER BY run, iteration", island)]


def test_a_killed_coordinator_resumed_takes_its_islands_back_and_ends_by_its_own_rule(spawn, tmp_path):
    """SIGKILL the coordinator and one of three islands mid-campaign, resume on the same endpoint and
    database (no stop rule repeated), a new island waiting for it: the survivors rejoin carrying on, the dead
    island is recorded lost, no history row is lost, the new island takes migrants from the
    survivors, and the campaign ends by its evaluation budget with the right answer."""
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "r.sqlite"
    budget = 100_000  # the outage (the survivors search on until they find the coordinator silent) and what follows fit in it many times
    first = start_coordinator(spawn, endpoint, "back", db, tmp_path / "out1", "--algos", "ga,pso", *SMALL, "--min-islands", "3", "--evaluations", str(budget))
    islands = {name: start_island(spawn, endpoint, "back", name, db, "--wait", "60") for name in ("a", "b", "c")}
    wait_for(lambda: all(rows_of(db, n) > 30 for n in islands), 90, "every island's history")
    first.send_signal(signal.SIGKILL)
    islands["b"][0].send_signal(signal.SIGKILL)
    first.communicate(timeout=30)
    before = {n: iterations(db, n) for n in islands}
    spent_before = query(db, "SELECT sum(evaluations) FROM islands")[0][0]
    assert spent_before < budget / 2
    for name in ("a", "c"):  # the survivors notice, and wait (searching on)
        islands[name][1].wait_for("has been silent", 60)
    for name in ("a", "c"):  # frozen until the coordinator is back: the outage may last as long as a loaded machine needs, the
        islands[name][0].send_signal(signal.SIGSTOP)  # survivors do not spend the budget in it before the new island can join
    late, late_err = start_island(spawn, endpoint, "back", "d", db, "--wait", "60")  # a new island, waiting for the coordinator
    late_err.wait_for("no coordinator of campaign 'back' at", 60)
    second = start_coordinator(spawn, endpoint, "back", db, tmp_path / "out2", "--resume")
    for name in ("a", "c"):
        islands[name][0].send_signal(signal.SIGCONT)
    doc = finished(second)
    # (b) it did not stop at once: it stopped by the stored budget, after the islands spent it
    assert doc["settings"]["stop_reason"] == f"budget of {budget:,} evaluations spent"
    assert doc["evaluations"] >= budget
    # (a) the island that died with the coordinator is lost, not alive; the others left at the end
    assert events(db, "b") == ["join", "lost"]
    assert events(db, "a") == events(db, "c") == ["join", "join", "left"]  # joined, taken up again by the resumed coordinator, left
    assert events(db, "d") == ["join", "left"]
    status = {i["island"]: i["status"] for i in doc["islands"]}
    assert status == {"a": "left", "b": "lost", "c": "left", "d": "left"}
    # (c) one campaign: the survivors' rows before, during and after the outage are all stored, once
    for name in ("a", "c"):
        after = iterations(db, name)
        assert after[: len(before[name])] == before[name] and after == list(range(len(after)))
        assert len(after) > len(before[name]) + 50
        islands[name][1].wait_for("is back after", 30)
    d = next(i for i in doc["islands"] if i["island"] == "d")
    assert d["received"] > 2  # migrants of the survivors, not only the global best it joined with
    for name in ("a", "c"):
        assert islands[name][0].wait(30) == 0
        assert "stopped by the coordinator" in islands[name][1].text()
    assert late.wait(30) == 0 and "stopped by the coordinator" in late_err.text()
    assert doc["fitness"] < 1e-20 and all(doc["params"][k] == pytest.approx(v, rel=1e-6) for k, v in TRUE_PARAMS.items())


def test_an_island_started_before_its_coordinator_waits_for_it_and_joins(spawn, tmp_path):
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "e.sqlite"
    early, err = start_island(spawn, endpoint, "early", "first", db, "--wait", "60")
    err.wait_for("no campaign secret at", 60)  # its coordinator writes it when it starts
    assert early.poll() is None
    coordinator = start_coordinator(spawn, endpoint, "early", db, tmp_path / "out", "--algos", "pso", *SMALL, "--evaluations", "5000")
    doc = finished(coordinator)
    assert doc["settings"]["stop_reason"] == "budget of 5,000 evaluations spent"
    assert [(i["island"], i["status"]) for i in doc["islands"]] == [("first", "left")]
    assert early.wait(30) == 0 and "waiting up to 60 s (--wait)" in err.text()


def test_an_island_whose_coordinator_never_comes_back_stops_after_its_wait(spawn, tmp_path):
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "g.sqlite"
    coordinator = start_coordinator(spawn, endpoint, "gone", db, tmp_path / "out", "--algos", "pso", *SMALL, "--time", "600")
    island, err = start_island(spawn, endpoint, "gone", "orphan", db, "--wait", "3")
    wait_for(lambda: rows_of(db, "orphan") > 10, 60, "the island's history")
    coordinator.send_signal(signal.SIGKILL)
    assert island.wait(90) == 0  # its budget is open-ended (--time): only the wait ends it
    err.thread.join(10)
    text = err.text()
    assert "the coordinator of campaign 'gone' has been silent for" in text and "waiting up to 3 s (--wait)" in text
    assert "island orphan: the coordinator was silent for" in text and "; stopping" in text
    assert "did not confirm its history" in text


def test_mixed_islands_with_an_evaluation_budget_all_search_until_the_coordinator_stops(spawn, tmp_path):
    """GA islands iterate many times faster than PSO ones: with a budget in evaluations none stops on
    its own iteration budget; every island searches, and migrates, until the coordinator's stop."""
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "m.sqlite"
    coordinator = start_coordinator(spawn, endpoint, "mixed", db, tmp_path / "out", "--algos", "ga,pso", *SMALL, "--min-islands", "4", "--evaluations", "15000")
    islands = [start_island(spawn, endpoint, "mixed", f"{algo}-{i}", db, "--algo", algo) for i, algo in enumerate(["ga", "pso", "ga", "pso"])]
    doc = finished(coordinator)
    assert doc["settings"]["stop_reason"] == "budget of 15,000 evaluations spent" and doc["settings"]["until_stopped"] is True
    for p, err in islands:
        assert p.wait(30) == 0
        err.thread.join(10)
        assert "; stopped by the coordinator;" in err.text() and "own budget spent" not in err.text()
    assert all(i["final"] and i["received"] > 0 for i in doc["islands"])
