"""Discovery's place in a diagnosis: the proposals sought where the library runs out, and which one is kept.

Where the library search (:mod:`.selection`) ends unexplained, a force is proposed from the data
(:func:`hysid.diagnosis.discovery.propose`) from the start model and from the final library model; the
proposals the acceptance rules take (:mod:`.acceptance`) compete with each other and with the library's
final model (:func:`choose`), and the one kept replaces the library effects it explains as well.
"""

from __future__ import annotations

from dataclasses import replace

from hysid.criteria import BIC_MARGIN
from hysid.diagnosis.discovery import Proposed, propose
from hysid.diagnosis.fitting import Fit, final_identifiability, soft_bounds
from hysid.diagnosis.metrics import gap_metrics
from hysid.diagnosis.naming import adequacy, loops_linear, residual_signature
from hysid.diagnosis.result import Diagnosis
from hysid.diagnosis.tally import Tally


def with_discovery(result: Diagnosis, cross_validate: bool, tally: Tally) -> Diagnosis:
    """``result`` (unexplained) with a force proposed from the data where one is taken (:func:`hysid.diagnosis.discovery.propose`).

    Proposals are sought from the start model and from the final library model. Of those taken by the
    acceptance rules, the one with the lowest BIC is kept, but the one added to the start model wherever it
    is within ``BIC_MARGIN`` of it and of the final library model: the library effects named on the way are
    then set aside, since one proposed law explains the loops as well as they do together (no library
    effect is kept as a substitute for a law the library lacks). The gap table gains the model with the
    proposed term. Where every loop on its own is linear within the noise (:func:`hysid.diagnosis.naming.loops_linear`),
    no force of x and v is sought: the loops show none."""
    harmonics = result.harmonics
    if loops_linear(harmonics):
        return replace(
            result,
            discovery={
                result.final.spec: (
                    f"each loop on its own is linear within the noise (linear per loop {result.references.linear_per_loop:.4g}, and coefficient "
                    "by coefficient): what the model misses is how its stiffness, damping or mass change from loop to loop, not a force "
                    "of x and v; nothing proposed"
                )
            },
        )
    bases = [result.start] + ([result.final] if result.final is not result.start else [])
    tally.expect(len(bases) * (2 + int(cross_validate)) + 1)
    tried, found = {}, []
    for base in bases:
        proposal, why = propose(base, harmonics, soft_bounds(base.model), cross_validate, tally)
        tried[base.spec] = why
        if proposal is not None:
            found.append(proposal)
    best, verdicts = choose(found, result.start, result.final)
    tried.update(verdicts)
    if best is None:
        tally.expect(-1)
        return replace(result, discovery=tried)
    steps, pruned, gaps, set_aside = result.steps, result.pruned, list(result.gap), {}
    if best.base is result.start and result.steps:
        set_aside = {
            s.effect: f"the proposed {best.name} alone explains the loops as well (BIC {best.fit.bic - result.final.bic:+.1f} against {result.final.spec})"
            for s in result.steps
        }
        steps, pruned, gaps = [], {}, gaps[:1]
    fit = best.fit
    check = adequacy(fit, harmonics)
    gaps.append(gap_metrics(fit, harmonics, cross_validate))
    tally.done(f"gap after the proposed {best.name}")
    return replace(
        result,
        steps=steps,
        pruned=pruned,
        final=fit,
        status="adequate" if check.adequate else "unexplained",
        unexplained=None if check.adequate else residual_signature(fit, harmonics),
        gap=gaps,
        identifiability=final_identifiability(fit, harmonics),
        proposed=[best],
        set_aside=set_aside,
        discovery=tried,
    )


def choose(found: list[Proposed], start: Fit, final: Fit) -> tuple[Proposed | None, dict[str, str]]:
    """Of the proposals ``found`` (each taken by the acceptance rules), the one kept (:func:`with_discovery`: the lowest
    BIC, but the one added to ``start`` wherever it is within ``BIC_MARGIN`` of it and of the library's ``final``),
    and what came of each, by the spec of the model it was added to: kept, or not kept and why."""
    best = min(found, key=lambda p: p.fit.bic, default=None)
    alone = next((p for p in found if p.base is start), None)
    if alone is not None and best is not None and alone.fit.bic < min(best.fit.bic, final.bic) + BIC_MARGIN:
        best = alone
    elif best is alone:
        best = None  # added to the start model, it explains less than the library's effects
    verdicts = {}
    for p in found:
        said = f"{p.notation} added to {p.base.spec} passes the acceptance rules"
        if p is best:
            verdicts[p.base.spec] = f"{said}: kept"
        elif best is None:
            verdicts[p.base.spec] = f"{said} but is not kept: {final.spec} explains the loops better (BIC {final.bic - p.fit.bic:+.1f})"
        else:
            verdicts[p.base.spec] = (
                f"{said} but is not kept: {best.name} added to {best.base.spec} explains the loops as well or "
                f"better (BIC {best.fit.bic - p.fit.bic:+.1f})" + (" with fewer effects" if best is alone else "")
            )
    return best, verdicts
