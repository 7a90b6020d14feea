"""Deploy security, used for real: TLS (deploy/tls/make-certs.sh certificates, mutual authentication, the
coordinator's address in its certificate), user/password authentication, the access control lists that
confine islands to their campaign and their own keys (deploy/secure-campaign.py), quiet logs, and the
threat model of deploy/GUIDE.md citing the tests that hold it. Helpers: tests/deploy_support.py.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
import zenoh

from coordinator.launch import free_port
from deploy_support import (
    CAMPAIGN,
    CREDENTIALS,
    DEPLOY,
    MAKE_CERTS,
    ZENOH_DIR,
    cannot_connect,
    collector,
    localized,
    make_certs,
    pair,
    put_setting,
    put_until_received,
    replies,
    require_openssl,
    session,
    setting,
    wait_until,
    watching,
)
from support import sizes

pytestmark = pytest.mark.timeout(60)


def test_tls_island_without_client_certificate_is_refused(certs: Path) -> None:
    coordinator_file, island_file = pair("-tls")
    port = free_port()
    with session(localized(coordinator_file, port, certs)):
        no_certificate = localized(island_file, port, certs)
        put_setting(no_certificate, "transport/link/tls/enable_mtls", False)
        put_setting(no_certificate, "transport/link/tls/connect_certificate", None)
        put_setting(no_certificate, "transport/link/tls/connect_private_key", None)
        assert cannot_connect(no_certificate)
        assert not cannot_connect(localized(island_file, port, certs))


def test_tls_island_with_certificate_of_another_ca_is_refused(certs: Path, tmp_path: Path) -> None:
    other = tmp_path / "other-ca"
    assert make_certs(other, "island-1").returncode == 0
    coordinator_file, island_file = pair("-tls")
    port = free_port()
    with session(localized(coordinator_file, port, certs)):
        foreign = localized(island_file, port, certs)
        put_setting(foreign, "transport/link/tls/connect_certificate", str(other / "islands/island-1/cert.pem"))
        put_setting(foreign, "transport/link/tls/connect_private_key", str(other / "islands/island-1/key.pem"))
        assert cannot_connect(foreign)


def test_tls_island_refuses_coordinator_whose_certificate_lacks_the_address(tmp_path: Path) -> None:
    require_openssl()
    wrong_name = tmp_path / "certs"
    assert make_certs(wrong_name, "-s", "coordinator.invalid", "island-1").returncode == 0
    coordinator_file, island_file = pair("-tls")
    port = free_port()
    with session(localized(coordinator_file, port, wrong_name)):
        assert cannot_connect(localized(island_file, port, wrong_name))


@pytest.mark.parametrize(
    ("user", "password"),
    [("island-1", "change-me-island-2"), ("island-9", "change-me-island-1"), (None, None)],
    ids=["wrong-password", "unknown-user", "no-credentials"],
)
def test_usrpwd_wrong_credentials_are_refused(user: str | None, password: str | None) -> None:
    coordinator_file, island_file = pair("-usrpwd")
    port = free_port()
    with session(localized(coordinator_file, port)):
        island = localized(island_file, port)
        put_setting(island, "transport/auth/usrpwd/user", user)
        put_setting(island, "transport/auth/usrpwd/password", password)
        assert cannot_connect(island)
        put_setting(island, "transport/auth/usrpwd/user", "island-2")
        put_setting(island, "transport/auth/usrpwd/password", "change-me-island-2")
        assert not cannot_connect(island)


def secure_island(port: int, certs: Path, credentials: Path, user: str, password: str, certificate: str = "island-1") -> zenoh.Config:
    config = localized(pair("-secure")[1], port, certs, credentials)
    put_setting(config, "transport/auth/usrpwd/user", user)
    put_setting(config, "transport/auth/usrpwd/password", password)
    put_setting(config, "transport/link/tls/connect_certificate", str(certs / "islands" / certificate / "cert.pem"))
    put_setting(config, "transport/link/tls/connect_private_key", str(certs / "islands" / certificate / "key.pem"))
    return config


def test_acl_confines_islands_to_their_campaign(certs: Path) -> None:
    port = free_port()
    with session(localized(pair("-secure")[0], port, certs)) as coordinator:
        seen: list = []
        members: list = []
        keep = watching(coordinator, seen, members) + [
            coordinator.declare_queryable(f"{CAMPAIGN}/config", lambda query: query.reply(query.key_expr, b"loop set")),
            coordinator.declare_queryable("hysid/other/config", lambda query: query.reply(query.key_expr, b"other")),
        ]
        with session(secure_island(port, certs, CREDENTIALS, "island-1", "change-me-island-1")) as island:
            heard: list = []
            keep += [island.declare_subscriber(f"{CAMPAIGN}/{key}", collector(heard)) for key in ("best", "control")]
            assert put_until_received(island, f"{CAMPAIGN}/migrants/island-1", b"first", seen)
            denied = [
                f"{CAMPAIGN}/control",
                f"{CAMPAIGN}/best",
                "hysid/other/migrants/island-1",
                "elsewhere/island-1",
            ]
            for key in denied:
                island.put(key, b"denied")
            island.put(f"{CAMPAIGN}/history/island-1", b"last")
            # one session, one reliable link: "last" arrives after anything sent before it
            assert wait_until(lambda: (f"{CAMPAIGN}/history/island-1", b"last") in seen)
            assert not [key for key, payload in seen if payload == b"denied"]

            keep.append(island.liveliness().declare_token("hysid/other/members/island-1"))
            keep.append(island.liveliness().declare_token(f"{CAMPAIGN}/members/island-1"))
            assert wait_until(lambda: f"{CAMPAIGN}/members/island-1" in members)
            assert "hysid/other/members/island-1" not in members

            assert replies(island, f"{CAMPAIGN}/config") == [b"loop set"]
            assert replies(island, "hysid/other/config", timeout=2.0) == []

            for key in (f"{CAMPAIGN}/history/island-1", "hysid/other/history/island-1"):
                keep.append(island.declare_queryable(key, lambda query: query.reply(query.key_expr, b"rows")))
            assert wait_until(lambda: replies(coordinator, f"{CAMPAIGN}/history/island-1?since=3", 0.5) == [b"rows"])
            assert replies(coordinator, "hysid/other/history/island-1", timeout=1.0) == []

            assert put_until_received(coordinator, f"{CAMPAIGN}/best", b"best", heard)
            coordinator.put(f"{CAMPAIGN}/control", b"stop")
            assert wait_until(lambda: (f"{CAMPAIGN}/control", b"stop") in heard)
        for entity in keep:
            entity.undeclare()


def test_acl_denies_everything_to_an_authenticated_user_not_listed(certs: Path, tmp_path: Path) -> None:
    credentials = tmp_path / "credentials.txt"
    credentials.write_text(CREDENTIALS.read_text() + "guest:guest-password\n")
    port = free_port()
    with session(localized(pair("-secure")[0], port, certs, credentials)) as coordinator:
        seen: list = []
        subscriber = coordinator.declare_subscriber("**", collector(seen))
        queryable = coordinator.declare_queryable(f"{CAMPAIGN}/config", lambda query: query.reply(query.key_expr, b"loop set"))
        with session(secure_island(port, certs, credentials, "guest", "guest-password")) as guest:
            assert guest.info.routers_zid() == [coordinator.zid()]
            assert not put_until_received(guest, f"{CAMPAIGN}/migrants/guest", b"guest", seen, timeout=2.0)
            assert replies(guest, f"{CAMPAIGN}/config", timeout=2.0) == []
        with session(secure_island(port, certs, credentials, "island-2", "change-me-island-2", certificate="island-2")) as island:
            assert put_until_received(island, f"{CAMPAIGN}/migrants/island-2", b"island", seen)
        subscriber.undeclare()
        queryable.undeclare()


def x509(certificate: Path, *fields: str) -> str:
    """``openssl x509 -noout FIELDS`` of a PEM certificate: what it prints."""
    return subprocess.run(["openssl", "x509", "-in", str(certificate), "-noout", *fields], capture_output=True, text=True, check=True, timeout=30).stdout


def test_make_certs_reuses_the_ca_to_add_an_island_later(certs: Path, tmp_path: Path) -> None:
    outdir = tmp_path / "certs"
    shutil.copytree(certs, outdir)
    ca_before = hashlib.sha256((outdir / "ca.pem").read_bytes()).hexdigest()
    done = make_certs(outdir, "island-3")
    assert done.returncode == 0, done.stderr
    assert hashlib.sha256((outdir / "ca.pem").read_bytes()).hexdigest() == ca_before
    text = x509(outdir / "islands/island-3/cert.pem", "-subject", "-ext", "extendedKeyUsage")
    assert "CN = island-3" in text and "TLS Web Client Authentication" in text
    coordinator_text = x509(outdir / "coordinator/cert.pem", "-ext", "subjectAltName")
    assert "IP Address:127.0.0.1" in coordinator_text and "DNS:localhost" in coordinator_text


@pytest.mark.parametrize("args", [["-o"], ["-d", "soon", "island-1"], ["bad id!"], ["-x"]])
def test_make_certs_rejects_bad_arguments_with_one_line(args: list[str], tmp_path: Path) -> None:
    done = subprocess.run(["bash", str(MAKE_CERTS), *args], capture_output=True, text=True, timeout=30, cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr.startswith("make-certs.sh: error: ") and done.stderr.count("\n") == 1
    assert not (tmp_path / "hysid-certs").exists()


# --- the secure recipe: identities bound to keys, campaigns apart, listening where told, quiet logs ---------
SECURE_CAMPAIGN = DEPLOY / "secure-campaign.py"
NEGATIVE_WAIT = 0.8
"""How long to wait for what the ACL must drop (on loopback an allowed message arrives within milliseconds)."""


def secure_campaign(outdir: Path, campaign: str, port: int, certs: Path, *islands: str) -> Path:
    done = subprocess.run(
        [
            sys.executable,
            str(SECURE_CAMPAIGN),
            "--campaign",
            campaign,
            "--listen",
            f"tls/127.0.0.1:{port}",
            "--connect",
            f"tls/127.0.0.1:{port}",
            "--certs",
            str(certs),
            "-o",
            str(outdir),
            *islands,
        ],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert done.returncode == 0, done.stderr
    assert "change-me" not in done.stdout and all(line.split(":")[1] not in done.stdout for line in (outdir / "credentials.txt").read_text().splitlines())
    return outdir


def island_as(outdir: Path, island: str, *, user_of: str | None = None) -> zenoh.Config:
    """Island ``island``'s generated config; ``user_of``: with another island's user name and password instead."""
    config = zenoh.Config.from_file(outdir / "islands" / f"{island}.json5")
    if user_of is not None:
        other = zenoh.Config.from_file(outdir / "islands" / f"{user_of}.json5")
        for key in ("user", "password"):
            put_setting(config, f"transport/auth/usrpwd/{key}", setting(other, f"transport/auth/usrpwd/{key}"))
    return config


def answering_joins(coordinator: zenoh.Session) -> tuple[list, list, list]:
    """What the coordinator's router sees put and which tokens, with a join queryable answering every id; and
    the entities to undeclare."""
    seen: list = []
    members: list = []
    keep = watching(coordinator, seen, members) + [
        coordinator.declare_queryable(f"{CAMPAIGN}/join/*", lambda query: query.reply(query.key_expr, b"joined")),
    ]
    return seen, members, keep


def speaks_only_as(speaker: zenoh.Session, own: str, others: list[str], seen: list, members: list) -> list:
    """Assert that ``speaker`` may publish, join and hold a token as island ``own`` and publish as none of
    ``others`` (nor join or hold a token as the first of them): what it puts as them never arrives (after
    what it put as itself, which does). Returns the tokens to undeclare."""
    assert put_until_received(speaker, f"{CAMPAIGN}/migrants/{own}", b"own", seen)
    for other in others:
        for kind in ("migrants", "history"):
            speaker.put(f"{CAMPAIGN}/{kind}/{other}", b"as another")
    speaker.put(f"{CAMPAIGN}/history/{own}", b"last")
    assert wait_until(lambda: (f"{CAMPAIGN}/history/{own}", b"last") in seen)
    assert not [key for key, payload in seen if payload == b"as another"]
    assert replies(speaker, f"{CAMPAIGN}/join/{own}") == [b"joined"]
    assert replies(speaker, f"{CAMPAIGN}/join/{others[0]}", timeout=NEGATIVE_WAIT) == []
    tokens = [speaker.liveliness().declare_token(f"{CAMPAIGN}/members/{i}") for i in (others[0], own)]
    assert wait_until(lambda: f"{CAMPAIGN}/members/{own}" in members)
    assert f"{CAMPAIGN}/members/{others[0]}" not in members
    return tokens


def test_the_secure_recipe_binds_each_island_to_its_own_keys(certs: Path, tmp_path: Path) -> None:
    """Island X (certificate CN=X and user X) may speak only as X: publish, join, serve and hold a token."""
    port = free_port()
    out = secure_campaign(tmp_path / "z", "demo", port, certs, "island-1", "island-2")
    assert oct((out / "credentials.txt").stat().st_mode & 0o777) == "0o600" and oct(out.stat().st_mode & 0o777) == "0o700"
    with session(zenoh.Config.from_file(out / "coordinator.json5")) as coordinator:
        seen, members, keep = answering_joins(coordinator)
        with session(island_as(out, "island-1")) as island:
            for key in ("control", "best", "join/island-2"):
                island.put(f"{CAMPAIGN}/{key}", b"as another")
            keep += speaks_only_as(island, "island-1", ["island-2"], seen, members)
        with session(island_as(out, "island-1", user_of="island-2")) as mixed:  # island-1's certificate, island-2's password
            assert not put_until_received(mixed, f"{CAMPAIGN}/migrants/island-2", b"mixed", seen, timeout=NEGATIVE_WAIT)
            assert not put_until_received(mixed, f"{CAMPAIGN}/migrants/island-1", b"mixed", seen, timeout=NEGATIVE_WAIT)
            assert (
                replies(mixed, f"{CAMPAIGN}/join/island-1", timeout=NEGATIVE_WAIT) == replies(mixed, f"{CAMPAIGN}/join/island-2", timeout=NEGATIVE_WAIT) == []
            )
        for entity in keep:
            entity.undeclare()


def test_a_process_of_many_islands_speaks_for_its_islands_only(certs: Path, tmp_path: Path) -> None:
    """``island-1:2`` (hysid island --id island-1 --count 2): one identity that may speak as island-1-0 and
    island-1-1 (publish, join, hold a token), not as island-1 itself nor as island-2; and island-2 not as them."""
    port = free_port()
    out = secure_campaign(tmp_path / "z", "demo", port, certs, "island-1:2", "island-2")
    assert sorted(p.name for p in (out / "islands").iterdir()) == ["island-1.json5", "island-2.json5"]
    with session(zenoh.Config.from_file(out / "coordinator.json5")) as coordinator:
        seen, members, keep = answering_joins(coordinator)
        with session(island_as(out, "island-1")) as host, session(island_as(out, "island-2")) as other:
            keep += speaks_only_as(host, "island-1-0", ["island-1", "island-1-2", "island-2"], seen, members)
            assert replies(host, f"{CAMPAIGN}/join/island-1-1") == [b"joined"]
            keep += speaks_only_as(other, "island-2", ["island-1-1"], seen, members)
        for entity in keep:
            entity.undeclare()


def test_campaigns_that_share_a_ca_and_island_names_stay_apart(certs: Path, tmp_path: Path) -> None:
    """Same CA, same island names, two routers: an island of campaign A cannot join, read or write B."""
    port_a, port_b = free_port(), free_port()
    a = secure_campaign(tmp_path / "a", "alpha", port_a, certs, "island-1")
    b = secure_campaign(tmp_path / "b", "beta", port_b, certs, "island-1")
    with session(zenoh.Config.from_file(a / "coordinator.json5")), session(zenoh.Config.from_file(b / "coordinator.json5")) as router_b:
        queryable = router_b.declare_queryable("hysid/beta/config", lambda query: query.reply(query.key_expr, b"beta's loop set"))
        a_at_b = island_as(a, "island-1")
        put_setting(a_at_b, "connect/endpoints", [f"tls/127.0.0.1:{port_b}"])
        assert cannot_connect(a_at_b)  # its password is A's
        with session(island_as(b, "island-1")) as b_island:
            assert replies(b_island, "hysid/beta/config") == [b"beta's loop set"]
        with session(island_as(a, "island-1")) as a_island:  # on its own router, B's key space is denied
            assert replies(a_island, "hysid/beta/config", timeout=1.5) == []
        queryable.undeclare()


def test_shipped_recipes_listen_where_told_and_are_secure_by_default() -> None:
    for path in ZENOH_DIR.glob("coordinator*.json5"):
        endpoints = setting(zenoh.Config.from_file(path), "listen/endpoints")
        assert all("127.0.0.1" in e for e in endpoints), (path.name, endpoints)
    env = (DEPLOY / "systemd" / "coordinator.env.example").read_text()
    assert "HYSID_LISTEN=tls/COORDINATOR-ADDRESS:7447" in env and "0.0.0.0:" not in env.split("HYSID_LISTEN=")[1].split("\n")[0]
    assert "HYSID_CONNECT=tls/" in (DEPLOY / "systemd" / "island.env.example").read_text()
    sbatch = (DEPLOY / "slurm" / "hysid-campaign.sbatch").read_text()
    assert "security=${HYSID_SECURITY:-secure}" in sbatch and '--listen "$protocol/$coordinator_address:$port"' in sbatch
    assert "0.0.0.0" not in sbatch.replace("would be every interface", "")
    guide = (DEPLOY / "GUIDE.md").read_text()
    assert "--listen tcp/0.0.0.0" not in guide and "--listen tls/0.0.0.0" not in guide


def test_the_guides_debug_log_recipe_keeps_passwords_out_of_the_log(tmp_path: Path) -> None:
    recipe = re.search(r"RUST_LOG=(\S+)", (DEPLOY / "GUIDE.md").read_text())
    assert recipe is not None
    coordinator_file, island_file = pair("-usrpwd")
    port = free_port()
    script = f"""
