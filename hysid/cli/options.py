"""The command line's shared options: one definition (flag, default, help) per concept, and the output rules.

Commands take their options from here, so ``--json`` means the same (one JSON
object on stdout, bound to ``as_json``) and ``--out`` follows one policy
everywhere (:func:`report_dir`). :data:`FLAGS` maps the Python parameter a
library error names to the flag the user typed.
"""

from __future__ import annotations

import datetime as dt
import os
from pathlib import Path
from typing import Any

import typer

from coordinator.store import Store
from hysid.campaigns import default_options, island_settings
from hysid_model.errors import HysidInputError
from hysid_model.loops import LoopSet
from hysid_model.presets import PRESETS
from island.algorithms import ALGORITHMS
from island.termination import Termination

INTERRUPTED = 130
"""Exit status after Ctrl-C (128 + SIGINT), as shells report it: also of a campaign that stopped at Ctrl-C and
reported (a script tells an interrupted campaign from a finished one by it)."""

FLAGS = {
    "model": "--model",
    "algo": "--algo",
    "algos": "--algos",
    "runs": "--runs",
    "seed": "--seed",
    "weights": "--weights",
    "noise_pct": "--noise",
    "noise_seed": "--noise-seed",
    "noise_seeds": "--seeds-noise",
    "n_points": "--points",
    "skip_rows": "--skip-rows",
    "islands": "--islands",
    "count": "--count",
    "campaign": "--campaign",
    "name": "--campaign",
    "island": "--id",
    "member": "--member",
    "population": "--population",
    "initial_population": "--initial",
    "iterations": "--iterations",
    "interval": "--interval",
    "k": "--migrants",
    "topology": "--topology",
    "share": "--share",
    "random_k": "--random-k",
    "min_islands": "--min-islands",
    "budget": "--evaluations",
    "target": "--target",
    "stall": "--stall",
    "time_limit_s": "--time-limit",
    "listen": "--listen",
    "connect": "--connect",
    "config_file": "--config",
    "out": "--out",
    "out_dir": "OUT_DIR",
    "db": "--db",
    "wait": "--wait",
    "secret_file": "--secret-file",
    "seeds": "--seeds",
    "thesis_runs": "--thesis-runs",
    "part": "PART",
    "bound": "--bound",
    "candidates": "--candidates",
    "displacement": "--displacement",
    "fix": "--fix",
    "records": "--records",
    "seconds": "--seconds",
    "sample_rate_hz": "--rate",
    "rounds": "--rounds",
}
"""Python parameter (as a :class:`HysidInputError` names it) -> command-line flag."""


def error_line(exc: HysidInputError) -> str:
    """A library error in the command line's words: the flag instead of the Python parameter."""
    if exc.param in FLAGS:
        return f"{exc.subject(FLAGS[exc.param])}: {exc.detail}"
    if exc.param and exc.param.startswith("bounds["):
        return f"--bound {exc.param[8:-2]}: {exc.detail}"
    return str(exc)


