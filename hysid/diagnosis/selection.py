"""The diagnosis loop: score, name, add, refit, accept, until nothing is left to explain.

From the start model (baseline or thesis) fitted to the loops' harmonics:

1. score every library effect not in the model (:mod:`.scoring`); the ones
   above the family-wise significance level (Bonferroni over all effects and
   shapes) are contenders;
2. refit the model plus each of the best few contenders (and of any contender
   whose projected signature is nearly parallel to the best one's), from the
   one-step estimate after a short line search along the strength;
3. where two contenders other than the top one together remove significantly
   more chi^2 (to first order) than the top one with any partner, refit them together as
   well: greedy selection never finds a pair whose members each explain less
   than a third effect alone (an amplitude-dependent stiffness with a constant
   dashpot needs both slopes of Eq. 4.8-4.9; either alone loses to a cubic
   spring). A pair that is acceptable and beats every single refit by
   ``BIC_MARGIN`` is named as two steps, the better member first;
4. accept the refit with the lowest BIC if it lowers the BIC by at least
   ``BIC_MARGIN``, it makes no harmonic order significantly worse (:func:`created_order`),
   its strength is significant (``MIN_Z`` standard errors) and
   has the physical sign, no parameter is pushed against a bound (:func:`binding`), and it
   removes at least ``MIN_SHARE`` of the chi^2 above the noise floor; every
   other acceptable refit within ``BIC_MARGIN`` of it is named as confusable
   with it (this data set cannot tell them apart);
5. repeat until no contender is left or none is accepted.

The result is ``adequate`` when the final residual is noise (:mod:`.naming`),
else ``unexplained`` with a description of what is left.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from itertools import combinations
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import chi2 as chi2_dist

from hysid.diagnosis.criteria import BIC_MARGIN, MIN_SHARE, MIN_Z, SIGNIFICANCE
from hysid.diagnosis.fitting import Fit, fit_objective, initial_fit, make_model, soft_bounds
from hysid.diagnosis.metrics import GapMetrics, References, gap_metrics, references
from hysid.diagnosis.naming import adequacy, residual_signature
from hysid.diagnosis.scoring import Candidate, joint_score, score_candidates
from hysid.identifiability import Identifiability, assess
from hysid.report import diagnosis as diagnosis_report
from hysid.report import tables, text
from hysid_model.effects import EFFECTS
from hysid_model.errors import HysidInputError
from hysid_model.frf import amplitude_levels
from hysid_model.harmonics import HarmonicObjective, Harmonics
from hysid_model.loops import LoopSet
from hysid_model.model import PRESETS, build_model
from hysid_model.problem import dataset_bounds, displaced
from hysid_model.uncertainty import jacobian_covariance

TRIALS = 4
"""Contenders refitted per round (plus those parallel to the best)."""
PARALLEL = 0.9
"""|cos| between projected signatures above which two contenders are refitted together."""
LINE_SEARCH = (0.25, 0.5, 1.0, 2.0, 4.0)
"""Multiples of the one-step estimate tried before polishing."""
MAX_STEPS = 6
PAIRS = 5
"""Best contenders whose pairs are scored together."""


@dataclass
class Step:
    """One accepted effect."""

    effect: str
    confusable_with: list[str]
    score: float
    before: Fit
    after: Fit
    rejected: dict[str, str]
    """Other contenders of this round and why they were not taken."""
    joint_with: str | None = None
    """The effect named together with this one (neither alone explains what both do)."""

    @property
    def params(self) -> dict[str, float]:
        names = [p.name for p in EFFECTS[self.effect]().params]
        return {n: v for n, v in self.after.params().items() if n in names}

    @property
    def errors(self) -> dict[str, float]:
        return {n: v for n, v in self.after.errors().items() if n in self.params}


@dataclass
class Diagnosis:
    """What :func:`diagnose` found: the start fit, every accepted step, the final fit and its gap to the data."""

    harmonics: Harmonics
    start: Fit
    steps: list[Step]
    final: Fit
    status: str
    unexplained: dict | None
    not_identifiable: dict[str, list[str]]
    rejected: dict[str, str]
    """Contenders of the last round and why none was taken."""
    gap: list[GapMetrics]
    """The gap between model and data at the start and after every step."""
    references: References
    """Model-free levels the gap is held against (linear per loop, repeatability)."""
    identifiability: Identifiability
    """What the data cannot determine of the final model, and its correlations."""
    last_scores: list[Candidate] = field(default_factory=list)
    report: str | None = None
    """The report written last (:meth:`write_report`)."""

    def effects_not_identifiable(self) -> dict[str, str]:
        """Why each effect of ``not_identifiable`` cannot be identified from these loops."""
        levels = amplitude_levels(self.harmonics.loops.x0)[0]
        out = {}
        for effect, absorbed in self.not_identifiable.items():
            if levels.size == 1 and EFFECTS[effect].slope_of:
                out[effect] = f"one amplitude level (X0 = {levels[0] * 1e3:.4g} mm) cannot show a change with amplitude: it is {', '.join(absorbed)} again"
            else:
                out[effect] = f"whatever it does, the model already does with {', '.join(absorbed)}"
        return out

    def fits(self) -> list[tuple[str, Fit]]:
        """(label, fit) for the start and after every step."""
        return [("start: " + self.start.spec, self.start)] + [("+ " + s.effect, s.after) for s in self.steps]

    @property
    def params(self) -> dict[str, float]:
        """The final model's parameters."""
        return self.final.params()

    @property
    def stderr(self) -> dict[str, float]:
        """The final model's standard errors (NaN where the data cannot determine a parameter)."""
        return self.final.model.as_dict(self.identifiability.stderr * max(1.0, self.final.whitened_rms))

    @property
    def reaches(self) -> str:
        """Which reference the final model reaches: noise floor, repeatability, linear per loop, or none."""
        return self.references.reached(self.final.whitened_rms, self.status == "adequate")

    def tables(self) -> dict[str, list[dict[str, Any]]]:
        """``parameters`` of the final model, ``steps`` (the effects named, with their parameters) and ``gap``."""
        return tables.diagnosis_tables(self)

    def to_csv(self, out_dir: str | Path) -> dict[str, Path]:
        """Each table of :meth:`tables` as ``<name>.csv`` in ``out_dir`` (a header line, SI units in the column names)."""
        return tables.write_tables(self.tables(), out_dir)

    def to_dataframes(self) -> dict[str, Any]:
        """Each table of :meth:`tables` as a pandas DataFrame (needs pandas, an optional dependency)."""
        return tables.data_frames(self.tables())

    def summary(self) -> str:
        """The gap after each step, the status and what cannot be identified, as text."""
        return text.diagnosis_summary(self)

    def write_report(self, out_dir: str | Path, dataset: str | None = None) -> Path:
        """``diagnosis.md`` with its figures and ``diagnosis.json`` in ``out_dir``; returns the Markdown path.

        ``dataset`` is how the reader reloads the data (default: the loop set's name).
        """
        return diagnosis_report.write_diagnosis_report(self, out_dir, dataset or self.harmonics.loops.name)

    def _repr_markdown_(self) -> str:
        return diagnosis_report.overview(self)

    def __repr__(self) -> str:
        return f"<Diagnosis of {self.harmonics.loops.name}: {self.start.spec} -> {self.final.spec}, {self.status}>"

    def to_dict(self) -> dict[str, Any]:
        """The JSON document of ``hysid diagnose --json``."""
        return {
            "dataset": self.harmonics.loops.name,
            "start_model": self.start.spec,
            "final_model": self.final.spec,
            "steps": [
                {
                    "effect": s.effect,
                    "confusable_with": s.confusable_with,
                    "params": s.params,
                    "stderr": s.errors,
                    "score": s.score,
                    "whitened_rms_before": s.before.whitened_rms,
                    "whitened_rms_after": s.after.whitened_rms,
                    "delta_bic": s.after.bic - s.before.bic,
                    "rejected": s.rejected,
                    "joint_with": s.joint_with,
                }
                for s in self.steps
            ],
            "status": self.status,
            "unexplained_signature": self.unexplained,
            "not_identifiable": sorted(self.not_identifiable) + list(self.identifiability.not_identifiable),
            "not_identifiable_reasons": {**self.effects_not_identifiable(), **self.identifiability.not_identifiable},
            "correlation": self.identifiability.correlation_dict(),
            "rejected": self.rejected,
            "final_params": self.final.params(),
            "final_stderr": self.stderr,
            "final_bounds": {p.name: [p.lower, p.upper] for p in self.final.model.parameters},
            "final_fixed": self.final.model.fixed,
            "bounds_from_data": sorted(p.name for p in self.final.model.parameters if p.soft),
            "whitened_rms": self.final.whitened_rms,
            "references": self.references.as_dict(),
            "reaches": self.reaches,
            "noise_sigma": "known" if np.all(self.harmonics.sigma_known) else "estimated from the data",
            "gap": [g.as_dict() for g in self.gap],
        }


