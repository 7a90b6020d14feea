"""CLI commands for a campaign's database: ``hysid watch`` (a live view) and ``hysid report`` (its report again)."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import typer
from rich.console import Console
from rich.live import Live
from rich.text import Text

from coordinator.store import Store
from hysid.campaigns import CampaignResult
from hysid.cli.directories import campaign_database
from hysid.cli.groups import Output, grouped, laid_out
from hysid.report.campaign_text import campaign_progress_line, watch_text
from hysid.watch import snapshot
from hysid_model.errors import HysidInputError

CAMPAIGN_DB = typer.Argument(..., help="Campaign database (SQLite) of 'hysid campaign' or 'hysid coordinator', or the output directory holding it.")
CAMPAIGN_NAME = typer.Option(None, "--campaign", help="Campaign in the database (default: the latest).")
REPORT_OUTPUT = laid_out("out", "as_json", "csv", "figures")
"""The output options of ``hysid report``: no ``--quiet``, as it shows no live progress."""


def register(app: typer.Typer) -> None:
    """Add ``watch`` and ``report`` to the hysid app."""

    @app.command("watch")
    def watch_command(
        db: Path = CAMPAIGN_DB,
        name: str | None = CAMPAIGN_NAME,
        interval: float = typer.Option(1.0, "--interval", help="Seconds between refreshes."),
        once: bool = typer.Option(False, "--once", help="Show the campaign once and exit."),
    ) -> None:
        """Watch a campaign from its database (read-only, also over SSH): islands' best, migrations, members.

        Refreshes until the campaign stops, its coordinator is gone (nothing committed for a lease), or Ctrl-C.
        On a terminal the view redraws in place; otherwise one progress line per refresh, and the full view at the end."""
        if not interval > 0:
            raise HysidInputError("must be a positive number of seconds", param="interval", value=interval)
        store = Store.read_only(campaign_database(db))
        try:
            snap = snapshot(store, name)
            if once:
                print(watch_text(snap))
            elif sys.stdout.isatty():
                with Live(Text(watch_text(snap)), console=Console(), auto_refresh=False) as live:
                    while not snap.over:
                        time.sleep(interval)
                        snap = snapshot(store, snap.name)
                        live.update(Text(watch_text(snap)), refresh=True)
            else:
                while not snap.over:
                    print(f"{snap.status}: {campaign_progress_line(snap.progress)}", flush=True)
                    time.sleep(interval)
                    snap = snapshot(store, snap.name)
                print(watch_text(snap))
        except KeyboardInterrupt:  # the usual way to stop watching a running campaign
            pass
        finally:
            store.close()

    @app.command("report")
    @grouped
    def report_command(
        db: Path = CAMPAIGN_DB,
        name: str | None = CAMPAIGN_NAME,
        output: Output = REPORT_OUTPUT,
    ) -> None:
        """The report and figures of a finished or interrupted campaign, rebuilt from its database alone."""
        target = output.directory("report")
        output.show(CampaignResult.from_database(campaign_database(db), name), target)
