"""Helpers of the deploy tests (tests/test_deploy_recipes.py, tests/test_deploy_security.py): the shipped
Zenoh configurations of deploy/zenoh opened for real on 127.0.0.1, deploy/tls/make-certs.sh, bounded waits.

A config is localized: only its endpoints, certificate and credential paths
are pointed at test files; everything else (mode, lease, TLS, authentication,
access control) is the file's. Each wait is bounded.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import subprocess
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zenoh

DEPLOY = Path(__file__).resolve().parents[1] / "deploy"
ZENOH_DIR = DEPLOY / "zenoh"
MAKE_CERTS = DEPLOY / "tls" / "make-certs.sh"
CREDENTIALS = ZENOH_DIR / "credentials.example.txt"
CAMPAIGN = "hysid/demo"
WAIT = 5.0
REFUSED_AFTER_MS = 1500

TLS_FILES = {
    "root_ca_certificate": "ca.pem",
    "listen_certificate": "coordinator/cert.pem",
    "listen_private_key": "coordinator/key.pem",
    "connect_certificate": "islands/island-1/cert.pem",
    "connect_private_key": "islands/island-1/key.pem",
}


def setting(config: zenoh.Config, key: str):
    return json.loads(config.get_json(key))


def put_setting(config: zenoh.Config, key: str, value) -> None:
    config.insert_json5(key, json.dumps(value))


def uses_tls(path: Path) -> bool:
    return "tls" in (setting(zenoh.Config.from_file(path), "transport/link/protocols") or [])


def localized(path: Path, port: int, certs: Path | None = None, credentials: Path = CREDENTIALS) -> zenoh.Config:
    """The config of `path` with its endpoint moved to 127.0.0.1:port and its file paths to test files."""
    config = zenoh.Config.from_file(path)
    endpoints_key = "listen/endpoints" if setting(config, "mode") == "router" else "connect/endpoints"
    protocol = setting(config, endpoints_key)[0].split("/")[0]
    put_setting(config, endpoints_key, [f"{protocol}/127.0.0.1:{port}"])
    for key, name in TLS_FILES.items():
        if setting(config, f"transport/link/tls/{key}") is not None:
            assert certs is not None, f"{path.name} needs certificates"
            put_setting(config, f"transport/link/tls/{key}", str(certs / name))
    if setting(config, "transport/auth/usrpwd/dictionary_file") is not None:
        put_setting(config, "transport/auth/usrpwd/dictionary_file", str(credentials))
    return config


def refused_quickly(config: zenoh.Config) -> zenoh.Config:
    """Stop retrying after REFUSED_AFTER_MS instead of the file's 60 s (islands wait for a late coordinator)."""
    put_setting(config, "connect/timeout_ms", REFUSED_AFTER_MS)
    return config


@contextlib.contextmanager
def session(config: zenoh.Config) -> Iterator[zenoh.Session]:
    opened = zenoh.open(config)
    try:
        yield opened
    finally:
        opened.close()


def cannot_connect(config: zenoh.Config) -> bool:
    try:
        zenoh.open(refused_quickly(config)).close()
    except zenoh.ZError:
        return True
    return False


def require_openssl() -> None:
    if shutil.which("openssl") is None:
        pytest.skip("openssl is not installed: make-certs.sh cannot create the TLS certificates")


def make_certs(outdir: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", str(MAKE_CERTS), "-o", str(outdir), *args], capture_output=True, text=True, timeout=60)


def collector(received: list) -> Callable[[zenoh.Sample], None]:
    return lambda sample: received.append((str(sample.key_expr), sample.payload.to_bytes()))


def wait_until(predicate: Callable[[], bool], timeout: float = WAIT) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return predicate()


def put_until_received(sender: zenoh.Session, key: str, payload: bytes, received: list, timeout: float = WAIT) -> bool:
    """Put until the receiver got it: subscriptions reach a new client asynchronously."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        sender.put(key, payload)
        if wait_until(lambda: (key, payload) in received, 0.2):
            return True
    return False


def watching(router: zenoh.Session, seen: list, members: list) -> list:
    """The router's view of everything put and every liveliness token (entities to undeclare)."""
    return [
        router.declare_subscriber("**", collector(seen)),
        router.liveliness().declare_subscriber("**", lambda sample: members.append(str(sample.key_expr))),
    ]


def replies(asker: zenoh.Session, selector: str, timeout: float = WAIT) -> list[bytes]:
    return [reply.ok.payload.to_bytes() for reply in asker.get(selector, timeout=timeout) if reply.ok is not None]


def pair(flavour: str) -> tuple[Path, Path]:
    return ZENOH_DIR / f"coordinator{flavour}.json5", ZENOH_DIR / f"island{flavour}.json5"