def threshold(candidates: list[Candidate]) -> float:
    """The score a contender needs: chi^2_1 at the family-wise ``SIGNIFICANCE`` (Bonferroni over all effects and shapes)."""
    return float(chi2_dist.isf(SIGNIFICANCE / max(sum(c.n_shapes for c in candidates), 1), 1))


def passing(candidates: list[Candidate]) -> list[Candidate]:
    """The candidates that pass the round's score test, best first."""
    level = threshold(candidates)
    return [c for c in candidates if c.physical and c.identifiable and c.score > level]


def contenders(candidates: list[Candidate]) -> list[Candidate]:
    """The contenders to refit one by one: the best few, and any nearly parallel to the best."""
    ok = passing(candidates)
    if not ok:
        return []
    top = ok[0]
    return [c for i, c in enumerate(ok) if i < TRIALS or abs(float(c.direction @ top.direction)) > PARALLEL]


def best_pair(candidates: list[Candidate], residual: np.ndarray) -> tuple[tuple[Candidate, Candidate], np.ndarray, float] | None:
    """The pair of contenders without the top one that together remove the most chi^2 (to first order),
    if that exceeds by a significant amount what the top one removes with any partner (where greedy
    selection would go); (pair, joint one-step strengths, chi^2 removed)."""
    ok = passing(candidates)[:PAIRS]
    if len(ok) < 3:
        return None
    top, level = ok[0], threshold(candidates)
    greedy = max(joint_score(top, c, residual)[0] for c in ok[1:])
    best = None
    for a, b in combinations(ok[1:], 2):
        removed, step = joint_score(a, b, residual)
        if removed > greedy + level and (best is None or removed > best[2]):
            best = ((a, b), step, removed)
    return best