DATASET_HELP = "Dataset directory, loops file, .mat or .lvm directory, or 'synth' (the thesis' Synth set)."
DATASET = typer.Argument(..., help=DATASET_HELP)
DATASET_OR_SYNTH = typer.Argument(None, help=DATASET_HELP + " Default: synth.")
MODEL = typer.Option(
    "thesis",
    "--model",
    help="A preset (thesis, baseline, mr_damper) with +effects (see 'hysid models') and +module:attribute terms of your own (hysid.term).",
)
CANDIDATES = typer.Option(
    None,
    "--candidates",
    metavar="MODULE:ATTRIBUTE,...",
    help="Terms of your own (made by hysid.term, imported from modules on the Python path) scored beside the library's effects.",
)
NO_DISCOVER = typer.Option(
    False,
    "--no-discover",
    help="Do not propose a force of your own from the data where no library effect explains the loops (proposed.py).",
)
START_MODEL = typer.Option("baseline", "--model", help=f"Start model: {' or '.join(PRESETS)}.")
WEIGHTS = typer.Option(None, "--weights", help="thesis or ml (1/sigma^2); default: ml when every loop's noise sigma is known.")
NOISE = typer.Option(0.0, "--noise", help="Gaussian force noise, % of each loop's peak force (as the thesis' Synth tests).")
NOISE_SEED = typer.Option(0, "--noise-seed", help="Seed of that noise.")
SYNTH_NOISE_SEED = typer.Option(0, "--noise-seed", "--seed", help="Seed of that noise (--seed, its old name, works too).")
POINTS = typer.Option(None, "--points", help="Points per branch when loops are extracted from raw records (default 100; a loops file keeps its own).")
SKIP_ROWS = typer.Option(
    None,
    "--skip-rows",
    metavar="N",
    help="Lines before the header of every CSV record (a preamble of free text), as skip_rows in dataset.toml. "
    "Default: a preamble is found by the rows of numbers under the header and skipped with a warning.",
)
ALGO = typer.Option("pso", "--algo", help="Optimizer: ga or pso (the thesis' settings, section 5.1).")
RUNS = typer.Option(1, "--runs", help="Independent runs with seeds SEED..SEED+RUNS-1; the best is reported.")
SEED = typer.Option(0, "--seed", help="Seed of the first run (island i of a campaign uses SEED + i).")
POLISH = typer.Option(True, "--polish/--no-polish", help="Refine the best by bounded least squares.")
FIGURES = typer.Option(
    True,
    "--figures/--no-figures",
    help="Draw the report's figures (PNG); --no-figures saves their seconds, the report saying where each would be ('hysid report DB' draws a campaign's later).",
)
OUT = typer.Option(None, "--out", help="Report directory, new or empty (default hysid-out/<command>-<time>).")
JSON = typer.Option(False, "--json", help="Print one JSON object on stdout instead of the summary.")
QUIET = typer.Option(False, "--quiet", help="No live progress on stderr.")
CSV = typer.Option(False, "--csv", help="Also write the result's tables as CSV files in the report directory (parameters.csv, amplitudes.csv, ...).")
ALGOS = typer.Option("ga,pso", "--algos", help="Comma-separated algorithm mix the islands cycle through (ga, pso).")
ISLAND_POPULATION, ISLAND_INITIAL = 200, 2000
"""Each island's population and initial population when none is given, on a model without memory."""
MEMETIC = "on a model with memory, with none of --population, --initial, --iterations: the memetic islands of hysid.campaign"
POPULATION = typer.Option(None, "--population", help=f"GA population / PSO swarm of each island (the thesis: 500). Default {ISLAND_POPULATION}; {MEMETIC}.")
INITIAL = typer.Option(None, "--initial", help=f"Initial random population / swarm of each island (the thesis: 6000). Default {ISLAND_INITIAL}; {MEMETIC}.")
ISLAND_ITERATIONS = 60
"""Each island's iteration budget when neither --iterations nor an evaluation or time budget is given."""
ITERATIONS = typer.Option(
    None,
    "--iterations",
    help=f"Iterations of each island: its own budget (the thesis: 18). Default: none with --evaluations or --time "
    f"(every island searches and migrates until the campaign stops), else {ISLAND_ITERATIONS}.",
)
SHARE = typer.Option(
    "staged",
    "--share",
    help="With several --algos: staged moves GA islands to PSO after their first migration interval (GA explores, PSO converges); "
    "adaptive moves islands to the algorithm whose own moves gain more; fixed keeps each island's algorithm.",
)
TOPOLOGY = typer.Option("ring", "--topology", help="Who takes migrants from whom: ring, full or random.")
INTERVAL = typer.Option(
    5, "--interval", help="Migrate every N iterations (0: isolated islands, which take nothing from others, a late joiner not even the best so far)."
)
MIGRANTS = typer.Option(2, "--migrants", help="Best candidates each island sends per migration.")
RANDOM_K = typer.Option(2, "--random-k", help="Neighbours of each island per migration with --topology random.")
BUDGET = typer.Option(None, "--evaluations", "--budget", help="Stop after this many evaluations over all islands (--budget is the same).")
TARGET = typer.Option(None, "--target", help="Stop once the global best fitness is at or below this.")
STALL = typer.Option(None, "--stall", help="Stop after this many evaluations without improvement of the global best.")
TIME_LIMIT = typer.Option(None, "--time-limit", "--time", help="Stop after this many seconds (--time is the same).")
DB = typer.Option(None, "--db", help="Campaign database (SQLite; default OUT/campaign.sqlite).")
CONFIG = typer.Option(None, "--config", help="Zenoh configuration file (JSON5); authoritative for mode, TLS, auth, ACL, lease.")
CAMPAIGN = typer.Option("default", "--campaign", help="Campaign name: its key space is hysid/<name>/**.")
BOUND = typer.Option(
    None,
    "--bound",
    metavar="NAME=LO:HI",
    help="A hard search bound (repeatable): kept as given, never widened; overrides the dataset's and the data-derived bound.",
)
DISPLACEMENT = typer.Option(
    "auto",
    "--displacement",
    help="auto: the data decide whether the displacement's harmonics are the motion or the sensor's distortion; "
    "measured: the model is driven by each loop's measured waveform; fundamental: by its fundamental (the harmonics are the "
    "sensor's); sine: the ideal X0 sin(wt) of Eq. 4.5 (as the thesis).",
)
FIX = typer.Option(None, "--fix", metavar="NAME=VALUE", help="A parameter known, not searched (repeatable), e.g. --fix meq=0.2.")


