"""The reproduction's report: Tables 5.5-5.13 and Figs. 5.2-5.13 next to the thesis' published numbers, and its text summary."""

from __future__ import annotations

import datetime as dt
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hysid import thesis_tables as tt
from hysid.report import jsondoc
from hysid.report.markdown import FITNESS_LABEL, image, num, table
from hysid_model.synth import TRUE_PARAMS

if TYPE_CHECKING:
    from hysid.reproduce import Reproduction

UNITS = {"xi0": "1", "S_xi": "1/m", "w0": "rad/s", "S_w": "rad/s/m"}
PARAMS = tt.PARAMS


def _run_table(rep: "Reproduction", algo: str, noise: int) -> str:
    n_cols = max(rep.n_runs, 4)
    headers = ["parameter", "source", "actual"] + [f"run {i + 1}" for i in range(n_cols)] + ["mean", "sigma", "sigma/mean", "Cramer-Rao"]
    rows = []
    for i, p in enumerate(PARAMS):
        pub = tt.RUNS[(algo, noise)][p]
        mean, std, rel = tt.SUMMARY[(algo, noise)][p]
        cr = num(rep.cramer_rao[noise][i], 3) if noise > 0 else "0"
        rows.append([f"`{p}`", "published", num(TRUE_PARAMS[p], 7)] + [num(v, 7) for v in pub] + [""] * (n_cols - 4) + [num(mean, 7), num(std, 4), num(rel, 4), cr])
        for s in rep.settings:
            v = rep.values((s.key, algo, noise))[:, i]
            st = rep.stats((s.key, algo, noise))
            rows.append(
                ["", s.label, ""] + [num(x, 7) for x in v] + [""] * (n_cols - v.size)
                + [num(st["mean"][i], 7), num(st["std"][i], 4), num(st["rel_std"][i], 4), ""]
            )
    return table(headers, rows)


def _table_5_13(rep: "Reproduction") -> str:
    headers = ["parameter", "source"] + [f"{n} % {a.upper()}" for n in tt.NOISE_LEVELS for a in tt.ALGOS]
    rows = []
    for i, p in enumerate(PARAMS):
        rows.append([f"`{p}`", "published"] + [num(tt.TABLE_5_13[p][(a, n)], 3) for n in tt.NOISE_LEVELS for a in tt.ALGOS])
        for s in rep.settings:
            rows.append(["", s.label] + [num(rep.stats((s.key, a, n))["error"][i], 3) for n in tt.NOISE_LEVELS for a in tt.ALGOS])
        rows.append(["", f"CR / sqrt({rep.n_runs})"] + [num(rep.cramer_rao[n][i] / np.sqrt(rep.n_runs), 3) for n in tt.NOISE_LEVELS for _ in tt.ALGOS])
    return table(headers, rows)


