"""A campaign's database: ``hysid watch`` (live, read-only) and ``hysid report`` (the report again, from the file alone)."""

from __future__ import annotations

import hashlib
import json
import re
import signal
import subprocess
import time

import pytest

from coordinator.queries import COORDINATOR_LEASE_S
from coordinator.store import Store
from hysid.campaigns import CampaignResult
from hysid.cli import main
from support import hysid, interruptible, rows_of, screen_of, wait_for

SMALL = ["--population", "20", "--initial", "40"]
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A finished single-node campaign, reported without its figures: its database and its own result document."""
    out = tmp_path_factory.mktemp("campaign") / "out"
    assert main(["campaign", "--single-node", "--islands", "3", *SMALL, "--iterations", "12", "--no-figures", "--quiet", "--out", str(out)]) == 0
    return out / "campaign.sqlite", json.loads((out / "result.json").read_text())


def digest(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.mark.slow  # over 3 s (fast lane, 2 cores, 2026-11-29)
def test_report_rebuilds_a_campaign_from_its_database_alone(finished, tmp_path, capsys):
    db, original = finished
    first = (db.parent / "report.md").read_text()  # --no-figures: the report says why, and where they are drawn
    assert f"not drawn, the report was asked for without figures (`hysid report {db}` draws them)" in first and not list(db.parent.glob("*.png"))
    before = digest(db)
    capsys.readouterr()
    assert main(["report", str(db), "--json", "--out", str(tmp_path / "again")]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["params"] == pytest.approx(original["params"], rel=1e-9) and doc["stderr"] == pytest.approx(original["stderr"], rel=1e-6)
    assert doc["islands"] == original["islands"] and doc["migrations"] == original["migrations"]
    assert doc["settings"]["stop_reason"] == "every island finished" and doc["settings"]["db"] == str(db)
    assert doc["dataset"] == original["dataset"]  # the loop set came from the configuration message
    report = tmp_path / "again" / "report.md"
    assert report.read_text().startswith("# hysid campaign: synth")
    assert all((tmp_path / "again" / f).is_file() for f in ("convergence.png", "loops.png", "residuals.png", "half_power.png"))
    assert digest(db) == before  # read only
    result = CampaignResult.from_database(db)
    assert [i["island"] for i in result.islands] == ["island-0", "island-1", "island-2"]


def test_watch_once_shows_islands_migrations_and_members(finished, capsys):
    db, original = finished
    assert main(["watch", str(db), "--once"]) == 0
    screen = capsys.readouterr().out
    assert screen.startswith("campaign 'campaign' on synth: stopped (every island finished) after ")
    assert f"migrant messages {original['migrations']['messages']}" in screen
    for island in original["islands"]:
        row = next(line for line in screen.splitlines() if line.strip().startswith(island["island"] + " "))
        assert island["algo"].upper() in row and " left " in row and f"{island['received']}/{island['taken']}" in row
        assert re.search(r"[▁▂▃▄▅▆▇█]{13}$", row)  # the best fitness over iterations 0..12
    assert "members: 0 alive, 3 left, 0 lost" in screen


def test_watch_and_report_name_what_is_wrong_and_create_nothing(finished, tmp_path, capsys):
    missing = tmp_path / "missing.sqlite"
    assert main(["watch", str(missing)]) == 2
    assert capsys.readouterr().err == f"hysid: error: {missing}: no such campaign database\n" and not missing.exists()
    assert main(["report", str(finished[0]), "--campaign", "other", "--out", str(tmp_path / "r")]) == 2
    assert "no campaign 'other' (stored: 'campaign')" in capsys.readouterr().err and not (tmp_path / "r").exists()
    junk = tmp_path / "junk.sqlite"
    junk.write_text("not a database\n")
    assert main(["watch", str(junk), "--once"]) == 2
    assert "not a campaign database" in capsys.readouterr().err and junk.read_text() == "not a database\n"


@pytest.mark.slow  # over 3 s (fast lane, 2 cores, 2026-11-29)
def test_watch_and_report_of_a_finished_campaign_create_no_file_and_take_its_output_directory(finished, tmp_path, capsys):
    """The README's "never written, nor created": watching or reporting a finished campaign leaves no -wal or -shm
    file beside its database (a read-only reader of a WAL database would create both); the campaign's output
    directory names its database."""
    db, original = finished
    before = digest(db)
    assert main(["watch", str(db), "--once"]) == 0
    assert not [p.name for p in db.parent.iterdir() if p.name.endswith(("-wal", "-shm"))]
    assert main(["watch", str(db.parent), "--once"]) == 0
    capsys.readouterr()
    assert main(["report", str(db.parent), "--json", "--out", str(tmp_path / "again")]) == 0
    assert json.loads(capsys.readouterr().out)["params"] == pytest.approx(original["params"], rel=1e-9)
    assert not [p.name for p in db.parent.iterdir() if p.name.endswith(("-wal", "-shm"))] and digest(db) == before
    assert main(["report", str(tmp_path), "--out", str(tmp_path / "r")]) == 2
    assert capsys.readouterr().err == (
        f"hysid: error: {tmp_path}: a directory without campaign.sqlite; give the campaign database (--db of the campaign, or OUT/campaign.sqlite)\n"
    )


def start_campaign(tmp_path, islands: int = 2):
    db = tmp_path / "out" / "campaign.sqlite"
    proc = subprocess.Popen(
        hysid(
            "campaign",
            "--single-node",
            "--islands",
            str(islands),
            "--algos",
            "pso",
            *SMALL,
            "--iterations",
            "10000000",
            "--time-limit",
            "300",
            "--quiet",
            "--json",
            "--out",
            str(tmp_path / "out"),
        ),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=interruptible,
    )
    wait_for(lambda: all(rows_of(db, f"island-{i}") > 20 for i in range(islands)), 120, "both islands' history")
    return db, proc


@pytest.mark.slow
def test_watch_follows_a_running_campaign_on_a_terminal_until_it_stops(tmp_path):
    db, campaign = start_campaign(tmp_path)
    stopped = []

    def stop_once_seen_running(text: str) -> bool:
        screen = ANSI.sub("", text)
        if not stopped and "running after" in screen and "island-1" in screen and " alive " in screen:
            campaign.send_signal(signal.SIGINT)  # Ctrl-C on the campaign: it stops and reports
            stopped.append(True)
        return False

    try:
        code, text = screen_of(hysid("watch", str(db), "--interval", "0.2"), 180, until=stop_once_seen_running)
        out, err = campaign.communicate(timeout=120)
    finally:
        campaign.kill()
        campaign.wait()
    assert stopped and code == 0  # watch ended by itself when the campaign stopped
    screen = ANSI.sub("", text)
    assert "campaign 'campaign' on synth: running after" in screen and "global best " in screen
    assert re.search(r"island-0\s+PSO\s+alive\s+\d+", screen) and re.search(r"island-1\s+PSO\s+alive\s+\d+", screen)
    final = screen[screen.rindex("campaign 'campaign' on synth: stopped (interrupted)") :]
    assert re.search(r"island-0\s+PSO\s+stopped\s+\d+", final) and "members: 0 alive, 0 left, 2 stopped by the user, 0 lost" in final
    assert campaign.returncode == 130 and err.endswith("hysid: error: interrupted\n"), err  # interrupted, and reported
    assert json.loads(out)["settings"]["stop_reason"] == "interrupted"


@pytest.mark.slow
def test_watch_and_report_of_a_campaign_whose_coordinator_was_killed(tmp_path, capsys):
    """A second run on the --out of a running campaign is refused as such. Its coordinator SIGKILLed: once its process is
    gone (or it committed nothing for a lease), watch and report say the campaign was interrupted, since its last
    heartbeat, and its islands' state unknown; watch shows it and ends instead of refreshing a 'running' campaign; the
    --out is then one to --resume."""
    db, campaign = start_campaign(tmp_path)
    store = Store.read_only(db)
    assert store.gone_since("campaign") is None  # running: it commits
    assert main(["campaign", "--single-node", "--out", str(db.parent)]) == 2  # a second run on the same --out, named as such
    assert capsys.readouterr().err == (
        f"hysid: error: --out {db.parent}: is the output directory of campaign 'campaign', which is still running "
        f"(its coordinator writes {db}): two runs cannot share one --out; choose a new directory (nothing was written)\n"
    )
    campaign.kill()  # SIGKILL: no stop, no result, the database left as it was
    campaign.communicate()
    wait_for(lambda: store.gone_since("campaign") is not None, 3 * COORDINATOR_LEASE_S, "the coordinator's lease to run out")
    since = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(store.gone_since("campaign")))
    gone = f"its coordinator is gone (last heartbeat {since}) and left the campaign running"
    store.close()
    code, text = screen_of(hysid("watch", str(db), "--interval", "0.2"), 60)
    screen = ANSI.sub("", text)
    assert code == 0 and f"campaign 'campaign' on synth: interrupted ({gone}) after " in screen
    assert re.search(r"island-0\s+PSO\s+unknown\s+\d+", screen) and "members: 0 alive, 0 left, 0 lost, 2 unknown (its coordinator gone)" in screen
    assert main(["report", str(db), "--out", str(tmp_path / "r")]) == 0
    summary = capsys.readouterr().out
    assert f"stopped because interrupted: {gone}" in summary
    assert re.search(r"island-0 +PSO +seed 0 +unknown +best ", summary) and (tmp_path / "r" / "report.md").is_file()
    assert main(["campaign", "--single-node", "--out", str(db.parent)]) == 2
    assert "holds the database of a campaign that did not finish" in capsys.readouterr().err
