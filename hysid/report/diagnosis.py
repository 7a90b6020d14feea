"""The diagnosis report: ``diagnosis.md`` with its PNG figures and ``diagnosis.json``.

It shows the gap between model and data shrink step by step (whitened RMS,
loop NRMSE, energy per cycle, leave-one-frequency-out cross-validation), the
residual over frequency x amplitude before and after, and loops.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hysid.diagnosis.criteria import BIC_MARGIN, MIN_SHARE, MIN_Z, SIGNIFICANCE
from hysid.report import jsondoc, proposed
from hysid.report.amplitudes import EFFECTIVE_TITLE, effective_rows
from hysid.report.bounds import widened_sentence
from hysid.report.markdown import MARKDOWN_POINTS, image, num, table, warnings_section, with_error
from hysid.report.text import band_text, mass_text, reference_text
from hysid_model.frf import amplitude_levels
from hysid_model.survey import survey
from hysid_model.model import effect_term
from hysid_model.model_names import named

if TYPE_CHECKING:
    from hysid.diagnosis.result import Diagnosis


def _effect_section(diagnosis: "Diagnosis", i: int) -> list[str]:
    step = diagnosis.steps[i]
    term = effect_term(step.effect)
    units = {p.name: p.unit for p in term.params}
    rows = [[name, with_error(value, step.errors[name]), units[name]] for name, value in step.params.items()]
    freed = [n for n in step.after.freed if n in units]
    heading = f"### Step {i + 1}: {step.effect}" + (f" ({', '.join(freed)} free)" if freed else "")
    lines = [heading, "", term.explanation, "", table(["parameter", "value +- std. error", "unit"], rows), ""]
    lines.append(
        f"Score {num(step.score, 4)} (chi^2 the effect removes to first order); after refitting, the BIC changes by "
        f"{num(step.after.bic - step.before.bic, 5)} and the whitened RMS falls from {num(step.before.whitened_rms, 4)} "
        f"to {num(step.after.whitened_rms, 4)}."
    )
    if step.joint_with:
        lines += ["", f"**Named together with {step.joint_with}**: the two, refitted together, fit better than any single "
                  "effect refitted alone, so they are taken as a pair."]
    if step.confusable_with:
        lines += ["", f"**Confusable with** {', '.join(step.confusable_with)}: on this data set they fit within "
                  f"{BIC_MARGIN:g} BIC of it, so the data cannot tell them apart (e.g. too narrow a band of frequencies or amplitudes)."]
    if step.rejected:
        lines += ["", "Other contenders this step: " + "; ".join(f"{e} ({why})" for e, why in step.rejected.items()) + "."]
    return lines + [""]


def _summary(diagnosis: "Diagnosis") -> str:
    effects = [s.effect + (f" (confusable with {', '.join(s.confusable_with)})" if s.confusable_with else "") for s in diagnosis.steps]
    found = "The start model misses: " + ", ".join(effects) + "." if effects else "No library effect is missing from the start model."
    if diagnosis.proposed:
        found = (("The start model misses: " + ", ".join(effects) + ", and a force" if effects else "No library effect is named; the start "
                  "model misses a force") + " proposed from the data, not a library effect: "
                 + "; ".join(f"{p.name}, F = {p.notation}" for p in diagnosis.proposed) + ".")
    if diagnosis.status == "adequate":
        return f"{found} The final model {named(diagnosis.final.model)} leaves only noise (whitened RMS {num(diagnosis.final.whitened_rms, 3)})."
    return (
        f"{found} What the final model {named(diagnosis.final.model)} leaves is still not noise (whitened RMS "
        f"{num(diagnosis.final.whitened_rms, 3)}), and no effect of the library explains it: "
        f"{diagnosis.unexplained['description']}."
    )


def gap_rows(diagnosis: "Diagnosis") -> list[list[str]]:
    fits = diagnosis.fits()
    return [
        [label, num(m.whitened_rms, 4), num(m.nrmse_pct, 3), num(m.energy_error_pct, 3), num(m.cv_whitened_rms, 4),
         "" if i == 0 else num(fits[i][1].bic - fits[i - 1][1].bic, 5)]
        for i, ((label, _), m) in enumerate(zip(fits, diagnosis.gap))
    ]


GAP_HEADERS = ["model", "whitened RMS", "loop NRMSE %", "energy/cycle error %", "LOFO-CV RMS", "delta BIC"]


def overview(diagnosis: "Diagnosis") -> str:
    """The status, the warnings and the gap table, as Markdown (a notebook's view of a diagnosis)."""
    return "\n\n".join([f"**Status: {diagnosis.status}.** {_summary(diagnosis)}", *warnings_section(diagnosis.warnings),
                        table(GAP_HEADERS, gap_rows(diagnosis))])


def write_diagnosis_report(diagnosis: "Diagnosis", out_dir: Path | str, dataset: str) -> Path:
    """Write ``diagnosis.md``, its figures and ``diagnosis.json`` into ``out_dir``; returns the Markdown path."""
    from hysid.report import diagnosis_figures as figures  # matplotlib loads only when a report is drawn
    from hysid.report.effective_figure import effective_figure

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "diagnosis.md"
    diagnosis.report = str(path)
    fits = diagnosis.fits()
    gap = figures.gap_figure(out / "gap.png", [label for label, _ in fits], diagnosis.gap)
    maps = figures.residual_map_figure(out / "residual_map.png", diagnosis)
    loops = figures.loops_figure(out / "loops.png", diagnosis)
    h = diagnosis.harmonics
    levels, _ = amplitude_levels(h.loops.x0)
    mass = mass_text(diagnosis.final.model.fixed.get("meq"))
    sigma = "known per loop" if np.all(h.sigma_known) else "estimated from the data (second differences along each branch)"
    lines = [
        f"# hysid diagnose: {h.loops.name}",
        "",
        f"{h.loops.n_loops} loops at {levels.size} amplitude(s) ({', '.join(f'{a * 1e3:.3g}' for a in levels)} mm), "
        f"{band_text(h.loops.freq_hz)}, {h.loops.n_samples} samples per branch; {mass}; "
        f"force noise {sigma}. Each loop is reduced to its harmonics of orders 0-{int(h.orders().max())} "
        f"({h.coef.shape[1]} coefficients, in phase and in quadrature with the measured displacement).",
        "",
        *([f"**Displacement model**: {diagnosis.motion.as_dict()['meaning']} ({diagnosis.motion.reason}).", ""]
          if diagnosis.motion is not None and diagnosis.motion.decided_by != "none" else []),
        f"**Status: {diagnosis.status}.** {_summary(diagnosis)}",
        "",
        *[part + "\n" for part in warnings_section(diagnosis.warnings)],
        "## The gap, step by step",
        "",
        table(GAP_HEADERS, gap_rows(diagnosis)),
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
    drawn = [figures.proposed_force_figure(out / f"proposed_{p.name}.png", p, diagnosis) for p in diagnosis.proposed]
    lines += proposed.section(diagnosis, out, drawn)
    lines += ["## What is left", ""]
    if diagnosis.status == "adequate":
        lines.append("The residual is consistent with the noise: its chi^2 and the chi^2 of every harmonic coefficient are within their noise range.")
    else:
        lines.append(f"**Unexplained**: {diagnosis.unexplained['description']}. "
                     + ("No effect of the library accounts for it; it is not named." if not diagnosis.proposed else "Nothing else accounts for it."))
        lines += ["", f"Against references that need no physical model, {reference_text(diagnosis.to_dict())}."]
    if diagnosis.rejected:
        lines += ["", "Candidates tried last and not taken: " + "; ".join(f"{e} ({why})" for e, why in diagnosis.rejected.items()) + "."]
    for effect, why in diagnosis.impossible.items():
        lines += ["", f"**{effect} is impossible here**: {why}."]
    for term, why in diagnosis.pruned.items():
        lines += ["", f"**{term} dropped from the final model**: {why}."]
    if diagnosis.at_bounds:
        lines += ["", "**On a bound**: " + "; ".join(f"`{n}` on its {kind}" for n, kind in diagnosis.at_bounds.items()) + "."]
    for note in diagnosis.notes + ([widened_sentence(diagnosis.bounds_widened)] if diagnosis.bounds_widened else []):
        lines += ["", f"**Note**: {note}."]
    for effect, why in diagnosis.effects_not_identifiable().items():
        lines += ["", f"**{effect} cannot be identified with this setup**: {why}."]
    for name, why in diagnosis.identifiability.not_identifiable.items():
        lines += ["", f"**`{name}` of the final model is not identifiable** (no standard error): it {why}."]
    names = diagnosis.final.model.names
    corr = diagnosis.identifiability.correlation
    lines += ["", "Correlation between the final model's parameters:", "",
              table([""] + [f"`{n}`" for n in names],
                    [[f"`{a}`"] + ["" if not np.isfinite(corr[i, j]) else f"{corr[i, j]:+.3f}" for j in range(len(names))] for i, a in enumerate(names)])]
    effective = effective_figure(out / "effective.png", h.loops, survey(h.loops, diagnosis.final.model.fixed.get("meq")), diagnosis.effective)
    lines += ["", "## Effective stiffness and equivalent damping", "",
              f"The final model's {EFFECTIVE_TITLE}; one standard error (delta method through the full covariance); "
              "every row in `amplitudes.csv`.", "", table(*effective_rows(diagnosis.effective, MARKDOWN_POINTS)), "",
              image(effective, out, "Effective stiffness and equivalent damping per amplitude against frequency: final model "
                    "(one standard error) and each loop's own (the forces at its branches' ends, its area)")]
    lines += [
        "",
        image(maps, out, "Residual per loop over frequency x amplitude, before and after"),
        "",
        "## Loops",
        "",
        image(loops, out, "Measured loops (points), start model (dashed) and final model (solid); rows: amplitudes, "
              "columns: the loop the start model fits worst and the one at the median frequency"),
        "",
        "## Method",
        "",
        "Every effect of the library is scored by a Lagrange-multiplier (score) test: its derivative on all harmonic "
        "coefficients, with whatever the current model can absorb projected out, against the whitened residual "
        f"(Bonferroni level {SIGNIFICANCE:g}). Effects that cannot be at work on these loops (a force high-pass where the "
        "force keeps its mean) are set aside. The best few, and the best pair of the others, are refitted from several "
        f"starts each, so that every effect is judged at its best fit. One is taken when the BIC improves by at least "
        f"{BIC_MARGIN:g}, it adds no harmonic content the loops lack, its strength has the physical sign, no parameter is "
        f"pushed against a bound (a score test of {MIN_Z:g} standard errors), it removes at least {100 * MIN_SHARE:.0f}% of "
        "the chi^2 above the noise floor, neither the loop NRMSE nor the energy error rises, its values are physically "
        "possible, and it predicts held-out frequencies better (leave one frequency out); of those, the lowest BIC. "
        "Effects fitting within the BIC margin of the one taken are named as confusable. Where the diagnosis ends unexplained "
        "and the loops are not each linear, a force of x and v is sought from the data (FROLS over a library of powers, "
        "products, one-sided, dead-zone and saturating laws, shapes refined by least squares, at most four parameters), from the "
        "start model and from the final one, and taken by the same rules; where it alone explains the loops as well as the "
        "library's effects together, those are set aside.",
        "",
        "## Reproduce",
        "",
        f"    hysid diagnose {dataset} --model {diagnosis.start.start} --out {out}",
        "",
    ]
    path.write_text("\n".join(lines))
    jsondoc.write(out / "diagnosis.json", diagnosis.to_dict())
    return path
