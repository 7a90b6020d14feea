"""Campaigns end to end: ``hysid campaign`` (processes over Zenoh and --single-node),
``hysid coordinator`` + ``hysid island`` by hand, the fallback, and CLI errors."""

from __future__ import annotations

import csv
import json
import os
import signal
import socket
import subprocess
import threading

import numpy as np
import pytest

from coordinator.launch import free_port, island_specs, run_campaign
from coordinator.state import Coordinator
from coordinator.store import Store
from hysid.cli import main
from hysid_model.errors import HysidWarning
from hysid_model.synth import TRUE_PARAMS, synth_loops
from island.config import CampaignConfig
from island.migration import Migration
from support import PSO_ISLANDS, coordinator_args, events, history_iterations, hysid, query, rows_of, secret_file, sizes, wait_for

SMALL = ["--population", "20", "--initial", "40", "--iterations", "15", "--interval", "5"]
FIT_KEYS = {"params", "stderr", "fitness", "evaluations", "history"}


def json_of(capsys, out, *argv: str) -> dict:
    """``hysid ARGV --json --quiet --out OUT`` run in this process, which must succeed: its JSON document."""
    assert main([*argv, "--json", "--quiet", "--out", str(out)]) == 0, capsys.readouterr().err
    return json.loads(capsys.readouterr().out)


@pytest.mark.slow  # over 3 s (fast lane, 2 cores, 2026-11-29)
def test_single_node_campaign_gives_the_fit_document_plus_islands_and_migrations(tmp_path, capsys):
    out = tmp_path / "out"
    doc = json_of(capsys, out, "campaign", "--single-node", "--islands", "3", *SMALL)
    assert FIT_KEYS | {"islands", "migrations"} <= set(doc)
    for name, true in TRUE_PARAMS.items():  # noiseless data: the polished global best is the truth
        assert doc["params"][name] == pytest.approx(true, rel=1e-6)
    assert [i["island"] for i in doc["islands"]] == ["island-0", "island-1", "island-2"]  # by index: the share may move an island
    assert all(i["status"] == "left" and i["iterations"] == 15 for i in doc["islands"])
    assert doc["migrations"]["messages"] == 6  # 3 islands x migrations after iterations 5 and 10
    migrants = query(out / "campaign.sqlite", "SELECT SUM(n) FROM migrations")[0][0]
    assert 6 <= migrants <= 12  # 2 per message; 1 from an island handed over from GA to PSO with one distinct best (the staged share)
    assert doc["migrations"]["received"] == migrants and doc["migrations"]["rejected"] == 0  # a ring: each message taken by one island
    assert doc["evaluations"] == sum(i["evaluations"] for i in doc["islands"]) + doc["runs"][doc["best_run"]]["polish"]["evaluations"]
    assert history_iterations(out / "campaign.sqlite") == {i: list(range(16)) for i in ("island-0", "island-1", "island-2")}
    assert json.loads((out / "result.json").read_text())["islands"] == doc["islands"]
    assert (out / "report.md").is_file() and (out / "convergence.png").is_file()
    report = (out / "report.md").read_text()  # why it stopped (the summary), then its own section: migrations, moves, islands
    section = report[report.index("## Islands and migrations") : report.index("## Model vs measured loops")]
    assert "- **Stopped**: every island finished." in report and f"Migrations: {doc['migrations']['messages']} messages (ring, every 5" in section
    assert "- share: staged" in section and all(f"| `{i['island']}` | {' -> '.join(i['algorithms']).upper()} |" in section for i in doc["islands"])
    assert [i["algorithms"][0] for i in doc["islands"]] == ["ga", "pso", "ga"] and all(i["algorithms"][-1] == i["algo"] for i in doc["islands"])


