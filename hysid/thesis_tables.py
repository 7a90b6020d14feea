"""The thesis' published Synth-set results (section 5.2.1) as reference data.

Table 5.3's parameters and Table 5.4's bounds live in :mod:`hysid_model.synth`
(``TRUE_PARAMS``, ``BOUNDS``); this module holds what the thesis *reports*:

* the modal values listed under Table 5.3 (wn and xi at each amplitude),
* Tables 5.5-5.12: four runs of GA and PSO at 0, 10, 20 and 30 % noise, with
  the published mean, standard deviation and sigma/mean,
* Table 5.13: |mean - actual| for each algorithm and noise level.

Numbers are transcribed as printed (including the thesis' rounding).
"""

from __future__ import annotations

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

Row = tuple[float, float, float, float, float, float, float]
"""One parameter's row of Tables 5.5-5.12: run 1, run 2, run 3, run 4, mean, standard deviation, sigma/mean."""

TABLES_5_5_TO_5_12: dict[tuple[int, str], Row] = {
    # Table 5.5: GA, 0 % noise
    (5, "xi0"): (0.00413, 0.004444, 0.004306, 0.003081, 0.00399, 0.00062, 0.155336),
    (5, "S_xi"): (-0.33347, -0.58421, -0.42632, 0.372055, -0.24299, 0.42289, 1.740382),
    (5, "w0"): (189.1282, 189.1831, 189.222, 189.1089, 189.1605, 0.051628, 0.000273),
    (5, "S_w"): (-1256.03, -1311.81, -1309.71, -1298.78, -1294.08, 26.00358, 0.020094),
    # Table 5.6: GA, 10 % noise
    (6, "xi0"): (0.00379, 0.003934, 0.004319, 0.004104, 0.004037, 0.000227, 0.056337),
    (6, "S_xi"): (-0.00494, -0.22136, -0.52046, -0.32666, -0.26836, 0.214907, 0.800830),
    (6, "w0"): (189.0764, 189.1619, 189.2238, 189.1275, 189.1474, 0.061878, 0.000327),
    (6, "S_w"): (-1199.93, -1303.86, -1327.24, -1256.3, -1271.83, 56.29433, 0.044262),
    # Table 5.7: GA, 20 % noise
    (7, "xi0"): (0.004398, 0.004363, 0.004103, 0.004045, 0.004227, 0.000179, 0.042303),
    (7, "S_xi"): (-0.61225, -0.50622, -0.33247, -0.25812, -0.42726, 0.161295, 0.377506),
    (7, "w0"): (188.9366, 189.1497, 189.0965, 189.1741, 189.0892, 0.106813, 0.000565),
    (7, "S_w"): (-1092.83, -1243.7, -1226.6, -1303.53, -1216.66, 88.90028, 0.073069),
    # Table 5.8: GA, 30 % noise
    (8, "xi0"): (0.004771, 0.003594, 0.003973, 0.003385, 0.003931, 0.000611, 0.155381),
    (8, "S_xi"): (-0.71675, 0.208465, -0.25031, 0.246317, -0.12807, 0.452737, 3.535067),
    (8, "w0"): (189.0589, 189.052, 189.1316, 189.0822, 189.0812, 0.035996, 0.000190),
    (8, "S_w"): (-1200.27, -1201.69, -1228.52, -1233.67, -1216.04, 17.52276, 0.014410),
    # Table 5.9: PSO, 0 % noise
    (9, "xi0"): (0.004437, 0.004611, 0.004557, 0.004614, 0.004555, 8.27e-05, 0.018151),
    (9, "S_xi"): (-0.56995, -0.81059, -0.70964, -0.67819, -0.69209, 0.099097, 0.143185),
    (9, "w0"): (189.1421, 189.0642, 189.0937, 189.1477, 189.1119, 0.039992, 0.000211),
    (9, "S_w"): (-1302.46, -1192.85, -1245.96, -1288.61, -1257.47, 49.3357, 0.039234),
    # Table 5.10: PSO, 10 % noise
    (10, "xi0"): (0.004785, 0.004713, 0.003923, 0.003881, 0.004326, 0.00049, 0.113324),
    (10, "S_xi"): (-0.79555, -0.81552, -0.23406, -0.14349, -0.49716, 0.358097, 0.720290),
    (10, "w0"): (188.9828, 189.0352, 189.1041, 189.088, 189.0525, 0.054989, 0.000291),
    (10, "S_w"): (-1131.53, -1192.03, -1253.12, -1236.37, -1203.26, 54.32264, 0.045146),
    # Table 5.11: PSO, 20 % noise
    (11, "xi0"): (0.003963, 0.004014, 0.003709, 0.00389, 0.003894, 0.000134, 0.034335),
    (11, "S_xi"): (-0.14437, -0.26865, -0.02538, -0.24365, -0.17052, 0.110643, 0.648877),
    (11, "w0"): (189.0428, 189.1218, 189.1098, 189.1164, 189.0977, 0.036953, 0.000195),
    (11, "S_w"): (-1194.78, -1245.47, -1245.32, -1240.31, -1231.47, 24.57532, 0.019956),
    # Table 5.12: PSO, 30 % noise
    (12, "xi0"): (0.004226, 0.004108, 0.004937, 0.003767, 0.004259, 0.000492, 0.115522),
    (12, "S_xi"): (-0.4518, -0.4938, -1.07537, -0.1138, -0.53369, 0.399173, 0.747946),
    (12, "w0"): (189.1569, 189.1508, 189.3972, 189.1963, 189.2253, 0.116378, 0.000615),
    (12, "S_w"): (-1264.21, -1262.62, -1442.37, -1347.87, -1329.27, 85.26707, 0.064146),
}
"""Tables 5.5-5.12 as printed, row by row: (n of Table 5.<n>, parameter) -> the four runs, then their mean,
standard deviation and sigma/mean (the thesis' last three columns); which run each table holds: ``TABLE_NUMBERS``."""

