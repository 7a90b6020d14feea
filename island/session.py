"""Opening Zenoh sessions for coordinators (routers) and islands (clients).

Without a configuration file the defaults are safe for one machine: the coordinator
listens on loopback only (``tcp/127.0.0.1:7447``), islands connect there,
multicast scouting is off, and the transport lease is 2 s with a keep-alive
every 0.5 s (Zenoh 1.x ``transport.link.tx.lease`` / ``keep_alive``) so that a
frozen or vanished island loses its liveliness token within about 2 s.

With ``config_file`` (a Zenoh JSON5 configuration, e.g. from ``deploy/``)
the file is authoritative, including mode, TLS, authentication, ACL, scouting
and lease; ``listen`` / ``connect`` endpoints given as well replace the file's
endpoints.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import zenoh

from hysid_model.errors import HysidInputError

DEFAULT_PORT = 7447
DEFAULT_ENDPOINT = f"tcp/127.0.0.1:{DEFAULT_PORT}"
LEASE_MS = 2000
KEEP_ALIVE = 4
"""Keep-alive messages per lease period."""
ENDPOINT_PATTERN = re.compile(r"[a-z][a-z0-9-]*/\S+\Z")
_RUST_LOCATION = re.compile(r"\s*at\s+\S+\.rs:\d+\.?")


def zenoh_message(exc: BaseException) -> str:
    """A Zenoh error as one readable line (without Rust source locations)."""
    return " ".join(_RUST_LOCATION.sub("", str(exc)).split())[:300]


def check_endpoints(param: str, endpoints: list[str]) -> list[str]:
    for e in endpoints:
        if not ENDPOINT_PATTERN.match(e):
            raise HysidInputError("a Zenoh endpoint looks like tcp/127.0.0.1:7447 or tls/host:7447", param=param, value=e)
    return list(endpoints)


def session_config(
    mode: str,
    *,
    listen: list[str] | None = None,
    connect: list[str] | None = None,
    config_file: Path | None = None,
    connect_timeout_s: float = 10.0,
) -> zenoh.Config:
    """The Zenoh configuration of a coordinator (``mode="router"``) or island (``"client"``)."""
    listen = check_endpoints("listen", listen or [])
    connect = check_endpoints("connect", connect or [])
    if config_file is not None:
        path = Path(config_file)
        if not path.is_file():
            raise HysidInputError("no such file", param="config_file", value=path)
        try:
            config = zenoh.Config.from_file(str(path))
        except zenoh.ZError as exc:
            raise HysidInputError(f"not a valid Zenoh configuration ({zenoh_message(exc)})", param="config_file", value=path) from None
    else:
        config = zenoh.Config()
        config.insert_json5("mode", json.dumps(mode))
        config.insert_json5("scouting/multicast/enabled", "false")
        config.insert_json5("transport/link/tx/lease", str(LEASE_MS))
        config.insert_json5("transport/link/tx/keep_alive", str(KEEP_ALIVE))
        if mode == "router" and not listen:
            listen = [DEFAULT_ENDPOINT]
        if mode == "client" and not connect:
            connect = [DEFAULT_ENDPOINT]
    if listen:
        config.insert_json5("listen/endpoints", json.dumps(listen))
    if connect:
        config.insert_json5("connect/endpoints", json.dumps(connect))
        config.insert_json5("connect/timeout_ms", str(int(connect_timeout_s * 1000)))
    return config


def authenticated_name(config: zenoh.Config) -> str | None:
    """The user name a client configuration authenticates with (``transport.auth.usrpwd.user``),
    None without user/password: with the access-control list of ``deploy/secure-campaign.py`` it is
    the only island id the coordinator lets this island use."""
    try:
        user = json.loads(config.get_json("transport/auth/usrpwd/user"))
    except (zenoh.ZError, ValueError):
        return None
    return user if isinstance(user, str) and user else None


def open_session(config: zenoh.Config, what: str) -> zenoh.Session:
    """Open a session; failure -> :class:`HysidInputError` naming ``what`` (e.g. the endpoint)."""
    try:
        return zenoh.open(config)
    except zenoh.ZError as exc:
        raise HysidInputError(f"cannot open Zenoh session ({what}): {zenoh_message(exc)}") from None
