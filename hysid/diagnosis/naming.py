"""What is left, where a model is not adequate (when no effect explains it).

Whether what is left is noise is :mod:`hysid.adequacy`'s rule, the same for ``hysid fit``, campaigns and the
diagnosis; here the excess chi^2 is described by harmonic coefficient and by its trend over the loops.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hysid.adequacy import Adequacy, groups, judge
from hysid.diagnosis.metrics import linear_per_loop_residual
from hysid.harmonic_fits import Fit, final_identifiability
from hysid_model.harmonics import Harmonics

TREND = 0.5
"""|Spearman correlation| of the per-loop excess with amplitude or frequency worth reporting."""


def adequacy(fit: Fit, harmonics: Harmonics) -> Adequacy:
    """The verdict of :func:`hysid.adequacy.judge` on a diagnosis' fit (at its optimum on the harmonics already)."""
    return judge(fit.residual, fit.model.dim, harmonics)


def loops_linear(harmonics: Harmonics) -> bool:
    """Whether every loop on its own is linear within the noise: what a linear fit of each loop on its own (an
    offset, a spring, a dashpot and a mass, :func:`hysid.diagnosis.metrics.linear_per_loop_residual`) leaves
    passes the adequacy rule, in total and coefficient by coefficient."""
    residual, used = linear_per_loop_residual(harmonics, harmonics.whiten(harmonics.loops.forces()))
    return judge(residual.ravel(), used, harmonics).adequate


def _coefficient_words(name: str) -> str:
    if name == "dc":
        return "a constant offset"
    kind = "in phase with the displacement" if name[0] == "s" else "in quadrature (with the velocity)"
    return f"order {name[1:]} {kind}"


def excess_words(names: list[str], orders: np.ndarray, share: np.ndarray) -> str:
    """Where the excess chi^2 sits, in words: the odd and the even orders' shares, each with its
    largest coefficients (at least 10 % of the excess, three at most), the larger kind first."""
    even_mask = orders % 2 == 0
    kinds = []
    for kind, mask in (("odd", ~even_mask), ("even", even_mask)):
        ranked = [i for i in np.argsort(-np.where(mask, share, -1.0), kind="stable") if mask[i] and share[i] >= 0.1][:3]
        parts = ", ".join(f"{_coefficient_words(names[i])} {100 * share[i]:.0f}%" for i in ranked)
        kinds.append((float(share[mask].sum()), kind, parts))
    kinds.sort(key=lambda k: -k[0])
    (top, kind, parts), (rest, other, other_parts) = kinds
    if not parts:
        return "spread over all harmonics"
    text = f"{kind} harmonics ({100 * top:.0f}% of the excess: {parts})"
    if kind == "even":
        text += ": the loops are not point-symmetric, F(-x, -v) != -F(x, v)"
    if other_parts:
        text += f"; {other} harmonics {100 * rest:.0f}% ({other_parts})"
    return text


def final_fields(fit: Fit, harmonics: Harmonics) -> dict[str, Any]:
    """What a diagnosis says of the model it ends with, as :class:`~hysid.diagnosis.result.Diagnosis` fields: ``final``,
    ``status`` (adequate where :func:`adequacy` finds only noise left, else unexplained), ``unexplained`` (where the
    excess sits, :func:`residual_signature`, or None) and the final model's ``identifiability``."""
    adequate = adequacy(fit, harmonics).adequate
    return {
        "final": fit,
        "status": "adequate" if adequate else "unexplained",
        "unexplained": None if adequate else residual_signature(fit, harmonics),
        "identifiability": final_identifiability(fit, harmonics),
    }


def residual_signature(fit: Fit, harmonics: Harmonics) -> dict:
    """Where the chi^2 above the noise floor sits: by harmonic coefficient, and its trend over the loops."""
    from scipy.stats import spearmanr  # on first use: a fast CLI and island start

    observed, expected = groups(fit.residual, fit.dof, harmonics)
    excess = np.maximum(observed - expected, 0.0)
    total = float(excess.sum())
    share = excess / total if total > 0 else excess
    orders = harmonics.orders()
    even = float(share[orders % 2 == 0].sum())
    text = excess_words(harmonics.names, orders, share)
    e = fit.residual.reshape(harmonics.loops.n_loops, -1)
    per_loop = np.sum(e**2, axis=1) - e.shape[1] * fit.dof / fit.n
    trends = {}
    for label, values in (("amplitude", harmonics.loops.x0), ("frequency", harmonics.loops.freq_hz)):
        if np.unique(values).size > 2 and np.ptp(per_loop) > 0:
            rho = float(spearmanr(values, per_loop).statistic)
            trends[label] = rho
            if abs(rho) >= TREND:
                text += f"; {'grows' if rho > 0 else 'shrinks'} with {label}"
    return {
        "description": text,
        "excess_chi2": total,
        "share_by_coefficient": {n: float(s) for n, s in zip(harmonics.names, share) if s >= 0.01},
        "even_share": even,
        "trend_spearman": trends,
    }
