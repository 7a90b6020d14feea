"""CLI command ``hysid island``: join a campaign served by ``hysid coordinator`` (:mod:`hysid.cli.campaign`).

An island (or ``--count`` of them, threads over one Zenoh session) takes its campaign secret from
``--secret-file`` or the environment (:mod:`island.secret`), waits for its coordinator and says so,
fetches the campaign's loop set and settings, optimizes, migrates and reports its history until told
to stop.
"""

from __future__ import annotations

import os
import re
import socket
import sys
import threading
import time
import warnings
from pathlib import Path

import typer

from hysid.cli import options as o
from hysid_model.errors import HysidInputError, HysidWarning
from island.algorithms import check_algorithm
from island.config import MAX_SEED, decode_config
from island.host import cores, describe, host_specs, run_islands
from island.joining import fetch_config
from island.secret import SECRET_ENV, SECRET_FILE_ENV, CampaignSecret, of_member
from island.session import DEFAULT_ENDPOINT, authenticated_name, open_session, session_config
from island.wire import MAX_MEMBERS, check_name

MAX_WAIT_S = 86400.0
WAIT_NOTICE_S = 1.0
"""An island still without its coordinator after this says that it waits."""


def register(app: typer.Typer) -> None:
    """Add ``island`` to the hysid app."""

    @app.command("island")
    def island_command(
        connect: list[str] = typer.Option([], "--connect", help="Coordinator endpoint, repeatable (default tcp/127.0.0.1:7447)."),
        config_file: Path | None = o.CONFIG,
        name: str = o.CAMPAIGN,
        algo: str | None = typer.Option(None, "--algo", help="ga or pso (default: from the campaign's mix, by seed)."),
        seed: int | None = typer.Option(None, "--seed", help="Optimizer seed (default: from the campaign seed and the island id)."),
        island_id: str | None = typer.Option(
            None, "--id", help="Island name, unique in the campaign (default: the user name of --config's authentication, else island-<host>-<pid>)."
        ),
        wait: float = typer.Option(
            30.0,
            "--wait",
            help="Seconds to wait for the coordinator: at the start, for the final confirmation, and for one that fell silent to come back.",
        ),
        secret_file: Path | None = typer.Option(
            None,
            "--secret-file",
            envvar=SECRET_FILE_ENV,
            show_envvar=False,
            help=f"The secret its coordinator wrote beside its database (waited for up to --wait): this host's member secret "
            f"(DB-CAMPAIGN+NAME.secret, hysid coordinator --member NAME; ids NAME or NAME-...), or the shared one (DB-CAMPAIGN.secret); "
            f"or give its text in ${SECRET_ENV}, or the file in ${SECRET_FILE_ENV}.",
        ),
        count: str = typer.Option(
            "1",
            "--count",
            help="Islands in this process, threads over one Zenoh session: a number, or 'cores' for one per core the process may run on "
            "(under SLURM its task's CPUs). Several islands are ID-0, ID-1, ... with seeds SEED, SEED+1, ...",
        ),
        quiet: bool = typer.Option(False, "--quiet", help="Print nothing but errors."),
    ) -> None:
        """Join a campaign: fetch its loop set, optimize, migrate, report history until told to stop (--count: many islands)."""
        check_name("campaign", name)
        if algo is not None:
            check_algorithm(algo)
        if seed is not None and not 0 <= seed <= MAX_SEED:
            raise HysidInputError("seeds must be from 0 to 2**62", param="seed", value=seed)
        if not 0 <= wait <= MAX_WAIT_S:  # also NaN
            raise HysidInputError(f"must be from 0 to {MAX_WAIT_S:g} seconds", param="wait", value=wait)
        islands = island_count(count)
        zconfig = session_config("client", connect=connect, config_file=config_file, connect_timeout_s=wait)
        identity = authenticated_name(zconfig)
        if island_id is not None and identity is not None and island_id != identity:
            raise HysidInputError(
                f"this island authenticates as {identity!r} (user name in {config_file}); its id is that name", param="island", value=island_id
            )
        island = check_name("island", island_id or identity or default_island_id())
        where = ", ".join(connect) or (f"as in {config_file}" if config_file else DEFAULT_ENDPOINT)
        secret = island_secret(secret_file, name, wait, island)
        if secret.member and island_id is None and identity is None:
            island = secret.member  # a member's island bears its name
        elif secret.member and not of_member(island, secret.member):
            raise HysidInputError(
                f"the secret is member {secret.member!r}'s: its islands' ids are {secret.member!r} or begin with '{secret.member}-'",
                param="island",
                value=island,
            )
        waiting = threading.Timer(
            WAIT_NOTICE_S, lambda: say(f"island {island}: no coordinator of campaign {name!r} at {where} yet; waiting up to {wait:g} s (--wait)")
        )
        waiting.start()  # an island started before its coordinator waits for it, and says so
        try:
            session = open_session(zconfig, f"connect {where}")
            try:
                message = fetch_config(session, secret, wait)
            except BaseException:
                session.close()
                raise
        finally:
            waiting.cancel()
        try:
            config, loops = decode_config(message, name)
            specs = host_specs(island, islands, config, algo, seed)
            hosted = run_islands(session, secret, config, loops, specs, wait_s=wait, notify=say)
        finally:
            session.close()
        failed = [h for h in hosted if h.error is not None]
        first = failed[0].error if failed else None
        if len(hosted) == 1 and first is not None:
            raise first  # one island: its error as it is
        for h in hosted:
            if h.error is not None or h.node is None:
                continue
            node = h.node
            if node.confirmed is False:
                warnings.warn(
                    HysidWarning(
                        f"island {node.island}: the coordinator did not confirm its history within {wait:g} s; rows sent since its last "
                        "confirmation may be missing from the campaign database"
                    ),
                    stacklevel=1,
                )
            if not quiet:
                rows = node.rows
                best = rows[-1][1] if rows else float("inf")
                s = node.stats
                print(
                    f"island {node.island} ({node.algo.upper()}, seed {node.seed}): best {best:.6g} after {rows[-1][0] if rows else 0} iterations, "
                    f"{rows[-1][2] if rows else 0:,} evaluations; {node.stop_reason}; migrant messages sent {s['sent']}, "
                    f"migrants received {s['received']}, taken {s['taken']}, rejected messages {s['rejected']}"
                    + (f", messages that waited in vain for the roster {s['unlisted']}" if s["unlisted"] else ""),
                    file=sys.stderr,
                )
        if failed:
            raise HysidInputError(
                f"{len(failed)} of {len(hosted)} islands of this process failed: "
                + "; ".join(f"{h.spec.id}: {describe(h.error)}" for h in failed[:3] if h.error is not None)
                + ("; ..." if len(failed) > 3 else "")
            )


