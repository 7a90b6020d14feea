"""The command line's shared options: one definition (flag, default, help) per concept, and the output rules.

Commands take their options from here, so ``--json`` means the same (one JSON
object on stdout, bound to ``as_json``) and ``--out`` follows one policy
everywhere (:func:`hysid.cli.directories.report_dir`). :data:`FLAGS` maps the Python parameter a
library error names to the flag the user typed.
"""

from __future__ import annotations

import typer

from hysid_model.errors import HysidInputError
from hysid_model.presets import PRESETS
from island.algorithms import ALGORITHMS

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
