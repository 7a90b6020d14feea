"""The current model refitted with one or two new effects, from several starts: an effect is judged at its best fit.

A new effect's strength is 0 in the current model, where its shape
parameters (a yield displacement, a relaxation time) are undefined; a single
polish from there may land in a poor optimum and make a real effect look
useless. So every refit polishes its ``STARTS`` best starting points, chosen
by their chi^2 among:

* the previous model's optimum with the effect's one-step estimate of its
  strength (:mod:`.scoring`) at each of its best shapes, scaled along a line
  (``LINE_SEARCH``);
* for two effects, their joint one-step estimate along the same line;
* the points each effect's term reads off the loops' shape
  (:meth:`hysid_model.terms.Term.data_starts`, e.g. a Bouc-Wen spring's
  initial stiffness and yield from the reversals and the plateau), on the
  previous model's optimum.

A refit that brings memory or a non-smooth force into the model (a Bouc-Wen
spring, Coulomb friction: :func:`island.memetic.needs_islands`) is searched by
the memetic islands ``hysid fit`` uses on such models
(:func:`island.memetic.memetic_search`, from the same starts, ``SEARCH_BUDGET``
evaluations), then polished: a polish alone lands in a poor optimum there for
some starts, and an effect must not be judged by one.

An effect with a parameter it fixes by default (Bouc-Wen's exponent, n = 1,
the closed form) is refitted with it free as well, from that refit's optimum,
the shapes with n = 2 and the loops' own starts; the free variant is kept
where its BIC is lower by ``BIC_MARGIN`` (Bouc-Wen as practitioners fit it,
the ``mr_damper`` preset where the start is the baseline).

Where the motion is the fundamental (the displacement's harmonics the
sensor's), a Bouc-Wen spring and a channel delay are also refitted together
as one contender (:func:`joint_contender`), judged as any other.
"""

from __future__ import annotations

import numpy as np

from hysid.criteria import BIC_MARGIN
from hysid.diagnosis.scoring import Candidate
from hysid.diagnosis.tally import MEMORY_FIT_WEIGHT
from hysid.harmonic_fits import Fit, fit_objective, make_model
from hysid_model.harmonics import HarmonicObjective, Harmonics
from hysid_model.model import Model, effect_term
from island.memetic import memetic_search, needs_islands

JOINT = ("bouc_wen", "channel_delay")
"""Effects refitted together as one contender where the motion is the fundamental (:func:`joint_contender`)."""
LINE_SEARCH = (0.25, 0.5, 1.0, 2.0, 4.0)
"""Multiples of the one-step estimate tried before polishing."""
STARTS = 3
"""Starting points polished per refit (the best by chi^2, distinct)."""
SEARCH_BUDGET = 5000
"""Evaluations of the memetic search of a refit that brings memory or a non-smooth force into the model
(half of ``hysid fit``'s: the diagnosis' harmonic objective is smooth in the rest, and starts near the optimum)."""


def joint_contender(candidates: list[Candidate], harmonics: Harmonics) -> tuple[Candidate, ...] | None:
    """A Bouc-Wen spring and a channel delay as one contender (refitted together, the exponent freed as for
    any Bouc-Wen refit), where the displacement is read as the fundamental (its harmonics the sensor's) and
    both are candidates the data can identify: a wire-rope isolator's loops behind a delaying chain, which
    neither explains alone well enough to be taken first. None elsewhere."""
    by_effect = {c.effect: c for c in candidates if c.physical and c.identifiable}
    if harmonics.loops.motion != "fundamental" or not set(JOINT) <= set(by_effect):
        return None
    return tuple(by_effect[e] for e in JOINT)


def data_starts(effect: str, harmonics: Harmonics, free: list[str]) -> list[dict[str, float]]:
    """The starting points ``effect``'s term reads off the loops (none where it reads nothing), with values for
    the parameters of ``free`` it fixes by default."""
    return effect_term(effect).data_starts(harmonics.loops, free)


