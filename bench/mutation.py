"""Mutation benchmark of hysid's rule modules (issue 36): mutmut makes one-line bugs in each module's rule functions
and runs, for each module, only its fast targeted tests; the score and every survivor go to
bench/results/mutation-<date>-<host>.json. A benchmark, not CI: it takes tens of minutes on two shared cores.

    pip install -e '.[test,mutation]'
    python bench/mutation.py                      # every module below
    python bench/mutation.py motion sealing       # some of them (the keys of MODULES)

Each module is mutated in a copy of the four packages and tests/ in a temporary directory (mutmut writes its
mutants/ beside its configuration, which names that module and its tests only), so the work tree is never touched.
mutmut mutates code inside functions only (a module-level constant such as a threshold is left to the rule tests,
which pin each one from both sides). The score is mutmut's own: killed (or timed out) over all mutants run;
a mutant no selected test reaches counts as a survivor ("no tests"). ``EQUIVALENT`` lists mutants examined by hand
that no test can kill, with why; they are reported apart and left out of the score.
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from importlib.metadata import version
from pathlib import Path

from mutation_verdicts import EQUIVALENT, UNTESTABLE  # beside this script, on the path it is run from

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hysid.bench import environment  # noqa: E402  (the repository's own package, from this checkout)

PACKAGES = ("hysid", "hysid_model", "island", "coordinator")
TARGET = 0.90

MODULES: dict[str, dict[str, object]] = {
    "acceptance": {
        "path": "hysid/diagnosis/acceptance.py",
        "functions": ["judge", "degenerate_gives_way", "created_order"],
        "tests": ["tests/test_rules_acceptance.py", "tests/test_own_shape.py::test_a_cubic_spring_standing_in_for_a_gap_is_refused_for_its_shape"],
    },
    "motion": {
        "path": "hysid/motion.py",
        "functions": ["decide", "distorted", "linear_start", "MotionChoice.delta_bic"],
        "tests": ["tests/test_rules_motion.py"],
    },
    "plausibility": {
        "path": "hysid_model/plausibility.py",
        "functions": ["_outliers", "warn_loops", "names", "amplitude_drift"],
        "tests": ["tests/test_rules_plausibility.py"],
    },
    "uncertainty": {
        "path": "hysid_model/uncertainty.py",
        "functions": ["scaled_inverse", "jacobian_covariance", "noise_sigma"],
        "tests": ["tests/test_rules_uncertainty.py"],
    },
    "identifiability": {
        "path": "hysid/identifiability.py",
        "functions": ["partners", "unseen", "assess", "side_width", "crossing"],
        "tests": [
            "tests/test_rules_identifiability.py",
            "tests/test_identifiability.py::test_the_profile_crossing_is_found_for_a_quadratic_a_wall_and_a_flat_profile",
        ],
    },
    "channels": {
        "path": "hysid_model/readers/channels.py",
        "functions": ["choose"],
        "tests": ["tests/test_rules_channels.py"],
    },
    "sealing": {
        "path": "island/sealing.py",
        "functions": ["ReplayGuard.check", "ReplayGuard.fresh", "ReplayGuard.high", "check_replay"],
        "tests": ["tests/test_rules_sealing.py"],
    },
    "secret": {
        "path": "island/secret.py",
        "functions": ["read_owner_only", "write_owner_only"],
        "tests": ["tests/test_rules_secret.py"],
    },
    "members": {
        "path": "coordinator/members.py",
        "functions": ["Membership.take_up", "Membership.alive", "Membership.heard", "Membership.final_history", "Membership.settle"],
        "tests": ["tests/test_rules_members.py"],
    },
    "user_terms": {
        "path": "hysid_model/user_terms.py",
        "functions": ["check_strength"],
        "tests": ["tests/test_rules_user_terms.py"],
    },
    "model": {
        "path": "hysid_model/model.py",
        "functions": ["Model._on_bounds", "Model.at_bounds", "Model.bound_kinds"],
        "tests": ["tests/test_rules_model.py"],
    },
}
"""Per module: the file, its rule functions in scope (``Class.method`` for a method) and its fast targeted tests."""

STATUS = {
    1: "killed",
    3: "killed",
    0: "survived",
    5: "no tests",
    33: "no tests",
    34: "skipped",
    36: "timeout",
    24: "timeout",
    -24: "timeout",
    152: "timeout",
    255: "timeout",
    37: "caught by type check",
    None: "not checked",
}
"""mutmut's exit codes of a mutant's test run (mutmut.stats.status_by_exit_code), those that occur here."""
DIFFS = """import json, sys
from pathlib import Path
from mutmut.mutation.diff_apply import get_diff_for_mutant
print(json.dumps({name: get_diff_for_mutant(name, path=Path(sys.argv[1])) for name in sys.argv[2:]}))
"""
"""What ``mutmut show`` prints, for many mutants in one process (run in the scratch copy): name -> unified diff."""
CLASS_SEPARATOR = "\u01c1"
"""How mutmut joins a class and a method in a mutant's name (``x<sep>Class<sep>method``)."""


