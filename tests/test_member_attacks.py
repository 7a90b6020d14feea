"""No holder of a secret an island is given outweighs the campaign: the attack of a holder of the campaign secret who
joins 16 runs claiming the most each can plausibly have done, mounted with the secrets a real campaign hands out:

* the one an island process of ``hysid campaign`` got in its environment (read from ``/proc``, as another process of
  its user can): a member secret of that process alone, so the 16 runs count for that one member;
* the shared secret that ``hysid coordinator`` writes beside its database, in a campaign whose islands were started
  by hand with member secrets of their own (``--member``): the 16 runs count for the one shared member.

Either way the attacker's accepted claims pass three budgets while the honest islands have spent less than half of
one, yet the campaign goes on (a member counts no further than the other members together), and a late honest island
still joins and searches. Real processes, real Zenoh on loopback, real SQLite; the attacker has its own Zenoh session.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import signal
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from coordinator.histories import HistoryChecks
from coordinator.launch import free_port
from hysid_model.errors import HysidInputError
from island.config import decode_config
from island.island_messages import History, encode_history
from island.joining import fetch_config, join
from island.secret import SECRET_ENV, CampaignSecret, member_path, secret_path
from island.session import open_session, session_config
from support import hysid, interruptible, query, rows_of, wait_for
from test_faults import coordinator

pytestmark = [pytest.mark.slow, pytest.mark.timeout(240)]  # processes and an attack of seconds

BUDGET = 4_000_000
SMALL = ["--algos", "pso", "--population", "20", "--initial", "40", "--no-polish", "--json", "--quiet"]
STATS = dict.fromkeys(("sent", "received", "taken", "rejected"), 0)
CLAIMS = 0.95 * 0.93 ** np.arange(16)
"""Of the most evaluations and iterations a run can have reached since it joined (the coordinator's bound, at the rate
measured here as the coordinator measures it there), what each of the 16 attacking runs claims: 95 % down to 32 %, so
that whatever the coordinator measured on its loaded host, the runs claiming at most its bound are taken at their word."""


class Sybil:
    """Runs ``ids`` (16) joined with ``secret`` from an attacker's own Zenoh session, each sending a history every half
    second that claims its part (:data:`CLAIMS`) of the most it can plausibly have done (until :meth:`leave`)."""

    def __init__(self, endpoint: str, secret: CampaignSecret, ids: list[str]) -> None:
        self.session = open_session(session_config("client", connect=[endpoint], connect_timeout_s=60.0), endpoint)
        self.campaign = secret.campaign
        config, loops = decode_config(fetch_config(self.session, secret, 60), secret.campaign)
        objective = config.objective(loops)
        self.checks = HistoryChecks(config, objective, range(len(ids) + 3))  # the coordinator's own bounds
        self.checks.rate("pso")
        self.x = objective.bounds.mean(axis=1)
        self.f = float(objective(self.x[None, :])[0])
        self.runs = [(join(self.session, self.campaign, island, "pso", 100 + k, secret, 30.0), time.time(), 100 + k) for k, island in enumerate(ids)]
        self.publishers = [self.session.declare_publisher(f"hysid/{self.campaign}/history/{c.island}") for c, _, _ in self.runs]
        self.stop = threading.Event()
        self.seq = 0
        self.thread = threading.Thread(target=self._claim, daemon=True)
        self.thread.start()

    def _claim(self) -> None:
        while not self.stop.is_set():
            for (credentials, joined, seed), publisher, claim in zip(self.runs, self.publishers, CLAIMS):
                most, iterations = self.checks.effort_bound(["pso"], time.time() - joined)
                it = min(int(claim * iterations), self.checks.optimizer("pso").iterations)
                evaluations = min(claim * most, float(self.checks.evaluation_bound("pso", np.array([float(it)]))[0]))
                rows = np.array([[it, self.f, int(evaluations), 0.0]])
                publisher.put(
                    encode_history(
                        History(self.campaign, credentials.island, credentials.run, "pso", seed, rows, self.x, self.f, STATS, seq=self.seq), credentials
                    )
                )
            self.seq += 1
            self.stop.wait(0.5)

    def admitted(self, secret: CampaignSecret, island: str) -> bool:
        """Whether the coordinator admits ``island`` with ``secret`` (it answers a proof that does not hold with silence)."""
        try:
            join(self.session, self.campaign, island, "pso", 7, secret, 1.0)
        except HysidInputError as exc:
            assert "no coordinator admitted" in str(exc)
            return False
        return True

    def leave(self) -> None:
        """Stop claiming; each run sends its final history (its leave), so that a stopping coordinator need not wait for it."""
        self.stop.set()
        self.thread.join(10)
        for (credentials, _, seed), publisher in zip(self.runs, self.publishers):
            publisher.put(
                encode_history(
                    History(self.campaign, credentials.island, credentials.run, "pso", seed, np.empty((0, 4)), self.x, self.f, STATS, final=True, seq=self.seq),
                    credentials,
                )
            )

    def close(self) -> None:
        self.stop.set()
        self.thread.join(10)
        self.session.close()


def made_from(secret: CampaignSecret, member: str) -> CampaignSecret:
    """What a holder of ``secret`` can compute toward ``member``'s secret: an HMAC of the name under its admission secret
    (how member secrets were made before they came from a key only the coordinator holds)."""
    admission = hmac.new(secret.admission, b"hysid member\x00" + member.encode(), hashlib.sha256).digest()
    return CampaignSecret(secret.campaign, admission, secret.coordinator, member)


def effort(db: Path, attacker: str) -> tuple[int, int]:
    """Evaluations of the attacker's runs (ids beginning with ``attacker``) and of everyone else's, as last accepted."""
    ((theirs, ours),) = query(
        db,
        "SELECT coalesce(sum(CASE WHEN island LIKE ? THEN evaluations END), 0), "
        "coalesce(sum(CASE WHEN island NOT LIKE ? THEN evaluations END), 0) FROM islands",
        f"{attacker}%",
        f"{attacker}%",
    )
    return theirs, ours


def outlast(campaign: subprocess.Popen, db: Path, sybil: Sybil, attacker: str, late: subprocess.Popen) -> dict:
    """The attack's claims accepted past three budgets, with the honest islands below half of one: the campaign still
    runs, the late honest island joins and searches, the campaign still runs; then the attacker leaves, and Ctrl-C: its
    report."""

    def running() -> bool:
        assert campaign.poll() is None and query(db, "SELECT status, stop_reason FROM campaigns") == [("running", None)], query(
            db, "SELECT status, stop_reason FROM campaigns"
        )
        return True

    wait_for(lambda: running() and effort(db, attacker)[0] > 3 * BUDGET, 90, "the attacker's claims to pass three budgets")
    claimed, honest = effort(db, attacker)
    assert honest < BUDGET / 2, (claimed, honest)  # without the members' bound these claims alone would end it
    wait_for(lambda: running() and rows_of(db, "late") > 5, 90, "the late honest island's history")
    running()
    sybil.leave()
    campaign.send_signal(signal.SIGINT)
    out, _err = campaign.communicate(timeout=120)
    assert late.wait(60) == 0
    return json.loads(out)


def test_the_secret_of_one_launched_island_process_is_one_member_and_cannot_end_the_campaign(tmp_path):
    """``hysid campaign --islands 2``: each island process has a member secret of its own in its environment. Another
    process of the user reads one (``/proc/PID/environ``), joins 16 runs with it (ids ``<member>-x<k>``: its member's)
    claiming the plausible maximum: they count for that member only, which counts no further than the other island."""
    out = tmp_path / "out"
    campaign = subprocess.Popen(
        hysid("campaign", "--islands", "2", "--budget", str(BUDGET), "--out", str(out), "--no-figures", *SMALL),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=interruptible,
    )
    db, sybil, late = out / "campaign.sqlite", None, None
    try:
        wait_for(lambda: db.exists() and rows_of(db, "island-0") > 5 and rows_of(db, "island-1") > 5, 120, "the islands to search")
        env, argv = island_processes(campaign.pid)["island-1"]
        stolen = CampaignSecret.parse(env[SECRET_ENV], "/proc/PID/environ")
        endpoint = argv[argv.index("--connect") + 1]
        assert stolen.member == argv[argv.index("--id") + 1] and stolen.text() != secret_path(db, "campaign").read_text().strip()
        sybil = Sybil(endpoint, stolen, [f"{stolen.member}-x{k}" for k in range(16)])
        assert query(db, "SELECT DISTINCT member FROM runs WHERE island LIKE ?", f"{stolen.member}-x%") == [(stolen.member,)]
        assert not sybil.admitted(made_from(stolen, "other"), "other")  # nor does it make another member's secret
        late = subprocess.Popen(
            hysid("island", "--connect", endpoint, "--campaign", "campaign", "--id", "late", "--quiet", "--secret-file", str(secret_path(db, "campaign"))),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        doc = outlast(campaign, db, sybil, f"{stolen.member}-x", late)
    finally:
        for p in (campaign, late):
            if p is not None and p.poll() is None:
                p.kill()
                p.communicate()
        if sybil is not None:
            sybil.close()
    assert doc["settings"]["stop_reason"] == "interrupted" and "late" in {i["island"] for i in doc["islands"]}


def test_the_shared_secret_of_a_coordinator_is_one_member_and_cannot_end_the_campaign(spawn, tmp_path):
    """``hysid coordinator --member h1 --member h2 --member late``, islands started by hand with their member secrets;
    the attacker holds the shared secret the coordinator wrote beside its database and joins 16 runs with it: they
    count for the one shared member."""
    endpoint, db = f"tcp/127.0.0.1:{free_port()}", tmp_path / "hand.sqlite"
    coord = coordinator(
        spawn, endpoint, "hand", db, "--min-islands", "2", "--budget", str(BUDGET), "--member", "h1", "--member", "h2", "--member", "late", "--no-polish"
    )
    islands = [
        spawn("island", "--connect", endpoint, "--campaign", "hand", "--quiet", "--secret-file", str(member_path(db, "hand", name))) for name in ("h1", "h2")
    ]  # no --id: the member's name
    sybil = None
    try:
        wait_for(lambda: rows_of(db, "h1") > 5 and rows_of(db, "h2") > 5, 120, "the islands to search")
        shared = CampaignSecret.read(secret_path(db, "hand"))
        assert shared.member == ""
        sybil = Sybil(endpoint, shared, [f"x-{k}" for k in range(16)])
        assert query(db, "SELECT DISTINCT member FROM runs WHERE island LIKE 'x-%'") == [("",)]
        assert not sybil.admitted(made_from(shared, "x1"), "x1")  # 16 members of its own: refused
        late = spawn("island", "--connect", endpoint, "--campaign", "hand", "--quiet", "--secret-file", str(member_path(db, "hand", "late")))
        doc = outlast(coord, db, sybil, "x-", late)
    finally:
        if sybil is not None:
            sybil.close()
    assert doc["settings"]["stop_reason"] == "interrupted" and "late" in {i["island"] for i in doc["islands"]}
    assert all(p.wait(60) == 0 for p in islands)


def island_processes(parent: int) -> dict[str, tuple[dict[str, str], list[str]]]:
    """The environment and command line of each ``hysid island`` child of process ``parent``, by its ``--id`` (what any
    process of the same user may read in ``/proc``)."""
    found = {}
    for entry in Path("/proc").iterdir():
        try:
            if not entry.name.isdigit() or int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1]) != parent:
                continue
            argv = (entry / "cmdline").read_bytes().decode().split("\0")
            env = dict(item.split("=", 1) for item in (entry / "environ").read_bytes().decode().split("\0") if "=" in item)
        except (OSError, ValueError, IndexError):
            continue  # gone meanwhile
        if "island" in argv and "--id" in argv:
            found[argv[argv.index("--id") + 1]] = (env, argv)
    return found
