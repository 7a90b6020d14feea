"""Every plain-text summary hysid prints: fits, diagnoses, loop tables (a campaign's, its progress and the
``hysid watch`` screen: :mod:`.campaign_text`; the reproduction's: reproduction.py).

The result objects' ``summary()`` methods and the command line both come
here, so a notebook and a terminal read the same words.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import PurePath
from typing import TYPE_CHECKING, Any

import numpy as np

from hysid.criteria import LINEAR_LOOPS
from hysid.report.amplitudes import EFFECTIVE_TITLE, combination_rows, effective_rows, modal_rows, resonance_note
from hysid.report.bounds import bounds_sentence, widened_sentence
from hysid.report.records import DiagnosisRecord, FitRecord
from hysid_model import notices
from hysid_model.effects import EFFECTS
from hysid_model.frf import amplitude_levels
from hysid_model.loops import LoopSet
from hysid_model.model import build_model
from hysid_model.model_names import named
from hysid_model.notices import Notice
from hysid_model.presets import PRESET_EXPLANATIONS, PRESETS
from hysid_model.survey import survey
from hysid_model.user_terms import made_terms

if TYPE_CHECKING:
    from hysid.adequacy import Adequacy
    from hysid_model.model import Model
    from hysid_model.survey import Survey
    from hysid_model.terms import Term


def text_table(headers: Sequence[str], rows: Sequence[Sequence[str]], indent: str = "  ") -> str:
    """Columns padded to their widest cell; the first left-aligned, the others right-aligned."""
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(headers)]

    def line(cells: Sequence[str]) -> str:
        return indent + "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))

    return "\n".join([line(headers)] + [line(r) for r in rows])


def models_text() -> str:
    """``hysid models``: every preset (what it models, its terms and parameters), the effect library and the terms of
    the user's own made or imported in this process, with every parameter's unit and default bounds (or fixed value)."""
    lines = []
    for spec in PRESETS:
        lines += [build_model(spec).describe(), f"  ({PRESET_EXPLANATIONS[spec]})"]
    lines.append("effects (add with MODEL+EFFECT, e.g. thesis+coulomb_friction):")
    for effect_id, term_type in sorted(EFFECTS.items()):
        term = term_type()
        lines.append(f"  {effect_id}: {term_line(term)}\n      {term.explanation}")
    mine = made_terms()
    if mine:
        lines.append("terms of your own made or imported so far (add with MODEL+MODULE:ATTRIBUTE, e.g. thesis+myterms:drag):")
        lines += [f"  {t.spec}: {term_line(t)}" + (f" (strength {t.strength})" if t.strength else "") + f"\n      {t.explanation}" for t in mine]
    return "\n".join(lines)


def term_line(term: Term) -> str:
    """A term's parameters: name, unit and default bounds (or fixed value) of each."""
    return ", ".join(
        f"{p.name} [{p.unit}] " + (f"in [{p.lower:g}, {p.upper:g}]" if p.vary else f"fixed at {p.value:g} (search [{p.lower:g}, {p.upper:g}] when freed)")
        for p in term.params
    )


def mass_text(meq_kg: float | None) -> str:
    """The equivalent mass as a reader wants it: known (in g below 1 kg, else in kg) or unknown (fitted)."""
    if meq_kg is None:
        return "Meq unknown (fitted)"
    return f"Meq = {meq_kg * 1e3:.4g} g (known)" if meq_kg < 1.0 else f"Meq = {meq_kg:.4g} kg (known)"


def hz_text(f_hz: float) -> str:
    """A frequency as a reader wants it: four significant digits (``0.25 Hz``, not ``0.250027 Hz``)."""
    return f"{f_hz:.4g} Hz"


def band_text(freq_hz: Sequence[float] | np.ndarray) -> str:
    """The frequency band of some loops: ``0.25-2 Hz``, or one frequency (``12 Hz``, not ``12-12 Hz``)."""
    low, high = f"{min(freq_hz):.4g}", f"{max(freq_hz):.4g}"
    return f"{low} Hz" if low == high else f"{low}-{high} Hz"


