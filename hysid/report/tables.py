"""Results as tables to take away: rows of plain dicts, CSV files, and pandas DataFrames when pandas is installed.

Column names carry their SI unit (``x0_m``, ``k_n_per_m``) so that a CSV file
read years later still says what it holds; a standard error sits in the
column after its value (``xi``, ``xi_stderr``).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from hysid.report.records import Estimates
from hysid_model.effective import OperatingPoint
from hysid_model.errors import HysidInputError
from hysid_model.modal import COMBINATIONS, DERIVED_UNITS

Rows = list[dict[str, Any]]

AMPLITUDE_COLUMNS = {"fn_hz": "fn_hz", "xi": "xi", "k": "k_n_per_m", "c": "c_n_s_per_m", "m": "m_kg"}
"""Per-amplitude quantities (:mod:`hysid_model.modal`) and their CSV column names."""
EFFECTIVE_COLUMNS = {"k_eff": "k_eff_n_per_m", "xi_eq": "xi_eq", "energy": "energy_per_cycle_j"}
"""Per amplitude and frequency (:mod:`hysid_model.effective`) and their CSV column names."""


def parameter_rows(params: Mapping[str, float], stderr: Mapping[str, float], model: Any, at_bounds: Sequence[str] = ()) -> Rows:
    """One row per parameter of ``model``: value, standard error, unit, search bounds, and whether it was
    fitted, fixed (a known value) or ended on a bound."""
    rows = []
    for p in model.parameters:
        rows.append(
            {
                "parameter": p.name,
                "value": params[p.name],
                "stderr": stderr[p.name],
                "unit": p.unit,
                "lower": p.lower,
                "upper": p.upper,
                "status": "at bound" if p.name in at_bounds else "fitted",
            }
        )
    for name, value in model.fixed.items():
        unit = next((p.unit for t in model.terms for p in t.params if p.name == name), "")
        rows.append({"parameter": name, "value": value, "stderr": 0.0, "unit": unit, "lower": value, "upper": value, "status": "fixed"})
    return rows


def fit_tables(result: Estimates) -> dict[str, Rows]:
    """``parameters`` (with standard errors, and the combinations k = meq w0^2, c = 2 xi0 meq w0) and
    ``amplitudes``: one row per amplitude level and frequency of the loops, with fn, xi, k, c, m of that level,
    the whole model's effective stiffness, equivalent damping and energy per cycle at that amplitude and
    frequency (:mod:`hysid_model.effective`), all with standard errors, and the level's half-power damping (Eq. 2.7)."""
    level = {a.x0: k for k, a in enumerate(result.levels)}
    amplitudes = []
    for point in result.effective:
        k = level[point.x0]
        a, hp = result.levels[k], result.half_power[k]
        row: dict[str, Any] = {"x0_m": a.x0, "f_hz": point.freq_hz}
        for quantity, column in AMPLITUDE_COLUMNS.items():
            row[column] = a.values[quantity]
            row[f"{column}_stderr"] = a.stderr[quantity]
        row.update(effective_cells(point))
        row.update(
            {
                "xi_half_power": hp.xi if hp.ok else None,
                "xi_half_power_resolution": hp.resolution if hp.ok else None,
                "half_power_loops": hp.n_loops,
                "half_power_note": hp.note,
            }
        )
        amplitudes.append(row)
    parameters = parameter_rows(result.params, result.stderr, result.model, result.at_bounds) + combination_rows(result.combinations)
    return {"parameters": parameters, "amplitudes": amplitudes}


def combination_rows(found: Mapping[str, tuple[float, float]]) -> Rows:
    """The stiffness k = meq w0^2 and damping coefficient c = 2 xi0 meq w0 as rows of the parameter table (status 'derived')."""
    return [
        {"parameter": name, "value": value, "stderr": se, "unit": DERIVED_UNITS[name], "lower": None, "upper": None, "status": f"derived: {COMBINATIONS[name]}"}
        for name, (value, se) in found.items()
    ]


def diagnosis_tables(final: Estimates, document: Mapping[str, Any], labels: Sequence[str]) -> dict[str, Rows]:
    """``parameters`` of the ``final`` model, ``steps`` (each effect named, with its parameters) and ``gap``
    (whitened RMS, loop NRMSE, energy error after each fit, ``labels`` naming them), from a diagnosis's
    ``document`` (:meth:`hysid.diagnosis.result.Diagnosis.to_dict`)."""
    steps = [
        {
            "step": i + 1,
            "effect": s["effect"],
            "parameter": name,
            "value": value,
            "stderr": s["stderr"][name],
            "confusable_with": " ".join(s["confusable_with"]),
            "whitened_rms_after": s["whitened_rms_after"],
        }
        for i, s in enumerate(document["steps"])
        for name, value in s["params"].items()
    ]
    gap = [{"step": label, **g} for label, g in zip(labels, document["gap"])]
    return {
        "parameters": parameter_rows(final.params, final.stderr, final.model) + combination_rows(final.combinations),
        "steps": steps,
        "gap": gap,
        "amplitudes": [{"x0_m": p.x0, "f_hz": p.freq_hz, **effective_cells(p)} for p in final.effective],
    }


def effective_cells(point: OperatingPoint) -> dict[str, Any]:
    """k_eff, xi_eq and the energy per cycle at one amplitude and frequency with their standard errors (None where not given)."""
    out: dict[str, Any] = {}
    for quantity, column in EFFECTIVE_COLUMNS.items():
        value, se = point.values[quantity], point.stderr[quantity]
        out[column] = value if math.isfinite(value) else None
        out[f"{column}_stderr"] = se if math.isfinite(se) else None
    return out


def cell(value: Any) -> Any:
    """A CSV cell: numbers at full precision, missing and non-finite values empty."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return ""
    return repr(float(value)) if isinstance(value, float) else value


def write_csv(path: Path, rows: Rows) -> Path:
    """``rows`` (dicts with the same keys) as a CSV file with a header line."""
    path.parent.mkdir(parents=True, exist_ok=True)
    columns = list(rows[0]) if rows else []
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(columns)
        writer.writerows([cell(row[c]) for c in columns] for row in rows)
    return path


def write_tables(tables: Mapping[str, Rows], out_dir: str | Path) -> dict[str, Path]:
    """Each table as ``<name>.csv`` in ``out_dir``; returns the paths by table name."""
    out = Path(out_dir)
    return {name: write_csv(out / f"{name}.csv", rows) for name, rows in tables.items()}


def data_frames(tables: Mapping[str, Rows]) -> dict[str, Any]:
    """Each table as a pandas DataFrame (pandas is optional: ``pip install 'hysid[pandas]'``)."""
    try:
        import pandas as pd
    except ImportError:
        raise HysidInputError("DataFrames need pandas (pip install 'hysid[pandas]'); tables() gives the same rows as plain dicts") from None
    return {name: pd.DataFrame(rows) for name, rows in tables.items()}
