"""CLI ``hysid router``: the Zenoh router of one site of a multi-site campaign.

A site's islands connect to their site's router (``hysid island --connect
tcp/<router>:7447``), and the router connects over the wide-area link to the
coordinator, itself the campaign's router (or to another site's router): one
long-lived connection per site crosses the WAN instead of one per island, and
traffic between two islands of a site stays in the site. The router holds no
campaign state; it forwards ``hysid/<campaign>/**`` both ways, liveliness
tokens included, so islands join, migrate and report exactly as on one network.

Zenoh's own router, ``zenohd``, does the same job but is not on PyPI (it comes
as a binary or a Debian package from the Zenoh project); this is a Zenoh session
in router mode from the ``eclipse-zenoh`` package hysid already needs, so it
takes a Zenoh configuration file (``deploy/sites/router.json5``).

The router keeps dialling its ``--connect`` endpoints from the start (it may
come up before the coordinator) and after every lost link (Zenoh's connect
retry). It prints one ready line (also with ``--quiet``: scripts wait for it)
and one line for every router or peer link that comes or goes, with the
number of clients (islands) connected; it runs until Ctrl-C or SIGTERM.
"""

from __future__ import annotations

import json
import signal
import sys
import threading
import time
from pathlib import Path

import typer
import zenoh

from hysid.cli import options as o
from hysid_model.errors import HysidInputError
from island.session import DEFAULT_ENDPOINT, open_session, session_config


def register(app: typer.Typer) -> None:
    """Add ``router`` to the hysid app."""

    @app.command("router")
    def router_command(
        listen: list[str] = typer.Option([], "--listen", help=f"Endpoint this site's islands connect to, repeatable (default {DEFAULT_ENDPOINT})."),
        connect: list[str] = typer.Option(
            [], "--connect", help="The coordinator's (or another site router's) endpoint, repeatable; dialled until it answers and again after every loss."
        ),
        config_file: Path | None = o.CONFIG,
        quiet: bool = typer.Option(False, "--quiet", help="Print only the ready line and errors."),
    ) -> None:
        """Forward a campaign between this site's islands and the coordinator: a Zenoh router (what zenohd does)."""
        zconfig = session_config("router", listen=listen, connect=connect, config_file=config_file)
        if json.loads(zconfig.get_json("mode")) != "router":
            raise HysidInputError('is not a router configuration (its mode must be "router")', param="config_file", value=config_file)
        listening = ", ".join(listen) or (f"as in {config_file}" if config_file else DEFAULT_ENDPOINT)
        session = open_session(zconfig, f"listen {listening}")
        stop = threading.Event()
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, lambda *_: stop.set())
        started = time.monotonic()
        links: dict[str, set[str]] = {"router": set(), "peer": set(), "client": set()}

        def changed(event: zenoh.TransportEvent) -> None:
            kind = str(event.transport.whatami).rsplit(".", 1)[-1].lower()
            zid, up = str(event.transport.zid), event.kind == zenoh.SampleKind.PUT
            (links[kind].add if up else links[kind].discard)(zid)
            if not quiet and kind != "client":
                print(
                    f"[{time.monotonic() - started:7.1f} s] {kind} {zid} {'up' if up else 'down'} | routers {len(links['router'])}, "
                    f"peers {len(links['peer'])}, clients {len(links['client'])}",
                    file=sys.stderr,
                    flush=True,
                )

        upstream = f"; dialling {', '.join(connect) or ('as in ' + str(config_file) if config_file else 'nothing')}"
        zid = session.info.zid()
        print(f"router {zid} ready (listening on {listening}{upstream})", file=sys.stderr, flush=True)
        listener = session.info.declare_transport_events_listener(changed, history=True)  # links made while opening come first
        try:
            while not stop.wait(0.5):
                pass
        finally:
            listener.undeclare()
            session.close()
        if not quiet:
            print(f"router {zid} stopped", file=sys.stderr, flush=True)
