"""The tables of a result at each amplitude (and frequency), as rows of cells for the text and Markdown reports.

* modal: xi, fn, k, c, m of the oscillator at each amplitude level (as listed
  under Table 5.3) with the half-power cross-check (Eq. 2.7);
* effective: the whole model's effective stiffness k_eff = (F+ - F-) / (2 X0)
  and energy-based equivalent damping xi_eq = E_d / (4 pi E_s) at each amplitude
  and frequency (:mod:`hysid_model.effective`; ISO 10846, EN 15129, AASHTO);
* combinations: the stiffness k = meq w0^2 and damping c = 2 xi0 meq w0 the
  data determine best, beside the parameters.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence

from hysid_model.effective import OperatingPoint
from hysid_model.frf import HalfPower
from hysid_model.modal import COMBINATIONS, DERIVED_UNITS, AmplitudeResult

Table = tuple[list[str], list[list[str]]]
MAX_POINTS = 24
"""Beyond this many amplitude-frequency points a summary gives each amplitude's range over the frequencies."""
EFFECTIVE_TITLE = (
    "effective stiffness k_eff = (F+ - F-) / (2 X0) and equivalent damping xi_eq = E_d / (4 pi E_s), "
    "E_s = k_eff X0^2 / 2, of the whole model under X0 sin(wt) (ISO 10846, EN 15129)"
)


def pm(value: float, stderr: float, digits: int = 4) -> str:
    """``value +- stderr``; the value alone where the error is 0 (fixed), 'n/a' where there is no value."""
    if not math.isfinite(value):
        return "n/a"
    if stderr == 0:
        return f"{value:.{digits}g}"
    return f"{value:.{digits}g} +- " + (f"{stderr:.2g}" if math.isfinite(stderr) else "n/a")


def modal_rows(levels: Sequence[AmplitudeResult], half_power: Sequence[HalfPower]) -> Table:
    """xi, fn, k, c at each amplitude level with the half-power damping there (the summary's 'at each amplitude' table)."""
    rows = []
    for a, hp in zip(levels, half_power):
        half = f"{hp.xi:.5f} (grid resolution {hp.resolution:.2g})" if hp.ok else f"n/a ({hp.note})"
        rows.append(
            [
                f"{a.x0 * 1e3:.4g}",
                pm(a.values["fn_hz"], a.stderr["fn_hz"], 6),
                pm(a.values["xi"], a.stderr["xi"]),
                half,
                pm(a.values["k"], a.stderr["k"], 5),
                pm(a.values["c"], a.stderr["c"]),
            ]
        )
    return ["X0 (mm)", "fn (Hz)", "xi (fit)", "xi half-power (Eq. 2.7)", "k (N/m)", "c (N s/m)"], rows


def effective_rows(points: Sequence[OperatingPoint], most: int | None = MAX_POINTS) -> Table:
    """k_eff, xi_eq and E_d at each amplitude and frequency; beyond ``most`` points, each amplitude's range over its frequencies."""
    if most is None or len(points) <= most:
        return ["X0 (mm)", "f (Hz)", "k_eff (N/m)", "xi_eq", "E_d per cycle (J)"], [
            [
                f"{p.x0 * 1e3:.4g}",
                f"{p.freq_hz:.4g}",
                pm(p.values["k_eff"], p.stderr["k_eff"], 5),
                pm(p.values["xi_eq"], p.stderr["xi_eq"]),
                pm(p.values["energy"], p.stderr["energy"]),
            ]
            for p in points
        ]
    rows = []
    for x0 in dict.fromkeys(p.x0 for p in points):
        level = [p for p in points if p.x0 == x0]
        cells = [f"{x0 * 1e3:.4g}", f"{level[0].freq_hz:.4g}-{level[-1].freq_hz:.4g}"]
        for q, digits in (("k_eff", 5), ("xi_eq", 4), ("energy", 4)):
            finite = [p.values[q] for p in level if math.isfinite(p.values[q])]
            cells.append(f"{min(finite):.{digits}g} to {max(finite):.{digits}g}" if finite else "n/a")
        rows.append(cells)
    return ["X0 (mm)", "f (Hz)", "k_eff (N/m), range", "xi_eq, range", "E_d per cycle (J), range"], rows


def resonance_note(points: Sequence[OperatingPoint]) -> str | None:
    """A sentence where an amplitude level's k_eff changes sign over its frequencies: the band crosses the resonance,
    where the whole model's force (the inertia of the moving mass with it) makes k_eff pass zero and xi_eq diverge; None
    otherwise. The frequency of each crossing is interpolated linearly in k_eff."""
    crossings = []
    for x0 in dict.fromkeys(p.x0 for p in points):
        level = sorted((p for p in points if p.x0 == x0 and math.isfinite(p.values["k_eff"])), key=lambda p: p.freq_hz)
        for a, b in itertools.pairwise(level):
            ka, kb = a.values["k_eff"], b.values["k_eff"]
            if ka > 0.0 >= kb or ka <= 0.0 < kb:
                crossings.append(a.freq_hz + (b.freq_hz - a.freq_hz) * ka / (ka - kb))
                break
    if not crossings:
        return None
    at = f"{min(crossings):.4g} Hz" if max(crossings) - min(crossings) < 5e-4 * max(crossings) else f"{min(crossings):.4g}-{max(crossings):.4g} Hz"
    return (
        f"the band crosses the resonance (k_eff passes zero at {at}): the whole model's force holds the inertia of the "
        "moving mass, so k_eff falls through zero and xi_eq grows without bound near it; the oscillator's fn and xi are "
        "the specimen's frequency and damping"
    )


def combination_rows(found: Mapping[str, tuple[float, float]], columns: int) -> list[list[str]]:
    """The combinations k and c ``found`` (value, standard error) as rows of the parameter table (``columns`` cells
    each): name, value, error, unit."""
    rows = []
    for name, (value, se) in found.items():
        row = [f"{name} = {COMBINATIONS[name]}", f"{value:.7g}", "not determined" if not math.isfinite(se) else f"{se:.2g}", DERIVED_UNITS[name]]
        rows.append(row + [""] * (columns - len(row)))
    return rows
