"""CLI commands of distributed campaigns: ``hysid campaign``, ``hysid coordinator`` and ``hysid island``.

``campaign`` is the one-machine job (coordinator + N island processes on
loopback, or ``--single-node``); ``coordinator`` and ``island`` are its two
halves for clusters (see ``deploy/``), connected by Zenoh endpoints or a Zenoh
configuration file. The coordinator keeps the campaign's shared secret in a file
of mode 0600 beside its database (or at ``--secret-file``), and a member secret
for each ``--member``; an island takes one from ``--secret-file`` or the
environment (:mod:`island.secret`), and without it cannot join.
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
from typing import Optional

import typer

from coordinator.launch import island_specs
from coordinator.keys import key_path
from coordinator.links import ZenohLink
from coordinator.loop import serve
from coordinator.progress import CampaignProgress
from coordinator.queries import COORDINATOR_LEASE_S
from coordinator.state import Coordinator, resume
from coordinator.store import Store
from hysid.campaigns import CampaignResult, campaign, finish
from hysid.cli import options as o
from hysid.cli.progress import Progress, announcing_stop, campaign_reporter
from hysid.motion import choose_motion
from hysid.report.campaign_text import campaign_progress_line
from hysid_model.datasets import load_dataset
from hysid_model.errors import HysidInputError, HysidWarning
from island.algorithms import check_algorithm
from island.config import MAX_SEED, CampaignConfig, decode_config
from island.migration import Migration
from island.host import cores, describe, host_specs, run_islands
from island.secret import SECRET_ENV, SECRET_FILE_ENV, CampaignSecret, member_path, of_member, secret_path
from island.session import DEFAULT_ENDPOINT, authenticated_name, open_session, session_config
from island.termination import Termination
from island.joining import fetch_config
from island.wire import MAX_MEMBERS, check_name


MAX_WAIT_S = 86400.0
WAIT_NOTICE_S = 1.0
"""An island still without its coordinator after this says that it waits."""


def print_progress(p: CampaignProgress) -> None:
    print_line(campaign_progress_line(p))


def print_line(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def database(db: Optional[Path], out: Path, campaign_name: str, resuming: bool) -> Path:
    """The campaign database: ``--db`` or OUT/campaign.sqlite; a stored campaign is only ever resumed.
    Whether it can be written is checked here, before any work."""
    path = db if db is not None else out / o.DB_NAME
    if resuming:
        if db is None:
            raise HysidInputError("--resume needs --db FILE, the database of the coordinator to carry on")
        if not db.is_file():
            raise HysidInputError("no such file to resume", param="db", value=db)
    elif db is not None and not db.exists():
        o.check_writable(db.parent, "db")
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
        raise HysidInputError(f"{store.path}: campaign {name!r} is {status} (its coordinator is alive{ago}); stop it first, or wait "
                              f"{COORDINATOR_LEASE_S:g} s after a crash on another machine")
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
        kept = store.has_campaign(campaign_name) and store.count("history", campaign_name) > 0 or len(store.campaign_list()) > 1
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
    def campaign_command(
        dataset: Optional[str] = o.DATASET_OR_SYNTH,
        islands: int = typer.Option(4, "--islands", help="Number of islands."),
        name: str = typer.Option("campaign", "--campaign", help="Campaign name (in the database and the key space hysid/<name>/**)."),
        algos: str = o.ALGOS,
        share: str = o.SHARE,
        topology: str = o.TOPOLOGY,
        interval: int = o.INTERVAL,
        migrants: int = o.MIGRANTS,
        random_k: int = o.RANDOM_K,
        population: Optional[int] = o.POPULATION,
        initial: Optional[int] = o.INITIAL,
        iterations: Optional[int] = o.ITERATIONS,
        seed: int = o.SEED,
        model: str = o.MODEL,
        weights: Optional[str] = o.WEIGHTS,
        noise: float = o.NOISE,
        noise_seed: int = o.NOISE_SEED,
        points: Optional[int] = o.POINTS,
        skip_rows: Optional[int] = o.SKIP_ROWS,
        budget: Optional[int] = o.BUDGET,
        target: Optional[float] = o.TARGET,
        stall: Optional[int] = o.STALL,
        time_limit: Optional[float] = o.TIME_LIMIT,
        single_node: bool = typer.Option(False, "--single-node", help="All islands in this process, migrating in memory (no network)."),
        out: Optional[Path] = o.OUT,
        db: Optional[Path] = o.DB,
        as_json: bool = o.JSON,
        polish: bool = o.POLISH,
        quiet: bool = o.QUIET,
        csv: bool = o.CSV,
        bound: Optional[list[str]] = o.BOUND,
        fix: Optional[list[str]] = o.FIX,
        displacement: str = o.DISPLACEMENT,
    ) -> Optional[int]:
        """Run GA/PSO islands on this machine that share their best candidates; report the polished global best."""
        bounds, fixed = o.parse_bounds(bound), o.parse_fixed(fix)
        algo_list = o.parse_algos(algos)
        termination = Termination(budget=budget, target=target, stall=stall, time_limit_s=time_limit)
        given_iterations = iterations
        iterations, until_stopped = o.island_budget(iterations, termination)
        sizes = o.island_sizes(population, initial, iterations)
        migration = Migration(interval=interval, k=migrants, topology=topology, random_k=random_k)
        check_name("campaign", name)
        island_specs(islands, algo_list, seed)  # every setting is checked before the report directory is made
        CampaignConfig(
            name=name, algos=algo_list, options=sizes, migration=migration, seed=seed, min_islands=islands, until_stopped=until_stopped, share=share,
        )
        target_dir = o.report_dir(out, "campaign")
        path = database(db, target_dir, name, resuming=False)
        new_db = not path.exists()
        loops = load_dataset(dataset or "synth", noise_pct=noise, noise_seed=noise_seed, n_points=points, skip_rows=skip_rows)
        sizes, termination, until_stopped, iterations = o.island_plan(
            loops, model, bounds, algo_list, population, initial, given_iterations, termination)
        try:
            with Progress("campaign", islands * (iterations or 0) or 100, enabled=not (quiet or as_json)) as bar:
                result = campaign(
                    loops, model, islands=islands, name=name, weights=weights, bounds=bounds, fixed=fixed, displacement=displacement,
                    algos=algo_list, options=sizes, migration=migration,
                    seed=seed, termination=termination, single_node=single_node, db=path, dataset=dataset or "synth",
                    polish=polish, progress=campaign_reporter(bar, islands, iterations, termination), until_stopped=until_stopped, share=share,
                )
        except BaseException:
            if new_db:
                discard_failed(target_dir, path, name)
            raise
        o.show_result(result, target_dir, as_json, csv, figures=not result.interrupted)  # Ctrl-C: out in seconds
        return exit_status(result)

    @app.command("coordinator")
    def coordinator_command(
        dataset: Optional[str] = o.DATASET_OR_SYNTH,
        listen: list[str] = typer.Option([], "--listen", help="Endpoint to listen on, repeatable (default tcp/127.0.0.1:7447)."),
        connect: list[str] = typer.Option([], "--connect", help="Zenoh router to connect to as well, repeatable."),
        config_file: Optional[Path] = o.CONFIG,
        name: str = o.CAMPAIGN,
        db: Optional[Path] = o.DB,
        resume_db: bool = typer.Option(False, "--resume", help="Carry on the campaign stored in --db after a crash (its settings and loop set come from there)."),
        secret_file: Optional[Path] = typer.Option(
            None, "--secret-file",
            help="Where to keep the campaign's shared secret (mode 0600; default DB-CAMPAIGN.secret beside the database): islands joined "
                 "with it, whoever holds it, count as one member.",
        ),
        members: list[str] = typer.Option(
            [], "--member",
            help="Also write a member secret for NAME (repeatable; DB-CAMPAIGN+NAME.secret, mode 0600; the same again with --resume): "
                 "its holder joins only as NAME's islands (ids NAME or NAME-...), and no member (the shared secret's holders together "
                 "are one) takes more than half the run slots or counts more effort than all the other members together. Hand each "
                 "host or process its own.",
        ),
        min_islands: int = typer.Option(1, "--min-islands", help="Islands wait (up to 60 s) until this many have joined before they start."),
        algos: str = o.ALGOS,
        share: str = o.SHARE,
        topology: str = o.TOPOLOGY,
        interval: int = o.INTERVAL,
        migrants: int = o.MIGRANTS,
        random_k: int = o.RANDOM_K,
        population: Optional[int] = o.POPULATION,
        initial: Optional[int] = o.INITIAL,
        iterations: Optional[int] = o.ITERATIONS,
        seed: int = o.SEED,
        model: str = o.MODEL,
        weights: Optional[str] = o.WEIGHTS,
        noise: float = o.NOISE,
        noise_seed: int = o.NOISE_SEED,
        points: Optional[int] = o.POINTS,
        skip_rows: Optional[int] = o.SKIP_ROWS,
        budget: Optional[int] = o.BUDGET,
        target: Optional[float] = o.TARGET,
        stall: Optional[int] = o.STALL,
        time_limit: Optional[float] = o.TIME_LIMIT,
        out: Optional[Path] = o.OUT,
        as_json: bool = o.JSON,
        polish: bool = o.POLISH,
        quiet: bool = o.QUIET,
        bound: Optional[list[str]] = o.BOUND,
        fix: Optional[list[str]] = o.FIX,
        displacement: str = o.DISPLACEMENT,
    ) -> Optional[int]:
        """Serve a campaign over Zenoh to islands ('hysid island'), record it in SQLite, report the result."""
        check_name("campaign", name)
        for member in members:
            check_name("member", member)
        bounds, fixed = o.parse_bounds(bound), o.parse_fixed(fix)
        termination = Termination(budget=budget, target=target, stall=stall, time_limit_s=time_limit)
        if resume_db and dataset is not None:
            raise HysidInputError(f"--resume takes the loop set from {db}; drop DATASET {dataset!r}")
        if resume_db and (bounds or fixed):
            raise HysidInputError(f"--resume takes the bounds and fixed values from {db}; drop --bound and --fix")
        target_dir = o.report_dir(out, "coordinator")
        path = database(db, target_dir, name, resuming=resume_db)
        motion = None
        if not resume_db:  # every argument is checked before the database is written or a session opened
            o.island_sizes(population, initial, iterations)  # checked before the loops are read
            migration = Migration(interval=interval, k=migrants, topology=topology, random_k=random_k)
            loops = load_dataset(dataset or "synth", noise_pct=noise, noise_seed=noise_seed, n_points=points, skip_rows=skip_rows)
            sizes, termination, until_stopped, iterations = o.island_plan(
                loops, model, bounds, o.parse_algos(algos), population, initial, iterations, termination)
            motion = choose_motion(loops, model, displacement, bounds=bounds, fixed=fixed)
            config = CampaignConfig.create(
                loops, name=name, model=model, weights=weights, bounds=bounds, fixed=fixed,
                displacement=motion.displacement, displacement_by=motion.decided_by,
                algos=o.parse_algos(algos), options=sizes, migration=migration, seed=seed, min_islands=min_islands,
                until_stopped=until_stopped, share=share,
            )
        store = Store(path)
        try:
            if resume_db:
                said = resumed_from(store, name)
                coordinator = resume(store, name, termination)
                if said and not quiet:
                    print(said, file=sys.stderr, flush=True)
            else:
                coordinator = Coordinator(store, config, loops, termination, dataset=dataset or "synth")
            kept = keep_secret(coordinator.secret, secret_file or secret_path(path, name))
            for member in members:
                kept_member = keep_secret(coordinator.keys.member_secret(member), member_path(path, name, member))
                if not quiet:
                    print(f"hysid: member {member!r}'s secret {kept_member}", file=sys.stderr, flush=True)
            zconfig = session_config("router", listen=listen, connect=connect, config_file=config_file)
            session = open_session(zconfig, f"listen {', '.join(listen) or (f'as in {config_file}' if config_file else DEFAULT_ENDPOINT)}")
            link = ZenohLink(session, coordinator)
            print(f"coordinator of campaign {name!r} ready (database {store.path}, islands' shared secret {kept})", file=sys.stderr, flush=True)  # also with --quiet: scripts wait for it
            try:
                serve(coordinator, link, announcing_stop(None if quiet else print_progress, print_line))
            finally:
                link.close()
                session.close()
            result = finish(coordinator, coordinator.outcome(polish_best=polish), motion)
            o.show_result(result, target_dir, as_json, csv=False, figures=not result.interrupted)
        finally:
            store.close()
        return exit_status(result)

    @app.command("island")
    def island_command(
        connect: list[str] = typer.Option([], "--connect", help="Coordinator endpoint, repeatable (default tcp/127.0.0.1:7447)."),
        config_file: Optional[Path] = o.CONFIG,
        name: str = o.CAMPAIGN,
        algo: Optional[str] = typer.Option(None, "--algo", help="ga or pso (default: from the campaign's mix, by seed)."),
        seed: Optional[int] = typer.Option(None, "--seed", help="Optimizer seed (default: from the campaign seed and the island id)."),
        island_id: Optional[str] = typer.Option(
            None, "--id", help="Island name, unique in the campaign (default: the user name of --config's authentication, else island-<host>-<pid>)."
        ),
        wait: float = typer.Option(
            30.0, "--wait",
            help="Seconds to wait for the coordinator: at the start, for the final confirmation, and for one that fell silent to come back.",
        ),
        secret_file: Optional[Path] = typer.Option(
            None, "--secret-file", envvar=SECRET_FILE_ENV, show_envvar=False,
            help=f"The secret its coordinator wrote beside its database (waited for up to --wait): this host's member secret "
                 f"(DB-CAMPAIGN+NAME.secret, hysid coordinator --member NAME; ids NAME or NAME-...), or the shared one (DB-CAMPAIGN.secret); "
                 f"or give its text in ${SECRET_ENV}, or the file in ${SECRET_FILE_ENV}.",
        ),
        count: str = typer.Option(
            "1", "--count",
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
            raise HysidInputError(f"this island authenticates as {identity!r} (user name in {config_file}); its id is that name", param="island", value=island_id)
        island = check_name("island", island_id or identity or default_island_id())
        where = ', '.join(connect) or (f'as in {config_file}' if config_file else DEFAULT_ENDPOINT)
        secret = island_secret(secret_file, name, wait, island)
        if secret.member and island_id is None and identity is None:
            island = secret.member  # a member's island bears its name
        elif secret.member and not of_member(island, secret.member):
            raise HysidInputError(f"the secret is member {secret.member!r}'s: its islands' ids are {secret.member!r} or begin with "
                                  f"'{secret.member}-'", param="island", value=island)
        waiting = threading.Timer(WAIT_NOTICE_S, lambda: say(f"island {island}: no coordinator of campaign {name!r} at {where} yet; waiting up to {wait:g} s (--wait)"))
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
        if len(hosted) == 1 and failed:
            raise failed[0].error  # one island: its error as it is
        for h in hosted:
            if h.error is not None or h.node is None:
                continue
            node = h.node
            if node.confirmed is False:
                warnings.warn(HysidWarning(
                    f"island {node.island}: the coordinator did not confirm its history within {wait:g} s; rows sent since its last "
                    "confirmation may be missing from the campaign database"
                ), stacklevel=1)
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
                + "; ".join(f"{h.spec.id}: {describe(h.error)}" for h in failed[:3]) + ("; ..." if len(failed) > 3 else "")
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


def keep_secret(secret: CampaignSecret, path: Path) -> Path:
    """Write the campaign secret to ``path`` (mode 0600) for the islands; one line if it cannot be written."""
    try:
        return secret.write(path)
    except OSError as exc:
        raise HysidInputError(f"cannot write the campaign secret ({exc.strerror or exc})", param="secret_file", value=path) from None


def island_secret(secret_file: Optional[Path], campaign_name: str, wait: float, island: str) -> CampaignSecret:
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
