"""Does a model describe the loops? The one rule behind the verdict of ``hysid fit``, campaigns and ``hysid diagnose``.

A model is adequate when what it leaves of the loops is noise. The test is on
the loops' harmonic coefficients (orders 0-7, :class:`hysid_model.harmonics.Harmonics`),
whitened by their noise: at the model's optimum on them, the residual of an
adequate model is standard normal, its chi^2 follows chi^2(dof), and so does
every coefficient group (one harmonic order, in phase or in quadrature, over
all loops) with L dof / N. A structured miss shows far more clearly in its own
group than in the total, so both are tested (Bonferroni over the groups, a
family-wise ``ADEQUATE_ALPHA``). Where the noise is estimated rather than
known, chi^2/dof up to 1 + ``SIGMA_SLACK`` still counts as the noise floor.

The samples extraction could not resolve (the reversal samples of a force
with a cusp there, :mod:`hysid_model.resolution`) are part of no test: an
extraction error is not the model's.

The diagnosis judges its final fit, which sits at that optimum already; a
fit or a campaign, whose optimum is that of the force samples, is polished
on the harmonics from its own before it is judged (:func:`model_adequacy`), so
that the same model on the same loops gets the same verdict whichever command
fitted it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.harmonics import HarmonicObjective, Harmonics
from hysid_model.loops import LoopSet
from hysid_model.model import Model
from island.polish import polish

ADEQUATE_ALPHA = 1e-3
"""Family-wise level at which the residual is declared not to be noise."""
SIGMA_SLACK = 0.1
"""With noise estimated from the data (not known), chi^2/dof up to 1 + this still counts as the noise floor."""
POLISH_NFEV_PER_PARAMETER = 40
"""Residual evaluations per free parameter of the polish on the harmonics before a fit is judged."""


@dataclass
class Adequacy:
    """The verdict: chi^2/dof of the whitened harmonic residual, its p-value, each coefficient group's, and
    whether the residual is noise."""

    chi2_per_dof: float
    p_global: float
    p_groups: dict[str, float]
    adequate: bool

    @property
    def worst(self) -> tuple[str, float]:
        """The coefficient group least like noise and its p-value."""
        name = min(self.p_groups, key=self.p_groups.__getitem__)
        return name, self.p_groups[name]

    def words(self) -> str:
        """The verdict in a sentence's worth of words."""
        if self.adequate:
            return f"the model leaves only noise (chi^2/dof {self.chi2_per_dof:.3g} on the loops' harmonics 0-7)"
        name, p = self.worst
        return (
            f"the model does not describe these loops: what it leaves is not noise (chi^2/dof {self.chi2_per_dof:.3g} on the "
            f"loops' harmonics 0-7, p = {self.p_global:.2g}; least like noise: {name}, p = {p:.2g})"
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "adequate": self.adequate,
            "chi2_per_dof": self.chi2_per_dof,
            "p_global": self.p_global,
            "p_groups": dict(self.p_groups),
            "rule": f"harmonics 0-7, whitened; global and per-group chi^2, family-wise level {ADEQUATE_ALPHA:g}",
        }


def groups(residual: np.ndarray, dof: int, harmonics: Harmonics) -> tuple[np.ndarray, np.ndarray]:
    """Per coefficient (over loops) the chi^2 of the whitened harmonic ``residual`` ``(L*M,)`` and its
    expectation under noise (``dof`` of the whole)."""
    e = residual.reshape(harmonics.loops.n_loops, -1)
    return np.sum(e**2, axis=0), np.full(e.shape[1], e.shape[0] * dof / residual.size)


def judge(residual: np.ndarray, dim: int, harmonics: Harmonics) -> Adequacy:
    """The rule of the module docstring on the whitened harmonic ``residual`` ``(L*M,)`` of a model with ``dim``
    free parameters at its optimum."""
    from scipy.stats import chi2 as chi2_dist  # on first use: a fast CLI and island start

    dof = max(residual.size - dim, 1)
    chi2 = float(residual @ residual)
    observed, expected = groups(residual, dof, harmonics)
    p_groups = chi2_dist.sf(observed, expected)
    p_global = float(chi2_dist.sf(chi2, dof))
    level = ADEQUATE_ALPHA / (observed.size + 1)
    ratio = chi2 / dof
    global_ok = p_global > level or (not np.all(harmonics.sigma_known) and ratio <= 1.0 + SIGMA_SLACK)
    return Adequacy(
        chi2_per_dof=float(ratio),
        p_global=p_global,
        p_groups=dict(zip(harmonics.names, map(float, p_groups))),
        adequate=bool(global_ok and np.all(p_groups > level)),
    )


def model_adequacy(loops: LoopSet, model: Model, theta: np.ndarray) -> Adequacy | None:
    """The verdict on ``model`` for ``loops`` (as the model sees them: the displacement reading applied), from
    ``theta`` polished on their harmonics; None where the loops hold too few samples per branch for harmonics
    up to order 7."""
    try:
        harmonics = Harmonics.from_loops(loops)
    except HysidInputError:
        return None
    objective = HarmonicObjective(harmonics, model)
    best = polish(objective, theta, max_nfev=POLISH_NFEV_PER_PARAMETER * model.dim).theta if model.dim else np.asarray(theta, dtype=float)
    return judge(objective.weighted_residuals(best), model.dim, harmonics)
