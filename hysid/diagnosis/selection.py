"""The diagnosis loop: score, refit the best contenders from several starts, judge, take the best, until nothing is left.

From the start model (baseline or thesis) fitted to the loops' harmonics, under
the displacement the data read (:mod:`hysid.motion`: the measured waveform is
the motion, or the sensor's distortion of its fundamental):

1. score every library effect not in the model (:mod:`.scoring`); an effect
   that cannot be at work on these loops whatever its values is set aside with
   why (:mod:`.plausible`, e.g. a force high-pass where the force keeps its
   mean); the ones above the family-wise significance level are contenders;
2. refit the model plus each of the best few contenders (and of any contender
   whose projected signature is nearly parallel to the best one's), and plus
   the best pair of the others (by the chi^2 they remove together to first
   order), each from several starts (:mod:`.refits`): an effect is judged at
   its best fit, never at one poor optimum. The pair is there because greedy
   selection never finds two effects whose members each explain less than a
   third alone (an amplitude-dependent stiffness with a constant dashpot needs
   both slopes of Eq. 4.8-4.9), and because a leading effect must beat two
   others together (a Bouc-Wen spring against friction plus a delay);
3. judge every refit by the rules of :mod:`.acceptance` (information
   criterion, shape, sign, bounds, share of the excess, the visible loop and
   energy errors, plausible values); of those that pass, in BIC order, the
   first that also predicts held-out frequencies better is taken. A pair is
   named as two steps, its better member first. Every other passing refit
   within ``BIC_MARGIN`` of the one taken is named as confusable with it (this
   data set cannot tell them apart);
4. repeat until no contender is left or none is taken.

The reading of the displacement is then confirmed with the final model; if
that model reads it the other way (:func:`hysid.motion.confirm_motion`), the
diagnosis runs again under the other reading and the final model with the
lower BIC is kept. The result is ``adequate`` when the final residual is noise
(:mod:`.naming`), else ``unexplained`` with a description of what is left.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from itertools import combinations
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import chi2 as chi2_dist

from hysid.diagnosis.acceptance import held_out, judge
from hysid.diagnosis.criteria import BIC_MARGIN, SIGNIFICANCE
from hysid.diagnosis.fitting import Fit, initial_fit, profile_errors, soft_bounds
from hysid.diagnosis.metrics import GapMetrics, References, gap_metrics, references
from hysid.diagnosis.naming import adequacy, residual_signature
from hysid.diagnosis.plausible import implausible_effect, mass_note
from hysid.diagnosis.refits import refit
from hysid.diagnosis.scoring import Candidate, joint_score, score_candidates
from hysid.identifiability import Identifiability, assess
from hysid.motion import MotionChoice, choose_motion, confirm_motion
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
MAX_STEPS = 6
PAIRS = 5
"""Best contenders whose pairs are scored together."""

Progress = Callable[[str], None]


@dataclass
class Step:
    """One accepted effect."""

    effect: str
    confusable_with: list[str]
    score: float
    before: Fit
    after: Fit
    rejected: dict[str, str]
    """Other contenders of this step and why they were not taken."""
    joint_with: str | None = None
    """The effect named together with this one (the two were taken as a pair)."""

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
    impossible: dict[str, str] = field(default_factory=dict)
    """Effects set aside as impossible on these loops, and why (:mod:`hysid.diagnosis.plausible`)."""
    motion: MotionChoice | None = None
    """Which displacement drove the models, how that was decided and the evidence (:mod:`hysid.motion`)."""
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
        """The final model's standard errors (NaN where the data cannot determine a parameter; a profile's
        half-width where the chi^2 is not quadratic, :func:`hysid.diagnosis.fitting.profile_errors`)."""
        errors = self.final.model.as_dict(self.identifiability.stderr * max(1.0, self.final.whitened_rms))
        return {**errors, **{n: e for n, e in self.final.profiled.items() if n in errors and np.isfinite(errors[n])}}

    @property
    def at_bounds(self) -> dict[str, str]:
        """The final model's parameters on a bound, each with which (:meth:`hysid_model.model.Model.bound_kinds`)."""
        return self.final.model.bound_kinds(self.final.theta)

    @property
    def notes(self) -> list[str]:
        """What a reader must know about the final values: a mass the loops' inertia does not support."""
        note = mass_note(self.final.model, self.final.theta, self.harmonics.loops)
        return [note] if note else []

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
            "displacement_model": self.motion.as_dict() if self.motion else None,
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
            "impossible": self.impossible,
            "correlation": self.identifiability.correlation_dict(),
            "rejected": self.rejected,
            "final_params": self.final.params(),
            "final_stderr": self.stderr,
            "final_bounds": {p.name: [p.lower, p.upper] for p in self.final.model.parameters},
            "final_fixed": self.final.model.fixed,
            "at_bounds": sorted(self.at_bounds),
            "at_bounds_kind": self.at_bounds,
            "notes": self.notes,
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