def starting_rows(fit: Fit, model: Model, harmonics: Harmonics, candidates: tuple[Candidate, ...], joint: np.ndarray | None) -> np.ndarray:
    """Candidate parameter vectors of ``model`` (the current one plus ``candidates``' effects), see the module docstring."""
    terms = [effect_term(c.effect) for c in candidates]
    base = {**{p.name: 0.0 for t in terms for p in t.params}, **fit.params()}
    strengths = [model.names.index(t.strength) for t in terms]
    scale = np.array(LINE_SEARCH)
    rows = []
    for i, c in enumerate(candidates):
        for shape, one_step in c.starts:
            others = {k: v for j, other in enumerate(candidates) if j != i for k, v in other.starts[0][0].items()} if c.starts else {}
            line = np.repeat(model.from_dict({**base, **others, **shape})[None, :], scale.size, axis=0)
            line[:, strengths[i]] = one_step * scale
            if joint is not None:
                for j, s in enumerate(joint):
                    line[:, strengths[j]] = s * scale
            rows.append(line)
    for c in candidates:
        for point in data_starts(c.effect, harmonics, model.names):
            shapes = {k: v for other in candidates if other.starts for k, v in other.starts[0][0].items()}
            rows.append(model.from_dict({**base, **shapes, **point})[None, :])
    if not rows:
        rows.append(model.from_dict(base)[None, :])
    return np.clip(np.concatenate(rows), model.bounds[:, 0], model.bounds[:, 1])


def refit(fit: Fit, harmonics: Harmonics, candidates: tuple[Candidate, ...], bounds: dict[str, tuple[float, float]], joint: np.ndarray | None = None) -> Fit:
    """The current ``fit`` plus the effects of ``candidates`` (one, or two with their ``joint`` one-step strengths),
    polished from its ``STARTS`` best distinct starting points (module docstring); the best polish is the refit."""
    effects = fit.effects + tuple(c.effect for c in candidates)
    model = make_model(harmonics, fit.start, effects, bounds, fit.freed)
    hard = needs_islands(model) and not needs_islands(fit.model)
    fixed = best_of(HarmonicObjective(harmonics, model), fit.start, effects, starting_rows(fit, model, harmonics, candidates, joint), hard)
    freeable = [p.name for c in candidates for p in effect_term(c.effect).params if not p.vary and p.name in model.fixed]
    if not freeable:
        return fixed
    wider = model.vary(*freeable)
    values = fixed.params()
    rows = [wider.from_dict({**values, **{n: model.fixed[n] for n in freeable}})]
    rows += [wider.from_dict({**values, **{n: float(np.clip(2.0 * model.fixed[n], *wider.bounds[wider.names.index(n)])) for n in freeable}})]
    rows += [wider.from_dict({**values, **point}) for c in candidates for point in data_starts(c.effect, harmonics, wider.names) if set(freeable) <= set(point)]
    free = best_of(HarmonicObjective(harmonics, wider), fit.start, effects, np.clip(np.array(rows), wider.bounds[:, 0], wider.bounds[:, 1]), hard)
    return free if free.bic < fixed.bic - BIC_MARGIN else fixed


def best_of(objective: HarmonicObjective, start: str, effects: tuple[str, ...], rows: np.ndarray, search: bool = False) -> Fit:
    """The fit polished from the ``STARTS`` best distinct ``rows`` (by chi^2) of ``objective``; with ``search``,
    from what the memetic islands find from them as well."""
    rows = np.unique(rows, axis=0)
    order = np.argsort(objective(rows), kind="stable")
    starts = [rows[j] for j in order[:STARTS]]
    if search:
        starts.insert(0, memetic_search(objective, starts, seed=0, budget=SEARCH_BUDGET).theta)
    return fit_objective(objective, start, effects, starts)


def weight(fit: Fit, effects: tuple[str, ...]) -> float:
    """The work of a fit of ``fit``'s model plus ``effects``: :data:`MEMORY_FIT_WEIGHT` where its force has memory."""
    return MEMORY_FIT_WEIGHT if fit.model.has_memory or any(effect_term(e).memory for e in effects) else 1.0
