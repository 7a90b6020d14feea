"""The reproduction's report: Tables 5.5-5.13 and Figs. 5.2-5.13 next to the thesis' published numbers, and its text summary."""

from __future__ import annotations

import datetime as dt
from pathlib import Path
from typing import Any

import numpy as np

from hysid import thesis_tables as tt
from hysid.report import jsondoc
from hysid.report.markdown import FITNESS_LABEL, image, num, table
from hysid.report.records import ReproductionCurves
from hysid_model.synth import TRUE_PARAMS

UNITS = {"xi0": "1", "S_xi": "1/m", "w0": "rad/s", "S_w": "rad/s/m"}
PARAMS = tt.PARAMS


def cells(doc: dict[str, Any]) -> dict[tuple[str, str, int], dict[str, Any]]:
    """The document's cells by (setting, algorithm, noise %)."""
    return {(c["setting"], c["algo"], c["noise_pct"]): c for c in doc["cells"]}


def _run_table(doc: dict[str, Any], labels: dict[str, str], algo: str, noise: int) -> str:
    found = cells(doc)
    n_cols = max(len(doc["noise_seeds"]), 4)
    headers = ["parameter", "source", "actual"] + [f"run {i + 1}" for i in range(n_cols)] + ["mean", "sigma", "sigma/mean", "Cramer-Rao"]
    rows = []
    for p in PARAMS:
        pub = tt.RUNS[(algo, noise)][p]
        mean, std, rel = tt.SUMMARY[(algo, noise)][p]
        cr = num(doc["cramer_rao"][str(noise)][p], 3) if noise > 0 else "0"
        rows.append(
            [f"`{p}`", "published", num(TRUE_PARAMS[p], 7)] + [num(v, 7) for v in pub] + [""] * (n_cols - 4) + [num(mean, 7), num(std, 4), num(rel, 4), cr]
        )
        for key, label in labels.items():
            cell = found[(key, algo, noise)]
            v = cell["runs"][p]
            rows.append(
                ["", label, ""]
                + [num(x, 7) for x in v]
                + [""] * (n_cols - v.size)
                + [num(cell["mean"][p], 7), num(cell["std"][p], 4), num(cell["rel_std"][p], 4), ""]
            )
    return table(headers, rows)


def _table_5_13(doc: dict[str, Any], labels: dict[str, str]) -> str:
    found, n_runs = cells(doc), len(doc["noise_seeds"])
    headers = ["parameter", "source"] + [f"{n} % {a.upper()}" for n in tt.NOISE_LEVELS for a in tt.ALGOS]
    rows = []
    for p in PARAMS:
        rows.append([f"`{p}`", "published"] + [num(tt.TABLE_5_13[p][(a, n)], 3) for n in tt.NOISE_LEVELS for a in tt.ALGOS])
        for key, label in labels.items():
            rows.append(["", label] + [num(found[(key, a, n)]["abs_error_of_mean"][p], 3) for n in tt.NOISE_LEVELS for a in tt.ALGOS])
        rows.append(["", f"CR / sqrt({n_runs})"] + [num(doc["cramer_rao"][str(n)][p] / np.sqrt(n_runs), 3) for n in tt.NOISE_LEVELS for _ in tt.ALGOS])
    return table(headers, rows)


REPORT = "report.md"
"""The name of the reproduction's report in its directory."""