Pair = tuple[tuple[Candidate, Candidate], np.ndarray]
"""Two contenders and their joint one-step strengths (:func:`hysid.diagnosis.scoring.joint_score`)."""


def best_pairs(candidates: list[Candidate], residual: np.ndarray) -> tuple[Pair, Pair] | None:
    """The pair of contenders other than the top one that together remove the most chi^2 to first order, if
    that exceeds by a significant amount (the round's score threshold) what the top one removes with its best
    partner, and that greedy pair: (others, greedy), or None. Both are refitted and the pair of others is
    taken only if it beats the greedy pair, two effects against two, and every single refit."""
    ok = passing(candidates)[:PAIRS]
    if len(ok) < 3:
        return None
    top, level = ok[0], threshold(candidates)
    (greedy_removed, greedy_step), partner = max(((joint_score(top, c, residual), c) for c in ok[1:]), key=lambda item: item[0][0])
    (removed, step), pair = max(((joint_score(a, b, residual), (a, b)) for a, b in combinations(ok[1:], 2)), key=lambda item: item[0][0])
    if removed <= greedy_removed + level:
        return None
    return (pair, step), ((top, partner), greedy_step)


def label(effects: tuple[str, ...]) -> str:
    return " with ".join(effects)


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
    displacement: str = "auto",
    max_steps: int = MAX_STEPS,
    cross_validate: bool = True,
    progress: Callable[[int, int, str], None] | None = None,
) -> Diagnosis:
    """Find which library effects the start ``model`` (a preset) misses on ``loops`` (see the module docstring).

    ``bounds`` (``{"w0": (10, 200)}``, any parameter of the start model or of a library effect) are
    hard, as the dataset's: every model the diagnosis fits keeps them (:func:`hysid_model.problem.prepare_model`).
    ``displacement``: ``auto`` (the data decide whether the displacement's harmonics are the motion or the
    sensor's, :mod:`hysid.motion`), ``measured``, ``fundamental`` or ``sine``, as :func:`hysid.fit`;
    ``cross_validate`` adds the leave-one-frequency-out gap of every step and judges every effect by it
    (a refit per frequency). ``progress(done, total, what)`` is called after every fit; ``total`` is what is
    known so far (it grows while effects are found). It does not change the result.
    """
    if model not in PRESETS:
        raise HysidInputError(f"the start model must be one of {', '.join(PRESETS)}", param="model", value=model)
    count = [0, 2]  # fits done, fits known to come (the start fit, and the gap of the start model)

    def done(what: str, more: int = 0) -> None:
        count[0] += 1
        count[1] += more
        if progress is not None:
            progress(count[0], count[1], what)

    given = with_given_bounds(loops, model, bounds)
    motion = choose_motion(given, model, displacement, bounds=bounds)
    result = search(Harmonics.from_loops(displaced(given, motion.displacement)), model, max_steps, cross_validate, done, count)
    flipped = confirm_motion(given, result.final.model, result.final.theta, motion)
    if flipped is not None:
        count[1] += 2
        other = search(Harmonics.from_loops(displaced(given, flipped.displacement)), model, max_steps, cross_validate, done, count)
        if other.final.bic < result.final.bic:
            result, motion = other, flipped
        else:
            motion.reason += f"; read the other way the diagnosis ends {other.final.bic - result.final.bic:.4g} higher in BIC"
    result.motion = motion
    return result