RUNS: dict[tuple[str, int], dict[str, tuple[float, float, float, float]]] = {
    key: {p: TABLES_5_5_TO_5_12[(n, p)][:4] for p in PARAMS} for key, n in TABLE_NUMBERS.items()
}
"""Tables 5.5-5.12: (algorithm, noise %) -> parameter -> the four runs."""

SUMMARY: dict[tuple[str, int], dict[str, tuple[float, float, float]]] = {
    key: {p: TABLES_5_5_TO_5_12[(n, p)][4:] for p in PARAMS} for key, n in TABLE_NUMBERS.items()
}
"""Tables 5.5-5.12, last three columns: (mean, standard deviation, sigma/mean) as printed."""

TABLE_5_13_COLUMNS: tuple[tuple[str, int], ...] = tuple((algo, noise) for noise in NOISE_LEVELS for algo in ALGOS)
"""Table 5.13's columns in their printed order: (algorithm, noise %), GA then PSO at each noise level."""

TABLE_5_13_ROWS: dict[str, tuple[float, ...]] = {
    "xi0": (2.10e-4, 3.55e-4, 1.63e-4, 1.26e-4, 0.27e-4, 3.06e-4, 2.69e-4, 0.59e-4),
    "S_xi": (0.1570, 0.2920, 0.1320, 0.0972, 0.0273, 0.2290, 0.2720, 0.1340),
    "w0": (0.0366, 0.0120, 0.0235, 0.0714, 0.0347, 0.0262, 0.0427, 0.101),
    "S_w": (37.4, 0.834, 15.2, 53.4, 40.0, 25.2, 40.6, 72.6),
}
"""Table 5.13 as printed, a row a parameter: |mean - actual| in the columns ``TABLE_5_13_COLUMNS``."""

TABLE_5_13: dict[str, dict[tuple[str, int], float]] = {p: dict(zip(TABLE_5_13_COLUMNS, row, strict=True)) for p, row in TABLE_5_13_ROWS.items()}
"""Table 5.13: parameter -> (algorithm, noise %) -> |mean - actual|."""


def table_5_13_scale(param: str, algo: str) -> float:
    """The typical size of Table 5.13's errors for one parameter and algorithm: RMS over the noise levels."""
    values = [TABLE_5_13[param][(algo, noise)] for noise in NOISE_LEVELS]
    return (sum(v * v for v in values) / len(values)) ** 0.5
