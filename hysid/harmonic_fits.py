"""Fitting a model to the harmonic coefficients: the survey's linear start, data-derived bounds, polish.

The diagnosis (:mod:`hysid.diagnosis`) compares models by their chi^2 on the
whitened harmonic coefficients (:class:`hysid_model.harmonics.HarmonicObjective`),
and the choice of the displacement reading (:mod:`hysid.motion`) the readings
by theirs; every model they meet is smooth and low-dimensional, so a good start
plus the bounded least-squares polish of :mod:`island.polish` finds the
optimum. Both build on these fits, so they live below both.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from hysid.identifiability import PROFILED, Identifiability, assess, profile
from hysid_model.harmonics import HarmonicObjective, Harmonics
from hysid_model.model import MAX_WIDENINGS, Model, spec_of
from hysid_model.problem import prepare_model, starting_point
from hysid_model.terms import Oscillator
from hysid_model.uncertainty import jacobian_covariance
from island.polish import polish

NFEV_PER_PARAMETER = 40
"""Residual evaluations per polish and free parameter (a memory model's polish must not run out of them)."""


@dataclass
class Fit:
    """A model fitted to the harmonics, with its whitened residual and Jacobian at the optimum."""

    effects: tuple[str, ...]
    start: str
    objective: HarmonicObjective
    theta: np.ndarray
    residual: np.ndarray
    jacobian: np.ndarray
    stderr: np.ndarray = field(init=False)
    held_out: dict[str, float | None] = field(default_factory=dict, init=False, repr=False)
    """The leave-one-frequency-out whitened RMS once computed (:func:`hysid.diagnosis.metrics.cross_validated_rms`)."""
    profiled: dict[str, float] = field(default_factory=dict, init=False)
    """Standard errors from the chi^2 profile, where the curvature at the optimum cannot be trusted (:func:`profile_errors`)."""

    def __post_init__(self) -> None:
        """Standard errors from the Fisher information J^T J of the whitened residuals (the
        Cramer-Rao bound), inflated by sqrt(chi^2 / dof) where the model misses the noise floor."""
        cov = jacobian_covariance(self.jacobian)
        self.stderr = np.sqrt(np.clip(np.diag(cov), 0.0, None)) * max(1.0, self.whitened_rms)

    @property
    def model(self) -> Model:
        return self.objective.model

    @property
    def freed(self) -> list[str]:
        """Parameters the effects fix by default that this fit searches (Bouc-Wen's exponent ``bw_n``)."""
        return [p.name for t in self.model.terms for p in t.params if not p.vary and p.name in self.model.names]

    @property
    def spec(self) -> str:
        """The model string: the start preset plus the effects (:func:`hysid_model.model.spec_of` where a
        parameter fixed by default is searched: ``mr_damper``, Bouc-Wen with its exponent free)."""
        return spec_of(self.model.terms, self.model.names) if self.freed else "+".join((self.start,) + self.effects)

    @property
    def chi2(self) -> float:
        return float(self.residual @ self.residual)

    @property
    def n(self) -> int:
        return int(self.residual.size)

    @property
    def dof(self) -> int:
        return self.n - self.model.dim

    @property
    def bic(self) -> float:
        """Bayesian information criterion on the harmonic coefficients (sigma known): chi^2 + D ln N."""
        return self.chi2 + self.model.dim * np.log(self.n)

    @property
    def whitened_rms(self) -> float:
        """sqrt(chi^2 / dof): 1 is the noise floor."""
        return float(np.sqrt(self.chi2 / max(self.dof, 1)))

    def params(self) -> dict[str, float]:
        return self.model.as_dict(self.theta)

    def __repr__(self) -> str:
        return f"<Fit {self.spec}: whitened RMS {self.whitened_rms:.4g}, BIC {self.bic:.6g}, {self.model.dim} parameters>"

    def errors(self) -> dict[str, float]:
        return {**self.model.as_dict(self.stderr), **self.profiled}


def soft_bounds(model: Model) -> dict[str, tuple[float, float]]:
    """The data-derived (soft) bounds in force in ``model``, as they stand after any widening."""
    return {p.name: (p.lower, p.upper) for p in model.parameters if p.soft}


def make_model(harmonics: Harmonics, start: str, effects: tuple[str, ...], bounds: dict[str, tuple[float, float]], free: Sequence[str] = ()) -> Model:
    """The start model plus ``effects``, ready for the loops (known mass fixed, bounds by the one rule of
    :func:`hysid_model.problem.prepare_model`), with the parameters ``free`` searched that the effects fix by
    default (a Bouc-Wen exponent freed earlier) and the soft ``bounds`` widened so far."""
    model = prepare_model(harmonics.loops, "+".join((start,) + effects))
    model = model.vary(*(n for n in free if n in model.fixed))
    soft = soft_bounds(model) | {n: None for n in free}
    return model.with_bounds({k: v for k, v in bounds.items() if k in soft and k in model.names}, soft=True)


def fit_objective(objective: HarmonicObjective, start: str, effects: tuple[str, ...], starts: list[np.ndarray]) -> Fit:
    """Polish every start and keep the best (lowest chi^2); where it ends on a soft bound (from the data, or a term's
    default the physics does not set), widen that bound within the physical range and polish again (up to
    ``MAX_WIDENINGS`` times): such a bound decides nothing. An effect's shape parameter that runs to the end of
    every widening has no optimum the data resolve: the effect degenerates into another there (a Bouc-Wen
    spring of unbounded shape r is a friction jump), so the fit within its first bounds is kept and the
    acceptance rules judge it pressing on them (:func:`hysid.diagnosis.acceptance.degenerate`)."""
    nfev = NFEV_PER_PARAMETER * objective.dim
    results = [polish(objective, s, max_nfev=nfev) for s in starts]
    best = first = min(results, key=lambda r: r.fitness)
    within, widened = objective, set()
    for _ in range(MAX_WIDENINGS):
        wider, changed = objective.model.widen_at(best.theta)
        if not changed:
            break
        widened |= set(changed)
        objective = HarmonicObjective(objective.harmonics, wider)
        best = polish(objective, best.theta, max_nfev=nfev)
    if widened & set(objective.model.at_bounds(best.theta)) & shape_parameters(objective.model):
        objective, best = within, first
    return Fit(effects, start, objective, best.theta, objective.weighted_residuals(best.theta), objective.jacobian(best.theta))


def shape_parameters(model: Model) -> set[str]:
    """The effects' parameters other than their strengths (a yield displacement, a shape, an exponent)."""
    return {p.name for t in model.terms if not isinstance(t, Oscillator) for p in t.params if p.name != t.strength}


def initial_fit(harmonics: Harmonics, start: str) -> Fit:
    """Fit the preset ``start`` (baseline or thesis) from the survey's linear estimate."""
    model = prepare_model(harmonics.loops, start)
    return fit_objective(HarmonicObjective(harmonics, model), start, (), [starting_point(harmonics.loops, model)])


def profile_errors(fit: Fit) -> Fit:
    """``fit`` with the standard error of each of its non-smooth parameters (:data:`hysid.identifiability.PROFILED`,
    a delay) from the profile of its chi^2 (:func:`hysid.identifiability.profile`, the rule of the final model's
    errors too): the half-width where it rises by one unit (chi^2 / dof where the model misses the noise floor)."""
    unit = max(1.0, fit.whitened_rms**2)
    cov = unit * jacobian_covariance(fit.jacobian)
    for name in PROFILED:
        if name not in fit.model.names:
            continue
        i = fit.model.names.index(name)
        lower, upper = fit.model.bounds[i]
        se = float(fit.stderr[i])
        step = se if np.isfinite(se) and se > 0 else 1e-3 * (upper - lower)
        found = profile(fit.objective, fit.theta, i, cov, lambda m: HarmonicObjective(fit.objective.harmonics, m), unit, step)
        if found.width > 0:
            fit.profiled[name] = float(found.width)
    return fit


def final_identifiability(fit: Fit, harmonics: Harmonics) -> Identifiability:
    """The final fit's standard errors and what the harmonics cannot determine, by the rule of :mod:`hysid.identifiability`
    (as ``fit``'s): the full covariance scaled up by chi^2 / dof where the model misses the noise floor, the profile where
    the curvature cannot be trusted."""
    unit = max(1.0, fit.whitened_rms**2)
    return assess(fit.objective, fit.theta, unit * jacobian_covariance(fit.jacobian), lambda model: HarmonicObjective(harmonics, model), unit)