@pytest.mark.slow
def test_campaign_of_island_processes_over_zenoh(tmp_path):
    out = tmp_path / "out"
    proc = subprocess.run(
        hysid("campaign", "--islands", "2", *PSO_ISLANDS, "--iterations", "200", "--json", "--no-figures", "--out", str(out)),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert doc["fitness"] < 1e-20
    assert {i["island"]: (i["algo"], i["status"]) for i in doc["islands"]} == {"island-0": ("pso", "left"), "island-1": ("pso", "left")}
    assert doc["migrations"]["messages"] == 2 * 39  # after iterations 5, 10, ..., 195
    assert doc["migrations"]["received"] > 0  # how many arrive in time is up to the network
    assert "members" not in proc.stderr  # --json: no live progress (tests/test_progress.py has it)
    db = out / "campaign.sqlite"
    assert history_iterations(db) == {"island-0": list(range(201)), "island-1": list(range(201))}
    assert sorted(events(db)) == sorted([("island-0", "join"), ("island-1", "join"), ("island-0", "left"), ("island-1", "left")])


@pytest.mark.slow
def test_an_honest_campaign_of_two_island_processes_counts_no_message_rejected_or_unlisted(tmp_path):
    """The main job with two islands of 400 iterations (GA and PSO, the staged share; 20 members each, drawn from 40:
    the messages of the default's 80 migrations per island at a tenth of its work): no island counts a message
    rejected, nor one that waited for the roster in vain (the roster goes out at every join, before the joiner hears
    it joined), the coordinator rejects none, and every move of the share is followed."""
    out = tmp_path / "out"
    proc = subprocess.run(
        hysid("campaign", "--islands", "2", *sizes(20, 40, 400), "--json", "--no-figures", "--out", str(out)), capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert [(i["island"], i["rejected"], i["unlisted"]) for i in doc["islands"]] == [("island-0", 0, 0), ("island-1", 0, 0)]
    assert doc["migrations"]["rejected"] == 0 and doc["migrations"]["unlisted"] == 0 and doc["migrations"]["received"] > 0
    assert "not followed" not in (out / "report.md").read_text()


def test_campaign_falls_back_to_one_process_when_zenoh_cannot_open(tmp_path):
    loops = synth_loops(n_points=30)
    sizes = {"ga": {"population": 10, "initial_population": 20, "iterations": 6}, "pso": {"population": 10, "initial_population": 20, "iterations": 6}}
    config = CampaignConfig.create(loops, name="fb", options=sizes, migration=Migration(interval=2), min_islands=2)
    store = Store(tmp_path / "c.sqlite")
    with socket.socket() as busy, pytest.warns(HysidWarning) as caught:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        endpoint = f"tcp/127.0.0.1:{busy.getsockname()[1]}"
        result = run_campaign(Coordinator(store, config, loops), island_specs(2, ["ga", "pso"], 0), endpoint=endpoint)
    message = str(caught[0].message)
    assert message.startswith(f"cannot open Zenoh session (listen {endpoint}):")
    assert message.endswith("running every island in this process instead (single node)")
    assert [i["status"] for i in result.islands] == ["left", "left"]
    assert result.migrations["messages"] == 4


@pytest.mark.slow
def test_coordinator_and_islands_by_hand_a_late_joiner_gets_the_best(spawn, tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    db = tmp_path / "lj.sqlite"
    coordinator = spawn(
        *coordinator_args(endpoint, "lj", db, tmp_path / "out"),
        *PSO_ISLANDS,
        "--iterations",
        "10000000",
        "--interval",
        "1000000",
        "--time-limit",
        "120",
        "--json",
        "--quiet",
    )
    secret = ["--secret-file", secret_file(db, "lj")]
    early = subprocess.Popen(hysid("island", "--connect", endpoint, "--campaign", "lj", "--id", "early", "--quiet", *secret), stderr=subprocess.PIPE, text=True)
    late = None
    try:
        wait_for(lambda: rows_of(db, "early") > 50, 60, "the first island's history")
        late = subprocess.Popen(
            hysid("island", "--connect", endpoint, "--campaign", "lj", "--id", "late", "--seed", "99", *secret), stderr=subprocess.PIPE, text=True
        )
        wait_for(lambda: rows_of(db, "late") > 50, 60, "the late island's history")
        coordinator.send_signal(signal.SIGINT)  # Ctrl-C: stop the campaign and report
        out, err = coordinator.communicate(timeout=60)
        assert coordinator.returncode == 130 and err.endswith("hysid: error: interrupted\n"), err
        assert early.wait(timeout=30) == 0 and late.wait(timeout=30) == 0
        assert "island late (PSO, seed 99)" in late.stderr.read()
    finally:
        for p in (coordinator, early, late):
            if p is not None:
                p.kill()
                p.communicate()
    doc = json.loads(out)
    islands = {i["island"]: i for i in doc["islands"]}
    assert islands["late"]["received"] == 1 and islands["late"]["taken"] == 1  # the global best, taken in
    assert islands["early"]["received"] == 0  # isolated islands: --interval 0
    assert doc["settings"]["stop_reason"] == "interrupted" and "hysid: stopping: waiting for 2 islands' last rows" in err
    assert all(i["status"] == "stopped" and i["final"] for i in doc["islands"])  # by the user, each with its last rows


@pytest.mark.slow  # over 3 s
def test_ctrl_c_mid_campaign_reports_it_interrupted_and_exits_130(tmp_path, capsys):
    """Ctrl-C once the islands search: the campaign stops them, writes its report marked interrupted, and exits 130
    (as Ctrl-C while it starts does), so that a script tells an interrupted campaign from a finished one."""
    out = tmp_path / "o"
    db = out / "campaign.sqlite"

    def ctrl_c_once_searching() -> None:
        wait_for(lambda: db.is_file() and rows_of(db, "island-1") > 5, 60, "the islands to search")
        os.kill(os.getpid(), signal.SIGINT)

    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # a user's Ctrl-C, also where the runner ignores SIGINT
    user = threading.Thread(target=ctrl_c_once_searching)
    user.start()
    try:
        code = main(["campaign", "--single-node", "--islands", "2", *PSO_ISLANDS, "--time", "300", "--no-polish", "--json", "--quiet", "--out", str(out)])
    finally:
        user.join()
        signal.signal(signal.SIGINT, previous)
    captured = capsys.readouterr()
    assert code == 130 and captured.err.endswith("hysid: error: interrupted\n"), captured.err
    assert captured.err.startswith("hysid: stopping: waiting for 2 islands' last rows (Ctrl-C again to leave now)\n")  # also --quiet
    doc = json.loads(captured.out)
    assert doc["settings"]["stop_reason"] == "interrupted" and [i["status"] for i in doc["islands"]] == ["stopped", "stopped"]
    report = (out / "report.md").read_text()
    assert report.startswith("# hysid campaign (interrupted): synth") and "- **Stopped**: interrupted." in report
    assert "not drawn, the campaign was interrupted" in report and not list(out.glob("*.png"))  # out in seconds


@pytest.mark.parametrize(
    "argv, message",
    [
        (["campaign", "--algos", "ga,cmaes"], "--algos 'ga,cmaes': give a comma-separated list of ga, pso"),
        (["campaign", "--islands", "0"], "--islands 0: a campaign needs at least one island"),
        (["campaign", "--topology", "star"], "--topology 'star': must be one of ring, full, random"),
        (["campaign", "--share", "greedy"], "--share 'greedy': share must be one of staged, adaptive, fixed"),
        (["coordinator", "--share", "greedy"], "--share 'greedy': share must be one of staged, adaptive, fixed"),
        (["campaign", "--initial", "10"], "--initial 10: must be at least --population 200"),
        (["coordinator", "--resume"], "--resume needs --db FILE"),
        (["coordinator", "--campaign", "a/b"], "--campaign 'a/b': must be 1-64 characters"),
        (["coordinator", "--listen", "localhost"], "--listen 'localhost': a Zenoh endpoint looks like tcp/127.0.0.1:7447"),
        (["island", "--algo", "de"], "--algo 'de': unknown algorithm; choose one of ga, pso"),
        (["island", "--connect", "tcp/127.0.0.1:1", "--wait", "0.5"], "no campaign secret; give --secret-file"),
        (["island", "--secret-file", "/nonexistent/x.secret", "--wait", "0"], "--secret-file /nonexistent/x.secret: no such file"),
    ],
)
def test_bad_arguments_are_one_line_errors(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.delenv("HYSID_SECRET", raising=False)
    monkeypatch.delenv("HYSID_SECRET_FILE", raising=False)
    assert main([*argv, "--out", str(tmp_path / "o")] if argv[0] != "island" else argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("hysid: error: ") and message in err and err.count("\n") == 1


def test_a_stored_campaign_is_never_overwritten(tmp_path, capsys):
    db = tmp_path / "c.sqlite"
    Store(db).create_campaign("default", "synth", b"cfg")
    assert main(["coordinator", "--db", str(db), "--out", str(tmp_path / "o")]) == 2
    assert "campaign 'default' already exists; use --resume" in capsys.readouterr().err
    assert Store(db).campaign("default") == ("synth", b"cfg", "running")


@pytest.mark.slow
@pytest.mark.parametrize(
    "rule, reason",
    [(["--target", "1e-6"], "target fitness 1e-06 reached"), (["--stall", "3000"], "no improvement in 3,000 evaluations")],
)
def test_target_and_stall_rules_stop_an_endless_campaign(rule, reason, tmp_path, capsys):
    doc = json_of(
        capsys, tmp_path / "o", "campaign", "--single-node", "--islands", "2", *PSO_ISLANDS, "--iterations", "10000000", *rule, "--no-polish", "--no-figures"
    )
    assert doc["settings"]["stop_reason"] == reason
    assert all(i["status"] == "left" and i["final"] for i in doc["islands"])
    if rule[0] == "--target":
        assert doc["fitness"] <= 1e-6


@pytest.mark.slow
def test_resuming_a_finished_campaign_reports_it_again_from_the_database(tmp_path, capsys):
    db = tmp_path / "c.sqlite"
    first = json_of(capsys, tmp_path / "a", "campaign", "--single-node", "--islands", "2", *SMALL, "--db", str(db), "--no-figures")
    again = json_of(
        capsys,
        tmp_path / "b",
        "coordinator",
        "--resume",
        "--db",
        str(db),
        "--campaign",
        "campaign",
        "--listen",
        f"tcp/127.0.0.1:{free_port()}",
        "--no-figures",
        "--csv",
    )
    assert again["settings"]["stop_reason"] == "every island finished"
    assert again["islands"] == first["islands"] and again["params"] == pytest.approx(first["params"], rel=1e-9)
    assert again["dataset"]["true_params"] == TRUE_PARAMS  # the loop set's metadata travelled through the database
    with open(tmp_path / "b" / "islands.csv", newline="") as f:  # --csv: the coordinator's tables, as a campaign's
        assert [row["island"] for row in csv.DictReader(f)] == [i["island"] for i in first["islands"]]


def shadow_package(where):
    """A folder ``hysid/`` in ``where`` that fails on import, as the parent folder of a clone named hysid would."""
    fake = where / "hysid"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise SystemExit('imported the hysid folder of the working directory')\n")
    (fake / "__main__.py").write_text("")
    return where


@pytest.mark.slow
def test_a_folder_named_hysid_in_the_working_directory_does_not_shadow_the_islands_package(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(shadow_package(tmp_path / "parent"))
    doc = json_of(capsys, tmp_path / "o", "campaign", "--islands", "2", "--algos", "pso", *SMALL, "--no-polish", "--no-figures")
    assert [(i["island"], i["iterations"], i["status"]) for i in doc["islands"]] == [("island-0", 15, "left"), ("island-1", 15, "left")]


@pytest.mark.slow
def test_a_failed_campaign_leaves_no_directory_that_blocks_the_next_run(tmp_path, monkeypatch, capsys):
    out = tmp_path / "o"
    argv = ["campaign", "--islands", "1", "--algos", "pso", *SMALL, "--no-polish", "--no-figures", "--json", "--quiet", "--out", str(out)]
    monkeypatch.setenv("PYTHONPATH", str(shadow_package(tmp_path / "broken")))  # every island process fails at its start
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("hysid: error: ") and "imported the hysid folder" in err
    assert not out.exists()  # nothing was stored: nothing is kept
    monkeypatch.delenv("PYTHONPATH")
    assert main(argv) == 0, capsys.readouterr().err


def test_an_unfinished_campaign_database_in_out_is_kept_and_named(tmp_path, capsys):
    from hysid.cli.campaign import discard_failed

    out = tmp_path / "o"
    db = out / "campaign.sqlite"
    loops = synth_loops(n_points=30)
    store = Store(db)
    Coordinator(store, CampaignConfig.create(loops, name="campaign"), loops)
    store.add_history("campaign", "a", "r", np.array([[0, 1.0, 10, 0.1]]))
    store.close()
    discard_failed(out, db, "campaign")  # history: kept
    assert db.is_file()
    assert main(["campaign", "--islands", "1", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"holds the database of a campaign that did not finish ({db}, no report.md)" in err
    assert f"hysid coordinator --resume --db {db}" in err and err.count("\n") == 1


@pytest.mark.slow  # over 3 s
def test_an_evaluation_budget_keeps_ga_and_pso_islands_searching_together_until_the_stop(tmp_path, capsys):
    argv = ["campaign", "--single-node", "--islands", "2", "--algos", "ga,pso", "--share", "fixed", "--population", "20", "--initial", "40", "--interval", "5"]
    doc = json_of(capsys, tmp_path / "o", *argv, "--evaluations", "6000", "--no-polish", "--no-figures")
    assert doc["settings"]["stop_reason"] == "budget of 6,000 evaluations spent" and doc["settings"]["until_stopped"] is True
    assert doc["settings"]["share"] == "fixed" and doc["settings"]["moves"] == []
    ga, pso = doc["islands"]
    assert ga["algo"] == "ga" and pso["algo"] == "pso"
    assert abs(ga["iterations"] - pso["iterations"]) <= 5 and ga["iterations"] > 60  # in step to the end, past the old default of 60
    assert all(i["final"] and i["status"] == "left" and i["received"] > 0 for i in doc["islands"])


@pytest.mark.slow  # over 3 s
def test_iterations_given_stay_each_islands_own_budget(tmp_path, capsys):
    doc = json_of(capsys, tmp_path / "o", "campaign", "--single-node", "--islands", "2", *SMALL, "--time", "600", "--no-polish", "--no-figures")
    assert doc["settings"]["stop_reason"] == "every island finished" and doc["settings"]["until_stopped"] is False
    assert [i["iterations"] for i in doc["islands"]] == [15, 15]


def test_islands_search_until_stopped_by_default_only_with_a_budget_that_surely_ends():
    from hysid.campaigns import islands_until_stopped
    from island.termination import Termination

    assert islands_until_stopped(Termination(budget=10_000), None)
    assert islands_until_stopped(Termination(time_limit_s=60.0), {"pso": {"population": 20}})
    assert not islands_until_stopped(Termination(budget=10_000), {"ga": {"iterations": 30}})
    assert not islands_until_stopped(Termination(target=1e-6, stall=5000), None)  # might never fire
    assert not islands_until_stopped(None, None)