def write_reproduction_report(rep: "Reproduction", out_dir: Path | str) -> Path:
    """Write ``report.md``, ``reproduction.json`` and Figs. 5.2-5.13 into ``out_dir``; returns the report path."""
    from hysid.report import figures  # matplotlib loads only when a report is drawn

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rep.report = str(out_dir / "report.md")
    jsondoc.write(out_dir / "reproduction.json", rep.to_dict())
    parts = [
        "# hysid reproduce thesis: the Synth benchmark of section 5.2.1",
        f"Written {dt.datetime.now().isoformat(timespec='seconds')}. {rep.n_runs} run(s) per algorithm, noise level and "
        f"setting; run r uses noise seed {', '.join(map(str, rep.noise_seeds))} (in order) and optimizer seed "
        f"{rep.seed} + r. All numbers are also in [`reproduction.json`](reproduction.json).",
        "- **thesis-faithful**: the thesis' GA and PSO (section 5.1: 6000 initial, 500 per iteration, 18 iterations), "
        "the thesis' loop weights (Appendix A), no polish.\n"
        "- **hysid defaults**: the same search, then a bounded least-squares polish; maximum-likelihood weights "
        "(1/sigma^2) when the data are noisy.\n"
        "- **published**: the thesis' Tables 5.5-5.13 as printed. **Cramer-Rao**: the smallest standard error any "
        "unbiased estimator can reach at that noise level (one run).",
    ]
    parts += ["## Table 5.13: |mean - actual|", _table_5_13(rep)]
    n_fig = 2
    parts.append("## Figs. 5.2-5.5: parameter scatter per noise level")
    for i, p in enumerate(PARAMS):
        panels = [
            (f"({'ab'[k]}) {algo.upper()}", [
                ("published", {n: np.array(tt.RUNS[(algo, n)][p]) for n in tt.NOISE_LEVELS}),
                *[(s.label, {n: rep.values((s.key, algo, n))[:, i] for n in tt.NOISE_LEVELS if (s.key, algo, n) in rep.results}) for s in rep.settings],
            ])
            for k, algo in enumerate(tt.ALGOS)
        ]
        path = figures.scatter_figure(out_dir / f"fig5_{n_fig}_{p}.png", p, UNITS[p], TRUE_PARAMS[p], panels, {n: b[i] for n, b in rep.cramer_rao.items()})
        parts.append(image(path, out_dir, f"Fig. 5.{n_fig}: {p} per noise level; hollow: runs, filled: mean, red dashed: true value, "
                           "grey band: true +- Cramer-Rao bound"))
        n_fig += 1
    parts.append("## Figs. 5.6-5.9: convergence (thesis-faithful runs)")
    for noise in tt.NOISE_LEVELS:
        runs = [(f"({'ab'[k]}) {algo.upper()}", [r.runs[0] for r in rep.results[("thesis", algo, noise)]]) for k, algo in enumerate(tt.ALGOS)]
        path = figures.convergence_figure(out_dir / f"fig5_{n_fig}_convergence_{noise}pct.png", runs, FITNESS_LABEL["thesis"], f"{noise} % noise")
        parts.append(image(path, out_dir, f"Fig. 5.{n_fig}: convergence at {noise} % noise, all runs overlaid, matching scales"))
        n_fig += 1
    parts.append("## Figs. 5.10-5.13: measured vs model loops (thesis-faithful PSO, run 1)")
    for noise in tt.NOISE_LEVELS:
        result = rep.results[("thesis", "pso", noise)][0]
        predicted = result.objective().predict(result.theta)[0]
        path = figures.loops_figure(out_dir / f"fig5_{n_fig}_loops_{noise}pct.png", result.loops, predicted, title=f"{noise} % noise")
        parts.append(image(path, out_dir, f"Fig. 5.{n_fig}: loops at {noise} % noise; rows: 0.5, 1.0, 1.5 mm"))
        n_fig += 1
    parts.append("## Tables 5.5-5.12: every run")
    for algo in tt.ALGOS:
        for noise in tt.NOISE_LEVELS:
            parts += [f"### Table 5.{tt.TABLE_NUMBERS[(algo, noise)]}: {algo.upper()}, {noise} % noise", _run_table(rep, algo, noise)]
    report = out_dir / "report.md"
    report.write_text("\n\n".join(parts) + "\n")
    return report


def reproduction_summary(rep: "Reproduction") -> str:
    """Table 5.13 side by side, for the terminal."""
    lines = [f"Table 5.13, |mean - actual| over {rep.n_runs} run(s) (noise seeds {', '.join(map(str, rep.noise_seeds))}):"]
    head = f"  {'parameter':<9} {'source':<16}" + "".join(f"{f'{n}% ' + a.upper():>11}" for n in tt.NOISE_LEVELS for a in tt.ALGOS)
    lines.append(head)
    for i, p in enumerate(tt.PARAMS):
        row = f"  {p:<9} {'published':<16}" + "".join(f"{tt.TABLE_5_13[p][(a, n)]:>11.3g}" for n in tt.NOISE_LEVELS for a in tt.ALGOS)
        lines.append(row)
        for s in rep.settings:
            row = f"  {'':<9} {s.label:<16}" + "".join(
                f"{rep.stats((s.key, a, n))['error'][i]:>11.3g}" for n in tt.NOISE_LEVELS for a in tt.ALGOS
            )
            lines.append(row)
    if rep.report:
        lines += ["", f"report: {rep.report}"]
    return "\n".join(lines)
