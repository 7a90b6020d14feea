"""What the data can and cannot determine: parameters that are not identifiable, and the correlations of the rest.

With loops at a single amplitude, xi(X0) = xi0 + S_xi X0 (Eq. 4.8) pins only
the sum: xi0 and S_xi trade off exactly, and a fit that reports both with tiny
standard errors (a pseudo-inverse of a singular Fisher matrix) misleads. So:

1. rank and conditioning: the Fisher information of the weighted residuals,
   with its columns scaled to unit length, J^T J; its eigenvalues below
   ``RANK_TOL`` of the largest are directions the data do not see;
2. naming: a parameter in such a direction is named, preferring an effect's
   parameters (the amplitude slopes S_xi, S_w included) over the equivalent
   mass, and the mass over the oscillator's xi0 and w0, until the rest is well
   conditioned: the ones left are what the data determine (xi0, w0 at the
   measured amplitude, say);
3. a profile confirms each: with the parameter moved across a good part of its
   range and every other parameter refitted (:mod:`island.polish`), the
   objective must stay within one chi^2 unit (the noise) of the optimum. A
   parameter whose profile rises is identifiable after all (the singularity
   was local) and is not named.

4. correlation: a parameter whose correlation with another exceeds
   ``CORRELATION_LIMIT`` in magnitude (the covariance's condition at unit
   diagonal beyond 1 / (1 - 0.999)) is named too, by the same priority: its
   standard error would be the other's in disguise (an MR damper's xi0, w0 and
   meq at 0.9997 say only what its stiffness and damping are).

Standard errors and the correlation matrix come from the covariance with the
named parameters held at their values; the named ones get none. Loops at a
single amplitude level never search S_xi, S_w (they are fixed at 0 before the
fit, :func:`one_amplitude` says why).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from hysid_model.frf import amplitude_levels
from hysid_model.loops import LoopSet
from hysid_model.model import Model
from island.polish import polish

RANK_TOL = 1e-9
"""Eigenvalue of the column-scaled Fisher matrix, relative to its largest, below which a direction is unseen."""
PARTICIPATION = 0.1
"""A parameter takes part in an unseen direction when its component there exceeds this."""
PROFILE_POINTS = (-0.5, 0.5)
"""Profile points, as fractions of the parameter's distance to the far ends of its bounds (or of its value)."""
PROFILE_NFEV = 60
FLAT = 1.0
"""Largest rise of the profile's chi^2 (noise units) for the parameter to count as undetermined."""
CORRELATION_LIMIT = 0.999
"""|correlation| beyond which one of the two parameters is named as not identifiable (step 4 of the module docstring)."""


