"""Standard errors that cover the truth: the full covariance, the profile where it cannot be trusted, and what the data cannot determine.

One rule for ``fit``, campaigns (both :class:`hysid.fit_result.FitResult`) and a
diagnosis' final model (:func:`hysid.diagnosis.selection.diagnose`):

1. every standard error comes from the covariance of *all* the free
   parameters (its inverse taken at unit diagonal, :func:`hysid_model.uncertainty.scaled_inverse`),
   never from one conditional on a parameter held at its estimate: an
   equivalent mass that trades off with w0 (loops in one band, far below a
   resonance) makes w0's error large, and that is the honest answer;
2. the profile of the objective (the parameter moved, every other refitted
   from the covariance's ridge, :mod:`island.polish`) replaces the curvature
   where the problem may not be locally quadratic: a parameter in a direction
   the Jacobian does not see (eigenvalue of the column-scaled Fisher matrix
   below ``RANK_TOL`` of the largest), one correlated beyond
   ``CORRELATION_LIMIT`` with another, and the non-smooth ones of
   :data:`PROFILED` (a delay). Its error is the half-width where the profile
   rises by one unit of chi^2 (the wider side; never below the curvature's,
   except for the non-smooth ones, whose curvature means nothing);
3. a parameter is *not identifiable* only when its profile stays within that
   unit over its range, both ways (over at least half the way to each bound:
   where a bound of another parameter stops the trade-off near its end, the
   data still say nothing of the parameter; one amplitude level and a bounded
   S_w, one frequency and a fitted mass): it gets no error, and a quantity
   derived from the parameters gets none where it depends on such a direction
   (:meth:`Identifiability.propagate`; the damping coefficient c at one
   frequency does not).

Loops at a single amplitude level never search S_xi, S_w (they are fixed at 0
before the fit, :func:`one_amplitude` says why).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hysid_model.frf import amplitude_levels
from hysid_model.loops import LoopSet
from hysid_model.model import Model
from island.polish import polish

RANK_TOL = 1e-9
"""Eigenvalue of the column-scaled Fisher matrix, relative to its largest, below which a direction is unseen."""
PARTICIPATION = 0.1
"""A parameter takes part in an unseen direction when its component there exceeds this."""
CORRELATION_LIMIT = 0.999
"""|correlation| beyond which a parameter's error is checked against its profile (step 2 of the module docstring)."""
PROFILED = ("delay_s",)
"""Parameters whose chi^2 is not smooth: a delay moves a friction jump across the samples, so the curvature at
the optimum says little about the spread and the profile gives their error."""
FLAT_SHARE = 0.5
"""A side of a profile is flat when it stays within one unit over at least this share of the way to its bound."""
GROWTH = 4.0
"""Factor by which a profile's step grows until the rise reaches one unit."""
MAX_STEPS = 7
"""Steps of a profile on one side until its rise brackets one unit; the last growing one goes to the bound."""
BISECTIONS = 6
"""Probes of a bracket at most: the quadratic's crossing, then geometric halvings (to a ratio of 1.02 between its ends)."""
PROFILE_NFEV = 40
"""Residual evaluations per free parameter of each profile point's polish (it starts on the covariance's ridge)."""
ESTIMABLE = 1e-3
"""A derived quantity depends on a direction the data do not determine when its scaled gradient's component
there exceeds this fraction of its length."""


