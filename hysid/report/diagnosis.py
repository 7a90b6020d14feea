"""The diagnosis report: ``diagnosis.md`` with its PNG figures and ``diagnosis.json``.

It shows the gap between model and data shrink step by step (whitened RMS,
loop NRMSE, energy per cycle, leave-one-frequency-out cross-validation), the
residual over frequency x amplitude before and after, and loops.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from hysid.criteria import BIC_MARGIN, MIN_SHARE, MIN_Z, SIGNIFICANCE
from hysid.report import jsondoc, proposed
from hysid.report.amplitudes import EFFECTIVE_TITLE, effective_rows, resonance_note
from hysid.report.bounds import widened_sentence
from hysid.report.markdown import MARKDOWN_POINTS, num, picture, table, warnings_section, with_error
from hysid.report.records import DiagnosisCurves, DiagnosisRecord
from hysid.report.text import band_text, law_text, mass_text, reference_text
from hysid_model.frf import amplitude_levels
from hysid_model.model import effect_term
from hysid_model.survey import survey


def _effect_section(step: dict[str, Any], i: int) -> list[str]:
    """Step ``i`` (its entry of the document's ``steps``): the effect, its parameters and what it changed."""
    term = effect_term(step["effect"])
    units = {p.name: p.unit for p in term.params}
    rows = [[name, with_error(value, step["stderr"][name]), units[name]] for name, value in step["params"].items()]
    freed = step["freed"]
    heading = f"### Step {i + 1}: {step['effect']}" + (f" ({', '.join(freed)} free)" if freed else "")
    lines = [heading, "", term.explanation, "", table(["parameter", "value +- std. error", "unit"], rows), ""]
    lines.append(
        f"Score {num(step['score'], 4)} (chi^2 the effect removes to first order); after refitting, the BIC changes by "
        f"{num(step['delta_bic'], 5)} and the whitened RMS falls from {num(step['whitened_rms_before'], 4)} "
        f"to {num(step['whitened_rms_after'], 4)}."
    )
    if step["joint_with"]:
        lines += [
            "",
            f"**Named together with {step['joint_with']}**: the two, refitted together, fit better than any single "
            "effect refitted alone, so they are taken as a pair.",
        ]
    if step["confusable_with"]:
        lines += [
            "",
            f"**Confusable with** {', '.join(step['confusable_with'])}: on this data set they fit within "
            f"{BIC_MARGIN:g} BIC of it, so the data cannot tell them apart (e.g. too narrow a band of frequencies or amplitudes).",
        ]
    if step["rejected"]:
        lines += ["", "Other contenders this step: " + "; ".join(f"{e} ({why})" for e, why in step["rejected"].items()) + "."]
    return lines + [""]


def _summary(doc: dict[str, Any]) -> str:
    effects = [s["effect"] + (f" (confusable with {', '.join(s['confusable_with'])})" if s["confusable_with"] else "") for s in doc["steps"]]
    found = "The start model misses: " + ", ".join(effects) + "." if effects else "No library effect is missing from the start model."
    if doc["proposed"]:
        found = (
            ("The start model misses: " + ", ".join(effects) + ", and a force" if effects else "No library effect is named; the start model misses a force")
            + " proposed from the data, not a library effect: "
            + "; ".join(f"{p['name']}, {law_text(p)}" for p in doc["proposed"])
            + "."
        )
    if doc["status"] == "adequate":
        return f"{found} The final model {doc['final_model_name']} leaves only noise (whitened RMS {num(doc['whitened_rms'], 3)})."
    return (
        f"{found} What the final model {doc['final_model_name']} leaves is still not noise (whitened RMS "
        f"{num(doc['whitened_rms'], 3)}), and no effect of the library explains it: "
        f"{doc['unexplained_signature']['description']}."
    )


def gap_rows(doc: dict[str, Any], record: DiagnosisRecord) -> list[list[str]]:
    """One row per fit (the start, each step): the document's gap entries, and the BIC change from the fit before."""
    bic = record.bic
    return [
        [
            label,
            num(m["whitened_rms"], 4),
            num(m["loop_nrmse_pct"], 3),
            num(m["energy_error_pct"], 3),
            num(m["cv_whitened_rms"], 4),
            "" if i == 0 else num(bic[i] - bic[i - 1], 5),
        ]
        for i, (label, m) in enumerate(zip(record.labels, doc["gap"]))
    ]


GAP_HEADERS = ["model", "whitened RMS", "loop NRMSE %", "energy/cycle error %", "LOFO-CV RMS", "delta BIC"]


def overview(doc: dict[str, Any], record: DiagnosisRecord) -> str:
    """The status, the warnings and the gap table, as Markdown (a notebook's view of a diagnosis)."""
    return "\n\n".join([f"**Status: {doc['status']}.** {_summary(doc)}", *warnings_section(doc["warnings"]), table(GAP_HEADERS, gap_rows(doc, record))])


DIAGNOSIS_MD = "diagnosis.md"
"""The name of a diagnosis' report in its directory."""


def write_diagnosis_report(
    doc: dict[str, Any], record: DiagnosisRecord, curves: DiagnosisCurves, out_dir: Path, dataset: str, figures_left_out: str | None = None
) -> Path:
    """Write ``diagnosis.md`` (``out_dir / DIAGNOSIS_MD``, which ``record.report`` names), its figures (of ``curves``)
    and ``diagnosis.json`` (``doc``) into ``out_dir``; returns the Markdown path. ``figures_left_out``: why the
    figures are not drawn (said where each would be), None to draw them."""
    from hysid.report import diagnosis_figures as figures  # matplotlib loads only when a report is drawn
    from hysid.report.effective_figure import effective_figure

    out = out_dir
    out.mkdir(parents=True, exist_ok=True)
    path = out / DIAGNOSIS_MD
    measured = record.loops
    levels, _ = amplitude_levels(measured.x0)
    mass = mass_text(doc["final_fixed"].get("meq"))
    sigma = "known per loop" if doc["noise_sigma"] == "known" else "estimated from the data (second differences along each branch)"
    motion = doc["displacement_model"]
    lines = [
        f"# hysid diagnose: {measured.name}",
        "",
        f"{measured.n_loops} loops at {levels.size} amplitude(s) ({', '.join(f'{a * 1e3:.3g}' for a in levels)} mm), "
        f"{band_text(measured.freq_hz)}, {measured.n_samples} samples per branch; {mass}; "
        f"force noise {sigma}. Each loop is reduced to its harmonics of orders 0-{record.orders} "
        f"({record.coefficients} coefficients, in phase and in quadrature with the measured displacement).",
        "",
        *([f"**Displacement model**: {motion['meaning']} ({motion['reason']}).", ""] if motion is not None and motion["decided_by"] != "none" else []),
        f"**Status: {doc['status']}.** {_summary(doc)}",
        "",
        *[part + "\n" for part in warnings_section(doc["warnings"])],
        "## The gap, step by step",
        "",
        table(GAP_HEADERS, gap_rows(doc, record)),
        "",
        "Whitened RMS: sqrt(chi^2/dof) on the harmonic coefficients, 1 = noise floor. Loop NRMSE: RMS force error over "
        "peak-to-peak force, mean over loops. Energy: relative RMS error of the loop area pi X0 c1. LOFO-CV: whitened "
        "RMS of each frequency's loops predicted by a fit without them.",
        "",
        picture(
            lambda: figures.gap_figure(out / "gap.png", record.labels, doc["gap"]), out, "The gap between model and data after each step", figures_left_out
        ),
        "",
        "## Effects named",
        "",
    ]
    for i, step in enumerate(doc["steps"]):
        lines += _effect_section(step, i)
    if not doc["steps"]:
        lines += ["None.", ""]
    drawn = [lambda p=p: figures.proposed_force_figure(out / f"proposed_{p.name}.png", record.loops, p) for p in curves.proposed]
    lines += proposed.section(doc, record, out, drawn, figures_left_out)
    lines += ["## What is left", ""]
    if doc["status"] == "adequate":
        lines.append("The residual is consistent with the noise: its chi^2 and the chi^2 of every harmonic coefficient are within their noise range.")
    else:
        lines.append(
            f"**Unexplained**: {doc['unexplained_signature']['description']}. "
            + ("No effect of the library accounts for it; it is not named." if not doc["proposed"] else "Nothing else accounts for it.")
        )
        lines += ["", f"Against references that need no physical model, {reference_text(doc)}."]
    if doc["rejected"]:
        lines += ["", "Candidates tried last and not taken: " + "; ".join(f"{e} ({why})" for e, why in doc["rejected"].items()) + "."]
    for effect, why in doc["impossible"].items():
        lines += ["", f"**{effect} is impossible here**: {why}."]
    for term, why in doc["pruned"].items():
        lines += ["", f"**{term} dropped from the final model**: {why}."]
    if doc["at_bounds_kind"]:
        lines += ["", "**On a bound**: " + "; ".join(f"`{n}` on its {kind}" for n, kind in doc["at_bounds_kind"].items()) + "."]
    for note in doc["notes"] + ([widened_sentence(doc["bounds_widened"])] if doc["bounds_widened"] else []):
        lines += ["", f"**Note**: {note}."]
    reasons = doc["not_identifiable_reasons"]  # the effects the data cannot identify, then the final model's parameters
    for effect in (name for name in reasons if name not in doc["final_params"]):
        lines += ["", f"**{effect} cannot be identified with this setup**: {reasons[effect]}."]
    for name in (name for name in reasons if name in doc["final_params"]):
        lines += ["", f"**`{name}` of the final model is not identifiable** (no standard error): it {reasons[name]}."]
    corr = doc["correlation"]
    lines += [
        "",
        "Correlation between the final model's parameters:",
        "",
        table([""] + [f"`{n}`" for n in corr], [[f"`{a}`"] + ["" if r is None else f"{r:+.3f}" for r in row.values()] for a, row in corr.items()]),
    ]
    effective = lambda: effective_figure(out / "effective.png", measured, survey(measured, doc["final_fixed"].get("meq")), record.estimates.effective)
    lines += [
        "",
        "## Effective stiffness and equivalent damping",
        "",
        f"The final model's {EFFECTIVE_TITLE}; one standard error (delta method through the full covariance); every row in `amplitudes.csv`."
        + "".join(f" Note: {note}." for note in [resonance_note(record.estimates.effective)] if note),
        "",
        table(*effective_rows(record.estimates.effective, MARKDOWN_POINTS)),
        "",
        picture(
            effective,
            out,
            "Effective stiffness and equivalent damping per amplitude against frequency: final model "
            "(one standard error) and each loop's own (the forces at its branches' ends, its area)",
            figures_left_out,
        ),
    ]
    lines += [
        "",
        picture(
            lambda: figures.residual_map_figure(out / "residual_map.png", record.loops, curves, doc["start_model"], doc["final_model"]),
            out,
            "Residual per loop over frequency x amplitude, before and after",
            figures_left_out,
        ),
        "",
        "## Loops",
        "",
        picture(
            lambda: figures.loops_figure(out / "loops.png", record.loops, curves),
            out,
            "Measured loops (points), start model (dashed) and final model (solid); rows: amplitudes, "
            "columns: the loop the start model fits worst and the one at the median frequency",
            figures_left_out,
        ),
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
        f"    hysid diagnose {dataset} --model {record.start} --out {out}",
        "",
    ]
    path.write_text("\n".join(lines))
    jsondoc.write(out / "diagnosis.json", doc)
    return path
