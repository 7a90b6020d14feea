"""Fitting a model to the harmonic coefficients: a linear start, data-scaled bounds, polish.

The diagnosis compares models by their chi^2 on the whitened harmonic
coefficients (:class:`hysid_model.harmonics.HarmonicObjective`); every model it
meets is smooth and low-dimensional, so a good start plus the bounded
least-squares polish of :mod:`island.polish` finds the optimum.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hysid_model.harmonics import HarmonicObjective, Harmonics
from hysid_model.model import Model
from hysid_model.problem import prepare_model
from hysid_model.uncertainty import jacobian_covariance
from island.polish import polish

MAX_NFEV = 100
"""Residual evaluations per polish."""


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

    def __post_init__(self) -> None:
        """Standard errors from the Fisher information J^T J of the whitened residuals (the
        Cramer-Rao bound), inflated by sqrt(chi^2 / dof) where the model misses the noise floor."""
        cov = jacobian_covariance(self.jacobian)
        self.stderr = np.sqrt(np.clip(np.diag(cov), 0.0, None)) * max(1.0, self.whitened_rms)

    @property
    def model(self) -> Model:
        return self.objective.model

    @property
    def spec(self) -> str:
        return "+".join((self.start,) + self.effects)

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

    def errors(self) -> dict[str, float]:
        return self.model.as_dict(self.stderr)


def oscillator_estimate(harmonics: Harmonics, meq_kg: float | None) -> dict[str, float]:
    """xi, wn (and m) of Eq. 4.6 from the first harmonics by weighted linear least squares.

    s1 / X0 = k - m w^2 and c1 / X0 = c w for every loop (Eq. 4.6 with k = m wn^2,
    c = 2 m xi wn); with a known mass only k and c are regressed.
    """
    names = harmonics.names
    x0, w = harmonics.loops.x0, harmonics.loops.omega
    s1, c1 = harmonics.coef[:, names.index("s1")], harmonics.coef[:, names.index("c1")]
    err = harmonics.stderr
    ws = (x0 / err[:, names.index("s1")]) ** 2
    wc = (x0 * w / err[:, names.index("c1")]) ** 2
    c = float(np.sum(wc * c1 / (x0 * w)) / np.sum(wc))
    if meq_kg is None:
        design = np.column_stack([np.ones_like(w), -(w**2)]) * np.sqrt(ws)[:, None]
        k, m = np.linalg.lstsq(design, s1 / x0 * np.sqrt(ws), rcond=None)[0]
        m = float(m) if m > 0 else float(np.sum(ws * np.abs(s1) / x0) / np.sum(ws) / np.max(w) ** 2)
    else:
        m = float(meq_kg)
        k = float(np.sum(ws * (s1 / x0 + m * w**2)) / np.sum(ws))
    k = max(float(k), 1e-6 * m * float(np.max(w)) ** 2)
    wn = float(np.sqrt(k / m))
    out = {"xi0": max(c / (2.0 * m * wn), 0.0), "w0": wn}
    if meq_kg is None:
        out["meq"] = m
    return out


def scaled_bounds(model: Model, harmonics: Harmonics, estimate: dict[str, float]) -> dict[str, tuple[float, float]]:
    """Widen the oscillator's bounds (and the thesis slopes') so they hold the data's scale.

    A data set's own bounds (``meta['bounds']``, e.g. Table 5.4 for Synth) are
    kept as they are; otherwise each default range is stretched to hold a
    decade either side of the linear estimate.
    """
    given = harmonics.loops.meta.get("bounds") or {}
    x_max = float(np.max(harmonics.loops.x0))
    wanted = {
        "xi0": (0.0, 10.0 * estimate["xi0"]),
        "w0": (estimate["w0"] / 10.0, estimate["w0"] * 10.0),
        "S_xi": (-10.0 * estimate["xi0"] / x_max, 10.0 * estimate["xi0"] / x_max),
        "S_w": (-0.9 * estimate["w0"] / x_max, 0.9 * estimate["w0"] / x_max),
    }
    if "meq" in estimate:
        wanted["meq"] = (estimate["meq"] / 100.0, estimate["meq"] * 100.0)
    out: dict[str, tuple[float, float]] = {}
    for p in model.parameters:
        if p.name in given:
            out[p.name] = tuple(float(b) for b in given[p.name])
        elif p.name in wanted:
            lo, hi = wanted[p.name]
            out[p.name] = (min(p.lower, lo), max(p.upper, hi))
    return out


def make_model(harmonics: Harmonics, start: str, effects: tuple[str, ...], bounds: dict[str, tuple[float, float]]) -> Model:
    """The start model plus ``effects``, ready for the loops (known mass fixed), within ``bounds``."""
    model = prepare_model(harmonics.loops, "+".join((start,) + effects))
    return model.with_bounds({k: v for k, v in bounds.items() if k in model.names})


def fit_objective(objective: HarmonicObjective, start: str, effects: tuple[str, ...], starts: list[np.ndarray]) -> Fit:
    """Polish every start and keep the best (lowest chi^2)."""
    results = [polish(objective, s, max_nfev=MAX_NFEV) for s in starts]
    best = min(results, key=lambda r: r.fitness)
    return Fit(effects, start, objective, best.theta, objective.weighted_residuals(best.theta), objective.jacobian(best.theta))


def initial_fit(harmonics: Harmonics, start: str) -> tuple[Fit, dict[str, tuple[float, float]]]:
    """Fit the preset ``start`` (baseline or thesis) from the linear estimate; return it and the bounds in force."""
    probe = prepare_model(harmonics.loops, start)
    estimate = oscillator_estimate(harmonics, probe.fixed.get("meq"))
    bounds = scaled_bounds(probe, harmonics, estimate)
    model = make_model(harmonics, start, (), bounds)
    values = {**{n: 0.0 for n in model.names}, **estimate}
    theta0 = np.clip(model.from_dict(values), model.bounds[:, 0], model.bounds[:, 1])
    return fit_objective(HarmonicObjective(harmonics, model), start, (), [theta0]), bounds
