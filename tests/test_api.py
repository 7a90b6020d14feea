"""The Python front door (``import hysid``): load, fit, diagnose, campaign, result objects, models as data,
errors in Python's words, and the one-way flow between the packages."""

from __future__ import annotations

import ast
import inspect
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import hysid
from hysid.diagnosis.result import Step
from hysid.harmonic_fits import initial_fit
from hysid_model.harmonics import Harmonics
from hysid_model.objective import Objective
from hysid_model.synth import MEQ_KG, TRUE_PARAMS
from support import GA_SMALL as SMALL

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def loops():
    return hysid.load("synth", noise_pct=5.0, noise_seed=2)


@pytest.mark.slow  # over 3 s (fast lane, 2 cores, 2026-11-29)
def test_fit_returns_a_result_that_reports_itself(loops, tmp_path, capsys):
    result = hysid.fit(loops, "thesis", bounds={"w0": (150.0, 250.0)}, algo="ga", seed=1, options=SMALL)
    assert list(result.params) == ["xi0", "S_xi", "w0", "S_w"] and list(result.stderr) == list(result.params)
    for name, truth in TRUE_PARAMS.items():  # 5 % noise: within 5 standard errors of the truth
        assert abs(result.params[name] - truth) < 5 * result.stderr[name], name
    assert result.model.bounds[2].tolist() == [150.0, 250.0] and result.model.fixed == {"meq": MEQ_KG}
    doc = json.loads(json.dumps(result.to_dict()))
    assert doc["params"] == result.params and doc["fixed"] == {"meq": MEQ_KG}
    text = result.summary()
    assert "parameter" in text and "w0" in text and "Meq = 40 g (known)" in text
    path = result.write_report(tmp_path / "r")
    assert path == tmp_path / "r" / "report.md" and path.is_file() and result.report == str(path)
    markdown = result._repr_markdown_()
    assert "| `w0` |" in markdown and "X0 (mm)" in markdown
    assert capsys.readouterr() == ("", "")  # library code never prints


def test_results_and_their_parts_print_as_one_line_naming_what_they_are(loops):
    """``print(diagnosis.steps)`` and friends: a line each (the arrays are in the attributes, the rest in ``summary()``)."""
    few = loops.subset(np.arange(0, loops.n_loops, 8))
    result = hysid.fit(few, "thesis+coulomb_friction", algo="ga", options=SMALL, polish=False)
    assert re.fullmatch(r"<FitResult thesis\+coulomb_friction on synth-5pct-seed2: fitness [^;]+; xi0 \S+, S_xi \S+, w0 \S+, S_w \S+, F_d \S+>", repr(result))
    assert re.fullmatch(r"\[<RunResult run 1 \(ga, seed 0\): fitness \S+ after [\d,]+ evaluations>\]", repr(result.runs))
    assert repr(loops) == "<LoopSet synth-5pct-seed2: 120 loops at 25-34 Hz, X0 0.5-1.5 mm, 100 samples per branch, meq 0.04 kg>"
    assert repr(result.identifiability).startswith("<Identifiability of xi0, S_xi, w0, S_w, F_d: ")
    harmonics = Harmonics.from_loops(few)
    start = initial_fit(harmonics, "baseline")
    assert repr(harmonics) == "<Harmonics of synth-5pct-seed2: 15 loops x 15 coefficients (dc .. c7)>"
    assert re.fullmatch(r"<Fit baseline: whitened RMS \S+, BIC \S+, 2 parameters>", repr(start))
    step = Step("coulomb_friction", ["viscous_damping"], 12.5, start, start, {})
    assert re.fullmatch(r"\[<Step \+ coulomb_friction: score 12.5, whitened RMS (\S+) -> \1, BIC \+0.0; confusable with viscous_damping>\]", repr([step]))
    many = hysid.fit(few, "thesis+coulomb_friction+zener_thermoelastic", algo="ga", options=SMALL, polish=False)
    assert repr(many).endswith(", ... (7 in all)>") and "\n" not in repr(many)