def search(harmonics: Harmonics, start: str, max_steps: int, cross_validate: bool, done: Callable[..., None], count: list[int]) -> Diagnosis:
    """The diagnosis loop of the module docstring on ``harmonics`` from the preset ``start``."""
    fit = initial_fit(harmonics, start)
    bounds = soft_bounds(fit.model)
    done(f"start model {start} fitted")
    first = fit
    steps: list[Step] = []
    while True:
        candidates = score_candidates(fit, harmonics, bounds)
        impossible = {c.effect: why for c in candidates if (why := implausible_effect(c.effect, harmonics.loops)) is not None}
        candidates = [c for c in candidates if c.effect not in impossible]
        not_identifiable = {c.effect: c.absorbed_by for c in candidates if not c.identifiable}
        trials: list[tuple[tuple[Candidate, ...], np.ndarray | None]] = [((c,), None) for c in contenders(candidates)] if len(steps) < max_steps else []
        pairs = best_pairs(candidates, fit.residual) if trials else None
        if pairs is not None:
            trials.append(pairs[0])
        count[1] += len(trials) + (pairs is not None)
        refits: dict[tuple[str, ...], Fit] = {}
        scores = {c.effect: c.score for c in candidates}
        for members, joint in trials:
            effects = tuple(c.effect for c in members)
            refits[effects] = profile_errors(refit(fit, harmonics, members, bounds, joint))
            done(f"step {len(steps) + 1}: refitted with {label(effects)}")
        verdicts = {effects: judge(fit, r, effects, harmonics) for effects, r in refits.items()}
        if pairs is not None:  # the pair of others counts only where it beats the greedy pair and every single by BIC_MARGIN
            others, (members, joint) = tuple(c.effect for c in pairs[0][0]), pairs[1]
            greedy = refit(fit, harmonics, members, bounds, joint)
            done(f"step {len(steps) + 1}: refitted with {label(tuple(c.effect for c in members))} (the greedy pair)")
            rivals = [greedy.bic] + [r.bic for e, r in refits.items() if len(e) == 1 and verdicts[e] is None]
            if verdicts[others] is None and refits[others].bic > min(rivals) - BIC_MARGIN:
                verdicts[others] = (f"fits no better than {label(tuple(c.effect for c in members))} together or one effect alone "
                                    f"(BIC {refits[others].bic - min(rivals):+.1f})")
        ranked = sorted((r.bic, effects) for effects, r in refits.items() if verdicts[effects] is None)
        chosen = None
        for _, effects in ranked:
            verdicts[effects] = held_out(fit, refits[effects], harmonics) if cross_validate else None
            if verdicts[effects] is None:
                chosen = effects
                break
        rejected = {label(e): v for e, v in verdicts.items() if v is not None}
        if chosen is None:
            break
        best = refits[chosen]
        passed = [e for _, e in ranked if e != chosen and verdicts[e] is None]
        confusable = [label(e) for e in passed if refits[e].bic - best.bic < BIC_MARGIN]
        reasons = {label(e): v or f"fits worse than {label(chosen)} (BIC +{refits[e].bic - best.bic:.1f})"
                   for e, v in verdicts.items() if e != chosen and label(e) not in confusable}
        if len(chosen) == 1:
            steps.append(Step(effect=chosen[0], confusable_with=confusable, score=scores[chosen[0]], before=fit, after=best, rejected=reasons))
        else:
            steps += pair_steps(fit, harmonics, chosen, refits, bounds, candidates, confusable, reasons, done)
        count[1] += len(chosen)  # the gap after each step
        fit = steps[-1].after
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
        impossible=impossible,
    )


def pair_steps(
    fit: Fit,
    harmonics: Harmonics,
    pair: tuple[str, ...],
    refits: dict[tuple[str, ...], Fit],
    bounds: dict[str, tuple[float, float]],
    candidates: list[Candidate],
    confusable: list[str],
    reasons: dict[str, str],
    done: Callable[..., None],
) -> list[Step]:
    """The two steps that name ``pair``: the member whose refit alone fits better first (its single refit in
    between, refitted here if this round did not), then the joint refit."""
    by_effect = {c.effect: c for c in candidates}
    for effect in pair:
        if (effect,) not in refits:
            refits[(effect,)] = profile_errors(refit(fit, harmonics, (by_effect[effect],), bounds))
            done(f"refitted with {effect} alone", more=1)
    first, second = sorted(pair, key=lambda e: refits[(e,)].bic)
    scores = {c.effect: c.score for c in candidates}
    return [
        Step(effect=first, confusable_with=confusable, score=scores[first], before=fit, after=refits[(first,)], rejected=reasons, joint_with=second),
        Step(effect=second, confusable_with=[], score=scores[second], before=refits[(first,)], after=refits[pair], rejected={}, joint_with=first),
    ]


def final_identifiability(fit: Fit, harmonics: Harmonics) -> Identifiability:
    """Which parameters of the final fit the harmonics cannot determine (:mod:`hysid.identifiability`)."""
    return assess(
        fit.objective, fit.theta, lambda objective, theta: jacobian_covariance(objective.jacobian(theta)),
        lambda model: HarmonicObjective(harmonics, model), noise=1.0,
    )