def loops_description(result: FitRecord) -> str:
    loops = result.loops
    levels, _ = amplitude_levels(loops.x0)
    amps = ", ".join(f"{a * 1e3:.3g}" for a in levels)
    return (
        f"{loops.n_loops} loops at {levels.size} amplitude(s) X0 = {amps} mm, "
        f"{band_text(loops.freq_hz)}, {loops.n_samples} samples per branch; "
        f"{mass_text(result.estimates.model.fixed.get('meq'))}"
    )


def fixed_text(fixed: dict[str, float]) -> str:
    """The known parameters other than the mass (which the loop description gives), as ``; fixed S_xi = -0.4``."""
    known = {k: v for k, v in fixed.items() if k != "meq"}
    return "; fixed " + ", ".join(f"{k} = {v:.6g}" for k, v in known.items()) if known else ""


STDERR_TRUST = 1.3
"""A residual beyond this many times the noise makes the standard errors too small (a note says by how much)."""


def quality_text(result: FitRecord) -> str:
    """RMS residual against the force amplitude, next to the known noise level if there is one."""
    q = result.quality
    out = f"RMS residual {q['rms_residual_pct']:.3g} % of each loop's force amplitude |F1|"
    if q["noise_sigma_pct"] is not None:
        source = result.loops.sigma_source
        out += f" (noise sigma {'given' if source == 'given' else 'estimated from the records'}: {q['noise_sigma_pct']:.3g} %)"
    return out + ("" if result.loops.kept().all() else "; the four reversal samples of each loop are left out: extraction did not resolve the force there")


def fit_warnings(
    loops: LoopSet,
    model: Model,
    theta: np.ndarray,
    weights: str,
    settings: dict[str, Any],
    adequacy: Adequacy | None,
    misfit: float | None,
    implausible: str | None,
) -> list[Notice]:
    """What a reader must know before trusting a fit's numbers (``theta`` of ``model`` on ``loops``): a model that
    misses the data, a mass the loops' inertia does not support (``implausible``, :func:`hysid.diagnosis.plausible.mass_note`),
    parameters on bounds (each with its code, :data:`hysid_model.notices.CODES`; it reads as its message)."""
    out = []
    if "meq" in model.names:
        found = survey(loops)
        if found.meq_kg is None:
            out.append(
                Notice(
                    "mass_unknown",
                    f"note: the equivalent mass is fitted, but the survey cannot estimate it ({found.mass_source.removeprefix('unknown: ')}): "
                    "meq, w0 and xi0 stand for each amplitude's stiffness k and damping c (given below) more than for a resonance",
                )
            )
    if implausible:
        out.append(Notice("mass_implausible", f"warning: {implausible}"))
    missed = adequacy is not None and not adequacy.adequate
    if adequacy is not None and missed:
        out.append(Notice("misfit", f"warning: {adequacy.words()}; a diagnosis (hysid diagnose, or hysid.diagnose) tells what it is missing"))
    if misfit is not None and misfit > STDERR_TRUST and weights != "ml":  # ML weights' errors are scaled up by it
        out.append(
            Notice(
                "stderr_understated",
                f"note: the residual is {misfit:.3g} x the noise: the standard errors assume the model is right and "
                f"understate the uncertainty, by a factor of about {misfit:.2g}",
            )
        )
    soft = {p.name for p in model.parameters if p.soft}
    searched = model.at_bounds(theta)
    given = [n for n in searched if n not in soft]
    derived = [n for n in searched if n in soft]
    kinds = model.bound_kinds(theta)
    if kinds:
        out.append(Notice("on_bound", bounds_sentence(kinds)))
    if settings.get("bounds_widened"):
        out.append(Notice("bounds_widened", f"note: {widened_sentence(settings['bounds_widened'])}"))
    if given:
        out.append(
            Notice(
                "on_given_bound",
                f"warning: {', '.join(given)} ended on a bound that was given (by the dataset or the call), so the optimum may lie "
                "beyond it and its standard error means little; widen that bound ([bounds] in dataset.toml, bounds=...) if the physics allows",
            )
        )
    if derived:
        widened = [w["param"] for w in settings.get("bounds_widened", [])]
        times = max(widened.count(n) for n in derived)
        out.append(
            Notice(
                "on_data_bound",
                f"warning: {', '.join(derived)} ended on a search bound (from the data or its term's default) even after {times} widening(s): "
                + ("the model cannot reach the data there" if missed else "its value and standard error mean little"),
            )
        )
    return out