DB_NAME = "campaign.sqlite"
"""The database a campaign's output directory holds (``--db`` not given)."""


def campaign_database(path: Path) -> Path:
    """The database ``path`` names: itself, or for a campaign's output directory the ``campaign.sqlite`` in it."""
    if not path.is_dir():
        return path
    if (path / DB_NAME).is_file():
        return path / DB_NAME
    raise HysidInputError(f"{path}: a directory without {DB_NAME}; give the campaign database (--db of the campaign, or OUT/{DB_NAME})")


def report_dir(out: Path | None, kind: str, param: str = "out") -> Path:
    """Where a command writes: ``out`` if new or empty, else (not given) a new ``hysid-out/<kind>-<time>``.

    Every command that writes a directory (``fit``, ``diagnose``, ``synth``,
    ``campaign``, ``coordinator``, ``reproduce``, ``report``) checks it here
    before any work, so that a run never ends in an error after its work is
    done, and never overwrites an earlier report; a directory that cannot be
    written (read-only or full file system) fails here too. ``param`` names
    the option or argument in errors.
    """
    if out is None:
        stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S")
        base = Path("hysid-out") / f"{kind}-{stamp}"
        out, n = base, 1
        while out.exists():
            n += 1
            out = base.with_name(f"{base.name}-{n}")
        return check_writable(out, param)
    if out.exists() and not out.is_dir():
        raise HysidInputError("exists and is not a directory", param=param, value=out)
    if out.exists() and any(out.iterdir()):
        if (out / DB_NAME).is_file() and not (out / "report.md").exists():
            running = running_campaign(out / DB_NAME)
            if running is not None:
                raise HysidInputError(
                    f"is the output directory of campaign {running!r}, which is still running (its coordinator writes "
                    f"{out / DB_NAME}): two runs cannot share one {FLAGS.get(param, param)}; choose a new directory "
                    "(nothing was written)",
                    param=param,
                    value=out,
                )
            raise HysidInputError(
                f"holds the database of a campaign that did not finish ({out / DB_NAME}, no report.md): carry it on with "
                f"'hysid coordinator --resume --db {out / DB_NAME} --out NEW_DIR', or choose a new directory (nothing was written)",
                param=param,
                value=out,
            )
        raise HysidInputError("already exists and is not empty; choose a new directory (nothing was written)", param=param, value=out)
    return check_writable(out, param)


def running_campaign(db: Path) -> str | None:
    """The name of a campaign in ``db`` that did not stop and whose coordinator still commits (it did, within
    :data:`coordinator.queries.COORDINATOR_LEASE_S`), else None (also for a file that is no campaign database)."""
    try:
        store = Store.read_only(db)
    except HysidInputError:
        return None
    try:
        return next(
            (
                c["name"]
                for c in store.campaign_list()
                if c["status"] != "stopped" and store.last_commit(c["name"]) is not None and store.gone_since(c["name"]) is None
            ),
            None,
        )
    finally:
        store.close()


PROBE_BYTES = 64 << 10
"""What :func:`check_writable` writes: a disk with less room left is as good as full."""


def check_writable(directory: Path, param: str) -> Path:
    """``directory`` if it can be created and written (a probe file is written and removed, and
    directories made for it are removed again), else a one-line :class:`HysidInputError`."""
    made = [p for p in [directory, *directory.parents] if not p.exists()]
    probe = directory / f".hysid-probe-{os.getpid()}"
    try:
        directory.mkdir(parents=True, exist_ok=True)
        with open(probe, "wb") as f:
            f.write(bytes(PROBE_BYTES))
            f.flush()
            os.fsync(f.fileno())
    except OSError as exc:
        raise HysidInputError(f"cannot write there ({exc.strerror or exc}); nothing was run", param=param, value=directory) from None
    finally:
        try:
            probe.unlink(missing_ok=True)
            for p in made:
                p.rmdir()
        except OSError:
            pass
    return directory