def test_models_compose_and_a_known_value_is_one_fixed_parameter(loops):
    model = hysid.models.thesis + hysid.effects.coulomb_friction
    assert model.spec == "thesis+coulomb_friction" and model.names[-1] == "F_d"
    assert hysid.models.thesis.spec == "thesis"  # presets never change in place
    fixed = hysid.fit(loops, "baseline", fixed={"meq": 0.05}, algo="ga", options=SMALL, polish=False)
    assert fixed.model.fixed == {"meq": 0.05} and "meq" not in fixed.params
    fitted = hysid.fit(loops, "baseline", bounds={"meq": (0.01, 0.1)}, algo="ga", options=SMALL, polish=False)
    assert "meq" in fitted.params and fitted.model.fixed == {}
    unknown = hysid.fit(loops.with_meq(None), hysid.models.baseline, algo="ga", options=SMALL, polish=False)
    assert "meq" in unknown.params


@pytest.mark.slow  # over 3 s
def test_diagnosis_and_campaign_report_themselves_like_a_fit(loops, tmp_path, capsys):
    subset = loops.subset(np.arange(0, loops.n_loops, 4))
    diagnosis = hysid.diagnose(subset, "baseline", cross_validate=False)
    assert [s.effect for s in diagnosis.steps][:1] == ["amplitude_dependent_frequency"]
    assert set(diagnosis.params) == set(diagnosis.stderr) and "status" in diagnosis.to_dict()
    assert diagnosis.write_report(tmp_path / "d") == tmp_path / "d" / "diagnosis.md"
    assert "whitened RMS" in diagnosis.summary() and "**Status:" in diagnosis._repr_markdown_()
    sizes = {"population": 20, "initial_population": 40, "iterations": 10}
    campaign = hysid.campaign(subset, "thesis", islands=2, single_node=True, options={"ga": sizes, "pso": sizes}, migration=hysid.Migration(interval=5))
    doc = campaign.to_dict()
    assert [i["island"] for i in doc["islands"]] == ["island-0", "island-1"] and doc["params"] == campaign.params
    assert campaign.write_report(tmp_path / "c").read_text().startswith("# hysid campaign:")
    assert re.fullmatch(r"<CampaignResult 'campaign', thesis on \S+: 2 island run\(s\), fitness \S+, every island finished>", repr(campaign))
    assert repr(diagnosis).startswith(f"<Diagnosis of {subset.name}: baseline -> baseline+amplitude_dependent_frequency")
    assert len(repr(diagnosis.steps).splitlines()) == 1 and len(repr(diagnosis.steps)) < 200 * len(diagnosis.steps)
    assert "stopped because every island finished" in campaign.summary() and "| `w0` |" in campaign._repr_markdown_()
    assert capsys.readouterr() == ("", "")


def test_fit_diagnose_and_campaign_take_loops_then_model_and_the_rest_as_keywords():
    """One API shape: ``(loops, model, ...)`` in that order, everything else a keyword, as the README's table shows."""
    for function in (hysid.fit, hysid.diagnose, hysid.campaign):
        parameters = list(inspect.signature(function).parameters.values())
        assert [p.name for p in parameters[:2]] == ["loops", "model"], function.__name__
        assert all(p.kind is inspect.Parameter.POSITIONAL_OR_KEYWORD for p in parameters[:2])
        assert all(p.kind is inspect.Parameter.KEYWORD_ONLY for p in parameters[2:]), function.__name__


@pytest.mark.parametrize(
    "call, words",
    [
        (lambda lp: hysid.fit(lp, runs=0), "runs=0: "),
        (lambda lp: hysid.fit(lp, algo="de"), "algo='de': "),
        (lambda lp: hysid.fit(lp, weights="l2"), "weights='l2': "),
        (lambda lp: hysid.fit(lp, "thesis+warp_drive"), "unknown effect 'warp_drive'"),
        (lambda lp: hysid.fit(lp, bounds={"omega": (1.0, 2.0)}), "unknown parameter 'omega'"),
        (lambda lp: hysid.diagnose(lp, "quadratic"), "model='quadratic': "),
        (lambda lp: hysid.campaign(lp, islands=0), "islands=0: "),
        (
            lambda lp: hysid.campaign(lp, 4),
            "model=4: a model is a string such as 'thesis+coulomb_friction' or a hysid Model; "
            "the number of islands is a keyword: campaign(loops, model, islands=4)",
        ),
        (lambda lp: hysid.campaign(lp, options={"ga": {"population": 0}}), "population"),
        (lambda lp: hysid.load("synth", n_points=1), "n_points=1: "),
        (lambda lp: hysid.load("synth", noise_pct=-5), "noise_pct=-5: "),
        (lambda lp: Objective(lp, hysid.models.thesis)(np.zeros((1, 2))), "expected 5 parameter values"),
    ],
)
def test_library_errors_name_python_parameters_not_flags(loops, call, words):
    with pytest.raises(hysid.HysidInputError) as info:
        call(loops)
    message = str(info.value)
    assert words in message and "--" not in message and "\n" not in message


