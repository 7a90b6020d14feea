"""Success rates compared, for the benches that race searches over seeds (``hysid bench islands mixed``,
``hysid bench search``): the Wilson interval of one rate, and two searches seed by seed (the paired
difference of their rates with its interval, the sign test, which one ended lower)."""

from __future__ import annotations

from typing import Any

import numpy as np


def wilson(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The 95 % Wilson score interval of a success rate."""
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return float(max(centre - half, 0.0)), float(min(centre + half, 1.0))


NON_INFERIORITY_MARGIN = 0.10
"""How far below the better single algorithm's success rate the default mix may lie and still count as
at least as good: its seed-by-seed difference's 95 % interval must lie above minus this margin. Two
searches that are equally good tie, and a plain "rate >= rate" then decides by the seeds' luck (this
bench's earlier runs: met twice and missed twice, by two seeds in 100 and by one in 300); a margin of 10
points is the usual one for non-inferiority of success rates (e.g. the FDA's for antibacterial trials),
and with 300 seeds the interval's half-width is about 6 points, so only a real deficit fails."""


def paired(a: np.ndarray, b: np.ndarray) -> dict[str, Any]:
    """Two campaigns' successes compared seed by seed: how many seeds only ``a`` or only ``b`` passed,
    the difference of their success rates with its 95 % (Wald, paired) interval, and the exact
    two-sided sign-test (McNemar) p-value of the seeds only one of them passed."""
    from scipy.stats import binomtest  # on first use: a fast CLI and island start

    only_a, only_b, n = int(np.sum(a & ~b)), int(np.sum(b & ~a)), a.size
    d = (only_a - only_b) / n
    half = 1.96 * np.sqrt(max(only_a + only_b - n * d * d, 0.0)) / n
    p = binomtest(only_a, only_a + only_b).pvalue if only_a + only_b else 1.0
    return {"only_a": only_a, "only_b": only_b, "difference": d, "difference95": (d - half, d + half), "sign_test_p": float(p)}


def ended_lower(a: np.ndarray, b: np.ndarray) -> dict[str, Any]:
    """Two campaigns' final fitness compared seed by seed: in how many seeds ``a`` ended lower (and
    higher), and the two-sided Wilcoxon signed-rank p-value of the log10 ratios."""
    from scipy.stats import wilcoxon  # on first use: a fast CLI and island start

    r = np.log10(np.maximum(a, 1e-300)) - np.log10(np.maximum(b, 1e-300))
    r = r[np.isfinite(r)]
    p = wilcoxon(r).pvalue if np.any(r != 0) else 1.0
    return {"lower": int(np.sum(r < 0)), "higher": int(np.sum(r > 0)), "wilcoxon_p": float(p)}