def refit(fit: Fit, harmonics: Harmonics, candidate: Candidate, bounds: dict[str, tuple[float, float]]) -> Fit:
    """The current model plus ``candidate``, polished from the best two points (one for a model
    with memory, whose evaluations cost more) of a line search along the one-step estimate of
    each of its best shapes."""
    effects = fit.effects + (candidate.effect,)
    model = make_model(harmonics, fit.start, effects, bounds)
    objective = HarmonicObjective(harmonics, model)
    term = EFFECTS[candidate.effect]()
    i = model.names.index(term.strength)
    rows = []
    for shape, one_step in candidate.starts:
        base = model.from_dict({**{p.name: 0.0 for p in term.params}, **fit.params(), **shape})
        line = np.repeat(base[None, :], len(LINE_SEARCH), axis=0)
        line[:, i] = one_step * np.array(LINE_SEARCH)
        rows.append(line)
    rows = np.clip(np.concatenate(rows), model.bounds[:, 0], model.bounds[:, 1])
    order = np.argsort(objective(rows))
    return fit_objective(objective, fit.start, effects, [rows[j] for j in order[: 1 if model.has_memory else 2]])


def refit_pair(fit: Fit, harmonics: Harmonics, pair: tuple[Candidate, Candidate], step: np.ndarray, bounds: dict[str, tuple[float, float]]) -> Fit:
    """The current model plus both effects of ``pair`` (each at its best shape), polished from the best
    points of a line search along their joint one-step estimate (:func:`.scoring.joint_score`)."""
    effects = fit.effects + tuple(c.effect for c in pair)
    model = make_model(harmonics, fit.start, effects, bounds)
    objective = HarmonicObjective(harmonics, model)
    terms = [EFFECTS[c.effect]() for c in pair]
    base = model.from_dict(
        {**{p.name: 0.0 for t in terms for p in t.params}, **fit.params(), **pair[0].starts[0][0], **pair[1].starts[0][0]}
    )
    rows = np.repeat(base[None, :], len(LINE_SEARCH), axis=0)
    for t, strength in zip(terms, step):
        rows[:, model.names.index(t.strength)] = strength * np.array(LINE_SEARCH)
    rows = np.clip(rows, model.bounds[:, 0], model.bounds[:, 1])
    order = np.argsort(objective(rows))
    return fit_objective(objective, fit.start, effects, [rows[j] for j in order[: 1 if model.has_memory else 2]])