def told_line(found: list[dict[str, str]], document: str) -> list[str]:
    """The codes of the warnings of the data and the run (their messages went to stderr), as a summary's line."""
    return [f"warnings of the data and the run: {', '.join(dict.fromkeys(w['code'] for w in found))} (each in the report and {document})"] if found else []


def displacement_text(model: dict[str, Any]) -> str:
    """Which displacement drove the model and why (:class:`hysid.motion.MotionChoice` as a dict)."""
    return f"displacement model: {model['meaning']} ({model['reason']})"


def fit_summary(result: FitRecord, command: str = "hysid fit") -> str:
    """What a user reads after ``hysid fit`` (or ``command``): what was fitted, how well, and where the report is."""
    s = result.settings
    best = result.runs[result.best]
    true = result.loops.meta.get("true_params") or {}
    algo = str(s.get("algo", best.algo)).upper()
    polish = " + least-squares polish" if s.get("polish") else ""
    wall = s.get("wall_s", sum(r.wall_s for r in result.runs))  # a campaign's islands search side by side
    lines = [
        f"{command} {result.loops.name}: {loops_description(result)}",
        f"model {named(result.estimates.model)} ({', '.join(result.estimates.model.names)}{fixed_text(result.estimates.model.fixed)}); {algo} x {len(result.runs)} {'island' if command == 'hysid campaign' else 'run'}(s){polish}; {result.weights} weights",
        f"best: {best.label} (seed {best.seed}), fitness {best.fitness:.6g} after {result.evaluations:,} evaluations in {wall:.1f} s",
        f"fit quality: {quality_text(result)}",
    ]
    if result.adequacy is not None and result.adequacy.adequate:
        lines.append(f"adequacy: {result.adequacy.words()}")
    if result.displacement_model and result.displacement_model["decided_by"] != "none":
        lines.append(displacement_text(result.displacement_model))
    lines += told_line(notices.merged(notices.stored(result.loops.meta), result.raised), "result.json")
    lines.append("")
    se = result.estimates.stderr
    headers = ["parameter", "value", "std. error", "unit"] + (["true"] if true else [])
    rows = []
    for p in result.estimates.model.parameters:
        error = "not identifiable" if p.name in result.not_identifiable else f"{se[p.name]:.2g}"
        row = [p.name, f"{result.estimates.params[p.name]:.7g}", error, p.unit]
        if true:
            row.append(f"{true[p.name]:.7g}" if p.name in true else "")
        rows.append(row)
    lines += [text_table(headers, rows + combination_rows(result.estimates.combinations, len(headers))), f"  (standard errors: {result.stderr_method})"]
    lines += [f"  not identifiable: {name} {why}" for name, why in result.not_identifiable.items()]
    lines += [f"  {warning}" for warning in result.judgments]
    lines.append("")
    lines += [
        text_table(*modal_rows(result.estimates.levels, result.estimates.half_power)),
        "",
        f"  {EFFECTIVE_TITLE}:",
        text_table(*effective_rows(result.estimates.effective)),
    ]
    lines += [f"  note: {note}" for note in [resonance_note(result.estimates.effective)] if note]
    lines.append("")
    if result.report:
        lines.append(f"report: {result.report} (figures and result.json alongside)")
    return "\n".join(lines)


