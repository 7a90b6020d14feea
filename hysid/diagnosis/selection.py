"""The diagnosis loop: score, refit the best contenders from several starts, judge, take the best, until nothing is left.

From the start model (baseline or thesis) fitted to the loops' harmonics, under
the displacement the data read (:mod:`hysid.motion`: the measured waveform is
the motion, or the sensor's distortion of its fundamental):

1. score every library effect not in the model (:mod:`.scoring`), and the user's
   own terms given as ``candidates``; an effect that cannot be at work on these
   loops whatever its values is set aside with why (:mod:`.plausible`, e.g. a
   force high-pass where the force keeps its mean); the ones above the
   family-wise significance level are contenders;
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
4. repeat until no contender is left or none is taken;
5. drop from the final model every term whose strength is consistent with
   zero where the BIC does not rise (:mod:`.pruning`: a start model's amplitude
   slopes the loops do not need, an effect a later one made redundant).

The reading of the displacement is then confirmed with the final model; if
that model reads it the other way (:func:`hysid.motion.confirm_motion`), or
the diagnosis ends unexplained under the reading the data chose (the linear
start reads a nonlinear device's odd harmonics as the force's response to the
displacement's), the diagnosis runs again under the other reading and the
final model with the lower BIC is kept. The result is ``adequate`` when the final residual is noise
(:mod:`.naming`), else ``unexplained`` with a description of what is left.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from itertools import combinations

import numpy as np

from hysid.criteria import BIC_MARGIN, PARALLEL, SIGNIFICANCE
from hysid.diagnosis.acceptance import degenerate, degenerate_gives_way, held_out, judge
from hysid.diagnosis.contest import refused_base, stacked, with_discovery, with_refused
from hysid.diagnosis.metrics import GapMetrics, gap_metrics, references
from hysid.diagnosis.naming import final_fields
from hysid.diagnosis.plausible import implausible_effect
from hysid.diagnosis.pruning import prune
from hysid.diagnosis.refits import joint_contender, refit, weight
from hysid.diagnosis.result import Diagnosis, Refused, Step
from hysid.diagnosis.scoring import Candidate, candidate_effects, joint_score, score_candidates
from hysid.diagnosis.tally import MEMORY_FIT_WEIGHT, Report, Tally
from hysid.harmonic_fits import Fit, initial_fit, profile_errors, soft_bounds
from hysid.motion import WORDS, MotionChoice, choose_motion, confirm_motion
from hysid_model import notices
from hysid_model.errors import HysidInputError
from hysid_model.harmonics import Harmonics
from hysid_model.loops import LoopSet
from hysid_model.model import build_model
from hysid_model.presets import PRESETS
from hysid_model.problem import dataset_bounds, displaced
from hysid_model.terms import Term, TermGroup

TRIALS = 4
"""Contenders refitted per round (plus those parallel to the best)."""
MAX_STEPS = 6
PAIRS = 5
"""Best contenders whose pairs are scored together."""
EXPECTED_STEPS = 2
"""Effects a diagnosis is expected to name, for its progress estimate (:mod:`.tally`; more or fewer revise it)."""
EXPECTED_TRIALS = TRIALS + 1
"""Refits a round is expected to make: the best few contenders and a pair (the round's scores revise it)."""
EXPECTED_REFITS = EXPECTED_TRIALS + MEMORY_FIT_WEIGHT - 1
"""Their work in fits (:mod:`.tally`): one of them of a model with memory, as Bouc-Wen is scored in every round."""


def round_work(cross_validate: bool) -> float:
    """The work a round is expected to make: the scores (a fit's work), its refits and, with ``cross_validate``,
    the held-out check of the one taken."""
    return 1 + EXPECTED_REFITS + int(cross_validate)


def search_work(max_steps: int, cross_validate: bool) -> float:
    """The work one search is expected to make (:func:`search`), in fits: the start fit, a round per expected step
    and the round that finds nothing more, the pruning (:mod:`.pruning`), and the gap after the start and after each step."""
    rounds = min(EXPECTED_STEPS, max_steps) + 1
    return 1 + rounds * round_work(cross_validate) + 1 + rounds


def threshold(candidates: list[Candidate]) -> float:
    """The score a contender needs: chi^2_1 at the family-wise ``SIGNIFICANCE`` (Bonferroni over all effects and shapes)."""
    from scipy.stats import chi2 as chi2_dist  # on first use: a fast CLI and island start

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


def with_given_bounds(loops: LoopSet, start: str, bounds: Mapping[str, tuple[float, float]] | None, scored: tuple[str, ...]) -> LoopSet:
    """``loops`` whose given (hard) bounds are the dataset's and then ``bounds``, each checked against the
    parameters of the start model and of every candidate effect."""
    if not bounds:
        return loops
    build_model("+".join((start, *scored))).with_bounds(bounds)
    given = {**dataset_bounds(loops), **{name: (float(lo), float(hi)) for name, (lo, hi) in bounds.items()}}
    return replace(loops, meta={**loops.meta, "bounds": given})


@notices.keeps_warnings
def diagnose(
    loops: LoopSet,
    model: str = "baseline",
    *,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    candidates: Term | TermGroup | str | Sequence[Term | TermGroup | str] | None = None,
    displacement: str = "auto",
    max_steps: int = MAX_STEPS,
    cross_validate: bool = True,
    discover: bool = True,
    progress: Report | None = None,
) -> Diagnosis:
    """Find which library effects the start ``model`` (a preset) misses on ``loops`` (see the module docstring).

    ``candidates``: terms of your own (:func:`hysid.term`, or model strings ``module:attribute``) scored beside
    the library's effects; each must name its strength. ``bounds`` (``{"w0": (10, 200)}``, any parameter of the start
    model or of a candidate effect) are hard, as the dataset's: every model the diagnosis fits keeps them (:func:`hysid_model.problem.prepare_model`).
    ``displacement``: ``auto`` (the data decide whether the displacement's harmonics are the motion or the
    sensor's, :mod:`hysid.motion`), ``measured``, ``fundamental`` or ``sine``, as :func:`hysid.fit`;
    ``cross_validate`` adds the leave-one-frequency-out gap of every step and judges every effect by it
    (a refit per frequency). ``discover``: where the diagnosis ends unexplained, or adequate only by stacked effects
    (:func:`hysid.diagnosis.contest.stacked`), propose the missing force from the data (:mod:`hysid.diagnosis.discovery`, :func:`hysid.diagnosis.contest.with_discovery`). ``progress(done, total, what)`` is called after every fit: ``done`` of ``total``
    fits, an estimate from the start revised as the diagnosis learns how many effects it names, whose share
    done never falls and is 1 only at the end (:mod:`hysid.diagnosis.tally`). It does not change the result.
    """
    if model not in PRESETS:
        raise HysidInputError(f"the start model must be one of {', '.join(PRESETS)}", param="model", value=model)
    tally = Tally(progress)
    scored = candidate_effects(candidates)
    given = with_given_bounds(loops, model, bounds, scored)
    motion = choose_motion(given, model, displacement, bounds=bounds)
    tally.expect(search_work(max_steps, cross_validate) + (motion.decided_by == "data"))  # and the reading confirmed
    result = search(Harmonics.from_loops(displaced(given, motion.displacement)), model, scored, max_steps, cross_validate, tally)
    flipped = confirm_motion(given, result.final.model, result.final.theta, motion)
    if motion.decided_by == "data":
        tally.done(f"the {motion.displacement} reading of the displacement checked with the final model")
    if flipped is None and result.status != "adequate":
        flipped = other_reading(motion)
    if flipped is not None:
        tally.expect(search_work(max_steps, cross_validate))
        other = search(Harmonics.from_loops(displaced(given, flipped.displacement)), model, scored, max_steps, cross_validate, tally)
        if other.final.bic < result.final.bic:
            result, motion = other, flipped
        else:
            motion.reason += f"; read the other way the diagnosis ends {other.final.bic - result.final.bic:.4g} higher in BIC"
    result.motion = motion
    if discover and (result.status != "adequate" or stacked(result)):
        result = with_discovery(result, cross_validate, tally)
    elif result.status != "adequate":
        result = with_refused(result, refused_base(result, cross_validate, tally), cross_validate, tally)
    tally.finish(f"diagnosis done: {result.final.spec}, {result.status}")
    return result


def other_reading(motion: MotionChoice) -> MotionChoice | None:
    """The reading the data did not choose, to be searched as well where the diagnosis under the chosen one ends
    unexplained (the linear start reads a nonlinear device's odd harmonics as the force's response to the
    displacement's); None where the reading was not the data's choice."""
    if motion.decided_by != "data":
        return None
    other = "fundamental" if motion.displacement == "measured" else "measured"
    return MotionChoice(
        other,
        "data",
        f"{WORDS[other]}: the diagnosis under the reading the {motion.model} start chose ended unexplained",
        dict(motion.chi2),
        motion.model,
        motion.orders,
    )


def search(harmonics: Harmonics, start: str, scored: tuple[str, ...], max_steps: int, cross_validate: bool, tally: Tally) -> Diagnosis:
    """The diagnosis loop of the module docstring on ``harmonics`` from the preset ``start``, scoring the effects ``scored``;
    its fits counted in ``tally``, which expects :func:`search_fits` of them (revised here as rounds and steps come)."""
    done = tally.done
    fit = initial_fit(harmonics, start)
    bounds = soft_bounds(fit.model)
    done(f"start model {start} fitted")
    first = fit
    steps: list[Step] = []
    refused: list[Refused] = []
    expected_rounds, rounds = min(EXPECTED_STEPS, max_steps) + 1, 0
    while True:
        rounds += 1
        if rounds > expected_rounds:  # more steps than expected: this round is to come too
            tally.expect(round_work(cross_validate))
        candidates = score_candidates(fit, harmonics, bounds, scored)
        done(f"step {len(steps) + 1}: {len(candidates)} effects scored")
        impossible = {c.effect: why for c in candidates if (why := implausible_effect(c.effect, harmonics.loops)) is not None}
        candidates = [c for c in candidates if c.effect not in impossible]
        not_identifiable = {c.effect: c.absorbed_by for c in candidates if not c.identifiable}
        trials: list[tuple[tuple[Candidate, ...], np.ndarray | None]] = [((c,), None) for c in contenders(candidates)] if len(steps) < max_steps else []
        pairs = best_pairs(candidates, fit.residual) if trials else None
        if pairs is not None:
            trials.append(pairs[0])
        together = joint_contender(candidates, harmonics) if trials else None
        if together is not None and all({c.effect for c in t} != {c.effect for c in together} for t, _ in trials):
            trials.append((together, None))
        work = [weight(fit, tuple(c.effect for c in members)) for members, _ in trials]
        tally.expect(sum(work) + (weight(fit, tuple(c.effect for c in pairs[1][0])) if pairs else 0) - EXPECTED_REFITS)  # as the scores tell
        refits: dict[tuple[str, ...], Fit] = {}
        scores = {c.effect: c.score for c in candidates}
        for (members, joint), w in zip(trials, work):
            effects = tuple(c.effect for c in members)
            refits[effects] = profile_errors(refit(fit, harmonics, members, bounds, joint))
            done(f"step {len(steps) + 1}: refitted with {label(effects)}", w)
        verdicts = {effects: judge(fit, r, effects, harmonics, beside=beside(refits, effects)) for effects, r in refits.items()}
        for effects, why in [(e, degenerate(refits[e], e)) for e, v in verdicts.items() if v is None]:
            rivals = [r.bic for e, r in refits.items() if e != effects and verdicts[e] is None and degenerate(r, e) is None]
            if why is not None and degenerate_gives_way(refits[effects].bic, rivals):  # another explains as much without degenerating
                verdicts[effects] = why
        if pairs is not None:  # the pair of others counts only where it beats the greedy pair and every single by BIC_MARGIN
            others, (members, joint) = tuple(c.effect for c in pairs[0][0]), pairs[1]
            greedy = refit(fit, harmonics, members, bounds, joint)
            done(
                f"step {len(steps) + 1}: refitted with {label(tuple(c.effect for c in members))} (the greedy pair)",
                weight(fit, tuple(c.effect for c in members)),
            )
            rivals = [greedy.bic] + [r.bic for e, r in refits.items() if len(e) == 1 and verdicts[e] is None]
            if verdicts[others] is None and refits[others].bic > min(rivals) - BIC_MARGIN:
                verdicts[others] = (
                    f"fits no better than {label(tuple(c.effect for c in members))} together or one effect alone (BIC {refits[others].bic - min(rivals):+.1f})"
                )
        ranked = sorted((r.bic, effects) for effects, r in refits.items() if verdicts[effects] is None)
        chosen = None
        if cross_validate and not ranked:
            tally.expect(-1)  # no held-out check this round
        for checked, (_, effects) in enumerate(ranked):
            if cross_validate:
                w = weight(fit, effects)
                tally.expect(w - (checked == 0))  # one check was expected
                verdicts[effects] = held_out(fit, refits[effects], harmonics)
                done(f"step {len(steps) + 1}: {label(effects)} checked on held-out frequencies", w)
            if verdicts[effects] is None:
                chosen = effects
                break
        rejected = {label(e): v for e, v in verdicts.items() if v is not None}
        if chosen is None:
            refused = shape_refused(fit, refits, verdicts, scores, harmonics)
            break
        best = refits[chosen]
        passed = [e for _, e in ranked if e != chosen and verdicts[e] is None]
        confusable = [label(e) for e in passed if refits[e].bic - best.bic < BIC_MARGIN]
        reasons = {
            label(e): v or f"fits worse than {label(chosen)} (BIC +{refits[e].bic - best.bic:.1f})"
            for e, v in verdicts.items()
            if e != chosen and label(e) not in confusable
        }
        if len(chosen) == 1:
            steps.append(Step(effect=chosen[0], confusable_with=confusable, score=scores[chosen[0]], before=fit, after=best, rejected=reasons))
        else:
            steps += pair_steps(fit, harmonics, chosen, refits, bounds, candidates, confusable, reasons, tally)
        fit = steps[-1].after
        bounds.update(soft_bounds(fit.model))
    tally.expect(-max(expected_rounds - rounds, 0) * round_work(cross_validate) + len(steps) + 1 - expected_rounds)  # rounds never run; the gaps
    fit, pruned = prune(fit, harmonics)  # the last step: terms consistent with zero dropped
    tally.expect(bool(pruned))  # and the gap after it
    done(f"terms consistent with zero looked for{': dropped ' + ', '.join(pruned) if pruned else ''}")
    fits = [first] + [s.after for s in steps] + ([fit] if pruned else [])

    def gap(f: Fit, i: int) -> GapMetrics:
        metrics = gap_metrics(f, harmonics, cross_validate)
        done(f"gap after {'the start' if i == 0 else f'step {i}'}")
        return metrics

    return Diagnosis(
        harmonics=harmonics,
        start=first,
        steps=steps,
        not_identifiable=not_identifiable,
        rejected=rejected,
        gap=[gap(f, i) for i, f in enumerate(fits)],
        references=references(harmonics),
        **final_fields(fit, harmonics),
        last_scores=candidates,
        impossible=impossible,
        pruned=pruned,
        shape_refused=refused,
    )


def shape_refused(
    fit: Fit, refits: dict[tuple[str, ...], Fit], verdicts: dict[tuple[str, ...], str | None], scores: dict[str, float], harmonics: Harmonics
) -> list[Refused]:
    """The single effects of the last round (added to ``fit``) refused by rule 9 alone (:func:`hysid.diagnosis.acceptance.own_shape`):
    every other rule of :func:`hysid.diagnosis.acceptance.judge` passed and no shape parameter degenerates; best BIC first.
    A refused single effect's verdict is then rule 9's: judge's rules are the same but for rule 9, and a degenerate
    one's is degenerate's. The held-out frequencies (rule 8) are checked where discovery starts from one
    (:func:`hysid.diagnosis.contest.with_discovery`)."""
    out = []
    for effects, after in sorted(refits.items(), key=lambda item: item[1].bic):
        why = verdicts[effects]
        if len(effects) > 1 or why is None:
            continue
        if judge(fit, after, effects, harmonics, own=False) is None and degenerate(after, effects) is None:
            out.append(Refused(Step(effect=effects[0], confusable_with=[], score=scores[effects[0]], before=fit, after=after, rejected={}), why))
    return out


def beside(refits: dict[tuple[str, ...], Fit], effects: tuple[str, ...]) -> list[Fit]:
    """The other single effects of a round's ``refits``, each added to the same model: what rule 9 projects out when it
    judges the refit of ``effects`` (:func:`hysid.diagnosis.acceptance.own_shape`)."""
    return [r for e, r in refits.items() if len(e) == 1 and e[0] not in effects]


def pair_steps(
    fit: Fit,
    harmonics: Harmonics,
    pair: tuple[str, ...],
    refits: dict[tuple[str, ...], Fit],
    bounds: dict[str, tuple[float, float]],
    candidates: list[Candidate],
    confusable: list[str],
    reasons: dict[str, str],
    tally: Tally,
) -> list[Step]:
    """The two steps that name ``pair``: the member whose refit alone fits better first (its single refit in
    between, refitted here if this round did not), then the joint refit."""
    by_effect = {c.effect: c for c in candidates}
    for effect in pair:
        if (effect,) not in refits:
            tally.expect(work := weight(fit, (effect,)))
            refits[(effect,)] = profile_errors(refit(fit, harmonics, (by_effect[effect],), bounds))
            tally.done(f"refitted with {effect} alone", work)
    first, second = sorted(pair, key=lambda e: refits[(e,)].bic)
    scores = {c.effect: c.score for c in candidates}
    return [
        Step(effect=first, confusable_with=confusable, score=scores[first], before=fit, after=refits[(first,)], rejected=reasons, joint_with=second),
        Step(effect=second, confusable_with=[], score=scores[second], before=refits[(first,)], after=refits[pair], rejected={}, joint_with=first),
    ]
