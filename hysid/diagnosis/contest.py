"""Discovery's place in a diagnosis: where a force is proposed from the data, and which proposal is kept.

Discovery (:func:`hysid.diagnosis.discovery.propose`) runs where the library search (:mod:`.selection`)
ends unexplained, from the start model, from the final library model and from the refit of a library effect refused
there by its own shape alone (:func:`refused_base`: rule 9 of :mod:`.acceptance`, every other rule passed; a
device with two mechanisms, one in the library and one not); and where it ends adequate only by
stacking effects (:func:`stacked`: two or more, or a sensor effect), from the start model, so that one law
the library lacks can compete with the library effects that stand in for it together. A proposal added to the
model whose last round refused library effects by their own shape alone is judged by rule 9 with their forces as
the contenders beside it (:func:`hysid.diagnosis.acceptance.own_shape`: a memory term for one Jenkins slider beside
a Bouc-Wen spring for the other, whose strength loop by loop would otherwise take up the spring's misfit). Of the
proposals the acceptance rules take (:mod:`.acceptance`), :func:`choose` keeps one, or none:

* where the library search ended unexplained, the one with the lowest BIC, but the one added to the start
  model wherever it is within ``BIC_MARGIN`` of it and of the final library model (one law explains the
  loops as well as the library effects together: they are set aside). Kept where it was added to the refused
  effect, that effect is named with it, and the discovery text says it was refused alone and why;
* where it ended adequate by stacking, the one added to the start model only where it has fewer parameters
  than the effects stacked and a BIC lower than theirs by ``BIC_MARGIN``: the library's model is at the
  noise already, and a law replaces its names only where the data prefer it;
* never a law that is a library effect's own shape (:func:`library_shape`): where one library effect of the
  final model, refitted alone on the start model, explains the loops within ``BIC_MARGIN`` of the law added
  there (or better), the law is that effect (a fitted sgn v where Coulomb friction would do), and the
  library's name stands.

Where no proposal is kept (or discovery is off) and a library effect was refused by its own shape alone, it is
named after all as the library's best (:func:`with_refused`), with why it is not the loops' exact shape; the
diagnosis stays unexplained.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from hysid.criteria import BIC_MARGIN
from hysid.diagnosis.acceptance import held_out, judge
from hysid.diagnosis.discovery import Proposed, propose
from hysid.diagnosis.metrics import gap_metrics
from hysid.diagnosis.naming import final_fields, loops_linear
from hysid.diagnosis.refits import refit, weight
from hysid.diagnosis.result import Diagnosis, Refused
from hysid.diagnosis.scoring import score_candidates
from hysid.diagnosis.tally import Tally
from hysid.harmonic_fits import Fit, fit_objective, make_model, profile_errors, soft_bounds
from hysid_model.harmonics import HarmonicObjective
from hysid_model.model import effect_term
from hysid_model.terms import MeasurementTerm


def stacked(result: Diagnosis) -> bool:
    """Whether ``result``'s final library model holds two effects or more, or a sensor effect (a
    :class:`hysid_model.terms.MeasurementTerm`): where it is adequate, discovery still competes with them."""
    effects = result.final.effects
    return len(effects) > 1 or any(isinstance(effect_term(e), MeasurementTerm) for e in effects)


def added_parameters(fit: Fit, start: Fit) -> int:
    """The parameters ``fit`` searches beyond the ``start`` model's."""
    return fit.model.dim - start.model.dim


def alone(result: Diagnosis, effect: str, tally: Tally) -> Fit:
    """The start model of ``result`` with its library ``effect`` alone: the first step's refit where that named
    it (a pair's first member is refitted alone there too), else refitted here from the start's scores."""
    first = result.steps[0] if result.steps else None
    if first is not None and first.effect == effect and first.before is result.start:
        return first.after
    start, harmonics = result.start, result.harmonics
    bounds = soft_bounds(start.model)
    tally.expect(work := weight(start, (effect,)))
    (candidate,) = score_candidates(start, harmonics, bounds, (effect,))
    fit = profile_errors(refit(start, harmonics, (candidate,), bounds))
    tally.done(f"discovery: {effect} refitted alone on {start.spec}", work)
    return fit


def library_shape(proposal: Proposed, result: Diagnosis, tally: Tally) -> str | None:
    """Why ``proposal`` (added to the start model) is a library effect's own shape, or None: an effect of the
    final library model, refitted alone on the start model (:func:`alone`), whose BIC is within ``BIC_MARGIN``
    of the proposal's or lower."""
    for effect in result.final.effects:
        fit = alone(result, effect, tally)
        if fit.bic < proposal.fit.bic + BIC_MARGIN:
            return f"it is {effect}'s own shape: {effect} alone explains the loops as well (BIC {fit.bic - proposal.fit.bic:+.1f})"
    return None