def diagnosis_summary(doc: dict[str, Any], record: DiagnosisRecord) -> str:
    """The gap after each step, the status, and what cannot be identified (a diagnosis' document and record)."""
    lines = [
        f"hysid diagnose {doc['dataset']}: start model {doc['start_model']}, noise {doc['noise_sigma']}"
        + (f"; {doc['samples_left_out']}" if doc["samples_left_out"] else "")
    ]
    if doc["displacement_model"] and doc["displacement_model"]["decided_by"] != "none":
        lines.append(displacement_text(doc["displacement_model"]))
    lines += told_line(notices.merged(notices.stored(record.loops.meta), record.raised), "diagnosis.json")
    gap = doc["gap"]
    labels = []
    for step in doc["steps"]:
        also = f" (confusable with {', '.join(step['confusable_with'])})" if step["confusable_with"] else ""
        freed = f" ({', '.join(step['freed'])} free)" if step["freed"] else ""
        labels.append(step["effect"] + freed + also + (f" (with {step['joint_with']})" if step["joint_with"] else ""))
    pruned = ", ".join(doc["pruned"]) + " (consistent with zero)" if doc["pruned"] else ""
    width = max([38, *map(len, labels), len(pruned)])
    lines.append(f"  {'start':<{width + 2}} whitened RMS {gap[0]['whitened_rms']:10.4g}")
    for label, step, after in zip(labels, doc["steps"], gap[1:]):
        lines.append(f"  + {label:<{width}} whitened RMS {after['whitened_rms']:10.4g}   score {step['score']:.4g}")
    if pruned:
        lines.append(f"  - {pruned:<{width}} whitened RMS {gap[len(doc['steps']) + 1]['whitened_rms']:10.4g}")
    for entry, after in zip(doc["proposed"], gap[-len(doc["proposed"]) :] if doc["proposed"] else []):
        lines.append(f"  + {'proposed ' + entry['name'] + ' (from the data)':<{width}} whitened RMS {after['whitened_rms']:10.4g}")
    lines += proposed_lines(doc, record.report)
    if doc["status"] == "adequate":
        lines.append(f"status: adequate, the final model {doc['final_model_name']} leaves only noise")
    else:
        lines.append(f"status: unexplained, {doc['unexplained_signature']['description']}")
        lines.append(reference_text(doc))
    for name in doc["not_identifiable"]:
        lines.append(f"not identifiable here: {name} ({doc['not_identifiable_reasons'][name]})")
    for effect, why in doc["impossible"].items():
        lines.append(f"impossible here: {effect} ({why})")
    for term, why in doc["pruned"].items():
        lines.append(f"dropped from the final model: {term} ({why})")
    if doc["at_bounds_kind"]:
        lines.append(bounds_sentence(doc["at_bounds_kind"]))
    if doc["bounds_widened"]:
        lines.append(f"note: {widened_sentence(doc['bounds_widened'])}")
    lines += [f"note: {note}" for note in doc["notes"]]
    lines += [f"final model's {EFFECTIVE_TITLE}:", text_table(*effective_rows(record.estimates.effective))]
    lines += [f"note: {note}" for note in [resonance_note(record.estimates.effective)] if note]
    if record.report:
        lines.append(f"report: {record.report}")
    return "\n".join(lines)


KIND = "proposed from the data, not a library effect"


def law_text(entry: dict[str, Any]) -> str:
    """A proposed term's law (its JSON entry): ``F = ...``, or for a term with memory the rate of its force F."""
    return entry["notation"] if entry.get("memory") else f"F = {entry['notation']}"


def fitted_text(entry: dict[str, Any]) -> str:
    """``name = value +- stderr unit`` of every parameter of a proposed term (its JSON entry)."""
    return "; ".join(f"{n} = {v:.4g} +- {entry['stderr'][n]:.2g} {entry['units'][n]}" for n, v in entry["params"].items())


def evidence_text(entry: dict[str, Any]) -> str:
    e = entry["evidence"]
    held = (
        f", held-out whitened RMS {e['held_out_before']:.4g} -> {e['held_out_after']:.4g}"
        if e["held_out_before"] is not None and e["held_out_after"] is not None
        else ""
    )
    return (
        f"BIC {e['delta_bic']:.5g} against {entry['added_to']}, whitened RMS {e['whitened_rms_before']:.4g} -> "
        f"{e['whitened_rms_after']:.4g}{held}, removes {100 * e['share_of_excess_removed']:.0f} % of the residual above the noise"
    )


