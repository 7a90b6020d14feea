"""CLI commands of distributed campaigns: ``hysid campaign``, ``hysid coordinator`` and ``hysid island``.

``campaign`` is the one-machine job (coordinator + N island processes on
loopback, or ``--single-node``); ``coordinator`` and ``island`` are its two
halves for clusters (see ``deploy/``), connected by Zenoh endpoints or a Zenoh
configuration file.
"""

from __future__ import annotations

import os
import re
import socket
import sys
import zlib
from pathlib import Path
from typing import Any, Optional

import typer

from coordinator.campaign import ProgressPrinter, island_specs, run_campaign
from coordinator.cli_fit import default_out, summary_text
from coordinator.report import jsondoc
from coordinator.server import CampaignResult, Coordinator, StopRules, ZenohLink, new_config, resume
from coordinator.store import Store
from coordinator.zenoh_session import DEFAULT_ENDPOINT, open_session, session_config
from hysid_model.datasets import load_dataset
from hysid_model.errors import HysidInputError
from island.node import IslandNode, ZenohTransport, fetch_config
from island.protocol import ALGORITHMS, Migration, check_name, decode_config

DATASET = typer.Argument(None, help="Dataset directory, loops file, .mat or .lvm directory, or 'synth' (default: the built-in Synth set).")
NOISE = typer.Option(0.0, "--noise", help="Gaussian force noise, % of each loop's peak force (as the thesis' Synth tests).")
NOISE_SEED = typer.Option(0, "--noise-seed", help="Seed of that noise.")
MODEL = typer.Option("thesis", "--model", help="thesis, baseline, or a preset with +effects (see 'hysid models').")
WEIGHTS = typer.Option(None, "--weights", help="thesis or ml (1/sigma^2); default: ml when every loop's noise sigma is known.")
ALGOS = typer.Option("ga,pso", "--algos", help="Comma-separated algorithm mix the islands cycle through (ga, pso).")
POPULATION = typer.Option(200, "--population", help="GA population / PSO swarm of each island (the thesis: 500).")
INITIAL = typer.Option(2000, "--initial", help="Initial random population / swarm of each island (the thesis: 6000).")
ITERATIONS = typer.Option(60, "--iterations", help="Iterations of each island: its own budget (the thesis: 18).")
TOPOLOGY = typer.Option("ring", "--topology", help="Who takes migrants from whom: ring, full or random.")
INTERVAL = typer.Option(5, "--interval", help="Migrate every N iterations (0: isolated islands).")
MIGRANTS = typer.Option(2, "--migrants", help="Best candidates each island sends per migration.")
RANDOM_K = typer.Option(2, "--random-k", help="Neighbours of each island per migration with --topology random.")
SEED = typer.Option(0, "--seed", help="Campaign seed (island i of 'hysid campaign' uses SEED + i).")
BUDGET = typer.Option(None, "--budget", help="Stop after this many evaluations over all islands.")
TARGET = typer.Option(None, "--target", help="Stop once the global best fitness is at or below this.")
STALL = typer.Option(None, "--stall", help="Stop after this many evaluations without improvement of the global best.")
TIME_LIMIT = typer.Option(None, "--time-limit", help="Stop after this many seconds.")
OUT = typer.Option(None, "--out", help="Report directory (default hysid-out/<command>-<timestamp>).")
DB = typer.Option(None, "--db", help="Campaign database (SQLite; default OUT/campaign.sqlite).")
JSON = typer.Option(False, "--json", help="Print one JSON object on stdout (the 'hysid fit' keys plus islands and migrations).")
POLISH = typer.Option(True, "--polish/--no-polish", help="Refine the global best by bounded least squares.")
CONFIG = typer.Option(None, "--config", help="Zenoh configuration file (JSON5); authoritative for mode, TLS, auth, ACL, lease.")
CAMPAIGN = typer.Option("default", "--campaign", help="Campaign name: its key space is hysid/<name>/**.")


def parse_algos(text: str) -> list[str]:
    algos = [a.strip() for a in text.split(",") if a.strip()]
    bad = [a for a in algos if a not in ALGORITHMS]
    if not algos or bad:
        raise HysidInputError(f"--algos {text!r}: give a comma-separated list of {', '.join(ALGORITHMS)}")
    return algos


def algorithm_options(population: int, initial: int, iterations: int) -> dict[str, dict[str, Any]]:
    """The per-island sizes as each algorithm names them."""
    if initial < population:
        raise HysidInputError(f"--initial {initial}: must be at least --population {population}")
    return {
        "ga": {"population": population, "initial_population": initial, "iterations": iterations},
        "pso": {"swarm": population, "initial_swarm": initial, "iterations": iterations},
    }


def open_store(db: Optional[Path], out: Path) -> Store:
    path = db if db is not None else out / "campaign.sqlite"
    path.parent.mkdir(parents=True, exist_ok=True)
    return Store(path)