def with_discovery(result: Diagnosis, cross_validate: bool, tally: Tally) -> Diagnosis:
    """``result`` (unexplained, or adequate by :func:`stacked` effects) with a force proposed from the data where
    one is kept (module docstring, :func:`choose`): the library effects named on the way are then set aside where
    the law was added to the start model, and the gap table gains the model with the proposed term. Where every
    loop on its own is linear within the noise (:func:`hysid.diagnosis.naming.loops_linear`), no force of x and v
    is sought: the loops show none."""
    harmonics, adequate = result.harmonics, result.status == "adequate"
    if loops_linear(harmonics):
        return result if adequate else replace(result, discovery={result.final.spec: linear_loops(result)})
    start, final = result.start, result.final
    bases = [start] + ([final] if final is not start and not adequate else [])
    beside = None if adequate else refused_base(result, cross_validate, tally)
    bases += [beside.step.after] if beside is not None else []
    tally.expect(len(bases) * (2 + int(cross_validate)) + 1)
    tried, found = {}, []
    for base in bases:
        contenders = [r.step.after for r in result.shape_refused if r.step.before is base]
        proposal, why = propose(base, harmonics, soft_bounds(base.model), cross_validate, tally, contenders)
        tried[base.spec] = why
        if proposal is not None:
            found.append(proposal)
    best, verdicts = choose(found, start, final, adequate)
    refused = {}
    if best is not None and best.base is start and final.effects and (shape := library_shape(best, result, tally)) is not None:
        refused[start.spec] = f"{passes(best)} but is not kept: {shape}"
        found.remove(best)  # then the law added to the final library model may still be kept
        best, verdicts = choose(found, start, final, adequate)
    if best is not None and beside is not None and best.base is beside.step.after and (lacking := needed_beside(best, beside.step.effect, tally)) is not None:
        refused[best.base.spec] = f"{passes(best)} but is not kept: {lacking}"
        found.remove(best)
        best, verdicts = choose(found, start, final, adequate)
    tried.update(verdicts | refused)
    if best is None:
        tally.expect(-1)
        return with_refused(replace(result, discovery=tried), beside, cross_validate, tally)
    steps, pruned, gaps, set_aside, rejected = result.steps, result.pruned, list(result.gap), {}, result.rejected
    if beside is not None and best.base is beside.step.after:
        effect, taken = beside.step.effect, f"taken with the proposed {best.name}; alone it was refused because it {beside.why}"
        tried[best.base.spec] += f"; {effect} is {taken}"
        rejected = {**rejected, effect: taken}
        steps, pruned, gaps = steps + [beside.step], {}, gaps[: len(steps) + 1]  # from the library model before pruning
        tally.expect(1)
        gaps.append(gap_metrics(beside.step.after, harmonics, cross_validate))
        tally.done(f"gap after {effect}, taken with the proposed {best.name}")
    if best.base is start and result.steps:
        how = "better with fewer parameters" if adequate else "as well"
        set_aside = {
            s.effect: f"the proposed {best.name} alone explains the loops {how} (BIC {best.fit.bic - final.bic:+.1f} against {final.spec})"
            for s in result.steps
        }
        steps, pruned, gaps = [], {}, gaps[:1]
    fit = best.fit
    gaps.append(gap_metrics(fit, harmonics, cross_validate))
    tally.done(f"gap after the proposed {best.name}")
    return replace(
        result,
        steps=steps,
        pruned=pruned,
        rejected=rejected,
        gap=gaps,
        **final_fields(fit, harmonics),
        proposed=[best],
        set_aside=set_aside,
        discovery=tried,
    )


def refused_base(result: Diagnosis, cross_validate: bool, tally: Tally) -> Refused | None:
    """The library effect refused by rule 9 alone (:attr:`hysid.diagnosis.result.Diagnosis.shape_refused`) that also
    predicts held-out frequencies better (rule 8; the first by BIC that does), or None: a device with two mechanisms,
    one in the library and one not, leaves beside the library's a force of another shape, and discovery may find it
    added to that effect's refit (a proposal kept there names the effect with it, :func:`choose`)."""
    for refused in result.shape_refused:
        if not cross_validate:
            return refused
        step = refused.step
        tally.expect(work := weight(step.before, (step.effect,)))
        why = held_out(step.before, step.after, result.harmonics)
        tally.done(f"discovery: {step.effect}, refused by its own shape alone, checked on held-out frequencies", work)
        if why is None:
            return refused
    return None


def with_refused(result: Diagnosis, refused: Refused | None, cross_validate: bool, tally: Tally) -> Diagnosis:
    """``result`` (unexplained) with the library effect ``refused`` by its own shape alone (:func:`refused_base`) named
    after all, where no proposed law explains the loops better (or discovery is off): it passed every other rule,
    held-out frequencies included, so it is the best the library has for what the loops hold, and the report says
    that it is not that force's exact shape (why rule 9 refused it) and that the loops stay unexplained. A real
    device whose law is near a library effect's (a Bouc-Wen spring whose shape changes a little with amplitude and
    frequency) keeps the library's name rather than none."""
    if refused is None or result.status == "adequate":
        return result
    step, harmonics = refused.step, result.harmonics
    taken = f"taken as the library's best for these loops, though not their exact shape: it {refused.why}; no law proposed from the data explains them better"
    steps, gaps = result.steps + [step], list(result.gap[: len(result.steps) + 1])  # from the library model before pruning
    tally.expect(1)
    gaps.append(gap_metrics(step.after, harmonics, cross_validate))
    tally.done(f"gap after {step.effect}, refused alone by its own shape, taken as the library's best")
    return replace(result, steps=steps, pruned={}, rejected={**result.rejected, step.effect: taken}, gap=gaps, **final_fields(step.after, harmonics))


