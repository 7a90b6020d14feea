"""The thesis' published Synth-set results (section 5.2.1) as reference data.

Table 5.3's parameters and Table 5.4's bounds live in :mod:`hysid_model.synth`
(``TRUE_PARAMS``, ``BOUNDS``); this module holds what the thesis *reports*:

* the modal values listed under Table 5.3 (wn and xi at each amplitude),
* Tables 5.5-5.12: four runs of GA and PSO at 0, 10, 20 and 30 % noise, with
  the published mean, standard deviation and sigma/mean,
* Table 5.13: |mean - actual| for each algorithm and noise level.

Tables 5.5-5.13 are transcribed as printed (including the thesis' rounding) in the CSV files beside this
module (``TABLES_5_5_TO_5_12_FILE``, ``TABLE_5_13_FILE``); the lookups below are read off them.
"""

from __future__ import annotations

import csv
from importlib.resources import files

PARAMS = ("xi0", "S_xi", "w0", "S_w")
NOISE_LEVELS = (0, 10, 20, 30)
ALGOS = ("ga", "pso")

MODAL_UNDER_TABLE_5_3: dict[float, tuple[float, float]] = {
    0.5e-3: (30.0, 0.0040),
    1.0e-3: (29.9, 0.0038),
    1.5e-3: (29.8, 0.0036),
}
"""X0 (m) -> (fn in Hz, xi) as listed under Table 5.3 ("At X0=0.5mm: wn = 2 pi 30.0, xi = 0.0040")."""

TABLE_NUMBERS: dict[tuple[str, int], int] = {
    ("ga", 0): 5,
    ("ga", 10): 6,
    ("ga", 20): 7,
    ("ga", 30): 8,
    ("pso", 0): 9,
    ("pso", 10): 10,
    ("pso", 20): 11,
    ("pso", 30): 12,
}
"""(algorithm, noise %) -> number of the thesis table (Table 5.<n>)."""

TABLES_5_5_TO_5_12_FILE = "thesis_tables_5_5_to_5_12.csv"
"""Tables 5.5-5.12 as printed, a row a line (beside this module): table, parameter, the four runs, then their mean,
standard deviation and sigma/mean (the thesis' last three columns)."""
TABLE_5_13_FILE = "thesis_table_5_13.csv"
"""Table 5.13 as printed (beside this module): a row a parameter, a column per noise level and algorithm."""


def printed(name: str) -> tuple[list[str], list[list[str]]]:
    """The header and the rows of the transcription ``name``, a CSV file beside this module."""
    header, *rows = csv.reader(files("hysid").joinpath(name).read_text(encoding="utf-8").splitlines())
    return header, rows


TABLES_5_5_TO_5_12: dict[tuple[int, str], tuple[float, ...]] = {
    (int(table.removeprefix("5.")), param): tuple(map(float, values)) for table, param, *values in printed(TABLES_5_5_TO_5_12_FILE)[1]
}
"""Tables 5.5-5.12: (n of Table 5.<n>, parameter) -> run 1, run 2, run 3, run 4, mean, standard deviation, sigma/mean;
which run each table holds: ``TABLE_NUMBERS``."""

RUNS: dict[tuple[str, int], dict[str, tuple[float, ...]]] = {key: {p: TABLES_5_5_TO_5_12[(n, p)][:4] for p in PARAMS} for key, n in TABLE_NUMBERS.items()}
"""Tables 5.5-5.12: (algorithm, noise %) -> parameter -> the four runs."""

SUMMARY: dict[tuple[str, int], dict[str, tuple[float, ...]]] = {key: {p: TABLES_5_5_TO_5_12[(n, p)][4:] for p in PARAMS} for key, n in TABLE_NUMBERS.items()}
"""Tables 5.5-5.12, last three columns: (mean, standard deviation, sigma/mean) as printed."""


def column(title: str) -> tuple[str, int]:
    """(algorithm, noise %) of a column of Table 5.13 titled as printed, e.g. ``10 % PSO`` -> ("pso", 10)."""
    noise, algo = title.split(" % ")
    return algo.lower(), int(noise)


TABLE_5_13_COLUMNS: tuple[tuple[str, int], ...] = tuple(column(title) for title in printed(TABLE_5_13_FILE)[0][1:])
"""Table 5.13's columns in their printed order: (algorithm, noise %), GA then PSO at each noise level."""

TABLE_5_13: dict[str, dict[tuple[str, int], float]] = {
    param: dict(zip(TABLE_5_13_COLUMNS, map(float, values), strict=True)) for param, *values in printed(TABLE_5_13_FILE)[1]
}
"""Table 5.13: parameter -> (algorithm, noise %) -> |mean - actual|."""


def table_5_13_scale(param: str, algo: str) -> float:
    """The typical size of Table 5.13's errors for one parameter and algorithm: RMS over the noise levels."""
    values = [TABLE_5_13[param][(algo, noise)] for noise in NOISE_LEVELS]
    return (sum(v * v for v in values) / len(values)) ** 0.5