def write_reproduction_report(doc: dict[str, Any], labels: dict[str, str], curves: ReproductionCurves, out_dir: Path) -> Path:
    """Write ``report.md`` (``out_dir / REPORT``, which ``doc`` names), ``reproduction.json`` (``doc``) and Figs. 5.2-5.13
    (of ``curves``) into ``out_dir``; ``labels``: each setting's words by its key. Returns the report path."""
    from hysid.report import figures  # matplotlib loads only when a report is drawn

    out_dir.mkdir(parents=True, exist_ok=True)
    jsondoc.write(out_dir / "reproduction.json", doc)
    found = cells(doc)
    parts = [
        "# hysid reproduce thesis: the Synth benchmark of section 5.2.1",
        f"Written {dt.datetime.now().isoformat(timespec='seconds')}. {len(doc['noise_seeds'])} run(s) per algorithm, noise level and "
        f"setting; run r uses noise seed {', '.join(map(str, doc['noise_seeds']))} (in order) and optimizer seed "
        f"{doc['seed']} + r. All numbers are also in [`reproduction.json`](reproduction.json).",
        "- **thesis-faithful**: the thesis' GA and PSO (section 5.1: 6000 initial, 500 per iteration, 18 iterations), "
        "the thesis' loop weights (Appendix A), no polish.\n"
        "- **hysid defaults**: the same search, then a bounded least-squares polish; maximum-likelihood weights "
        "(1/sigma^2) when the data are noisy.\n"
        "- **published**: the thesis' Tables 5.5-5.13 as printed. **Cramer-Rao**: the smallest standard error any "
        "unbiased estimator can reach at that noise level (one run).",
    ]
    parts += ["## Table 5.13: |mean - actual|", _table_5_13(doc, labels)]
    n_fig = 2
    parts.append("## Figs. 5.2-5.5: parameter scatter per noise level")
    for p in PARAMS:
        panels = [
            (
                f"({'ab'[k]}) {algo.upper()}",
                [
                    ("published", {n: np.array(tt.RUNS[(algo, n)][p]) for n in tt.NOISE_LEVELS}),
                    *[(label, {n: found[(key, algo, n)]["runs"][p] for n in tt.NOISE_LEVELS if (key, algo, n) in found}) for key, label in labels.items()],
                ],
            )
            for k, algo in enumerate(tt.ALGOS)
        ]
        path = figures.scatter_figure(
            out_dir / f"fig5_{n_fig}_{p}.png", p, UNITS[p], TRUE_PARAMS[p], panels, {int(n): b[p] for n, b in doc["cramer_rao"].items()}
        )
        parts.append(
            image(
                path, out_dir, f"Fig. 5.{n_fig}: {p} per noise level; hollow: runs, filled: mean, red dashed: true value, grey band: true +- Cramer-Rao bound"
            )
        )
        n_fig += 1
    parts.append("## Figs. 5.6-5.9: convergence (thesis-faithful runs)")
    for noise in tt.NOISE_LEVELS:
        runs = [(f"({'ab'[k]}) {algo.upper()}", curves.runs[(algo, noise)]) for k, algo in enumerate(tt.ALGOS)]
        path = figures.convergence_figure(out_dir / f"fig5_{n_fig}_convergence_{noise}pct.png", runs, FITNESS_LABEL["thesis"], f"{noise} % noise")
        parts.append(image(path, out_dir, f"Fig. 5.{n_fig}: convergence at {noise} % noise, all runs overlaid, matching scales"))
        n_fig += 1
    parts.append("## Figs. 5.10-5.13: measured vs model loops (thesis-faithful PSO, run 1)")
    for noise in tt.NOISE_LEVELS:
        loops, predicted = curves.loops[noise]
        path = figures.loops_figure(out_dir / f"fig5_{n_fig}_loops_{noise}pct.png", loops, predicted, title=f"{noise} % noise")
        parts.append(image(path, out_dir, f"Fig. 5.{n_fig}: loops at {noise} % noise; rows: 0.5, 1.0, 1.5 mm"))
        n_fig += 1
    parts.append("## Tables 5.5-5.12: every run")
    for algo in tt.ALGOS:
        for noise in tt.NOISE_LEVELS:
            parts += [f"### Table 5.{tt.TABLE_NUMBERS[(algo, noise)]}: {algo.upper()}, {noise} % noise", _run_table(doc, labels, algo, noise)]
    report = out_dir / REPORT
    report.write_text("\n\n".join(parts) + "\n")
    return report


def reproduction_summary(doc: dict[str, Any], labels: dict[str, str]) -> str:
    """Table 5.13 side by side (the reproduction's document; ``labels``: each setting's words by its key), for the terminal."""
    found = cells(doc)
    lines = [f"Table 5.13, |mean - actual| over {len(doc['noise_seeds'])} run(s) (noise seeds {', '.join(map(str, doc['noise_seeds']))}):"]
    head = f"  {'parameter':<9} {'source':<16}" + "".join(f"{f'{n}% ' + a.upper():>11}" for n in tt.NOISE_LEVELS for a in tt.ALGOS)
    lines.append(head)
    for p in tt.PARAMS:
        row = f"  {p:<9} {'published':<16}" + "".join(f"{tt.TABLE_5_13[p][(a, n)]:>11.3g}" for n in tt.NOISE_LEVELS for a in tt.ALGOS)
        lines.append(row)
        for key, label in labels.items():
            row = f"  {'':<9} {label:<16}" + "".join(f"{found[(key, a, n)]['abs_error_of_mean'][p]:>11.3g}" for n in tt.NOISE_LEVELS for a in tt.ALGOS)
            lines.append(row)
    if doc["report"]:
        lines += ["", f"report: {doc['report']}"]
    return "\n".join(lines)