def needed_beside(proposal: Proposed, effect: str, tally: Tally) -> str | None:
    """Why the refused library ``effect`` is not needed beside ``proposal`` (added to its refit, :func:`refused_base`),
    or None: the proposal's model without the effect, refitted from its values, must take the effect back by the
    acceptance rules (:func:`hysid.diagnosis.acceptance.judge`) but its own shape (rule 9, which refused it alone and is
    what the proposal is there for: a Bouc-Wen spring for one of two Jenkins sliders, 0.82 to 1.08 times its strength
    loop by loop beside a term for the other, is no slider's exact shape). A term that only bends the
    effect's force into another shape (Coulomb friction and a term that makes it a Stribeck curve) leaves the effect
    nothing of its own there: the two are a substitute for one law the library lacks, not two mechanisms."""
    fit, harmonics = proposal.fit, proposal.fit.objective.harmonics
    effects = tuple(e for e in fit.effects if e != effect)
    model = make_model(harmonics, fit.start, effects, soft_bounds(fit.model), fit.freed)
    row = np.clip(model.from_dict(fit.params()), model.bounds[:, 0], model.bounds[:, 1])
    tally.expect(work := weight(fit, ()))
    without = fit_objective(HarmonicObjective(harmonics, model), fit.start, effects, [row])
    tally.done(f"discovery: {proposal.name} refitted without {effect}", work)
    why = judge(without, fit, (effect,), harmonics, own=False)
    return None if why is None else f"{effect} added to {without.spec} is not taken ({why}): {proposal.name} only reshapes it"


def linear_loops(result: Diagnosis) -> str:
    """Why nothing is proposed where every loop on its own is linear within the noise."""
    return (
        f"each loop on its own is linear within the noise (linear per loop {result.references.linear_per_loop:.4g}, and coefficient "
        "by coefficient): what the model misses is how its stiffness, damping or mass change from loop to loop, not a force "
        "of x and v; nothing proposed"
    )


def passes(proposal: Proposed) -> str:
    return f"{proposal.notation} added to {proposal.base.spec} passes the acceptance rules"


def replaces(proposal: Proposed, start: Fit, final: Fit) -> bool:
    """Whether ``proposal`` (added to ``start``) replaces the adequate library model ``final``: fewer parameters
    than the effects stacked there, and a BIC lower by ``BIC_MARGIN``."""
    return added_parameters(proposal.fit, start) < added_parameters(final, start) and proposal.fit.bic < final.bic - BIC_MARGIN


def choose(found: list[Proposed], start: Fit, final: Fit, adequate: bool = False) -> tuple[Proposed | None, dict[str, str]]:
    """Of the proposals ``found`` (each taken by the acceptance rules), the one kept by the module docstring's
    rules (the own-shape rule apart, :func:`library_shape`: it needs refits) where the library's ``final`` model ends
    unexplained or, with ``adequate``, at the noise by stacked effects; and what came of each, by the spec of
    the model it was added to: kept, or not kept and why."""
    best = min(found, key=lambda p: p.fit.bic, default=None)
    first = next((p for p in found if p.base is start), None)
    if adequate:
        best = first if first is not None and replaces(first, start, final) else None
    elif first is not None and best is not None and first.fit.bic < min(best.fit.bic, final.bic) + BIC_MARGIN:
        best = first
    elif best is first:
        best = None  # added to the start model, it explains less than the library's effects
    verdicts = {}
    for p in found:
        said = passes(p)
        if p is best:
            verdicts[p.base.spec] = f"{said}: kept"
        elif best is None and adequate:
            verdicts[p.base.spec] = (
                f"{said} but is not kept: {final.spec} is at the noise, and the law replaces it only with fewer parameters "
                f"({added_parameters(p.fit, start)} against {added_parameters(final, start)}) and a BIC lower by {BIC_MARGIN:g} "
                f"({p.fit.bic - final.bic:+.1f})"
            )
        elif best is None:
            verdicts[p.base.spec] = f"{said} but is not kept: {final.spec} explains the loops better (BIC {final.bic - p.fit.bic:+.1f})"
        else:
            verdicts[p.base.spec] = (
                f"{said} but is not kept: {best.name} added to {best.base.spec} explains the loops as well or "
                f"better (BIC {best.fit.bic - p.fit.bic:+.1f})" + (" with fewer effects" if best is first else "")
            )
    return best, verdicts
