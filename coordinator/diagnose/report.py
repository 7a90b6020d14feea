"""The diagnosis report: ``diagnosis.md`` with its PNG figures and ``diagnosis.json``.

It shows the gap between model and data shrink step by step (whitened RMS,
loop NRMSE, energy per cycle, leave-one-frequency-out cross-validation), the
residual over frequency x amplitude before and after, and loops.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np
from matplotlib.colors import LogNorm
from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter

from coordinator.diagnose.fitting import Fit
from coordinator.diagnose.metrics import GapMetrics, gap_metrics, loop_whitened_rms
from coordinator.diagnose.selection import BIC_MARGIN, MIN_SHARE, MIN_Z, SIGNIFICANCE, Diagnosis
from coordinator.report import jsondoc
from coordinator.report.markdown import image, num, table, with_error
from coordinator.report.style import MODEL, PAGE_WIDTH_IN, TRIAL, new_figure, save, series_color, styled
from hysid_model.effects import EFFECTS
from hysid_model.frf import amplitude_levels

START = "#999999"
"""The start model in loop plots (grey, dashed)."""


def step_fits(diagnosis: Diagnosis) -> list[tuple[str, Fit]]:
    """(label, fit) for the start and after every step."""
    return [("start: " + diagnosis.start.spec, diagnosis.start)] + [("+ " + s.effect, s.after) for s in diagnosis.steps]


def all_metrics(diagnosis: Diagnosis, cross_validate: bool = True) -> list[GapMetrics]:
    return [gap_metrics(fit, diagnosis.harmonics, cross_validate) for _, fit in step_fits(diagnosis)]


def to_json(diagnosis: Diagnosis, metrics: Sequence[GapMetrics]) -> dict:
    doc = diagnosis.to_json()
    doc["gap"] = [
        {"model": m.spec, "whitened_rms": m.whitened_rms, "loop_nrmse_pct": m.nrmse_pct,
         "energy_error_pct": m.energy_error_pct, "cv_whitened_rms": m.cv_whitened_rms}
        for m in metrics
    ]
    return doc


@styled
def gap_figure(path: Path, labels: Sequence[str], metrics: Sequence[GapMetrics]) -> Path:
    """Whitened RMS (and its cross-validated value) and the loop/energy errors after each step."""
    fig = new_figure(2.6)
    left, right = fig.subplots(1, 2)
    x = np.arange(len(metrics))
    left.semilogy(x, [m.whitened_rms for m in metrics], "o-", color=MODEL, label="fit")
    cv = [m.cv_whitened_rms for m in metrics]
    if all(c is not None for c in cv):
        left.semilogy(x, cv, "s--", color=TRIAL, label="leave-one-frequency-out")
    left.axhline(1.0, color="k", lw=0.8, ls=":", label="noise floor")
    left.set_ylabel("whitened residual RMS")
    left.legend()
    right.plot(x, [m.nrmse_pct for m in metrics], "o-", color=series_color(2), label="loop NRMSE")
    right.plot(x, [m.energy_error_pct for m in metrics], "s-", color=series_color(3), label="energy per cycle")
    right.set_ylabel("error (%)")
    right.set_ylim(bottom=0)
    right.legend()
    for ax in (left, right):
        ax.set_xticks(x, [label.split(": ")[-1] if i == 0 else label for i, label in enumerate(labels)], rotation=20, ha="right")
    return save(fig, path)


@styled
def residual_map_figure(path: Path, diagnosis: Diagnosis) -> Path:
    """Per-loop whitened RMS over frequency x amplitude, start model vs final model, one colour scale."""
    h = diagnosis.harmonics
    before, after = loop_whitened_rms(diagnosis.start, h), loop_whitened_rms(diagnosis.final, h)
    norm = LogNorm(vmin=max(min(before.min(), after.min()), 0.1), vmax=max(before.max(), after.max(), 10.0))
    fig = new_figure(2.7)
    axes = fig.subplots(1, 2, sharex=True, sharey=True)
    for ax, values, title in ((axes[0], before, f"before: {diagnosis.start.spec}"), (axes[1], after, f"after: {diagnosis.final.spec}")):
        art = ax.scatter(h.loops.freq_hz, h.loops.x0 * 1e3, c=values, s=60, marker="s", cmap="viridis", norm=norm, edgecolors="none")
        ax.set_title(title, fontsize=7.5)
        ax.set_xlabel("frequency (Hz)")
        if h.loops.freq_hz.max() > 4 * h.loops.freq_hz.min():
            ax.set_xscale("log")
            ax.xaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
            ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
            ax.xaxis.set_minor_formatter(NullFormatter())
    axes[0].set_ylabel("amplitude X0 (mm)")
    fig.colorbar(art, ax=axes, label="whitened RMS per loop (1 = noise)")
    return save(fig, path)


def chosen_loops(diagnosis: Diagnosis, per_level: int = 2) -> list[int]:
    """Per amplitude level, the loop the start model misses most and the one at the median frequency."""
    h = diagnosis.harmonics
    levels, index = amplitude_levels(h.loops.x0)
    worst = loop_whitened_rms(diagnosis.start, h)
    out: list[int] = []
    for level in range(levels.size):
        members = np.flatnonzero(index == level)
        picks = [members[np.argmax(worst[members])], members[np.argsort(h.loops.freq_hz[members])[members.size // 2]]]
        out += [int(p) for p in dict.fromkeys(picks)][:per_level]
    return out[:6]


@styled
def loops_figure(path: Path, diagnosis: Diagnosis) -> Path:
    """Measured loops with the start and the final model's branches."""
    h = diagnosis.harmonics
    picks = chosen_loops(diagnosis)
    cols = min(3, len(picks))
    rows = -(-len(picks) // cols)
    fig = new_figure(2.1 * rows, PAGE_WIDTH_IN)
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).reshape(-1)
    n = h.loops.n_samples
    start = diagnosis.start.objective.objective.predict(diagnosis.start.theta)[0]
    final = diagnosis.final.objective.objective.predict(diagnosis.final.theta)[0]
    for ax, j in zip(axes, picks):
        x = np.concatenate([h.loops.top[j, :, 0], h.loops.bottom[j, :, 0]]) * 1e3
        ax.plot(x, h.loops.forces()[j], ".", ms=2.0, color=TRIAL, label="measured")
        for force, color, style, label in ((start, START, "--", "start model"), (final, MODEL, "-", "final model")):
            ax.plot(x[:n], force[j, :n], style, color=color, lw=1.0, label=label)
            ax.plot(x[n:], force[j, n:], style, color=color, lw=1.0)
        ax.set_title(f"{h.loops.freq_hz[j]:.4g} Hz, X0 = {h.loops.x0[j] * 1e3:.3g} mm", fontsize=7.5)
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("F (N)")
    for ax in axes[len(picks):]:
        ax.set_visible(False)
    axes[0].legend(loc="best")
    return save(fig, path)


