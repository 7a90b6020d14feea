"""``hysid bench proposals``: discovery proposes no force law where nothing is missing, over :data:`SEEDS` noise seeds
of two controls. The statistics of ``tests/test_discovery.py``.

The controls are specimens of ``hysid bench discovery`` (:mod:`hysid.bench.discovery_cases`: six loops, 1 % force
noise) whose model holds their whole force: the baseline alone fitted with the baseline, and the baseline with
Coulomb friction (Eq. 2.5) fitted with it (from the truth's friction, so that the fit is the optimum). On each seed
discovery (:func:`hysid.diagnosis.discovery.propose`) is asked for a law beside the fitted model; the criterion
(:func:`verdict`): at most :data:`ALLOWED` proposals per control over the seeds. ``tests/test_discovery.py`` reads
the committed result and runs each control's cheapest seed again live; :func:`definitions_hash` (of this file)
ties the two.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from hysid.bench import source_hash, sweep
from hysid.bench import verdict as pass_word
from hysid.bench.discovery_cases import loops_of, truth_model
from hysid.diagnosis.discovery import Proposed, propose
from hysid.diagnosis.tally import Tally
from hysid.harmonic_fits import Fit, fit_objective, initial_fit, make_model, soft_bounds
from hysid.report import jsondoc
from hysid_model.harmonics import HarmonicObjective, Harmonics

NOISE_PCT = 1.0
"""The force noise of the specimens, % of each record's peak."""
SEEDS = range(100, 120)
CONTROLS: dict[str, tuple[str, ...]] = {"no_effect": (), "coulomb_friction": ("coulomb_friction",)}
"""Each control's hidden law of :mod:`hysid.bench.discovery_cases` and the effects fitted beside the baseline."""
ALLOWED = 1
"""Proposals a control may get over :data:`SEEDS`."""


def proposal(law: str, seed: int = 0, start: str = "baseline", effects: tuple[str, ...] = ()) -> tuple[Proposed | None, str, Fit]:
    """What discovery proposes on the specimen with ``law`` from the ``start`` model plus ``effects`` fitted (from
    the truth's values of those effects), why, and that fit."""
    harmonics = Harmonics.from_loops(loops_of(law, NOISE_PCT, seed))
    fit = initial_fit(harmonics, start)
    if effects:
        model = make_model(harmonics, start, effects, soft_bounds(fit.model))
        truth = truth_model(law)[1]
        fit = fit_objective(HarmonicObjective(harmonics, model), start, effects, [model.from_dict({**fit.params(), **truth})])
    found, why = propose(fit, harmonics, soft_bounds(fit.model), False, Tally())
    return found, why, fit


def outcome(control: str, seed: int) -> dict[str, Any]:
    """One control on one seed: the law proposed (its notation, or None) and the CPU time it took."""
    cpu = time.process_time()
    found, _, _ = proposal(control, seed=seed, effects=CONTROLS[control])
    return {"proposed": None if found is None else found.notation, "cpu_s": time.process_time() - cpu}


def verdict(outcomes: dict[str, dict[str, dict[str, Any]]]) -> dict[str, Any]:
    """The criterion: every seed of :data:`SEEDS` run for every control, and no control with more than
    :data:`ALLOWED` proposals; the proposals per control."""
    counts = {c: sum(r["proposed"] is not None for r in outcomes.get(c, {}).values()) for c in CONTROLS}
    complete = all(sorted(outcomes.get(c, {})) == sorted(map(str, SEEDS)) for c in CONTROLS)
    return {"seeds": len(SEEDS), "proposals": counts, "ok": complete and all(n <= ALLOWED for n in counts.values())}


def run(progress: Callable[[int, int, str], None] | None = None) -> dict[str, Any]:
    """Discovery proposes a law on at most 1 of 20 noise seeds of each control whose model is complete (the statistics
    tests/test_discovery.py reads).

    ``progress(done, total, what)`` is called as each proposal ends."""
    say = lambda control, seed, record: f"{control} seed {seed}: {record['proposed'] or 'nothing proposed'}"
    return jsondoc.plain(sweep("proposals", __file__, CONTROLS, SEEDS, outcome, say, verdict, progress))


def to_text(result: dict[str, Any]) -> str:
    counts = ", ".join(f"{c} {n} of {result['seeds']}" for c, n in result["proposals"].items())
    return f"hysid bench proposals: laws proposed where nothing is missing: {counts} (at most {ALLOWED} each)  {pass_word(result['ok'])}  ({result['cpu_s']:.0f} s CPU)"


def definitions_hash() -> str:
    """sha256 of this file: the controls, their seeds and the criterion as the bench ran them."""
    return source_hash(__file__)