import zenoh
zenoh.try_init_log_from_env()
router = zenoh.Config.from_file({str(coordinator_file)!r})
router.insert_json5("listen/endpoints", '["tcp/127.0.0.1:{port}"]')
router.insert_json5("transport/auth/usrpwd/dictionary_file", '"{CREDENTIALS}"')
island = zenoh.Config.from_file({str(island_file)!r})
island.insert_json5("connect/endpoints", '["tcp/127.0.0.1:{port}"]')
r = zenoh.open(router)
i = zenoh.open(island)
i.put("hysid/demo/migrants/island-1", b"x")
i.close()
r.close()
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60, env={**os.environ, "RUST_LOG": recipe.group(1)})
    assert done.returncode == 0, done.stderr[-2000:]
    log = done.stdout + done.stderr
    assert "DEBUG" in log and "usrpwd" in log.lower()  # the recipe does show authentication at work
    assert not [line for line in CREDENTIALS.read_text().split() if line.split(":")[1] in log]


@pytest.mark.slow
def test_a_campaign_runs_with_the_secure_recipe_and_an_island_cannot_take_another_id(tmp_path: Path) -> None:
    require_openssl()
    port, certs = free_port(), tmp_path / "certs"
    assert make_certs(certs, "-s", "127.0.0.1", "island-1", "island-2", "island-3").returncode == 0
    out = secure_campaign(tmp_path / "z", "demo", port, certs, "island-1", "island-2", "island-3")
    hysid = [sys.executable, "-m", "hysid"]
    started: list[subprocess.Popen] = []

    def start(*args: str) -> subprocess.Popen:
        started.append(subprocess.Popen([*hysid, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
        return started[-1]

    def island(name: str, *id_option: str) -> subprocess.Popen:
        return start(
            "island",
            "--config",
            str(out / "islands" / f"{name}.json5"),
            "--campaign",
            "demo",
            *id_option,
            "--wait",
            "10",
            "--quiet",
            "--secret-file",
            str(tmp_path / "report" / "campaign.sqlite-demo.secret"),
        )

    try:
        coordinator = start(
            "coordinator",
            "--config",
            str(out / "coordinator.json5"),
            "--campaign",
            "demo",
            "--out",
            str(tmp_path / "report"),
            "--min-islands",
            "3",
            "--algos",
            "pso",
            *sizes(20, 40, 300),
            "--no-polish",
            "--no-figures",
            "--quiet",
            "--json",
        )
        _, impostor_err = island("island-1", "--id", "island-2").communicate(timeout=40)  # island-1's identity, island-2's id
        islands = [island("island-1", "--id", "island-1"), island("island-2", "--id", "island-2"), island("island-3")]  # no --id: its name
        for p in islands:
            assert p.wait(timeout=60) == 0, p.stderr.read()
        doc_text, err = coordinator.communicate(timeout=60)
        assert coordinator.returncode == 0, err
    finally:
        for p in started:
            p.kill()
            p.communicate()
    assert impostor_err.count("\n") == 1 and "--id 'island-2': this island authenticates as 'island-1'" in impostor_err
    doc = json.loads(doc_text)
    assert {i["island"] for i in doc["islands"]} == {"island-1", "island-2", "island-3"}
    assert doc["settings"]["stop_reason"] == "every island finished" and doc["migrations"]["rejected"] == 0


def test_the_threat_model_cites_tests_that_exist() -> None:
    """Every `file.py::test` (or `::test` after it) of the guide's threat model names a test of that file."""
    guide = (DEPLOY / "GUIDE.md").read_text()
    model = guide[guide.index("## Threat model") : guide.index("## Troubleshooting")]
    tests_dir = Path(__file__).resolve().parent
    cited, current = [], None
    for file, name in re.findall(r"`(?:(test_\w+\.py))?(?:::(test_\w+))?`", model):
        current = file or current
        if name:
            cited.append((current, name))
        elif file:
            assert (tests_dir / file).is_file(), file
    assert len(cited) >= 25
    for file, name in cited:
        assert re.search(rf"^def {name}\(", (tests_dir / file).read_text(), re.M), f"{file}::{name}"


def read_as_another_user(path: Path) -> bytes | None:
    """``path`` read by user ``nobody`` (None: it may not), where this process can act as it (root with ``setpriv``);
    else by the mode bits alone (what a user neither owner nor in the file's group may read)."""
    if os.geteuid() == 0 and shutil.which("setpriv"):
        got = subprocess.run(["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", "--", "cat", str(path)], capture_output=True)
        return got.stdout if got.returncode == 0 else None
    return path.read_bytes() if path.stat().st_mode & 0o004 else None


@pytest.mark.slow
@pytest.mark.timeout(180)
def test_another_user_finds_no_key_in_any_file_a_campaign_leaves(tmp_path: Path) -> None:
    """A campaign of two island processes in a directory every user may enter: its database, WAL, shared memory,
    reserve, key and secret files are 0600, and every file it leaves that another user can read (its report, figures,
    result) holds no byte of the admission secret, the members' key or the coordinator's private key, raw or in hex."""
    from coordinator.keys import CampaignKeys, key_path

    base = Path(tempfile.mkdtemp(prefix="hysid-other-user-"))
    try:
        base.chmod(0o755)
        out = base / "out"
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "hysid",
                "campaign",
                "--islands",
                "2",
                *sizes(10, 20, 30),
                "--out",
                str(out),
                "--quiet",
                "--json",
            ],
            capture_output=True,
            text=True,
            timeout=150,
        )
        assert done.returncode == 0, done.stderr
        db = out / "campaign.sqlite"
        keys = CampaignKeys.read(key_path(db, "campaign"), "campaign")
        forms = [k for key in (keys.admission, keys.signing, keys.members) for k in (key, key.hex().encode(), key.hex().upper().encode())]
        owner_only = {db.name, f"{db.name}-wal", f"{db.name}-shm", f"{db.name}-reserve", key_path(db, "campaign").name, f"{db.name}-campaign.secret"}
        left = [p for p in base.rglob("*") if p.is_file()]
        assert {db.name, key_path(db, "campaign").name, f"{db.name}-campaign.secret", "report.md", "result.json"} <= {p.name for p in left}
        readable = []
        for p in left:
            if p.name in owner_only:
                assert oct(p.stat().st_mode & 0o777) == "0o600", p
            data = read_as_another_user(p)
            if data is not None:
                readable.append(p.name)
                assert not any(k in data for k in forms), f"{p} holds a key and another user can read it"
        assert "report.md" in readable and not owner_only & set(readable)
    finally:
        shutil.rmtree(base, ignore_errors=True)