def _effect_section(diagnosis: Diagnosis, i: int) -> list[str]:
    step = diagnosis.steps[i]
    term = EFFECTS[step.effect]()
    units = {p.name: p.unit for p in term.params}
    rows = [[name, with_error(value, step.errors[name]), units[name]] for name, value in step.params.items()]
    lines = [f"### Step {i + 1}: {step.effect}", "", term.explanation, "", table(["parameter", "value +- std. error", "unit"], rows), ""]
    lines.append(
        f"Score {num(step.score, 4)} (chi^2 the effect removes to first order); after refitting, the BIC changes by "
        f"{num(step.after.bic - step.before.bic, 5)} and the whitened RMS falls from {num(step.before.whitened_rms, 4)} "
        f"to {num(step.after.whitened_rms, 4)}."
    )
    if step.confusable_with:
        lines += ["", f"**Confusable with** {', '.join(step.confusable_with)}: on this data set they fit within "
                  f"{BIC_MARGIN:g} BIC of it, so the data cannot tell them apart (e.g. too narrow a band of frequencies or amplitudes)."]
    if step.rejected:
        lines += ["", "Other contenders this step: " + "; ".join(f"{e} ({why})" for e, why in step.rejected.items()) + "."]
    return lines + [""]


def _summary(diagnosis: Diagnosis) -> str:
    named = [s.effect + (f" (confusable with {', '.join(s.confusable_with)})" if s.confusable_with else "") for s in diagnosis.steps]
    found = "The start model misses: " + ", ".join(named) + "." if named else "No library effect is missing from the start model."
    if diagnosis.status == "adequate":
        return f"{found} The final model {diagnosis.final.spec} leaves only noise (whitened RMS {num(diagnosis.final.whitened_rms, 3)})."
    return (
        f"{found} What the final model {diagnosis.final.spec} leaves is still not noise (whitened RMS "
        f"{num(diagnosis.final.whitened_rms, 3)}), and no effect of the library explains it: "
        f"{diagnosis.unexplained['description']}."
    )