@pytest.mark.slow  # over 3 s
def test_the_example_script_runs(tmp_path):
    done = subprocess.run([sys.executable, str(ROOT / "examples" / "quickstart.py"), "synth", str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "status: adequate" in done.stdout and "stopped because every island finished" in done.stdout
    assert (tmp_path / "fit" / "report.md").is_file() and (tmp_path / "campaign" / "report.md").is_file()


def imports_of(package: str) -> dict[str, set[str]]:
    """Each module of ``package`` and the top-level packages (and hysid modules) it imports."""
    out = {}
    for path in (ROOT / package).rglob("*.py"):
        found = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                found.add(node.module)
            elif isinstance(node, ast.Import):
                found.update(alias.name for alias in node.names)
        out[str(path.relative_to(ROOT))] = found
    return out


def test_the_command_line_and_an_island_start_without_the_heavy_scientific_modules():
    """A campaign starts hundreds of island processes: the command line loads scipy's statistics,
    optimizers, special functions and MATLAB reader on first use, not at start."""
    code = "import sys, hysid.cli, island.node; print(sorted(m for m in sys.modules if m.split('.')[:2] in HEAVY))"
    heavy = "[['scipy', 'stats'], ['scipy', 'optimize'], ['scipy', 'special'], ['scipy', 'io'], ['matplotlib', 'pyplot'], ['numba']]"
    done = subprocess.run([sys.executable, "-c", f"HEAVY = {heavy}; {code}"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


def test_an_island_command_loads_only_what_an_island_needs():
    """The rule of hysid.cli.CommandTable: a command loads its own module of the command line, so ``hysid island``
    (once per island process) loads no coordinator, report, bench or front-door fit, and every command is still there."""
    from hysid.cli import command_modules

    assert command_modules(["island", "--connect", "tcp/127.0.0.1:7447"]) == ["island"]
    assert command_modules(["models"]) == [] and command_modules(["--version"]) == command_modules(["nonsense"])
    assert {"bench", "campaign", "data", "diagnose", "fit", "island", "router", "watch"} == set(command_modules(["--help"]))
    code = (
        "import sys, hysid.cli; hysid.cli.load_commands(['island']); "
        "print(sorted(m for m in sys.modules if m.startswith(('coordinator', 'hysid.report', 'hysid.bench', 'hysid.fitting', 'hysid.campaigns'))))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"
    everything = subprocess.run([sys.executable, "-m", "hysid", "--help"], capture_output=True, text=True, timeout=60)
    listed = everything.stdout.split("Commands:")[1]
    assert [line.split()[0] for line in listed.strip().splitlines()] == [
        "synth",
        "loops",
        "fit",
        "campaign",
        "coordinator",
        "island",
        "router",
        "diagnose",
        "watch",
        "report",
        "models",
        "reproduce",
        "bench",
    ]


def test_data_flows_one_way_between_the_packages():
    """files -> loops -> objective (hysid_model) -> optimizer, island (island) -> coordinator -> report (hysid)."""
    above = {"hysid_model": ("island", "coordinator", "hysid"), "island": ("coordinator", "hysid"), "coordinator": ("hysid",)}
    for package, forbidden in above.items():
        for module, imported in imports_of(package).items():
            bad = sorted(m for m in imported if m.split(".")[0] in forbidden)
            assert not bad, f"{module} imports {bad}"
    island = imports_of("island")
    wire_format = {  # the wire format stands on the loop set and the error type only
        "island/wire.py": {"hysid_model.errors"},
        "island/sealing.py": {"island.wire"},
        "island/protocol.py": {"hysid_model.errors", "hysid_model.loops", "island.sealing", "island.wire"},
    }
    for module, allowed in wire_format.items():
        assert {m for m in island[module] if m.split(".")[0] in ("hysid_model", "island")} == allowed, module
    coordinator = imports_of("coordinator")
    below = {  # a module stands below the one it must not import: the node needs only its Transport, the checks and the share
        "island/node.py": "island.transports",  # not the coordinator, the coordinator not the run loop that drives it
        "coordinator/histories.py": "coordinator.state",
        "coordinator/sharing.py": "coordinator.state",
        "coordinator/state.py": "coordinator.loop",
        "coordinator/progress.py": "coordinator.state",
        "coordinator/outcome.py": "coordinator.state",  # the outcome takes a record of the end, not the coordinator
        "coordinator/queries.py": "coordinator.writes",  # the read side stands below the writes
    }
    for module, host in below.items():
        assert host not in {**island, **coordinator}[module], module


def test_every_name_the_front_door_exports_resolves():
    """``hysid.__all__`` is the export table itself, and every name in it imports (a subprocess: a fresh interpreter)."""
    script = "import hysid\nfor name in hysid.__all__:\n    assert getattr(hysid, name) is not None, name\nprint(len(hysid.__all__))"
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert set(hysid.__all__) == set(hysid._EXPORTS) | {"__version__"} and int(done.stdout) == len(hysid.__all__)


def test_the_command_line_takes_pythons_defaults_except_where_the_api_table_says():
    """Every option `hysid fit`, `diagnose` and `campaign` share with `hysid.fit`, `diagnose` and `campaign`
    has the same default; where they differ, docs/API.md's table says so, with both values as the code has them."""
    import inspect

    import typer

    from hysid.cli import app
    from hysid.cli import options as o
    from island.ga import GA

    commands = typer.main.get_command(app).commands
    for name, function in {"fit": hysid.fit, "diagnose": hysid.diagnose, "campaign": hysid.campaign}.items():
        python = inspect.signature(function).parameters
        shared = [p for p in commands[name].params if p.name in python and p.name not in ("dataset", "db")]
        assert len(shared) >= 3
        for p in shared:
            cli = p.default.split(",") if p.name == "algos" else p.default
            assert cli == (list(python[p.name].default) if p.name == "algos" else python[p.name].default), (name, p.name)
    campaign = {p.name: p for p in commands["campaign"].params}
    ga = inspect.signature(GA).parameters
    text = (Path(__file__).parents[1] / "docs" / "API.md").read_text()
    table = {
        row.split("|")[1].strip(): [c.strip() for c in row.split("|")[2:4]]
        for row in text.split("### The command line and Python")[1].splitlines()
        if row.startswith("| `--") or row.startswith("| DATASET")
    }
    assert table == {
        "`--interval`": [str(campaign["interval"].default), f"`Migration().interval` = {hysid.Migration().interval}"],
        "`--population` (memoryless model)": [str(o.ISLAND_POPULATION), f"`GA`/`PSO` `population` = {ga['population'].default}"],
        "`--initial` (memoryless model)": [str(o.ISLAND_INITIAL), f"`GA`/`PSO` `initial_population` = {ga['initial_population'].default}"],
        "`--iterations` (memoryless model, no budget)": [str(o.ISLAND_ITERATIONS), f"`GA`/`PSO` `iterations` = {ga['iterations'].default}"],
        "`--db`": ["OUT/campaign.sqlite", f"`db` = {inspect.signature(hysid.campaign).parameters['db'].default}"],
        "DATASET of `campaign`": ["synth", "`loops` (required)"],
    }
    assert campaign["interval"].default != hysid.Migration().interval and campaign["population"].default is None


def test_a_campaign_on_a_model_with_memory_gets_the_same_islands_from_the_command_line_and_python(loops):
    """With no island sizes given, `hysid campaign`'s islands on a Bouc-Wen model are hysid.campaign's memetic
    ones (small swarms, an evaluation budget, searching until the stop order), and sizes given are kept."""
    from hysid.campaigns import island_settings
    from hysid.cli import options as o
    from hysid.cli.plans import island_plan
    from island.termination import Termination

    cli = island_plan(loops, "thesis+bouc_wen", None, ["ga", "pso"], None, None, None, Termination())
    python = island_settings(loops, "thesis+bouc_wen", None, ["ga", "pso"], None, None, None)
    assert cli[:3] == python and cli[0]["pso"]["population"] < o.ISLAND_POPULATION and python[1].budget and python[2] is True
    given = island_plan(loops, "thesis+bouc_wen", None, ["ga", "pso"], 50, None, None, Termination())
    assert given[0]["ga"] == {"population": 50, "initial_population": o.ISLAND_INITIAL, "iterations": o.ISLAND_ITERATIONS} and given[2] is False
    thesis = island_plan(loops, "thesis", None, ["ga", "pso"], None, None, None, Termination(time_limit_s=5))
    assert thesis[0]["pso"]["population"] == o.ISLAND_POPULATION and thesis[1].budget is None and thesis[2] is True
