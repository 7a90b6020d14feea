"""Markdown building blocks and the fit report (``report.md`` plus its PNG figures and ``result.json``).

A campaign's report is a fit report too (its islands are the runs); the
diagnosis and the reproduction have theirs in :mod:`hysid.report.diagnosis`
and :mod:`hysid.report.reproduction`.
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from hysid.report import jsondoc
from hysid.report.amplitudes import combination_rows, effective_rows, resonance_note
from hysid.report.campaign_text import algorithms_text, migrations_text, share_lines
from hysid.report.records import FitCurves, FitRecord
from hysid.report.text import fixed_text, loops_description, quality_text
from hysid_model.frf import amplitude_levels, compliance, first_harmonic, model_compliance
from hysid_model.modal import DERIVED_UNITS
from hysid_model.model_names import named
from hysid_model.survey import survey

REPORT = "report.md"
"""The name of a fit's (and a campaign's) report in its directory."""
MODEL_CURVE_POINTS = 1500
MARKDOWN_POINTS = 60
"""Amplitude-frequency points a report lists one by one (beyond, each amplitude's range)."""

FITNESS_LABEL = {
    "thesis": "best fitness: weighted MSE (N$^2$)",
    "ml": r"best fitness: $\sum (r/\sigma)^2$",
}
FITNESS_MEANING = {
    "thesis": "sum over loops of (maxF_all/maxF_j) x mean squared force error of loop j (Appendix A, N^2)",
    "ml": "chi-square: sum of squared force errors divided by each loop's noise variance (maximum likelihood)",
}


def num(x: float | None, digits: int = 6) -> str:
    """A number for a table: ``digits`` significant figures, 'n/a' for missing values."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "n/a"
    return f"{x:.{digits}g}"


def with_error(value: float, stderr: float) -> str:
    """``value +- stderr``; just the value when it is fixed (zero standard error, e.g. a known mass)."""
    return num(value, 6) if stderr == 0 else f"{num(value, 6)} +- {num(stderr, 2)}"


def table(headers: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A GitHub-flavoured Markdown table (first column left-aligned, the others right-aligned)."""
    out = ["| " + " | ".join(headers) + " |", "|" + "|".join([":--"] + ["--:"] * (len(headers) - 1)) + "|"]
    out += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(out)


def image(path: Path, out_dir: Path, caption: str) -> str:
    return f"![{caption}]({path.relative_to(out_dir).as_posix()})\n\n*{caption}*"


NOT_ASKED = "the report was asked for without figures"
"""Why a report's figures are not drawn when its reader left them out."""


def picture(draw: Callable[[], Path], out_dir: Path, caption: str, left_out: str | None) -> str:
    """The figure ``draw()`` saves, as a Markdown image with its caption; where ``left_out`` says why it is not
    drawn, the caption and that reason instead (nothing is drawn)."""
    return f"*{caption}: not drawn, {left_out}.*" if left_out else image(draw(), out_dir, caption)


def model_curves(result: FitRecord) -> list[tuple[np.ndarray, np.ndarray]]:
    """The fitted model's compliance at each amplitude level over the measured band."""
    loops = result.loops
    levels, _ = amplitude_levels(loops.x0)
    f = np.linspace(loops.freq_hz.min(), loops.freq_hz.max(), MODEL_CURVE_POINTS)
    return [(f, model_compliance(result.estimates.model, result.theta, level, f)) for level in levels]


def write_figures(result: FitRecord, curves: FitCurves, out_dir: Path) -> dict[str, Path]:
    from hysid.report import figures  # matplotlib loads only when a report is drawn (fast CLI start for islands)

    loops = result.loops
    predicted = curves.predicted
    algos = sorted({r.algo for r in result.runs})
    panels = [(a.upper() if len(algos) > 1 else "", [r for r in result.runs if r.algo == a]) for a in algos]
    from hysid.report.effective_figure import effective_figure

    return {
        "effective": effective_figure(out_dir / "effective.png", loops, survey(loops, result.estimates.model.fixed.get("meq")), result.estimates.effective),
        "convergence": figures.convergence_figure(out_dir / "convergence.png", panels, FITNESS_LABEL[result.weights]),
        "loops": figures.loops_figure(out_dir / "loops.png", loops, predicted),
        "residuals": figures.residuals_figure(out_dir / "residuals.png", loops, predicted - curves.measured, np.abs(first_harmonic(loops))),
        "half_power": figures.half_power_figure(
            out_dir / "half_power.png",
            loops,
            compliance(loops),
            result.estimates.half_power,
            [a.values["xi"] for a in result.estimates.levels],
            model_curves(result),
        ),
    }


def summary_lines(result: FitRecord) -> list[str]:
    s = result.settings
    runs = result.runs
    best = runs[result.best]
    algos = "/".join(sorted({r.algo.upper() for r in runs}))
    polish = "then a least-squares polish" if s.get("polish") else "no polish"
    lines = [
        f"- **Data**: `{result.loops.name}`: {loops_description(result)}.",
        f"- **Model**: {named(result.estimates.model)}, parameters {', '.join(result.estimates.model.names)}{fixed_text(result.estimates.model.fixed)}.",
        f"- **Search**: {algos}, {len(runs)} run(s) (seeds {', '.join(str(r.seed) for r in runs)}), {polish}; {result.weights} loop weights.",
        f"- **Best**: {best.label}, fitness {best.fitness:.6g} ({FITNESS_MEANING[result.weights]}) after {result.evaluations:,} evaluations in total.",
        f"- **Fit quality**: {quality_text(result)}.",
    ]
    if result.adequacy is not None:
        lines.append(f"- **Adequacy**: {result.adequacy.words()}.")
    if s.get("stop_reason"):  # a campaign's: why it stopped (interrupted, a rule, its islands)
        lines.append(f"- **Stopped**: {s['stop_reason']}.")
    if result.displacement_model and result.displacement_model["decided_by"] != "none":
        lines.append(f"- **Displacement model**: {result.displacement_model['meaning']} ({result.displacement_model['reason']}).")
    return lines


def parameter_rows(result: FitRecord) -> tuple[list[str], list[list[str]]]:
    true = result.loops.meta.get("true_params") or {}
    headers = ["parameter", "value", "std. error", "unit", "bounds"]
    if true:
        headers += ["true", "error / std. error"]
    rows = []
    se = result.estimates.stderr
    defaults = {q.name: (q.lower, q.upper) for t in result.estimates.model.terms for q in t.params}
    widened = {w["param"] for w in result.settings.get("bounds_widened", [])}
    for p in result.estimates.model.parameters:
        value = result.estimates.params[p.name]
        error = "not identifiable" if p.name in result.not_identifiable else num(se[p.name], 3)
        where = ("widened" if p.name in widened else "default" if (p.lower, p.upper) == defaults[p.name] else "from the data") if p.soft else "given"
        row = [f"`{p.name}`", num(value, 7), error, p.unit, f"[{p.lower:g}, {p.upper:g}] ({where})"]
        if true:
            t = true.get(p.name)
            ratio = abs(value - t) / se[p.name] if t is not None and se[p.name] > 0 else float("nan")
            row += [num(t, 7), num(ratio, 3)]
        rows.append(row)
    return headers, rows + combination_rows(result.estimates.combinations, len(headers))


def correlation_rows(result: FitRecord) -> tuple[list[str], list[list[str]]]:
    """The parameter correlation matrix (as lmfit's fit report); blank for parameters not identifiable."""
    names = result.estimates.model.names
    matrix = result.correlation
    rows = [[f"`{a}`"] + ["" if not np.isfinite(matrix[i, j]) else f"{matrix[i, j]:+.3f}" for j in range(len(names))] for i, a in enumerate(names)]
    return [""] + [f"`{n}`" for n in names], rows


def amplitude_rows(result: FitRecord) -> tuple[list[str], list[list[str]]]:
    columns = ("fn_hz", "xi", "k", "c", "m")
    headers = ["X0 (mm)"] + [q if DERIVED_UNITS[q] == "1" else f"{q.split('_')[0]} ({DERIVED_UNITS[q]})" for q in columns]
    rows = []
    for a in result.estimates.levels:
        rows.append([num(a.x0 * 1e3, 4)] + [with_error(a.values[q], a.stderr[q]) for q in columns])
    return headers, rows


def half_power_rows(result: FitRecord) -> tuple[list[str], list[list[str]]]:
    headers = ["X0 (mm)", "loops", "peak (Hz)", "f1 (Hz)", "f2 (Hz)", "xi half-power", "resolution", "xi fit", "difference"]
    rows = []
    for hp, a in zip(result.estimates.half_power, result.estimates.levels):
        xi_fit = a.values["xi"]
        if hp.ok:
            rows.append(
                [
                    num(hp.x0 * 1e3, 4),
                    str(hp.n_loops),
                    num(hp.f_peak_hz, 6),
                    num(hp.f1_hz, 6),
                    num(hp.f2_hz, 6),
                    num(hp.xi, 4),
                    num(hp.resolution, 2),
                    num(xi_fit, 4),
                    f"{num(hp.xi - xi_fit, 2)} ({num(100 * (hp.xi - xi_fit) / xi_fit, 2)} %)",
                ]
            )
        else:
            rows.append([num(hp.x0 * 1e3, 4), str(hp.n_loops), num(hp.f_peak_hz, 6), "n/a", "n/a", f"n/a: {hp.note}", "n/a", num(xi_fit, 4), "n/a"])
    return headers, rows


def run_rows(result: FitRecord) -> tuple[list[str], list[list[str]]]:
    headers = ["run", "algorithm", "seed", "search fitness", "final fitness", "evaluations", "wall (s)"] + [f"`{n}`" for n in result.estimates.model.names]
    rows = []
    for i, r in enumerate(result.runs):
        label = f"**{r.label}** (best)" if i == result.best else r.label
        rows.append(
            [label, r.algo.upper(), str(r.seed), num(r.search_fitness, 4), num(r.fitness, 4), f"{r.evaluations:,}", f"{r.wall_s:.2f}"]
            + [num(v, 7) for v in r.theta]
        )
    return headers, rows


def warnings_section(found: Sequence[dict[str, str]]) -> list[str]:
    """The report's "Warnings" section: every warning of the result with its code (none: no section)."""
    if not found:
        return []
    return ["## Warnings", "\n".join(f"- **`{w['code']}`**: {w['message']}" for w in found)]


def fit_overview(result: FitRecord) -> str:
    """The summary, the warnings and the parameter and amplitude tables, as Markdown (a notebook's view of a result)."""
    p_head, p_rows = parameter_rows(result)
    a_head, a_rows = amplitude_rows(result)
    parts = ["\n".join(summary_lines(result)), *warnings_section(result.warnings), table(p_head, p_rows)]
    return "\n\n".join(parts + [table(a_head, a_rows), table(*effective_rows(result.estimates.effective))])


def island_rows(islands: Sequence[dict[str, Any]]) -> tuple[list[str], list[list[str]]]:
    """One row per island run of a campaign: its algorithm, status, best and what it exchanged."""
    headers = [
        "island",
        "algorithm",
        "seed",
        "status",
        "best fitness",
        "iterations",
        "evaluations",
        "migrant messages sent",
        "migrants received",
        "taken in",
        "messages rejected",
        "messages unlisted (waited for the roster)",
    ]
    rows = [
        [
            f"`{i['island']}`",
            algorithms_text(i),
            str(i["seed"]),
            i["status"],
            num(i["best_fitness"], 4),
            f"{i['iterations']:,}",
            f"{i['evaluations']:,}",
            f"{i['sent']:,}",
            f"{i['received']:,}",
            f"{i['taken']:,}",
            f"{i['rejected']:,}",
            f"{i.get('unlisted', 0):,}",
        ]
        for i in islands
    ]
    return headers, rows


def campaign_sections(m: dict[str, Any], settings: dict[str, Any], islands: list[dict[str, Any]]) -> list[str]:
    """The campaign's own part of its report (why it stopped is in the summary above): its migrations ``m``, the
    reasons of the messages rejected, the share's moves (its fit's ``settings``) and every island."""
    reasons = ", ".join(f"{k}: {v:,}" for k, v in sorted((m.get("rejected_reasons") or {}).items()))
    moves = [line.strip() for line in share_lines(settings, islands)]
    i_head, i_rows = island_rows(islands)
    return (
        ["## Islands and migrations", f"Migrations: {migrations_text(m)}" + (f" ({reasons})" if reasons else "") + "."]
        + (["\n".join(f"- {line}" for line in moves)] if moves else [])
        + [table(i_head, i_rows)]
    )


def write_fit_report(
    result: FitRecord,
    out_dir: Path,
    document: dict[str, Any],
    curves: FitCurves | None,
    *,
    title: str = "hysid fit",
    sections: Sequence[str] = (),
    figures_left_out: str | None = None,
) -> Path:
    """Write ``report.md`` (``out_dir / REPORT``, which ``result.report`` names), ``result.json`` (``document``: the
    fit's, or a campaign's, which holds it) and the PNG figures (of ``curves``) into ``out_dir``; returns the report path.

    ``sections`` are Markdown parts after the runs (a campaign's islands and migrations);
    ``figures_left_out``: why the figures are not drawn (said where each would be), None to draw them.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    figs = write_figures(result, curves, out_dir) if figures_left_out is None and curves is not None else {}

    def picture(name: str, caption: str) -> str:
        return image(figs[name], out_dir, caption) if figs else f"*{caption}: not drawn, {figures_left_out}.*"

    report = out_dir / REPORT
    jsondoc.write(out_dir / "result.json", document)

    p_head, p_rows = parameter_rows(result)
    a_head, a_rows = amplitude_rows(result)
    h_head, h_rows = half_power_rows(result)
    r_head, r_rows = run_rows(result)
    c_head, c_rows = correlation_rows(result)
    identifiable = (
        "Every parameter is determined by the data."
        if not result.not_identifiable
        else "Not identifiable with these loops (no standard error is given): " + "; ".join(f"`{n}` {why}" for n, why in result.not_identifiable.items()) + "."
    )
    parts = [
        f"# {title}: {result.loops.name}",
        f"Written {dt.datetime.now().isoformat(timespec='seconds')}; all numbers also in [`result.json`](result.json).",
        "\n".join(summary_lines(result)),
        *warnings_section(result.warnings),
        "## Parameters",
        table(p_head, p_rows),
        identifiable,
        "Correlation between the parameters (from the covariance of the standard errors):",
        table(c_head, c_rows),
        f"Standard errors: {result.stderr_method}. "
        "The model is xi(X0) = xi0 + S_xi X0 (Eq. 4.8), wn(X0) = w0 + S_w X0 (Eq. 4.9) in the force of Eq. 4.10 "
        "when the model is `thesis`; `hysid models` lists every term.",
        "## Damping ratio and natural frequency at each amplitude",
        "As listed under the thesis' Table 5.3: the constant xi and fn = wn/2pi of the 1-DOF oscillator "
        "(Eq. 4.6) at each excitation amplitude, and the physical stiffness k = m wn^2, damping "
        "coefficient c = 2 m xi wn and mass m (Eq. 2.4). Uncertainties are one standard error (delta method).",
        table(a_head, a_rows),
        "## Effective stiffness and equivalent damping at each amplitude and frequency",
        "How isolator and damper tests characterise a device (ISO 10846, EN 15129, AASHTO), from the whole fitted model "
        "(every term, the oscillator's inertia included; the measurement chain left out) under X0 sin(wt): "
        "k_eff = (F+ - F-) / (2 X0) from the forces at the peak displacements, and xi_eq = E_d / (4 pi E_s) with E_d "
        "the energy dissipated per cycle and E_s = k_eff X0^2 / 2 (none where the inertia makes k_eff negative). "
        "Uncertainties are one standard error (delta method through the full covariance); every row is in `amplitudes.csv`."
        + "".join(f" Note: {note}." for note in [resonance_note(result.estimates.effective)] if note),
        table(*effective_rows(result.estimates.effective, MARKDOWN_POINTS)),
        picture(
            "effective",
            "Effective stiffness and equivalent damping per amplitude against frequency: "
            "fitted model (one standard error) and each loop's own (the forces at its branches' ends, its area)",
        ),
        "## Half-power cross-check of the damping (Eq. 2.7)",
        "Independently of the model: the compliance |X0/F1| of every loop (F1 = first harmonic of the measured "
        "force) gives one frequency response per amplitude; its resonance peak and -3 dB points give "
        "xi = (w2 - w1) / (2 w0) (Eq. 2.7, Fig. 6.1). The resolution is what the frequency spacing alone "
        "guarantees; the estimate interpolates between frequencies and is much closer for a 1-DOF response.",
        table(h_head, h_rows),
        picture(
            "half_power",
            "Compliance per amplitude: loops (dots) and fitted model (lines)"
            + ("; (b) the resonance with its peak and -3 dB points" if any(hp.ok for hp in result.estimates.half_power) else ""),
        ),
        "## Runs",
        table(r_head, r_rows),
        picture("convergence", "Convergence: best fitness per iteration of every run (as Figs. 5.6-5.9); stars: after the least-squares polish"),
        *sections,
        "## Model vs measured loops",
        picture("loops", "Trial and model loops; rows: amplitudes, columns: frequencies across the band (as Figs. 5.10-5.13)"),
        "## Residuals",
        "Residuals that are noise-like and at the noise level mean the model explains the loops; a pattern "
        "repeated over loops (panel b) points to physics the model is missing.",
        picture("residuals", "(a) RMS residual of each loop; (b) residual vs phase with binned means"),
        "## Settings",
        "\n".join(f"- `{key}`: {jsondoc.dumps(value)}" for key, value in result.settings.items()),
    ]
    report.write_text("\n\n".join(parts) + "\n")
    return report