def proposed_lines(doc: dict[str, Any], report: str | None) -> list[str]:
    """The summary's lines on the proposed terms, the library effects set aside for them, and what discovery tried."""
    lines = []
    folder = str(PurePath(report).parent) if report else "<report folder>"
    for entry in doc["proposed"]:
        lines += [
            f"{KIND}: {entry['name']}, F = {entry['notation']}",
            f"  {fitted_text(entry)}",
            f"  evidence: {evidence_text(entry)}",
            f"  reuse: PYTHONPATH={folder} hysid fit DATA --model {entry['model']} (the term is {folder}/{entry['module']})",
        ]
    lines += [f"set aside: {effect} ({why})" for effect, why in doc["set_aside"].items()]
    if not doc["proposed"]:
        lines += [f"discovery from {base}: {what}" for base, what in doc["discovery"].items()]
    return lines


REACHES = {
    "noise floor": "the noise floor",
    "repeatability": "the scatter between repeated tests (the data repeat no better)",
    "linear per loop": "at least what a linear fit of each loop on its own reaches (no equivalent-linear description does better), not the noise floor",
    "none": "none of the references: not even what a linear fit of each loop on its own reaches",
}


def reference_text(doc: dict[str, Any]) -> str:
    """Where the final model's gap stands against the model-free references."""
    ref = doc["references"]
    repeat = f", repeated tests {ref['repeatability']:.4g}" if ref["repeatability"] is not None else ", no repeated tests"
    out = (
        f"the final model reaches {REACHES[doc['reaches']]}: whitened RMS {doc['whitened_rms']:.4g} against noise 1, "
        f"linear per loop {ref['linear_per_loop']:.4g}{repeat}"
    )
    if doc["reaches"] != "noise floor" and ref["linear_per_loop"] <= LINEAR_LOOPS:
        out += (
            "; each loop on its own is linear within the noise, so what the model misses is how stiffness, "
            "damping or mass change from loop to loop (with amplitude or frequency)"
        )
    return out


LOOP_COLUMNS = (
    ("label", "label", "{}"),
    ("frequency_hz", "freq_Hz", "{:.6g}"),
    ("x0_m", "X0_mm", "{:.4f}"),
    ("peak_force_n", "Fpk_N", "{:.5g}"),
    ("sigma_n", "sigma_N", "{:.3g}"),
    ("cycles", "cycles", "{:d}"),
    ("phase_deg", "phase_deg", "{:.2f}"),
    ("x_distortion", "x_thd_%", "{:.2f}"),
    ("k_dyn", "k_dyn_N/m", "{:.4g}"),
    ("c_eq", "c_eq_Ns/m", "{:.4g}"),
    ("loss_factor", "eta", "{:.3g}"),
    ("energy_per_cycle", "E_cycle_J", "{:.4g}"),
    ("fn_hz", "fn_Hz", "{:.4g}"),
    ("xi", "xi", "{:.4g}"),
)
"""The columns ``hysid loops`` can show, in order: the row's key, the title, the format."""


def loops_table(loops: LoopSet, rows: list[dict[str, Any]], survey: Survey | None = None) -> str:
    """``hysid loops``: one row per loop (label, frequency, X0, peak force, noise, cycles, phase, distortion,
    and the equivalent-linear survey where given): the :data:`LOOP_COLUMNS` the rows hold."""
    columns = [column for column in LOOP_COLUMNS if column[0] in rows[0]]
    scale = {"x0_m": 1e3, "x_distortion": 100.0}
    cells = []
    for row in rows:
        line = []
        for key, _, fmt in columns:
            value = row[key]
            line.append("-" if value is None else fmt.format(value * scale[key] if key in scale else value))
        cells.append(line)
    mass = "unknown (fitted)" if loops.meq_kg is None else f"{loops.meq_kg:g} kg"
    head = f"{loops.name}: {loops.n_loops} loops, {loops.n_samples} points per branch, meq = {mass}"
    if survey is not None and survey.mass_source != "known":
        found = f"{survey.meq_kg:.4g} kg, estimated from all loops (Re(F1/X1) = k - m w^2)" if survey.has_mass else survey.mass_source
        head += f"; survey mass {found}"
    head += "" if loops.kept().all() else f"\nnote: {loops.meta.get('reversals')}"
    return head + "\n" + text_table([title for _, title, _ in columns], cells, indent="")