@dataclass
class Identifiability:
    """Which parameters the data determine, why not the others, and the covariance of them all."""

    names: list[str]
    not_identifiable: dict[str, str]
    """Parameter -> why it is not identifiable."""
    full: np.ndarray
    """``(D, D)`` covariance of every free parameter (profile half-widths on its diagonal where they replace the curvature)."""
    profiled: dict[str, float] = field(default_factory=dict)
    """Parameters whose standard error is the profile's half-width, and that half-width."""
    flat: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    """``(D, k)``: directions (column-scaled parameter space) along which the profile is flat, with ``scale``."""
    scale: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """Column norms of the Jacobian: parameter -> scaled coordinates (``theta * scale``)."""
    unprofiled: list[str] = field(default_factory=list)
    """Parameters whose profile was due but left out (``assess(..., profiles=False)``): their error is the curvature's."""

    @property
    def covariance(self) -> np.ndarray:
        """``(D, D)``: :attr:`full` with NaN in the rows and columns of the parameters that are not identifiable."""
        out = np.array(self.full, dtype=float)
        for name in self.not_identifiable:
            if name in self.names:
                i = self.names.index(name)
                out[i, :] = out[:, i] = np.nan
        return out

    def __repr__(self) -> str:
        missing = f"not identifiable: {', '.join(self.not_identifiable)}" if self.not_identifiable else "every one determined by the data"
        return f"<Identifiability of {', '.join(self.names)}: {missing}>"

    @property
    def stderr(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def correlation(self) -> np.ndarray:
        cov = self.covariance
        se = np.sqrt(np.diag(cov))
        with np.errstate(invalid="ignore", divide="ignore"):
            return cov / np.outer(se, se)

    def propagate(self, grads: np.ndarray) -> np.ndarray:
        """Standard errors of quantities with gradients ``grads`` ``(Q, D)`` (delta method through :attr:`full`);
        NaN for a quantity that depends on a direction the data do not determine."""
        grads = np.atleast_2d(np.asarray(grads, dtype=float))
        se = np.sqrt(np.clip(np.einsum("qd,de,qe->q", grads, self.full, grads), 0.0, None))
        if self.flat.size:
            scaled = grads / np.where(self.scale > 0, self.scale, 1.0)
            along = np.abs(scaled @ self.flat).max(axis=1)
            se = np.where(along > ESTIMABLE * np.linalg.norm(scaled, axis=1), np.nan, se)
        return se

    def correlation_dict(self) -> dict[str, dict[str, float | None]]:
        """The correlation matrix as ``{a: {b: r}}`` (None where a parameter is not identifiable)."""
        r = self.correlation
        return {a: {b: (float(r[i, j]) if np.isfinite(r[i, j]) else None) for j, b in enumerate(self.names)} for i, a in enumerate(self.names)}

    def to_dict(self) -> dict[str, Any]:
        return {
            "not_identifiable": list(self.not_identifiable),
            "not_identifiable_reasons": dict(self.not_identifiable),
            "profiled": dict(self.profiled),
            "correlation": self.correlation_dict(),
        }


def one_amplitude(loops: LoopSet, model: Model) -> dict[str, str]:
    """The amplitude slopes (S_xi, S_w: terms with a ``slope_of``) that loops at a single amplitude level left
    fixed at 0 (:func:`hysid_model.problem.prepare_model`), each with why."""
    levels = amplitude_levels(loops.x0)[0]
    if levels.size > 1:
        return {}
    return {
        p.name: f"cannot be told from {t.slope_of} with one amplitude level (X0 = {levels[0] * 1e3:.4g} mm): fixed at 0, "
        f"so {t.slope_of} is the value at that amplitude"
        for t in model.terms
        if t.slope_of
        for p in t.params
        if model.fixed.get(p.name) == 0.0
    }


def unseen(jac: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Directions ``(D, k)`` of the column-scaled parameter space the Jacobian's columns do not span, and the
    column norms (the scale)."""
    scale = np.linalg.norm(jac, axis=0)
    scale = np.where(np.isfinite(scale) & (scale > 0), scale, 1.0)
    unit = jac / scale
    values, vectors = np.linalg.eigh(unit.T @ unit)
    small = values < RANK_TOL * max(values.max(), 1e-300)
    return vectors[:, small], scale


def partners(jac: np.ndarray, i: int, names: list[str]) -> list[str]:
    """The parameters whose columns reproduce column ``i`` of the Jacobian (least squares): what it trades off with."""
    others = [j for j in range(len(names)) if j != i]
    scale = np.linalg.norm(jac, axis=0)
    unit = jac / np.where(scale > 0, scale, 1.0)
    coef = np.linalg.lstsq(unit[:, others], unit[:, i], rcond=None)[0]
    big = np.abs(coef) >= PARTICIPATION * np.abs(coef).max() if coef.size else np.zeros(0, dtype=bool)
    return [names[others[j]] for j in np.argsort(-np.abs(coef)) if big[j]]


Rebuild = Callable[[Model], Any]
"""The same objective with another model (a parameter fixed): ``Objective`` or ``HarmonicObjective``."""


@dataclass
class Profile:
    """One parameter's profile: the half-width where it rises by one unit, and whether it stayed flat to both bounds."""

    width: float
    flat: bool


def profile(objective: Any, theta: np.ndarray, i: int, cov: np.ndarray, rebuild: Rebuild, unit: float, step: float) -> Profile:
    """The profile of parameter ``i`` of ``objective`` about its optimum ``theta``: moved either way, every
    other parameter refitted from the covariance ``cov``'s ridge, to where the objective rises by ``unit`` (one
    unit of chi^2). From ``step``, steps grow (by ``GROWTH``, the last to the bound) until the rise reaches a
    unit, or shrink until it does not; the bracket is then probed where a quadratic rise would cross the unit,
    and where it does not, halved geometrically (a profile may be flat and then rise like a wall, where a
    quadratic puts the crossing far too close), the crossing interpolated with the rise taken as quadratic
    between its ends. The wider side's half-width counts; a side that reaches its
    bound without rising a unit counts its distance to the bound. The profile is flat when it stays within the
    unit over ``FLAT_SHARE`` of the way to the bound on both sides (on the only side, at a bound)."""
    model = objective.model
    name = model.names[i]
    lower, upper = model.bounds[i]
    value = float(theta[i])
    f0 = float(objective(theta[None, :])[0])
    ridge = cov[:, i] / cov[i, i] if np.all(np.isfinite(cov[:, i])) and cov[i, i] > 0 else np.zeros(theta.size)
    nfev = PROFILE_NFEV * max(theta.size - 1, 1)

    def rise(target: float) -> float:
        reduced = rebuild(model.fix({name: target}))
        start = np.delete(theta + ridge * (target - value), i)
        return max((polish(reduced, start, max_nfev=nfev).fitness - f0) / unit, 0.0)

    widths, flat = [], []
    for side, room in ((-1.0, value - lower), (1.0, upper - value)):
        if not room > 0.0:
            continue
        found = side_width(lambda d: rise(value + side * d), min(step, room), room)  # noqa: B023 (called within this iteration)
        widths.append(room if found is None else found)
        flat.append(widths[-1] >= FLAT_SHARE * room)
    return Profile(width=max(widths) if widths else 0.0, flat=bool(flat) and all(flat))


def side_width(rise: Callable[[float], float], step: float, room: float) -> float | None:
    """Where ``rise(d)`` (d > 0 the distance from the optimum, up to ``room``) reaches one unit; None where it
    stays below it up to ``room`` (see :func:`profile`)."""
    near, r_near, far, r_far = 0.0, 0.0, step, rise(step)
    probes = 1
    while r_far < 1.0:  # grow
        if far >= room:
            return None
        near, r_near = far, r_far
        far = room if probes == MAX_STEPS - 1 else min(far * GROWTH, room)
        r_far, probes = rise(far), probes + 1
    while near == 0.0 and probes < MAX_STEPS:  # shrink: a point below one unit
        d = far / GROWTH
        r = rise(d)
        probes += 1
        if r >= 1.0:
            far, r_far = d, r
        else:
            near, r_near = d, r
    for k in range(BISECTIONS):  # first at the quadratic's crossing (where a quadratic profile ends), then halving
        if near == 0.0 or far / near < 1.02:
            break
        probe = crossing(near, r_near, far, r_far) if k == 0 else float(np.sqrt(near * far))
        r = rise(probe)
        if k == 0 and abs(np.sqrt(r) - 1.0) < 0.05:
            return probe
        if r >= 1.0:
            far, r_far = probe, r
        else:
            near, r_near = probe, r
    return crossing(near, r_near, far, r_far)


def crossing(near: float, r_near: float, far: float, r_far: float) -> float:
    """Where a rise that is quadratic in the step (its square root linear) reaches one unit between two points."""
    return near + (far - near) * (1.0 - np.sqrt(r_near)) / (np.sqrt(r_far) - np.sqrt(r_near))


def assess(objective: Any, theta: np.ndarray, cov: np.ndarray, rebuild: Rebuild, unit: float, *, profiles: bool = True) -> Identifiability:
    """Standard errors and identifiability of ``objective``'s parameters at its optimum ``theta`` (the module
    docstring's rule). ``cov`` is the covariance of all the free parameters as the caller computes it (Cramer-Rao,
    sandwich, or on the harmonics; scaled up where the model misses the noise floor), ``rebuild(model)`` the
    objective with another model, ``unit`` the objective's rise of one standard error (one unit of chi^2, times
    the same scaling). Without ``profiles`` (a result wanted in seconds: a campaign stopped by Ctrl-C) the
    parameters whose profile is due keep the curvature's error and are named in ``unprofiled``."""
    names = objective.model.names
    theta = np.asarray(theta, dtype=float).reshape(-1)
    jac = objective.jacobian(theta)
    directions, scale = unseen(np.where(np.isfinite(jac), jac, 0.0))
    cov = np.array(cov, dtype=float)
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    in_unseen = np.abs(directions).max(axis=1) > PARTICIPATION if directions.size else np.zeros(len(names), dtype=bool)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.abs(cov / np.outer(se, se))
    np.fill_diagonal(r, 0.0)
    correlated = np.where(np.isfinite(r), r, 0.0).max(axis=1, initial=0.0) > CORRELATION_LIMIT
    bounds = objective.model.bounds
    widths: dict[str, float] = {}
    named: dict[str, str] = {}
    unprofiled: list[str] = []
    for i, name in enumerate(names):
        if not (in_unseen[i] or correlated[i] or name in PROFILED):
            continue
        if not profiles:
            unprofiled.append(name)
            continue
        room = max(theta[i] - bounds[i, 0], bounds[i, 1] - theta[i])
        step = 0.5 * room if in_unseen[i] or not (np.isfinite(se[i]) and se[i] > 0) else float(se[i])
        found = profile(objective, theta, i, cov, rebuild, unit, step)
        if found.flat:
            with_what = partners(jac, i, names)
            named[name] = (
                f"trades off with {', '.join(with_what)}: " if with_what else ""
            ) + "its profile is flat over its range (the data determine only a combination)"
        else:
            curvature = float(se[i]) if np.isfinite(se[i]) and not in_unseen[i] and name not in PROFILED else 0.0
            widths[name] = max(found.width, curvature)
    full = corrected(cov, directions, scale, {names.index(n): w for n, w in widths.items()})
    flat_dirs = (
        directions[:, [k for k in range(directions.shape[1]) if any(abs(directions[names.index(n), k]) > PARTICIPATION for n in named)]]
        if named
        else np.zeros((len(names), 0))
    )
    return Identifiability(names=names, not_identifiable=named, full=full, profiled=widths, flat=flat_dirs, scale=scale, unprofiled=unprofiled)


def corrected(cov: np.ndarray, directions: np.ndarray, scale: np.ndarray, widths: dict[int, float]) -> np.ndarray:
    """``cov`` with the profile half-widths ``widths`` (parameter index -> width) on its diagonal: along each
    unseen direction (in parameter units) the variance the inverse dropped added back, as much as its widest
    participant needs (so that what the data do determine, a combination across that direction, keeps its
    error); every other parameter's row and column scaled to its half-width (its correlations kept)."""
    out = np.where(np.isfinite(cov), cov, 0.0)
    unseen_part = np.abs(directions).max(axis=1) > PARTICIPATION if directions.size else np.zeros(len(out), dtype=bool)
    for k in range(directions.shape[1]):
        u = directions[:, k] / scale
        need = [(w**2 - out[i, i]) / u[i] ** 2 for i, w in widths.items() if abs(directions[i, k]) > PARTICIPATION]
        if need and max(need) > 0:
            out = out + max(need) * np.outer(u, u)
    factor = np.ones(len(out))
    for i, w in widths.items():
        if not unseen_part[i] and out[i, i] > 0:
            factor[i] = w / np.sqrt(out[i, i])
    return out * np.outer(factor, factor)