def write_report(diagnosis: Diagnosis, out_dir: Path | str, dataset: str, cross_validate: bool = True) -> tuple[Path, dict]:
    """Write ``diagnosis.md``, its figures and ``diagnosis.json`` into ``out_dir``; return the Markdown path and the JSON document."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fits = step_fits(diagnosis)
    metrics = all_metrics(diagnosis, cross_validate)
    doc = to_json(diagnosis, metrics)
    gap = gap_figure(out / "gap.png", [label for label, _ in fits], metrics)
    maps = residual_map_figure(out / "residual_map.png", diagnosis)
    loops = loops_figure(out / "loops.png", diagnosis)
    h = diagnosis.harmonics
    levels, _ = amplitude_levels(h.loops.x0)
    mass = f"Meq = {h.loops.meq_kg:.4g} kg (known)" if h.loops.meq_kg is not None else "Meq unknown (fitted)"
    sigma = "known per loop" if np.all(h.sigma_known) else "estimated from the data (second differences along each branch)"
    gap_rows = [
        [label, num(m.whitened_rms, 4), num(m.nrmse_pct, 3), num(m.energy_error_pct, 3), num(m.cv_whitened_rms, 4),
         "" if i == 0 else num(fits[i][1].bic - fits[i - 1][1].bic, 5)]
        for i, ((label, _), m) in enumerate(zip(fits, metrics))
    ]
    lines = [
        f"# hysid diagnose: {h.loops.name}",
        "",
        f"{h.loops.n_loops} loops at {levels.size} amplitude(s) ({', '.join(f'{a * 1e3:.3g}' for a in levels)} mm), "
        f"{h.loops.freq_hz.min():.4g}-{h.loops.freq_hz.max():.4g} Hz, {h.loops.n_samples} samples per branch; {mass}; "
        f"force noise {sigma}. Each loop is reduced to its harmonics of orders 0-{int(h.orders().max())} "
        f"({h.coef.shape[1]} coefficients, in phase and in quadrature with the measured displacement).",
        "",
        f"**Status: {diagnosis.status}.** {_summary(diagnosis)}",
        "",
        "## The gap, step by step",
        "",
        table(["model", "whitened RMS", "loop NRMSE %", "energy/cycle error %", "LOFO-CV RMS", "delta BIC"], gap_rows),
        "",
        "Whitened RMS: sqrt(chi^2/dof) on the harmonic coefficients, 1 = noise floor. Loop NRMSE: RMS force error over "
        "peak-to-peak force, mean over loops. Energy: relative RMS error of the loop area pi X0 c1. LOFO-CV: whitened "
        "RMS of each frequency's loops predicted by a fit without them.",
        "",
        image(gap, out, "The gap between model and data after each step"),
        "",
        "## Effects named",
        "",
    ]
    for i in range(len(diagnosis.steps)):
        lines += _effect_section(diagnosis, i)
    if not diagnosis.steps:
        lines += ["None.", ""]
    lines += ["## What is left", ""]
    if diagnosis.status == "adequate":
        lines.append("The residual is consistent with the noise: its chi^2 and the chi^2 of every harmonic coefficient are within their noise range.")
    else:
        lines.append(f"**Unexplained**: {diagnosis.unexplained['description']}. No effect of the library accounts for it; it is not named.")
    if diagnosis.rejected:
        lines += ["", "Candidates tried last and not taken: " + "; ".join(f"{e} ({why})" for e, why in diagnosis.rejected.items()) + "."]
    for effect, absorbed in diagnosis.not_identifiable.items():
        lines += ["", f"**{effect} cannot be identified with this setup**: whatever it does, the model already does with "
                  f"{', '.join(absorbed)} (e.g. a transducer mass while the equivalent mass is fitted)."]
    lines += [
        "",
        image(maps, out, "Residual per loop over frequency x amplitude, before and after"),
        "",
        "## Loops",
        "",
        image(loops, out, "Measured loops (points), start model (dashed) and final model (solid)"),
        "",
        "## Method",
        "",
        "Every effect of the library is scored by a Lagrange-multiplier (score) test: its derivative on all harmonic "
        "coefficients, with whatever the current model can absorb projected out, against the whitened residual "
        f"(Bonferroni level {SIGNIFICANCE:g}). The best few are refitted; one is accepted when the BIC improves by at "
        f"least {BIC_MARGIN:g}, its strength is {MIN_Z:g} standard errors from zero with the physical sign, no parameter "
        f"is pushed against a bound, and it removes at least {100 * MIN_SHARE:.0f}% of the chi^2 above the noise floor. Effects "
        "fitting within the BIC margin of the accepted one are named as confusable.",
        "",
        "## Reproduce",
        "",
        f"    hysid diagnose {dataset} --model {diagnosis.start.start} --out {out}",
        "",
    ]
    path = out / "diagnosis.md"
    path.write_text("\n".join(lines))
    jsondoc.write(out / "diagnosis.json", doc)
    return path, doc