def binding(fit: Fit, j: int) -> bool:
    """True if parameter ``j`` sits on a bound that the data push against (the fit wants out of the range).

    One-parameter score test at the bound: the chi^2 gradient 2 J^T e along
    parameter j, with the others free, gives LM = (J^T e)_j^2 [(J^T J)^-1]_jj;
    the bound binds if that points outward and exceeds MIN_Z^2. A weakly
    determined shape that merely wanders onto its bound does not bind.
    """
    name = fit.model.names[j]
    if name not in fit.model.at_bounds(fit.theta):
        return False
    lower, upper = fit.model.bounds[j]
    value = fit.theta[j]
    gradient = (fit.jacobian.T @ fit.residual)[j]
    lm = gradient**2 * jacobian_covariance(fit.jacobian)[j, j]
    outward = gradient > 0 if value - lower <= upper - value else gradient < 0
    return bool(outward and lm > MIN_Z**2)


def created_order(before: Fit, after: Fit) -> tuple[int, float, float] | None:
    """A harmonic order that ``before`` fits at the noise and ``after`` significantly worse, no longer at the
    noise (the family-wise ``SIGNIFICANCE`` of chi^2 over that order's coefficients): (order, chi^2 before,
    after), or None. An effect that buys a better first harmonic with content the loops do not have
    (a hysteretic spring fitting how a linear stiffness changes with amplitude) has the wrong shape."""
    orders = before.objective.harmonics.orders()
    n_loops = before.objective.harmonics.loops.n_loops
    r0, r1 = (f.residual.reshape(n_loops, -1) for f in (before, after))
    levels = np.unique(orders)
    for k in levels:
        n = int(np.count_nonzero(orders == k)) * n_loops
        c0, c1 = float(np.sum(r0[:, orders == k] ** 2)), float(np.sum(r1[:, orders == k] ** 2))
        limit = float(chi2_dist.isf(SIGNIFICANCE / levels.size, n))
        if c0 <= limit < c1 and c1 - c0 > limit - n:
            return int(k), c0, c1
    return None