def parse_bounds(values: list[str] | None) -> dict[str, tuple[float, float]]:
    """``--bound w0=10:200 --bound S_w=-1e4:0`` as ``{"w0": (10.0, 200.0), ...}`` (names checked by the library)."""
    bounds = {}
    for value in values or []:
        name, _, pair = value.partition("=")
        lower, sep, upper = pair.partition(":")
        try:
            if not name.strip() or not sep:
                raise ValueError
            bounds[name.strip()] = (float(lower), float(upper))
        except ValueError:
            raise HysidInputError("give NAME=LOWER:UPPER, e.g. --bound w0=10:200", param="bound", value=value) from None
    return bounds


def parse_fixed(values: list[str] | None) -> dict[str, float]:
    """``--fix meq=0.2`` as ``{"meq": 0.2}`` (names checked by the library)."""
    fixed = {}
    for value in values or []:
        name, sep, number = value.partition("=")
        try:
            if not name.strip() or not sep:
                raise ValueError
            fixed[name.strip()] = float(number)
        except ValueError:
            raise HysidInputError("give NAME=VALUE, e.g. --fix meq=0.2", param="fix", value=value) from None
    return fixed


def parse_list(value: str | None) -> list[str]:
    """``--candidates a:b,c:d`` as a list (each checked by the library)."""
    return [part.strip() for part in (value or "").split(",") if part.strip()]


def parse_algos(value: str) -> list[str]:
    """``--algos ga,pso`` as a list (each checked by the library)."""
    algos = [a.strip() for a in value.split(",") if a.strip()]
    if not algos or any(a not in ALGORITHMS for a in algos):
        raise HysidInputError(f"give a comma-separated list of {', '.join(ALGORITHMS)}", param="algos", value=value)
    return algos


def island_sizes(population: int | None, initial: int | None, iterations: int | None) -> dict[str, dict[str, Any]]:
    """The per-island sizes of ``--population``, ``--initial``, ``--iterations`` (None: not given) for every algorithm."""
    population = ISLAND_POPULATION if population is None else population
    initial = max(ISLAND_INITIAL, population) if initial is None else initial
    if initial < population:
        raise HysidInputError(f"must be at least --population {population}", param="initial_population", value=initial)
    counts = {} if iterations is None else {"iterations": iterations}
    return {algo: {"population": population, "initial_population": initial, **counts} for algo in ALGORITHMS}


def island_plan(
    loops: LoopSet,
    model: str,
    bounds: dict[str, tuple[float, float]] | None,
    algos: list[str],
    population: int | None,
    initial: int | None,
    iterations: int | None,
    termination: Termination,
) -> tuple[dict[str, dict[str, Any]] | None, Termination, bool, int | None]:
    """The islands' ``(options, termination, until_stopped, iterations)`` from ``--population``, ``--initial``,
    ``--iterations`` and the stop rules: with none of the three given on a model with memory, the library's
    defaults (:func:`hysid.campaigns.island_settings`: memetic islands), so that the command line and Python
    search alike; else these sizes, each island running :func:`island_budget`'s iterations."""
    if population is None and initial is None and iterations is None and default_options(loops, model, bounds, algos) is not None:
        options, chosen, until_stopped = island_settings(loops, model, bounds, algos, None, termination, None)
        return options, chosen or termination, until_stopped, None  # chosen: never None when termination is given
    iterations, until_stopped = island_budget(iterations, termination)
    return island_sizes(population, initial, iterations), termination, until_stopped, iterations


def island_budget(iterations: int | None, termination: Termination) -> tuple[int | None, bool]:
    """Each island's iteration budget and whether it searches until the campaign stops: without
    ``--iterations``, a budget in evaluations or time (:attr:`Termination.bounded`) lets every island
    run until the stop order, else each runs :data:`ISLAND_ITERATIONS`."""
    if iterations is not None:
        return iterations, False
    return (None, True) if termination.bounded else (ISLAND_ITERATIONS, False)
