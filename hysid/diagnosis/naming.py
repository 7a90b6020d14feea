"""Is what is left noise? And if not, what does it look like (when no effect explains it)?

The whitened harmonic residual of an adequate model is standard normal noise:
its chi^2 follows chi^2(dof), and so does every coefficient group (one
harmonic order, in phase or in quadrature, over all loops) with L dof / N.
A structured miss shows up far more clearly in its own group than in the
total, so both are tested (Bonferroni over the groups).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hysid.diagnosis.fitting import Fit
from hysid_model.harmonics import Harmonics

ADEQUATE_ALPHA = 1e-3
"""Family-wise level at which the residual is declared not to be noise."""
SIGMA_SLACK = 0.1
"""With noise estimated from the data (not known), chi^2/dof up to 1 + this still counts as the noise floor."""
TREND = 0.5
"""|Spearman correlation| of the per-loop excess with amplitude or frequency worth reporting."""


@dataclass
class Adequacy:
    chi2_per_dof: float
    p_global: float
    p_groups: dict[str, float]
    adequate: bool


def _groups(fit: Fit, harmonics: Harmonics) -> tuple[np.ndarray, np.ndarray]:
    """Per-coefficient chi^2 over loops ``(M,)`` and its expectation under noise."""
    e = fit.residual.reshape(harmonics.loops.n_loops, -1)
    return np.sum(e**2, axis=0), np.full(e.shape[1], e.shape[0] * fit.dof / fit.n)


def adequacy(fit: Fit, harmonics: Harmonics) -> Adequacy:
    from scipy.stats import chi2 as chi2_dist  # on first use: a fast CLI and island start
    observed, expected = _groups(fit, harmonics)
    p_groups = chi2_dist.sf(observed, expected)
    p_global = float(chi2_dist.sf(fit.chi2, fit.dof))
    level = ADEQUATE_ALPHA / (observed.size + 1)
    ratio = fit.chi2 / max(fit.dof, 1)
    global_ok = p_global > level or (not np.all(harmonics.sigma_known) and ratio <= 1.0 + SIGMA_SLACK)
    return Adequacy(
        chi2_per_dof=float(ratio),
        p_global=p_global,
        p_groups=dict(zip(harmonics.names, map(float, p_groups))),
        adequate=bool(global_ok and np.all(p_groups > level)),
    )


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


def residual_signature(fit: Fit, harmonics: Harmonics) -> dict:
    """Where the chi^2 above the noise floor sits: by harmonic coefficient, and its trend over the loops."""
    from scipy.stats import spearmanr  # on first use: a fast CLI and island start
    observed, expected = _groups(fit, harmonics)
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