def judge(before: Fit, after: Fit, effect: str) -> str | None:
    """Why ``after`` (``before`` plus ``effect``) is not accepted, or None."""
    delta = after.bic - before.bic
    if delta > -BIC_MARGIN:
        return f"BIC changes by only {delta:+.1f}"
    created = created_order(before, after)
    if created is not None:
        k, c0, c1 = created
        return f"adds order-{k} content the loops do not have (chi^2 of order {k}: {c0:.4g} -> {c1:.4g})"
    term = EFFECTS[effect]()
    names = after.model.names
    values, errors, bounds = after.theta, after.stderr, after.model.bounds
    i = names.index(term.strength)
    if bounds[i, 0] == 0.0 and values[i] <= 0.0:
        return f"{term.strength} has the unphysical sign"
    if abs(values[i]) < MIN_Z * errors[i]:
        return f"{term.strength} = {values[i]:.4g} +- {errors[i]:.2g} is not significant"
    for p in term.params:
        if p.name != term.strength and p.name in names and binding(after, names.index(p.name)):  # a fixed one (bw_n) binds nothing
            return f"{p.name} is pushed against its bound ({values[names.index(p.name)]:.4g}): the effect degenerates here"
    excess = before.chi2 - before.dof
    if excess > 0 and before.chi2 - after.chi2 < MIN_SHARE * excess:
        return f"removes only {100 * (before.chi2 - after.chi2) / excess:.0f}% of the chi^2 above the noise floor"
    return None


def with_given_bounds(loops: LoopSet, start: str, bounds: Mapping[str, tuple[float, float]] | None) -> LoopSet:
    """``loops`` whose given (hard) bounds are the dataset's and then ``bounds``, each checked against the
    parameters of the start model and of every library effect."""
    if not bounds:
        return loops
    build_model("+".join((start, *EFFECTS))).with_bounds(bounds)
    given = {**dataset_bounds(loops), **{name: (float(lo), float(hi)) for name, (lo, hi) in bounds.items()}}
    return replace(loops, meta={**loops.meta, "bounds": given})


def diagnose(
    loops: LoopSet,
    model: str = "baseline",
    *,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    displacement: str = "measured",
    max_steps: int = MAX_STEPS,
    cross_validate: bool = True,
    progress: Callable[[int, int, str], None] | None = None,
) -> Diagnosis:
    """Find which library effects the start ``model`` (a preset) misses on ``loops`` (see the module docstring).

    ``bounds`` (``{"w0": (10, 200)}``, any parameter of the start model or of a library effect) are
    hard, as the dataset's: every model the diagnosis fits keeps them (:func:`hysid_model.problem.prepare_model`).
    ``displacement``: each loop's measured waveform or the ideal sine (as :func:`hysid.fit`);
    ``cross_validate`` adds the leave-one-frequency-out gap of every step (a refit per frequency).
    ``progress(done, total, what)`` is called after every fit; ``total`` is what is known so far (it
    grows while effects are found). It does not change the result.
    """
    if model not in PRESETS:
        raise HysidInputError(f"the start model must be one of {', '.join(PRESETS)}", param="model", value=model)
    count = [0, 2]  # fits done, fits known to come (the start fit, and the gap of the start model)

    def done(what: str) -> None:
        count[0] += 1
        if progress is not None:
            progress(count[0], count[1], what)

    start = model
    harmonics = Harmonics.from_loops(displaced(with_given_bounds(loops, start, bounds), displacement))
    fit = initial_fit(harmonics, start)
    bounds = soft_bounds(fit.model)
    done(f"start model {start} fitted")
    first = fit
    steps: list[Step] = []
    while True:
        candidates = score_candidates(fit, harmonics, bounds)
        not_identifiable = {c.effect: c.absorbed_by for c in candidates if not c.identifiable}
        trials = contenders(candidates) if len(steps) < max_steps else []
        count[1] += len(trials)
        refits = {}
        for c in trials:
            refits[c.effect] = refit(fit, harmonics, c, bounds)
            done(f"step {len(steps) + 1}: refitted with {c.effect}")
        verdicts = {e: judge(fit, r, e) for e, r in refits.items()}
        rejected = {e: v for e, v in verdicts.items() if v is not None}
        accepted = sorted((r.bic, e) for e, r in refits.items() if verdicts[e] is None)
        pair = best_pair(candidates, fit.residual) if trials else None
        if pair is not None:
            joint = pair_step(fit, harmonics, pair, bounds, refits, accepted, done, count)
            if joint is not None:
                steps += joint
                fit = joint[-1].after
                bounds.update(soft_bounds(fit.model))
                continue
        if not accepted:
            break
        best_bic, best = accepted[0]
        confusable = [e for b, e in accepted[1:] if b - best_bic < BIC_MARGIN]
        others = {e: v for e, v in verdicts.items() if e != best and e not in confusable}
        reasons = {e: v or f"fits worse than {best} (BIC +{refits[e].bic - best_bic:.1f})" for e, v in others.items()}
        score = next(c.score for c in trials if c.effect == best)
        steps.append(Step(effect=best, confusable_with=confusable, score=score, before=fit, after=refits[best], rejected=reasons))
        count[1] += 1  # the gap after this step
        fit = refits[best]
        bounds.update(soft_bounds(fit.model))
    check = adequacy(fit, harmonics)
    fits = [first] + [s.after for s in steps]

    def gap(f: Fit, i: int) -> GapMetrics:
        metrics = gap_metrics(f, harmonics, cross_validate)
        done(f"gap after {'the start' if i == 0 else f'step {i}'}")
        return metrics

    return Diagnosis(
        harmonics=harmonics,
        start=first,
        steps=steps,
        final=fit,
        status="adequate" if check.adequate else "unexplained",
        unexplained=None if check.adequate else residual_signature(fit, harmonics),
        not_identifiable=not_identifiable,
        rejected=rejected,
        gap=[gap(f, i) for i, f in enumerate(fits)],
        references=references(harmonics),
        identifiability=final_identifiability(fit, harmonics),
        last_scores=candidates,
    )


