"""CLI commands of distributed campaigns: ``hysid campaign`` and ``hysid coordinator`` (``hysid island``: :mod:`hysid.cli.island`).

``campaign`` is the one-machine job (coordinator + N island processes on
loopback, or ``--single-node``); ``coordinator`` and ``island`` are its two
halves for clusters (see ``deploy/``), connected by Zenoh endpoints or a Zenoh
configuration file. The coordinator keeps the campaign's shared secret in a file
of mode 0600 beside its database (or at ``--secret-file``), and a member secret
for each ``--member``; an island takes one from ``--secret-file`` or the
environment (:mod:`island.secret`), and without it cannot join.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import typer

from coordinator.keys import key_path
from coordinator.launch import island_specs
from coordinator.links import ZenohLink
from coordinator.loop import serve
from coordinator.progress import CampaignProgress
from coordinator.queries import COORDINATOR_LEASE_S
from coordinator.state import Coordinator, resume
from coordinator.store import Store
from hysid.campaigns import CampaignResult, campaign, finish
from hysid.cli import options as o
from hysid.cli.directories import DB_NAME, check_writable
from hysid.cli.groups import LAID_OUT, Constraints, Output, Reading, Search, Stop, grouped
from hysid.cli.plans import island_budget, island_plan, island_sizes
from hysid.cli.progress import Progress, announcing_stop, campaign_reporter
from hysid.motion import choose_motion
from hysid.report.campaign_text import campaign_progress_line
from hysid_model.errors import HysidInputError
from island.config import CampaignConfig
from island.secret import CampaignSecret, member_path, secret_path
from island.session import DEFAULT_ENDPOINT, open_session, session_config
from island.wire import check_name


def print_progress(p: CampaignProgress) -> None:
    print_line(campaign_progress_line(p))


def print_line(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def database(db: Path | None, out: Path, campaign_name: str, resuming: bool) -> Path:
    """The campaign database: ``--db`` or OUT/campaign.sqlite; a stored campaign is only ever resumed.
    Whether it can be written is checked here, before any work."""
    path = db if db is not None else out / DB_NAME
    if resuming:
        if db is None:
            raise HysidInputError("--resume needs --db FILE, the database of the coordinator to carry on")
        if not db.is_file():
            raise HysidInputError("no such file to resume", param="db", value=db)
    elif db is not None and not db.exists():
        check_writable(db.parent, "db")
    if path.is_file():
        store = Store(path)  # opening it checks that it can be written
        try:
            if not resuming and store.has_campaign(campaign_name):
                raise HysidInputError(f"{path}: campaign {campaign_name!r} already exists; use --resume to carry on, or another --campaign or --db")
        finally:
            store.close()
    return path


def resumed_from(store: Store, name: str) -> str:
    """The line ``--resume`` says of the state it takes campaign ``name`` up from (as :meth:`Queries.state` reads it:
    a campaign left running by a coordinator that is gone was interrupted); a :class:`HysidInputError` while its
    coordinator still runs (two coordinators of one campaign would each think it theirs)."""
    if not store.has_campaign(name):
        return ""  # resume() names the campaigns the database holds
    status, reason = store.state(name)
    if status in ("running", "stopping"):
        last = store.last_commit(name)
        ago = "" if last is None else f", its heartbeat {time.time() - last:.0f} s ago"
        raise HysidInputError(
            f"{store.path}: campaign {name!r} is {status} (its coordinator is alive{ago}); stop it first, or wait "
            f"{COORDINATOR_LEASE_S:g} s after a crash on another machine"
        )
    why = (reason or "").removeprefix("interrupted: ")
    return f"hysid: resuming campaign {name!r}, {status}" + (f" ({why})" if why else "")


def exit_status(result: CampaignResult) -> int | None:
    """:data:`hysid.cli.options.INTERRUPTED` for a campaign stopped by Ctrl-C (its report written and marked
    so), None (exit status 0) for one that ended by its rules."""
    return o.INTERRUPTED if result.interrupted else None


def discard_failed(out: Path, db: Path, campaign_name: str) -> None:
    """After a failed ``hysid campaign``: the database it made goes if it holds no history row
    (nothing is lost), and ``out`` with it if that leaves it empty, so that the same ``--out`` works
    again; a database with history stays (``hysid coordinator --resume`` carries it on, and
    :func:`hysid.cli.options.report_dir` says so)."""
    if not db.is_file():
        return
    store = Store.read_only(db)
    try:
        kept = (store.has_campaign(campaign_name) and store.count("history", campaign_name) > 0) or len(store.campaign_list()) > 1
    finally:
        store.db.close()
    if kept:
        return
    for suffix in ("", "-wal", "-shm", "-journal", "-reserve"):
        Path(f"{db}{suffix}").unlink(missing_ok=True)
    secret_path(db, campaign_name).unlink(missing_ok=True)
    key_path(db, campaign_name).unlink(missing_ok=True)
    if out.is_dir() and not any(out.iterdir()):
        out.rmdir()


def register(app: typer.Typer) -> None:
    """Add ``campaign``, ``coordinator`` and ``island`` to the hysid app."""

    @app.command("campaign")
    @grouped
    def campaign_command(
        dataset: str | None = o.DATASET_OR_SYNTH,
        islands: int = typer.Option(4, "--islands", help="Number of islands."),
        name: str = typer.Option("campaign", "--campaign", help="Campaign name (in the database and the key space hysid/<name>/**)."),
        search: Search = LAID_OUT,
        model: str = o.MODEL,
        weights: str | None = o.WEIGHTS,
        reading: Reading = LAID_OUT,
        stop: Stop = LAID_OUT,
        single_node: bool = typer.Option(False, "--single-node", help="All islands in this process, migrating in memory (no network)."),
        output: Output = LAID_OUT,
        db: Path | None = o.DB,
        polish: bool = o.POLISH,
        limits: Constraints = LAID_OUT,
    ) -> int | None:
        """Run GA/PSO islands on this machine that share their best candidates; report the polished global best."""
        bounds, fixed, displacement = limits.bounds(), limits.fixed(), limits.displacement
        algo_list = search.algo_list()
        termination = stop.termination()
        iterations, until_stopped = island_budget(search.iterations, termination)
        sizes = island_sizes(search.population, search.initial, iterations)
        migration = search.migration()
        check_name("campaign", name)
        seed, share = search.seed, search.share
        island_specs(islands, algo_list, seed)  # every setting is checked before the report directory is made
        CampaignConfig(name=name, algos=algo_list, options=sizes, migration=migration, seed=seed, min_islands=islands, until_stopped=until_stopped, share=share)
        target_dir = output.directory("campaign")
        path = database(db, target_dir, name, resuming=False)
        new_db = not path.exists()
        loops = reading.load(dataset or "synth")
        plan, termination, until_stopped, iterations = island_plan(
            loops, model, bounds, algo_list, search.population, search.initial, search.iterations, termination
        )
        try:
            with Progress("campaign", islands * (iterations or 0) or 100, enabled=output.live) as bar:
                result = campaign(
                    loops,
                    model,
                    islands=islands,
                    name=name,
                    weights=weights,
                    bounds=bounds,
                    fixed=fixed,
                    displacement=displacement,
                    algos=algo_list,
                    options=plan,
                    migration=migration,
                    seed=seed,
                    termination=termination,
                    single_node=single_node,
                    db=path,
                    dataset=dataset or "synth",
                    polish=polish,
                    progress=campaign_reporter(bar, islands, iterations, termination),
                    until_stopped=until_stopped,
                    share=share,
                )
        except BaseException:
            if new_db:
                discard_failed(target_dir, path, name)
            raise
        output.show(result, target_dir, figures=not result.interrupted)  # Ctrl-C: out in seconds
        return exit_status(result)

    @app.command("coordinator")
    @grouped
    def coordinator_command(
        dataset: str | None = o.DATASET_OR_SYNTH,
        listen: list[str] = typer.Option([], "--listen", help="Endpoint to listen on, repeatable (default tcp/127.0.0.1:7447)."),
        connect: list[str] = typer.Option([], "--connect", help="Zenoh router to connect to as well, repeatable."),
        config_file: Path | None = o.CONFIG,
        name: str = o.CAMPAIGN,
        db: Path | None = o.DB,
        resume_db: bool = typer.Option(
            False, "--resume", help="Carry on the campaign stored in --db after a crash (its settings and loop set come from there)."
        ),
        secret_file: Path | None = typer.Option(
            None,
            "--secret-file",
            help="Where to keep the campaign's shared secret (mode 0600; default DB-CAMPAIGN.secret beside the database): islands joined "
            "with it, whoever holds it, count as one member.",
        ),
        members: list[str] = typer.Option(
            [],
            "--member",
            help="Also write a member secret for NAME (repeatable; DB-CAMPAIGN+NAME.secret, mode 0600; the same again with --resume): "
            "its holder joins only as NAME's islands (ids NAME or NAME-...), and no member (the shared secret's holders together "
            "are one) takes more than half the run slots or counts more effort than all the other members together. Hand each "
            "host or process its own.",
        ),
        min_islands: int = typer.Option(1, "--min-islands", help="Islands wait (up to 60 s) until this many have joined before they start."),
        search: Search = LAID_OUT,
        model: str = o.MODEL,
        weights: str | None = o.WEIGHTS,
        reading: Reading = LAID_OUT,
        stop: Stop = LAID_OUT,
        output: Output = LAID_OUT,
        polish: bool = o.POLISH,
        limits: Constraints = LAID_OUT,
    ) -> int | None:
        """Serve a campaign over Zenoh to islands ('hysid island'), record it in SQLite, report the result."""
        check_name("campaign", name)
        for member in members:
            check_name("member", member)
        bounds, fixed, displacement = limits.bounds(), limits.fixed(), limits.displacement
        termination = stop.termination()
        if resume_db and dataset is not None:
            raise HysidInputError(f"--resume takes the loop set from {db}; drop DATASET {dataset!r}")
        if resume_db and (bounds or fixed):
            raise HysidInputError(f"--resume takes the bounds and fixed values from {db}; drop --bound and --fix")
        target_dir = output.directory("coordinator")
        path = database(db, target_dir, name, resuming=resume_db)
        motion = None
        if not resume_db:  # every argument is checked before the database is written or a session opened
            island_sizes(search.population, search.initial, search.iterations)  # checked before the loops are read
            migration = search.migration()
            loops = reading.load(dataset or "synth")
            sizes, termination, until_stopped, _ = island_plan(
                loops, model, bounds, search.algo_list(), search.population, search.initial, search.iterations, termination
            )
            motion = choose_motion(loops, model, displacement, bounds=bounds, fixed=fixed)
            config = CampaignConfig.create(
                loops,
                name=name,
                algos=search.algo_list(),
                model=model,
                seed=search.seed,
                weights=weights,
                share=search.share,
                bounds=bounds,
                displacement=motion.displacement,
                fixed=fixed,
                displacement_by=motion.decided_by,
                options=sizes,
                migration=migration,
                min_islands=min_islands,
                until_stopped=until_stopped,
            )
        store = Store(path)
        try:
            if resume_db:
                said = resumed_from(store, name)
                coordinator = resume(store, name, termination)
                if said and not output.quiet:
                    print(said, file=sys.stderr, flush=True)
            else:
                coordinator = Coordinator(store, config, loops, termination, dataset=dataset or "synth")
            kept = keep_secret(coordinator.secret, secret_file or secret_path(path, name))
            for member in members:
                kept_member = keep_secret(coordinator.keys.member_secret(member), member_path(path, name, member))
                if not output.quiet:
                    print(f"hysid: member {member!r}'s secret {kept_member}", file=sys.stderr, flush=True)
            zconfig = session_config("router", listen=listen, connect=connect, config_file=config_file)
            session = open_session(zconfig, f"listen {', '.join(listen) or (f'as in {config_file}' if config_file else DEFAULT_ENDPOINT)}")
            link = ZenohLink(session, coordinator)
            print(
                f"coordinator of campaign {name!r} ready (database {store.path}, islands' shared secret {kept})", file=sys.stderr, flush=True
            )  # also with --quiet: scripts wait for it
            try:
                serve(coordinator, link, announcing_stop(None if output.quiet else print_progress, print_line))
            finally:
                link.close()
                session.close()
            result = finish(coordinator, coordinator.outcome(polish_best=polish), motion)
            output.show(result, target_dir, figures=not result.interrupted)
        finally:
            store.close()
        return exit_status(result)


def keep_secret(secret: CampaignSecret, path: Path) -> Path:
    """Write the campaign secret to ``path`` (mode 0600) for the islands; one line if it cannot be written."""
    try:
        return secret.write(path)
    except OSError as exc:
        raise HysidInputError(f"cannot write the campaign secret ({exc.strerror or exc})", param="secret_file", value=path) from None