def finish(result: CampaignResult, out: Path, json_out: bool) -> None:
    """Write the ``hysid fit`` report and print the JSON document or the summary."""
    result.write_report(out)
    if json_out:
        print(jsondoc.dumps(result.as_dict()))
        return
    print(summary_text(result.fit, "hysid campaign"))
    m = result.migrations
    print(f"campaign {result.fit.settings['campaign']!r}: stopped because {result.fit.settings['stop_reason']}")
    print(
        f"migrations: {m['messages']} messages ({m['topology']}, every {m['interval']} iterations), "
        f"{m['received']} migrants re-evaluated, {m['taken']} taken in, {m['rejected']} messages rejected"
    )
    for isl in result.islands:
        print(
            f"  {isl['island']:<12} {isl['algo'].upper():<4} seed {isl['seed']:<4} {isl['status']:<6} best {isl['best_fitness']:.4g} "
            f"after {isl['iterations']} iterations, {isl['evaluations']:,} evaluations"
        )


def register(app: typer.Typer) -> None:
    """Add ``campaign``, ``coordinator`` and ``island`` to the hysid app."""

    @app.command("campaign")
    def campaign_command(
        dataset: Optional[str] = DATASET,
        islands: int = typer.Option(4, "--islands", help="Number of islands."),
        campaign: str = typer.Option("campaign", "--campaign", help="Campaign name (in the database and the key space hysid/<name>/**)."),
        algos: str = ALGOS,
        topology: str = TOPOLOGY,
        interval: int = INTERVAL,
        migrants: int = MIGRANTS,
        random_k: int = RANDOM_K,
        population: int = POPULATION,
        initial: int = INITIAL,
        iterations: int = ITERATIONS,
        seed: int = SEED,
        model: str = MODEL,
        weights: Optional[str] = WEIGHTS,
        noise: float = NOISE,
        noise_seed: int = NOISE_SEED,
        budget: Optional[int] = BUDGET,
        target: Optional[float] = TARGET,
        stall: Optional[int] = STALL,
        time_limit: Optional[float] = TIME_LIMIT,
        single_node: bool = typer.Option(False, "--single-node", help="All islands in this process, migrating in memory (no network)."),
        out: Optional[Path] = OUT,
        db: Optional[Path] = DB,
        json_out: bool = JSON,
        polish: bool = POLISH,
        quiet: bool = typer.Option(False, "--quiet", help="No live progress on stderr."),
    ) -> None:
        """Run GA/PSO islands on this machine that share their best candidates; report the polished global best."""
        algo_list = parse_algos(algos)
        specs = island_specs(islands, algo_list, seed)
        loops = load_dataset(dataset or "synth", noise_pct=noise, noise_seed=noise_seed)
        config = new_config(
            loops, name=check_name("--campaign", campaign), model=model, weights=weights, algos=algo_list,
            options=algorithm_options(population, initial, iterations),
            migration=Migration(interval=interval, k=migrants, topology=topology, random_k=random_k), seed=seed,
            min_islands=islands,
        )
        rules = StopRules(budget=budget, target=target, stall=stall, time_limit_s=time_limit)
        out_dir = out if out is not None else default_out("campaign")
        store = open_store(db, out_dir)
        try:
            coordinator = Coordinator(store, config, loops, rules, dataset=dataset or "synth")
            result = run_campaign(coordinator, specs, single_node=single_node, quiet=quiet, polish=polish)
            finish(result, out_dir, json_out)
        finally:
            store.close()

    @app.command("coordinator")
    def coordinator_command(
        dataset: Optional[str] = DATASET,
        listen: list[str] = typer.Option([], "--listen", help="Endpoint to listen on, repeatable (default tcp/127.0.0.1:7447)."),
        connect: list[str] = typer.Option([], "--connect", help="Zenoh router to connect to as well, repeatable."),
        config_file: Optional[Path] = CONFIG,
        campaign: str = CAMPAIGN,
        db: Optional[Path] = DB,
        resume_db: bool = typer.Option(False, "--resume", help="Carry on the campaign stored in --db after a crash (its settings and loop set come from there)."),
        min_islands: int = typer.Option(1, "--min-islands", help="Islands wait (up to 60 s) until this many have joined before they start."),
        algos: str = ALGOS,
        topology: str = TOPOLOGY,
        interval: int = INTERVAL,
        migrants: int = MIGRANTS,
        random_k: int = RANDOM_K,
        population: int = POPULATION,
        initial: int = INITIAL,
        iterations: int = ITERATIONS,
        seed: int = SEED,
        model: str = MODEL,
        weights: Optional[str] = WEIGHTS,
        noise: float = NOISE,
        noise_seed: int = NOISE_SEED,
        budget: Optional[int] = BUDGET,
        target: Optional[float] = TARGET,
        stall: Optional[int] = STALL,
        time_limit: Optional[float] = TIME_LIMIT,
        out: Optional[Path] = OUT,
        json_out: bool = JSON,
        polish: bool = POLISH,
        quiet: bool = typer.Option(False, "--quiet", help="No live progress on stderr."),
    ) -> None:
        """Serve a campaign over Zenoh to islands ('hysid island'), record it in SQLite, report the result."""
        check_name("--campaign", campaign)
        rules = StopRules(budget=budget, target=target, stall=stall, time_limit_s=time_limit)
        out_dir = out if out is not None else default_out("coordinator")
        if resume_db:
            if db is None:
                raise HysidInputError("--resume needs --db FILE, the database of the coordinator to carry on")
            if dataset is not None:
                raise HysidInputError(f"--resume takes the loop set from {db}; drop DATASET {dataset!r}")
            if not db.is_file():
                raise HysidInputError(f"--db {db}: no such file to resume")
        store = open_store(db, out_dir)
        try:
            if resume_db:
                coordinator = resume(store, campaign, rules)
            else:
                loops = load_dataset(dataset or "synth", noise_pct=noise, noise_seed=noise_seed)
                algo_list = parse_algos(algos)
                config = new_config(
                    loops, name=campaign, model=model, weights=weights, algos=algo_list,
                    options=algorithm_options(population, initial, iterations),
                    migration=Migration(interval=interval, k=migrants, topology=topology, random_k=random_k), seed=seed,
                    min_islands=min_islands,
                )
                coordinator = Coordinator(store, config, loops, rules, dataset=dataset or "synth")
            zconfig = session_config("router", listen=listen, connect=connect, config_file=config_file)
            session = open_session(zconfig, f"listen {', '.join(listen) or (f'as in {config_file}' if config_file else DEFAULT_ENDPOINT)}")
            link = ZenohLink(session, coordinator)
            if not quiet:
                print(f"coordinator of campaign {campaign!r} ready (database {store.path})", file=sys.stderr, flush=True)
            try:
                coordinator.serve(link, None if quiet else ProgressPrinter())
            finally:
                link.close()
                session.close()
            finish(coordinator.result(polish_best=polish), out_dir, json_out)
        finally:
            store.close()

    @app.command("island")
    def island_command(
        connect: list[str] = typer.Option([], "--connect", help="Coordinator endpoint, repeatable (default tcp/127.0.0.1:7447)."),
        config_file: Optional[Path] = CONFIG,
        campaign: str = CAMPAIGN,
        algo: Optional[str] = typer.Option(None, "--algo", help="ga or pso (default: from the campaign's mix, by seed)."),
        seed: Optional[int] = typer.Option(None, "--seed", help="Optimizer seed (default: from the campaign seed and the island id)."),
        island_id: Optional[str] = typer.Option(None, "--id", help="Island name, unique in the campaign (default: island-<host>-<pid>)."),
        wait: float = typer.Option(30.0, "--wait", help="Seconds to wait for the coordinator."),
        quiet: bool = typer.Option(False, "--quiet", help="Print nothing but errors."),
    ) -> None:
        """Join a campaign: fetch its loop set, optimize, migrate, report history until told to stop."""
        check_name("--campaign", campaign)
        if algo is not None and algo not in ALGORITHMS:
            raise HysidInputError(f"--algo {algo!r}: unknown algorithm; choose one of {', '.join(ALGORITHMS)}")
        if seed is not None and seed < 0:
            raise HysidInputError(f"--seed {seed}: seeds must be non-negative")
        zconfig = session_config("client", connect=connect, config_file=config_file, connect_timeout_s=wait)
        session = open_session(zconfig, f"connect {', '.join(connect) or (f'as in {config_file}' if config_file else DEFAULT_ENDPOINT)}")
        try:
            config, loops = decode_config(fetch_config(session, campaign, wait), campaign)
            name = island_id or default_island_id()
            seed_ = seed if seed is not None else config.seed + zlib.crc32(name.encode()) % (1 << 20)
            algo_ = algo or config.algo_for(seed_)
            node = IslandNode(name, algo_, seed_, config, config.objective(loops))
            transport = ZenohTransport(session, node)
            try:
                node.run(transport)
            finally:
                transport.close()
        finally:
            session.close()
        if not quiet:
            rows = node.rows
            best = rows[-1][1] if rows else float("inf")
            s = node.stats
            print(
                f"island {node.island} ({algo_.upper()}, seed {seed_}): best {best:.6g} after {len(rows)} iterations, "
                f"{rows[-1][2] if rows else 0:,} evaluations; {node.stop_reason}; migrant messages sent {s['sent']}, "
                f"migrants received {s['received']}, taken {s['taken']}, rejected messages {s['rejected']}",
                file=sys.stderr,
            )


def default_island_id() -> str:
    """``island-<host>-<pid>``, a valid key chunk."""
    host = re.sub(r"[^A-Za-z0-9_.-]", "-", socket.gethostname())[:40].strip("-.") or "host"
    return f"island-{host}-{os.getpid()}"