def island_count(text: str) -> int:
    """``--count``: a number of islands, or ``cores`` (one per core this process may run on)."""
    if text.strip().lower() == "cores":
        return cores()
    try:
        n = int(text)
    except ValueError:
        raise HysidInputError("must be a number of islands or 'cores'", param="count", value=text) from None
    if not 1 <= n <= MAX_MEMBERS:
        raise HysidInputError(f"must be from 1 to {MAX_MEMBERS} islands (or 'cores')", param="count", value=text)
    return n


def island_secret(secret_file: Path | None, campaign_name: str, wait: float, island: str) -> CampaignSecret:
    """The campaign secret of an island: ``--secret-file`` (waited for up to ``wait`` seconds: the
    coordinator writes it when it starts), else the environment; one line if there is none."""
    if secret_file is None:
        text = os.environ.get(SECRET_ENV)
        if not text:
            raise HysidInputError(
                f"island {island}: no campaign secret; give --secret-file (its coordinator writes DB-{campaign_name}.secret beside its "
                f"database) or put the secret's text in ${SECRET_ENV}"
            )
        return CampaignSecret.parse(text, f"${SECRET_ENV}").check_campaign(campaign_name, f"${SECRET_ENV}")
    start, said = time.monotonic(), False
    while not secret_file.exists() and time.monotonic() - start < wait:
        if not said and time.monotonic() - start >= WAIT_NOTICE_S:
            say(f"island {island}: no campaign secret at {secret_file} yet (its coordinator writes it when it starts); waiting up to {wait:g} s (--wait)")
            said = True
        time.sleep(0.1)
    return CampaignSecret.read(secret_file).check_campaign(campaign_name, str(secret_file))


def say(message: str) -> None:
    """A line about the island's wait for its coordinator, on stderr (also with --quiet: it is about a fault)."""
    print(f"hysid: {message}", file=sys.stderr, flush=True)


def default_island_id() -> str:
    """``island-<host>-<pid>``, a valid key chunk."""
    host = re.sub(r"[^A-Za-z0-9_.-]", "-", socket.gethostname())[:40].strip("-.") or "host"
    return f"island-{host}-{os.getpid()}"