def mutant_glob(module: str, function: str) -> str:
    """mutmut's name pattern of the mutants of ``function`` (``name`` or ``Class.method``) in dotted ``module``."""
    if "." in function:
        cls, method = function.split(".")
        return f"{module}.x{CLASS_SEPARATOR}{cls}{CLASS_SEPARATOR}{method}__mutmut_*"
    return f"{module}.x_{function}__mutmut_*"


def workspace(where: Path, path: str, tests: list[str]) -> None:
    """A copy of the packages and tests in ``where`` with a mutmut configuration for ``path`` and ``tests`` alone."""
    for package in PACKAGES:
        shutil.copytree(ROOT / package, where / package, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
    shutil.copytree(ROOT / "tests", where / "tests", ignore=shutil.ignore_patterns("__pycache__"))
    text = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    (where / "pyproject.toml").write_text(re.sub(r"\n\[tool\.mutmut\][^\[]*", "\n", text), encoding="utf-8")
    lines = [
        "[mutmut]",
        "source_paths =",
        *(f"    {p}" for p in PACKAGES),
        f"only_mutate = {path}",
        "pytest_add_cli_args_test_selection =",
        *(f"    {t}" for t in tests),
        "pytest_add_cli_args =",
        "    -p",
        "    no:cacheprovider",
        "    -m",
        "    not slow",
        "",
    ]
    (where / "setup.cfg").write_text("\n".join(lines), encoding="utf-8")


def function_spans(source: str) -> dict[str, int]:
    """``name`` or ``Class.method`` -> the first line (of its decorators, if any) of every function of ``source``."""
    spans: dict[str, int] = {}

    def first(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
        return min([node.lineno, *(d.lineno for d in node.decorator_list)])

    for node in ast.parse(source).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            spans[node.name] = first(node)
        elif isinstance(node, ast.ClassDef):
            for item in node.body:
                if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    spans[f"{node.name}.{item.name}"] = first(item)
    return spans


def function_of(name: str) -> str:
    """``Class.method`` or ``function`` of a mutant's name."""
    last = name.partition("__mutmut_")[0].rpartition(".")[2]
    if CLASS_SEPARATOR in last:
        _, cls, method = last.split(CLASS_SEPARATOR)
        return f"{cls}.{method}"
    return last[2:]


def located(diff: str, start: int) -> tuple[int | None, str, str]:
    """(line in the module, the original lines, the mutated lines) of a mutant's diff (``mutmut show``: a unified
    diff of the function's text, which begins on line ``start`` of the module)."""
    removed, added, line, at = [], [], None, None
    for text in diff.splitlines():
        hunk = re.match(r"@@ -(\d+)", text)
        if hunk:
            at = int(hunk.group(1))
        elif at is None or text.startswith(("---", "+++")):
            continue
        elif text.startswith("-"):
            line = start + at - 1 if line is None else line
            removed.append(text[1:].strip())
            at += 1
        elif text.startswith("+"):
            added.append(text[1:].strip())
        else:
            at += 1
    return line, "\n".join(removed), "\n".join(added)


def run_module(key: str, spec: dict[str, object], max_children: int) -> dict[str, object]:
    """Mutate one module's rule functions in a scratch copy and run its tests against every mutant."""
    path, functions, tests = str(spec["path"]), list(spec["functions"]), list(spec["tests"])  # type: ignore[arg-type]
    dotted = path.removesuffix(".py").replace("/", ".")
    source = (ROOT / path).read_text(encoding="utf-8")
    spans = function_spans(source)
    missing = [f for f in functions if f not in spans]
    if missing:
        raise SystemExit(f"bench/mutation.py: {path} has no function {', '.join(missing)} (update MODULES)")
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix=f"hysid-mutation-{key}-") as scratch:
        where = Path(scratch)
        workspace(where, path, tests)
        env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1", "MPLBACKEND": "Agg"}
        globs = [mutant_glob(dotted, f) for f in functions]
        run = subprocess.run(
            [sys.executable, "-m", "mutmut", "run", "--max-children", str(max_children), *globs], cwd=where, env=env, capture_output=True, text=True
        )
        meta = where / "mutants" / (path + ".meta")
        if run.returncode != 0 or not meta.exists():
            raise SystemExit(f"bench/mutation.py: mutmut failed on {path} (exit {run.returncode}):\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}")
        codes = json.loads(meta.read_text(encoding="utf-8"))["exit_code_by_key"]
        chosen = {name: code for name, code in codes.items() if function_of(name) in functions}
        order = sorted(chosen, key=lambda name: (name.partition("__mutmut_")[0], int(name.rpartition("_")[2])))
        listed = [name for name in order if STATUS.get(chosen[name]) != "killed" or name in EQUIVALENT]
        diffs = json.loads(subprocess.run([sys.executable, "-c", DIFFS, path, *listed], cwd=where, env=env, capture_output=True, text=True, check=True).stdout)
        mutants = []
        for name in order:
            status = STATUS.get(chosen[name], f"exit code {chosen[name]}")
            if name not in diffs:
                mutants.append({"name": name, "status": status})
                continue
            line, original, mutated = located(diffs[name], spans[function_of(name)])
            note = {"note": UNTESTABLE["stacklevel"]} if status == "survived" and "stacklevel" in original + mutated else {}
            mutants.append(
                {
                    "name": name,
                    "status": status,
                    "function": function_of(name),
                    "line": line,
                    "original": original,
                    "mutated": mutated,
                    **({"equivalent": EQUIVALENT[name]} if name in EQUIVALENT else {}),
                    **note,
                }
            )
    counted = [m for m in mutants if "equivalent" not in m and m["status"] not in ("skipped", "not checked")]
    killed = sum(m["status"] in ("killed", "timeout") for m in counted)
    return {
        "file": path,
        "functions": functions,
        "tests": tests,
        "mutants": len(mutants),
        "killed": killed,
        "counted": len(counted),
        "equivalent": sum("equivalent" in m for m in mutants),
        "score": round(killed / len(counted), 4) if counted else None,
        "score_equivalent_counted": round(killed / (len(counted) + sum("equivalent" in m for m in mutants)), 4) if mutants else None,
        "seconds": round(time.monotonic() - started, 1),
        "survivors": [
            {k: m[k] for k in ("name", "status", "function", "line", "original", "mutated", "equivalent", "note") if k in m}
            for m in mutants
            if m["status"] not in ("killed", "timeout") or "equivalent" in m
        ],
        "mutmut_exit": run.returncode,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("modules", nargs="*", help=f"modules to mutate, of {', '.join(MODULES)} (default: all)")
    parser.add_argument("--max-children", type=int, default=1, help="mutants tested at once (default 1: a shared machine)")
    parser.add_argument("--out", type=Path, default=None, help="result file (default bench/results/mutation-<date>-<host>.json)")
    parser.add_argument("--update", action="store_true", help="keep the other modules' results already in the result file")
    parser.add_argument(
        "--merge",
        type=Path,
        nargs="+",
        default=[],
        help="only combine these result files (runs of different modules, e.g. in parallel) into the result file; a module in several is taken from the last",
    )
    parser.add_argument("--note", default="", help="a sentence stored with the result (what the runs were made on)")
    args = parser.parse_args()
    if args.merge:
        merged = [json.loads(f.read_text(encoding="utf-8")) for f in args.merge]
        result = {
            **merged[-1],
            "modules": {k: rescored(v) for r in merged for k, v in r["modules"].items()},
            "merged_from": [r["date"] for r in merged],
            **({"note": args.note} if args.note else {}),
        }
        out = args.out or ROOT / "bench" / "results" / f"mutation-{time.strftime('%Y-%m-%d')}-{environment()['machine']['hostname']}.json"
        write(result, out)
        print(f"mutation: score {result['score']} ({result['killed']} of {result['counted']}); {out}", file=sys.stderr)
        return
    unknown = [m for m in args.modules if m not in MODULES]
    if unknown:
        parser.error(f"no module {unknown[0]!r}; choose of {', '.join(MODULES)}")
    chosen = args.modules or list(MODULES)
    out = args.out or ROOT / "bench" / "results" / f"mutation-{time.strftime('%Y-%m-%d')}-{environment()['machine']['hostname']}.json"
    before = json.loads(out.read_text(encoding="utf-8"))["modules"] if args.update and out.exists() else {}
    result: dict[str, object] = {
        "bench": "mutation",
        "tool": "mutmut " + version("mutmut"),
        "target": TARGET,
        **environment(),
        "modules": {k: v for k, v in before.items() if k in MODULES and k not in chosen},
    }
    for key in chosen:
        print(f"mutation: {key} ({MODULES[key]['path']}) ...", file=sys.stderr, flush=True)
        result["modules"][key] = found = run_module(key, MODULES[key], args.max_children)  # type: ignore[index]
        print(
            f"mutation: {key}: {found['killed']} of {found['counted']} killed, score {found['score']}, {len(found['survivors'])} listed, {found['seconds']} s",
            file=sys.stderr,
            flush=True,
        )
        write(result, out)  # after every module: a long run stopped keeps what it found
    print(f"mutation: score {result['score']} ({result['killed']} of {result['counted']}); {out}", file=sys.stderr)


def rescored(module: dict) -> dict:
    """A module's result with its survivors marked by the ``EQUIVALENT`` table as it is now (one examined after
    its run), and its counts and score again."""
    for survivor in module["survivors"]:
        survivor.setdefault("file", module["file"])
        if survivor["name"] in EQUIVALENT:
            survivor["equivalent"] = EQUIVALENT[survivor["name"]]
    equivalent = sum("equivalent" in s for s in module["survivors"])
    unrun = sum(s["status"] in ("skipped", "not checked") and "equivalent" not in s for s in module["survivors"])
    counted = module["mutants"] - equivalent - unrun
    return {
        **module,
        "equivalent": equivalent,
        "counted": counted,
        "score": round(module["killed"] / counted, 4) if counted else None,
        "score_equivalent_counted": round(module["killed"] / (counted + equivalent), 4) if counted + equivalent else None,
    }


def write(result: dict[str, object], out: Path) -> None:
    """``result`` with its overall score (killed over the mutants counted, every module together), to ``out``."""
    modules = result["modules"].values()  # type: ignore[union-attr]
    counted = sum(
        m["counted"]
        if "counted" in m
        else m["mutants"]
        - m["equivalent"]
        - sum(  # a result file of before "counted"
            s["status"] in ("skipped", "not checked") and "equivalent" not in s for s in m["survivors"]
        )
        for m in modules
    )
    killed = sum(m["killed"] for m in modules)
    equivalent = sum(m["equivalent"] for m in modules)
    result.update(
        score=round(killed / counted, 4) if counted else None,
        killed=killed,
        counted=counted,
        equivalent=equivalent,
        score_equivalent_counted=round(killed / (counted + equivalent), 4) if counted + equivalent else None,
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
