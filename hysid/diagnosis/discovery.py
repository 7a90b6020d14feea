"""Discovery: where no library effect brings the residual to the noise, propose the missing force from the data.

From a fitted model (the start model, and the best library model where the diagnosis named effects), every
family of the candidate library (:mod:`hysid_model.discovery.features`) is evaluated on the loops' motion at
every shape of its grid, less its cycle mean, and whitened as the data are (the harmonic coordinates of
:mod:`hysid_model.harmonics`); what the model's own parameters absorb (its spring, dashpot and mass, the
effects it has: the column space of its Jacobian J) is projected out, as for the score test of a library
effect (:mod:`.scoring`). FROLS (:func:`hysid_model.discovery.frols.frols`) selects at most two families, one at
a time: of the columns that remove more than their parameters cost by the information criterion (BIC_MARGIN +
p ln N) and more than the score test's family-wise level over every column, the one that removes the most less
its p ln N, once the best of the few leading families are refined (:func:`select`); at most
:data:`MAX_PARAMETERS` parameters in all. Each family's shapes (exponents, thresholds,
velocity scales) are refined by nonlinear least squares from its grid point
(:func:`hysid_model.discovery.frols.refine`) before the next is sought, and a family the next makes redundant
is dropped (:func:`backward`). The law becomes a term of the user's kind
(:mod:`hysid_model.discovery.proposal`) and the whole model is refitted with it. The refit is taken by the
rules that take a library effect (:mod:`.acceptance`): BIC, shape, share of the excess, the visible errors,
plausible values, then the held-out frequencies.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from hysid.criteria import BIC_MARGIN, SIGNIFICANCE
from hysid.diagnosis.acceptance import held_out, judge
from hysid.diagnosis.metrics import cross_validated_rms
from hysid.diagnosis.tally import Tally
from hysid.harmonic_fits import Fit, fit_objective, make_model
from hysid_model.discovery.features import Family, columns, library, scales
from hysid_model.discovery.frols import frols, refine
from hysid_model.discovery.memory import is_memory, memory_families
from hysid_model.discovery.proposal import Law, expression, initial_values, make_term, names, number_of
from hysid_model.effects.bouc_wen import mean_grid
from hysid_model.errors import HysidInputError
from hysid_model.harmonics import HarmonicObjective, Harmonics
from hysid_model.kinematics import Kinematics
from hysid_model.terms import ModalState
from hysid_model.user_laws import motion

MAX_FAMILIES = 2
"""Families a proposed law combines at most."""
MAX_PARAMETERS = 4
"""Parameters a proposed law has at most (its coefficients and shapes)."""
CONTENDERS = 6
"""Families refined at each step of the selection before one is taken (:func:`select`)."""
SIMPLE_WITHIN = 2.0
"""Standard errors within which a fitted exponent is taken at a simple value (:func:`parsimonious`)."""


@dataclass
class Proposed:
    """A force term proposed from the data (not a library effect), the fit it was added to, and its evidence."""

    number: int
    law: Law
    base: Fit
    """The model it was added to."""
    fit: Fit
    """The whole model refitted with it."""
    err: list[float]
    """The error-reduction ratio of each family when selected (share of the base's residual sum of squares)."""

    @property
    def name(self) -> str:
        return f"term_{self.number}"

    @property
    def param_names(self) -> list[str]:
        return [n for mapping in names(self.law, self.number) for n in mapping.values()]

    def params(self) -> dict[str, float]:
        values = self.fit.params()
        return {n: values[n] for n in self.param_names}

    def stderr(self) -> dict[str, float]:
        errors = self.fit.errors()
        return {n: float(errors[n]) for n in self.param_names}

    @property
    def formula(self) -> str:
        """A numpy expression in ``x`` (m) and ``v`` (m/s) with the fitted values in place: the force in N."""
        return expression(self.law, self.number, self.params())

    @property
    def notation(self) -> str:
        """The law in plain notation with the fitted values (four digits)."""
        return expression(self.law, self.number, self.params(), plain=True)

    def forces(self, harmonics: Harmonics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The loops' displacement and velocity at their samples and the term's force there as it enters the
        model (less its cycle mean), each ``(L, 2n)``: :attr:`formula` evaluated by numpy, or for a law with memory
        the term's periodic orbit (its formula is a rate)."""
        x, v, gx, gv = state(self.fit, harmonics)
        if self.law.memory:
            return x, v, self.term_force(self.fit.objective.objective.kin, harmonics.loops.phases())
        code = compile(self.formula, f"<{self.name}>", "eval")
        with np.errstate(all="ignore"):
            force = eval(code, {"np": np}, {"x": x, "v": v}) - np.mean(eval(code, {"np": np}, {"x": gx, "v": gv}), axis=-1, keepdims=True)
        return x, v, np.broadcast_to(force, x.shape)

    def term_force(self, kin: Kinematics, phase: np.ndarray) -> np.ndarray:
        """The term's force at ``phase`` ``(L, N)`` under the motion ``kin``, as the model computes it (less its cycle
        mean): for a law with memory, the periodic orbit of its rate."""
        made = next(t for t in self.fit.model.terms if t.id == self.name)
        values = {n: np.array([[value]]) for n, value in self.params().items()}
        at_rest = ModalState(xi=np.zeros(1), wn=np.zeros(1), m=np.zeros(1))  # a user's term's force needs no modal state
        return made.time_force(values, at_rest, kin, phase)[0]

    @property
    def share(self) -> float:
        """The share of the base's chi^2 above the noise floor the term removes."""
        excess = self.base.chi2 - self.base.dof
        return float((self.base.chi2 - self.fit.chi2) / excess) if excess > 0 else float("nan")

    def units(self) -> dict[str, str]:
        return {p.name: p.unit for p in self.fit.model.parameters if p.name in self.param_names}

    def evidence(self) -> dict[str, Any]:
        return {
            "delta_bic": self.fit.bic - self.base.bic,
            "bic_before": self.base.bic,
            "bic_after": self.fit.bic,
            "whitened_rms_before": self.base.whitened_rms,
            "whitened_rms_after": self.fit.whitened_rms,
            "held_out_before": self.base.held_out.get("rms"),
            "held_out_after": self.fit.held_out.get("rms"),
            "share_of_excess_removed": self.share,
            "error_reduction_ratio": self.err,
        }

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "kind": "proposed from the data, not a library effect",
            "formula": self.formula,
            "memory": self.law.memory,
            "notation": self.notation,
            "params": self.params(),
            "stderr": self.stderr(),
            "units": self.units(),
            "families": [f.key for f in self.law.families],
            "module": "proposed.py",
            "model": f"{self.base.start}+" + "".join(f"{e}+" for e in self.base.effects) + f"proposed:{self.name}",
            "added_to": self.base.spec,
            "evidence": self.evidence(),
        }


def state(fit: Fit, harmonics: Harmonics) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Displacement and velocity at the loops' samples ``(L, 2n)`` (a sample at a reversal on its branch's side,
    as a term's force is evaluated there) and on the uniform phases of a cycle mean, under the motion ``fit`` is driven by."""
    kin = fit.objective.objective.kin
    x, v = motion(kin, harmonics.loops.phases(), harmonics.loops.n_samples)
    gx, gv = motion(kin, mean_grid(kin.x0.size))
    return x[0], v[0], gx[0], gv[0]


class Columns:
    """The candidate forces of the library in whitened harmonic coordinates with what ``fit`` absorbs projected out."""

    def __init__(self, fit: Fit, harmonics: Harmonics) -> None:
        self.fit, self.harmonics = fit, harmonics
        self.x, self.v, self.gx, self.gv = state(fit, harmonics)
        kin = fit.objective.objective.kin
        x_ref, v_ref = scales(kin.x0, kin.omega)
        self.families = library(x_ref, v_ref) + memory_families(x_ref, *kin.extremes)
        self.basis = np.linalg.qr(fit.jacobian)[0]
        self.index, forces = columns(self.families, self.x, self.v, self.gx, self.gv)
        self.matrix = self.project(forces)
        self.cost = np.array([(1 + len(self.families[i].shapes)) * np.log(self.matrix.shape[0]) for i, _ in self.index])
        """Each column's parameters' cost in the information criterion, (1 + shapes) ln N."""

    def project(self, forces: np.ndarray) -> np.ndarray:
        """Forces ``(K, L, 2n)`` -> ``(N, K)`` whitened, less their part in the span of the fit's Jacobian."""
        white = self.harmonics.whiten(forces).reshape(forces.shape[0], -1).T
        return white - self.basis @ (self.basis.T @ white)

    def of(self, families: list[Family], values: np.ndarray) -> np.ndarray:
        """The columns of ``families`` at the shapes ``values`` (their shape parameters in order)."""
        out, at = [], 0
        for family in families:
            shape = {s.symbol: float(values[at + j]) for j, s in enumerate(family.shapes)}
            at += len(family.shapes)
            out.append(family.evaluate(self.x, self.v, shape) - family.evaluate(self.gx, self.gv, shape).mean(axis=-1, keepdims=True))
        return self.project(np.array(out))


def selection_threshold(n_columns: int) -> float:
    """The least a column must remove: the score test's chi^2_1 at the family-wise ``SIGNIFICANCE`` over every column."""
    from scipy.stats import chi2 as chi2_dist  # on first use: a fast CLI and island start

    return float(chi2_dist.isf(SIGNIFICANCE / max(n_columns, 1), 1))


def threshold(cols: Columns, n_data: int, used: list[Family]) -> Callable[[list[int], int], float]:
    """What column ``k`` must remove after the families ``used``: more than its parameters cost (BIC_MARGIN + p ln N)
    and the score test's family-wise level over every column; never a family used, nor one past
    :data:`MAX_PARAMETERS`, nor a family of memory with another (its term is the rate of its own force)."""
    level = selection_threshold(len(cols.index))
    spent = sum(1 + len(f.shapes) for f in used)
    memory = any(is_memory(f) for f in used)

    def limit(chosen: list[int], k: int) -> float:
        family = cols.families[cols.index[k][0]]
        n = 1 + len(family.shapes)
        if spent + n > MAX_PARAMETERS or family in used or (used and (memory or is_memory(family))):
            return np.inf
        return max(level, BIC_MARGIN + n * np.log(n_data))

    return limit


def contenders(cols: Columns, matrix: np.ndarray, target: np.ndarray, limit: Callable[[list[int], int], float]) -> list[int]:
    """The columns FROLS would select first (what they remove less their cost, above ``limit``) of the
    :data:`CONTENDERS` families that remove the most, one column each, best first."""
    picked: list[int] = []

    def new_family(taken: list[int], k: int) -> float:
        return np.inf if any(cols.index[k][0] == cols.index[j][0] for j in picked) else limit(taken, k)

    for _ in range(CONTENDERS):
        chosen = frols(matrix, target, new_family, 1, cols.cost)
        if not chosen:
            break
        picked.append(chosen[0].index)
    return picked


def select(cols: Columns, residual: np.ndarray) -> tuple[Law | None, list[float]]:
    """The law of at most :data:`MAX_FAMILIES` families FROLS selects (module docstring), each family's shapes
    refined with the ones before it before the next is sought (a grid shape's misfit must not pass for a second
    family), and the error-reduction ratio of each; a family is kept only where the refined law with it removes
    more than its cost (:func:`threshold`) beyond the refined law without it. At each step the best columns of
    the :data:`CONTENDERS` leading families are refined and the one that removes the most less its cost is
    taken: on a grid, a family whose shape lies between grid points (a Stribeck hump at v_s = 0.04 m/s) may
    remove less than another that only resembles it (a tanh), and lose to it before its shape is found."""
    families: list[Family] = []
    shapes: list[dict[str, float]] = []
    law, left, err = None, float(residual @ residual), []
    for _ in range(MAX_FAMILIES):
        limit = threshold(cols, residual.size, families)
        target, matrix = residual, cols.matrix
        if law is not None:
            basis = np.linalg.qr(cols.of(families, shape_vector(families, shapes)))[0]
            target, matrix = residual - basis @ (basis.T @ residual), cols.matrix - basis @ (basis.T @ cols.matrix)
        trials = []
        for k in contenders(cols, matrix, target, limit):
            family, shape = cols.families[cols.index[k][0]], cols.index[k][1]
            trial = refined_law(cols, families + [family], shapes + [shape], residual)
            if left - trial.chi2 > limit([], k):
                trials.append((left - trial.chi2 - cols.cost[k], trial))
        if not trials:
            break
        trial = max(trials, key=lambda t: t[0])[1]
        removed = left - trial.chi2
        law, families, shapes, left = trial, trial.families, trial.shapes, trial.chi2
        err.append(removed / max(float(residual @ residual), 1e-300))
        law, dropped = backward(cols, law, residual)
        if dropped is not None:
            families, shapes, left = law.families, law.shapes, law.chi2
            err = [e for i, e in enumerate(err) if i != dropped]
    return law, err


def backward(cols: Columns, law: Law, residual: np.ndarray) -> tuple[Law, int | None]:
    """``law`` without a family that the others, refined without it, make redundant (what it removes beyond them
    is below its cost, :func:`threshold`), and its index; or ``law`` as it is and None. A family selected at a
    grid point stands in for one that only its refined shape describes (a dead zone for |x|^5 with a grid up
    to 3), until that one comes."""
    if len(law.families) < 2:
        return law, None
    for i, family in enumerate(law.families):
        rest = [j for j in range(len(law.families)) if j != i]
        smaller = refined_law(cols, [law.families[j] for j in rest], [law.shapes[j] for j in rest], residual)
        cost = max(selection_threshold(len(cols.index)), BIC_MARGIN + (1 + len(family.shapes)) * np.log(residual.size))
        if smaller.chi2 - law.chi2 <= cost:
            return smaller, i
    return law, None


def shape_vector(families: list[Family], shapes: list[dict[str, float]]) -> np.ndarray:
    return np.array([shape[s.symbol] for f, shape in zip(families, shapes) for s in f.shapes])


def refined_law(cols: Columns, families: list[Family], shapes: list[dict[str, float]], residual: np.ndarray) -> Law:
    """The ``families`` with their shapes refined by least squares from ``shapes`` and their coefficients there."""
    lower = np.array([s.bounds[0] for f in families for s in f.shapes])
    upper = np.array([s.bounds[1] for f in families for s in f.shapes])
    found = refine(lambda values: cols.of(families, values), residual, shape_vector(families, shapes), (lower, upper))
    out, at = [], 0
    for f in families:
        out.append({s.symbol: float(found.shapes[at + j]) for j, s in enumerate(f.shapes)})
        at += len(f.shapes)
    peak = float(np.max(np.abs(cols.harmonics.loops.forces())))
    return Law(families, out, [float(c) for c in found.coefficients], peak, chi2=found.chi2)


def refit(fit: Fit, law: Law, harmonics: Harmonics, bounds: dict[str, tuple[float, float]]) -> tuple[int, Fit]:
    """The number of ``law``'s term and the whole model of ``fit`` refitted with it (from ``fit``'s values and the law's)."""
    number = number_of(law)
    made = make_term(law, number)
    effects = fit.effects + (made.id,)
    model = make_model(harmonics, fit.start, effects, bounds, fit.freed)
    row = model.from_dict({**fit.params(), **initial_values(law, number)})
    return number, fit_objective(HarmonicObjective(harmonics, model), fit.start, effects, [np.clip(row, model.bounds[:, 0], model.bounds[:, 1])])


def simple_value(value: float, error: float) -> float | None:
    """The simplest exponent within ``SIMPLE_WITHIN`` standard errors of ``value``, or None: the nearest whole
    number (at least 1) where it is that close, else the nearest multiple of 1/2 (at least 1/2). A weak law's
    2.4 +- 0.25 is 2, not 2.5: both are within reach, and the whole number is the simpler law."""
    if not np.isfinite(error):
        return None
    for simple in (max(float(round(value)), 1.0), max(round(2.0 * value) / 2.0, 0.5)):
        if abs(value - simple) <= SIMPLE_WITHIN * error:
            return simple
    return None


def parsimonious(proposal: Proposed, harmonics: Harmonics, bounds: dict[str, tuple[float, float]], tally: Tally) -> Proposed:
    """``proposal`` with every exponent that lies within ``SIMPLE_WITHIN`` standard errors of a simple value
    (:func:`simple_value`) fixed there, its term refitted with those parameters fewer, where its BIC gets
    worse by no more than ``BIC_MARGIN``; otherwise ``proposal`` (no more parameters than the law needs)."""
    law, values, errors = proposal.law, proposal.params(), proposal.stderr()
    fixed: list[dict[str, float]] = []
    shapes: list[dict[str, float]] = []
    for family, mapping in zip(law.families, names(law, proposal.number)):
        fitted = {s.symbol: values[mapping[s.symbol]] for s in family.shapes}
        simple = {s.symbol: simple_value(fitted[s.symbol], errors[mapping[s.symbol]]) for s in family.shapes if s.words == "exponent"}
        fixed.append({k: v for k, v in simple.items() if v is not None})
        shapes.append({**fitted, **fixed[-1]})
    if not any(fixed):
        return proposal
    mappings = names(law, proposal.number)
    c = values[mappings[0]["c"]]
    weights = [c] + [c * values[mappings[i][f"r{i + 1}"]] for i in range(1, len(law.families))]
    simpler = Law(law.families, shapes, weights, law.peak_force, law.bounds, law.chi2, fixed)
    tally.expect(1)
    try:
        number, after = refit(proposal.base, simpler, harmonics, bounds)
    except HysidInputError:
        tally.done("discovery: a simpler exponent cannot be made a term")
        return proposal
    tally.done(f"discovery: refitted {proposal.base.spec} with term_{number}, its exponents fixed at simple values")
    if after.bic > proposal.fit.bic + BIC_MARGIN:
        return proposal
    return Proposed(number, simpler, proposal.base, after, proposal.err)


def propose(
    fit: Fit, harmonics: Harmonics, bounds: dict[str, tuple[float, float]], cross_validate: bool, tally: Tally, beside: Sequence[Fit] = ()
) -> tuple[Proposed | None, str]:
    """A term proposed from what ``fit`` leaves, refitted with the whole model and taken by the acceptance rules
    (its own shape with the forces of the library contenders ``beside`` projected out, each added to ``fit``:
    :func:`hysid.diagnosis.acceptance.own_shape`), or None; and why (what was tried, or why nothing was taken).
    Counts its fits in ``tally`` (it expects the selection, the refit and, with ``cross_validate``, the held-out check)."""
    cols = Columns(fit, harmonics)
    law, err = select(cols, fit.residual)
    tally.done(f"discovery: {cols.matrix.shape[1]} candidate forces searched from {fit.spec}")
    if law is None:
        tally.expect(-1 - int(cross_validate))
        return None, f"no candidate force removes enough of what {fit.spec} leaves"
    try:
        number, after = refit(fit, law, harmonics, bounds)
    except HysidInputError as exc:  # a law whose force the probe motion cannot evaluate: nothing to propose
        tally.expect(-1 - int(cross_validate))
        return None, f"{expression(law, number_of(law), plain=True)} cannot be made a term ({exc})"
    tally.done(f"discovery: refitted {fit.spec} with term_{number}")
    proposal = parsimonious(Proposed(number, law, fit, after, err), harmonics, bounds, tally)
    made, after = proposal.fit.effects[-1], proposal.fit
    why = judge(fit, after, (made,), harmonics, beside=beside)
    if why is None and cross_validate:
        why = held_out(fit, after, harmonics)
        tally.done(f"discovery: {made} checked on held-out frequencies")
    elif cross_validate:
        tally.expect(-1)
    if why is not None:
        return None, f"{proposal.notation} added to {fit.spec}: {why}"
    if cross_validate:
        cross_validated_rms(fit, harmonics)  # the evidence: both held-out errors
    return proposal, f"{proposal.notation} added to {fit.spec}"