def pair_step(
    fit: Fit,
    harmonics: Harmonics,
    pair: tuple[tuple[Candidate, Candidate], np.ndarray, float],
    bounds: dict[str, tuple[float, float]],
    refits: dict[str, Fit],
    accepted: list[tuple[float, str]],
    done: Callable[[str], None],
    count: list[int],
) -> list[Step] | None:
    """The two steps that name ``pair`` together, if its joint refit is acceptable for both effects and
    beats every acceptable single refit by ``BIC_MARGIN``; else None. The member whose single refit fits
    better comes first, its single refit in between."""
    members, step, removed = pair
    names = tuple(c.effect for c in members)
    count[1] += 1
    joint = refit_pair(fit, harmonics, members, step, bounds)
    done(f"refitted with {' and '.join(names)} together")
    if any(judge(fit, joint, e) is not None for e in names):
        return None
    if accepted and joint.bic > accepted[0][0] - BIC_MARGIN:
        return None
    for c in members:
        if c.effect not in refits:
            count[1] += 1
            refits[c.effect] = refit(fit, harmonics, c, bounds)
            done(f"refitted with {c.effect} alone")
    first, second = sorted(members, key=lambda c: refits[c.effect].bic)
    both = f"{first.effect} with {second.effect} together"
    reasons = {
        e: f"fits worse than {both} (BIC +{r.bic - joint.bic:.1f})" for e, r in refits.items() if e not in names
    }
    count[1] += 2  # the gaps after both steps
    return [
        Step(effect=first.effect, confusable_with=[], score=first.score, before=fit, after=refits[first.effect], rejected=reasons,
             joint_with=second.effect),
        Step(effect=second.effect, confusable_with=[], score=removed - first.score, before=refits[first.effect], after=joint,
             rejected={}, joint_with=first.effect),
    ]


def final_identifiability(fit: Fit, harmonics: Harmonics) -> Identifiability:
    """Which parameters of the final fit the harmonics cannot determine (:mod:`hysid.identifiability`)."""
    return assess(
        fit.objective, fit.theta, lambda objective, theta: jacobian_covariance(objective.jacobian(theta)),
        lambda model: HarmonicObjective(harmonics, model), noise=1.0,
    )