@dataclass
class Identifiability:
    """Which parameters the data determine, why not the others, and the covariance of the rest."""

    names: list[str]
    not_identifiable: dict[str, str]
    """Parameter -> why it is not identifiable."""
    covariance: np.ndarray
    """``(D, D)``, NaN in the rows and columns of the parameters that are not identifiable."""

    @property
    def stderr(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def correlation(self) -> np.ndarray:
        se = np.sqrt(np.diag(self.covariance))
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.covariance / np.outer(se, se)

    def correlation_dict(self) -> dict[str, dict[str, float | None]]:
        """The correlation matrix as ``{a: {b: r}}`` (None where a parameter is not identifiable)."""
        r = self.correlation
        return {a: {b: (float(r[i, j]) if np.isfinite(r[i, j]) else None) for j, b in enumerate(self.names)} for i, a in enumerate(self.names)}

    def to_dict(self) -> dict[str, Any]:
        return {"not_identifiable": list(self.not_identifiable), "not_identifiable_reasons": dict(self.not_identifiable),
                "correlation": self.correlation_dict()}


def one_amplitude(loops: LoopSet, model: Model) -> dict[str, str]:
    """The amplitude slopes (S_xi, S_w: terms with a ``slope_of``) that loops at a single amplitude level left
    fixed at 0 (:func:`hysid_model.problem.prepare_model`), each with why."""
    levels = amplitude_levels(loops.x0)[0]
    if levels.size > 1:
        return {}
    return {
        p.name: f"cannot be told from {t.slope_of} with one amplitude level (X0 = {levels[0] * 1e3:.4g} mm): fixed at 0, "
                f"so {t.slope_of} is the value at that amplitude"
        for t in model.terms if t.slope_of for p in t.params if model.fixed.get(p.name) == 0.0
    }


def naming_priority(model: Model) -> list[str]:
    """Parameters in the order they are named when the data cannot tell them apart: effects' (last added
    first), then the equivalent mass, then the oscillator's w0 and xi0."""
    base = ["xi0", "w0", "meq"]
    rest = [n for n in model.names if n not in base]
    return rest[::-1] + [n for n in ("meq", "w0", "xi0") if n in model.names]


def unseen(jac: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit-scaled eigenvectors ``(D, k)`` of the directions the Jacobian's columns do not span, and the scaled matrix's eigenvalues."""
    scale = np.linalg.norm(jac, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    unit = jac / scale
    values, vectors = np.linalg.eigh(unit.T @ unit)
    small = values < RANK_TOL * max(values.max(), 1e-300)
    return vectors[:, small], values


def suspects(jac: np.ndarray, names: list[str], priority: list[str]) -> dict[str, list[str]]:
    """Parameters to name (greedily, by ``priority``) until the rest is well conditioned, each with the
    parameters it trades off with."""
    keep = list(range(len(names)))
    out: dict[str, list[str]] = {}
    for name in priority:
        directions, _ = unseen(jac[:, keep])
        if directions.shape[1] == 0:
            break
        i = keep.index(names.index(name))
        if np.abs(directions[i]).max() > PARTICIPATION:
            keep.remove(names.index(name))
            out[name] = partners(jac, names.index(name), keep, names)
    return out


def partners(jac: np.ndarray, i: int, others: list[int], names: list[str]) -> list[str]:
    """The parameters whose columns reproduce column ``i`` of the Jacobian (least squares): what it trades off with."""
    scale = np.linalg.norm(jac, axis=0)
    unit = jac / np.where(scale > 0, scale, 1.0)
    coef = np.linalg.lstsq(unit[:, others], unit[:, i], rcond=None)[0]
    big = np.abs(coef) >= PARTICIPATION * np.abs(coef).max() if coef.size else np.zeros(0, dtype=bool)
    return [names[others[j]] for j in np.argsort(-np.abs(coef)) if big[j]]


Rebuild = Callable[[Model], Any]
"""The same objective with another model (a parameter fixed): ``Objective`` or ``HarmonicObjective``."""


def profile_rise(objective: Any, theta: np.ndarray, name: str, noise: float, rebuild: Rebuild) -> float:
    """Smallest rise of the objective (chi^2 units: / ``noise``) when ``name`` is moved to the profile points and the rest refitted."""
    model = objective.model
    i = model.names.index(name)
    lo, hi = model.bounds[i]
    value = float(theta[i])
    rises = []
    for step in PROFILE_POINTS:
        target = value + step * ((hi - value) if step > 0 else (value - lo))
        if not lo <= target <= hi or target == value:
            continue
        fixed = rebuild(model.fix({name: target}))
        start = np.delete(theta, i)
        best = polish(fixed, start, max_nfev=PROFILE_NFEV)
        rises.append((best.fitness - float(objective(theta[None, :])[0])) / noise)
    return min(rises) if rises else np.inf


def assess(objective: Any, theta: np.ndarray, covariance_of: Callable[[Any, np.ndarray], np.ndarray], rebuild: Rebuild, noise: float) -> Identifiability:
    """Identifiability of ``objective``'s parameters at its optimum ``theta``. ``covariance_of(objective, theta)``
    gives the covariance of an identifiable set (as the fit computes it), ``rebuild(model)`` the objective with
    another model, and ``noise`` the objective's value of one unit of chi^2 (1 for ML weights and whitened fits)."""
    model = objective.model
    names = model.names
    jac = objective.jacobian(theta)
    found = suspects(jac, names, naming_priority(model))
    named = {}
    for name, partners in found.items():
        if profile_rise(objective, theta, name, noise, rebuild) < FLAT:
            with_what = f" with {', '.join(partners)}" if partners else ""
            named[name] = f"trades off{with_what}: the data determine only their combination (flat profile)"
    while True:
        cov = np.full((len(names), len(names)), np.nan)
        keep = [i for i, n in enumerate(names) if n not in named]
        if keep:
            reduced = rebuild(model.fix({n: float(theta[names.index(n)]) for n in named})) if named else objective
            cov[np.ix_(keep, keep)] = covariance_of(reduced, theta[keep])
        found = correlated(cov, names, naming_priority(model))
        if found is None:
            return Identifiability(names=names, not_identifiable=named, covariance=cov)
        name, others, r = found
        named[name] = f"is correlated with {', '.join(others)} (|r| up to {r:.4f}): the data determine only their combination"


def correlated(cov: np.ndarray, names: list[str], priority: list[str]) -> tuple[str, list[str], float] | None:
    """The first parameter by ``priority`` whose correlation with another exceeds ``CORRELATION_LIMIT``, the
    parameters it is so correlated with, and the largest |r|; None if no pair does."""
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.abs(cov / np.outer(se, se))
    np.fill_diagonal(r, 0.0)
    r = np.where(np.isfinite(r), r, 0.0)
    for name in priority:
        i = names.index(name)
        partners = [names[j] for j in np.argsort(-r[i]) if r[i, j] > CORRELATION_LIMIT]
        if partners:
            return name, partners, float(r[i].max())
    return None
