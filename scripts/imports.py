"""The figure of docs/ARCHITECTURE.md, drawn from the code's imports.

Reads every module of the four packages (hysid, hysid_model, island, coordinator) with ``ast``,
takes every import of one of them (module level, under ``TYPE_CHECKING`` and inside functions
alike: import-linter counts them all), and draws the rooms (a package's top modules, or one of
its sub-packages) as a Mermaid flowchart with an arrow per room imported, labelled with the
number of imports behind it. It also lists the import circles between modules (strongly
connected components), which must stay empty.

    python scripts/imports.py            # print the figure and any circle
    python scripts/imports.py --write    # rewrite the figure in docs/ARCHITECTURE.md
    python scripts/imports.py --check    # exit 1 if the figure there is stale (lint-imports fails CI on a circle)

The figure sits between the markers ``<!-- imports:begin -->`` and ``<!-- imports:end -->``.
"""

from __future__ import annotations

import argparse
import ast
import sys
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("hysid", "hysid_model", "island", "coordinator")
DOC = ROOT / "docs" / "ARCHITECTURE.md"
BEGIN, END = "<!-- imports:begin -->", "<!-- imports:end -->"


def modules() -> dict[str, Path]:
    """Every module of the four packages, by dotted name."""
    found: dict[str, Path] = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            found[name] = path
    return found


def imported(name: str, path: Path, known: dict[str, Path]) -> set[str]:
    """The modules of the four packages that module ``name`` imports (a name imported from a
    package counts as its sub-module where one exists, else as the package)."""
    is_package = path.name == "__init__.py"
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = name.split(".") if is_package else name.split(".")[:-1]
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join([*anchor, base] if base else anchor)
            targets = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base for alias in node.names]
        else:
            continue
        for target in targets:
            while target and target not in known:
                target = target.rpartition(".")[0]
            if target and target != name:
                out.add(target)
    return out


def graph() -> dict[str, set[str]]:
    known = modules()
    return {name: imported(name, path, known) for name, path in known.items()}


def room(module: str, rooms: set[str]) -> str:
    """The room a module is in: the deepest package among ``rooms`` that holds it."""
    parts = module.split(".")
    for k in range(len(parts), 0, -1):
        if ".".join(parts[:k]) in rooms:
            return ".".join(parts[:k])
    return parts[0]


def circles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Import circles: the strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    sys.setrecursionlimit(10_000)
    for v in sorted(edges):
        if v not in index:
            visit(v)
    return sorted(found)


def figure(edges: dict[str, set[str]]) -> str:
    """The rooms and their imports as a Mermaid flowchart, one subgraph per package."""
    known = modules()
    rooms = {name for name, path in known.items() if path.name == "__init__.py"}
    counts: Counter[tuple[str, str]] = Counter()
    sizes: Counter[str] = Counter()
    for source, targets in edges.items():
        sizes[room(source, rooms)] += 1
        for target in targets:
            a, b = room(source, rooms), room(target, rooms)
            if a != b:
                counts[a, b] += 1
    node = lambda r: r.replace(".", "_")
    lines = ["```mermaid", "flowchart TD"]
    for package in PACKAGES:
        lines.append(f"  subgraph {package}_pkg [{package}/]")
        for r in sorted(x for x in sizes if x.split(".")[0] == package):
            label = r if r == package else r.split(".", 1)[1]
            lines.append(f'    {node(r)}["{label} ({sizes[r]})"]')
        lines.append("  end")
    for (a, b), n in sorted(counts.items()):
        lines.append(f"  {node(a)} -->|{n}| {node(b)}")
    lines.append("```")
    return "\n".join(lines)


def block(edges: dict[str, set[str]]) -> str:
    loops = circles(edges)
    said = "no import circle between modules" if not loops else f"{len(loops)} import circles: " + "; ".join(" <-> ".join(c) for c in loops)
    return "\n".join(
        [
            BEGIN,
            "Drawn from the imports by `python scripts/imports.py --write` (a room: a package's top modules or a sub-package, with its",
            f"number of modules; an arrow: imports from one room into another, with their number); {said}.",
            "",
            figure(edges),
            END,
        ]
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--write", action="store_true", help="rewrite the figure in docs/ARCHITECTURE.md")
    ap.add_argument("--check", action="store_true", help="exit 1 if the figure in docs/ARCHITECTURE.md is stale")
    args = ap.parse_args()
    edges = graph()
    new = block(edges)
    if not (args.write or args.check):
        print(new)
        return 0
    text = DOC.read_text(encoding="utf-8")
    if BEGIN not in text or END not in text:
        print(f"scripts/imports.py: {DOC.relative_to(ROOT)} has no {BEGIN} ... {END} block", file=sys.stderr)
        return 1
    head, rest = text.split(BEGIN, 1)
    old, tail = rest.split(END, 1)
    if args.write:
        DOC.write_text(head + new + tail, encoding="utf-8")
    elif args.check:
        problems = []
        if BEGIN + old + END != new:
            problems.append(f"the figure in {DOC.relative_to(ROOT)} is stale: run python scripts/imports.py --write")
        for p in problems:
            print(f"scripts/imports.py: {p}", file=sys.stderr)
        return 1 if problems else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
