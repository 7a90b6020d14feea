"""How a diagnosis report shows a force proposed from the data (:mod:`hysid.diagnosis.discovery`): its section, and
the Python module ``proposed.py`` that defines the term for reuse (the summary's lines are :mod:`hysid.report.text`'s,
the figure :mod:`hysid.report.diagnosis_figures`')."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from hysid.report.markdown import image, table, with_error
from hysid.report.text import KIND, evidence_text, fitted_text
from hysid_model.discovery.proposal import MODULE, module_source

if TYPE_CHECKING:
    from hysid.diagnosis.result import Diagnosis


def section(diagnosis: Diagnosis, out: Path, figures: list[Path]) -> list[str]:
    """The report's section on the proposed terms (with their ``figures``, one each, and their module), or on what
    discovery tried."""
    if not diagnosis.proposed:
        if not diagnosis.discovery:
            return []
        return [
            "## Discovery",
            "",
            "No force was proposed from the data: " + "; ".join(f"from {base}, {what}" for base, what in diagnosis.discovery.items()) + ".",
            "",
        ]
    module = write_module(diagnosis, out)
    lines = ["## Proposed from the data", ""]
    for p, figure in zip(diagnosis.proposed, figures):
        entry = p.as_dict()
        rows = [[f"`{n}`", with_error(v, entry["stderr"][n]), entry["units"][n]] for n, v in entry["params"].items()]
        lines += [
            f"### {p.name}: {KIND}",
            "",
            f"F = {entry['notation']}",
            "",
            f"As numpy, x in m and v in m/s, F in N: `{entry['formula']}`",
            "",
            table(["parameter", "value +- std. error", "unit"], rows),
            "",
            f"Evidence: {evidence_text(entry)}.",
            "",
            f"Defined in `{module.name}` with `hysid.term`: `PYTHONPATH={out} hysid fit DATA --model {entry['model']}`, "
            f"or `--candidates {MODULE}:{p.name}` to a diagnosis.",
            "",
            image(figure, out, f"The proposed force {p.name} against displacement and velocity (lines) and what the final model leaves without it (points)"),
            "",
        ]
    for effect, why in diagnosis.set_aside.items():
        lines += [f"**{effect} set aside**: {why}.", ""]
    return lines


def write_module(diagnosis: Diagnosis, out: Path) -> Path:
    """``proposed.py`` in ``out``: every proposed term of ``diagnosis`` defined with ``hysid.term``."""
    entries = [(p.law, p.number, fitted_text(p.as_dict())) for p in diagnosis.proposed]
    path = out / f"{MODULE}.py"
    path.write_text(module_source(entries, diagnosis.harmonics.loops.name))
    return path
