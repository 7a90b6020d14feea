"""How a diagnosis report shows a force proposed from the data (:mod:`hysid.diagnosis.discovery`): its section, and
the Python module ``proposed.py`` that defines the term for reuse (the summary's lines are :mod:`hysid.report.text`'s,
the figure :mod:`hysid.report.diagnosis_figures`')."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from hysid.report.markdown import picture, table, with_error
from hysid.report.records import DiagnosisRecord
from hysid.report.text import KIND, evidence_text, fitted_text, law_text
from hysid_model.discovery.proposal import MODULE, module_source


def section(doc: dict[str, Any], record: DiagnosisRecord, out: Path, figures: Sequence[Callable[[], Path]], left_out: str | None = None) -> list[str]:
    """The report's section on the proposed terms of a diagnosis (its document and record; with their ``figures``, one
    each, drawn unless ``left_out`` says why not, and their module), or on what discovery tried."""
    if not doc["proposed"]:
        if not doc["discovery"]:
            return []
        return [
            "## Discovery",
            "",
            "No force was proposed from the data: " + "; ".join(f"from {base}, {what}" for base, what in doc["discovery"].items()) + ".",
            "",
        ]
    module = write_module(doc, record, out)
    lines = ["## Proposed from the data", ""]
    for entry, figure in zip(doc["proposed"], figures):
        name = entry["name"]
        rows = [[f"`{n}`", with_error(v, entry["stderr"][n]), entry["units"][n]] for n, v in entry["params"].items()]
        lines += [
            f"### {name}: {KIND}",
            "",
            law_text(entry),
            "",
            (
                f"A force with memory: its rate as numpy, z the force F in N, x in m and v in m/s, dz/dt in N/s: `{entry['formula']}`"
                if entry.get("memory")
                else f"As numpy, x in m and v in m/s, F in N: `{entry['formula']}`"
            ),
            "",
            table(["parameter", "value +- std. error", "unit"], rows),
            "",
            f"Evidence: {evidence_text(entry)}.",
            "",
            f"Defined in `{module.name}` with `hysid.term`: `PYTHONPATH={out} hysid fit DATA --model {entry['model']}`, "
            f"or `--candidates {MODULE}:{name}` to a diagnosis.",
            "",
            picture(
                figure,
                out,
                f"The proposed force {name} against displacement and velocity (lines) and what the final model leaves without it (points)",
                left_out,
            ),
            "",
        ]
    for effect, why in doc["set_aside"].items():
        lines += [f"**{effect} set aside**: {why}.", ""]
    return lines


def write_module(doc: dict[str, Any], record: DiagnosisRecord, out: Path) -> Path:
    """``proposed.py`` in ``out``: every proposed term of a diagnosis defined with ``hysid.term``."""
    entries = [(law, number, fitted_text(entry)) for (law, number), entry in zip(record.laws, doc["proposed"])]
    path = out / f"{MODULE}.py"
    path.write_text(module_source(entries, record.loops.name))
    return path
