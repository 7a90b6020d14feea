"""Score every candidate effect against what the current model leaves (a Lagrange-multiplier test).

At the current fit theta (whitened harmonic residual e, whitened Jacobian J),
candidate effect E with strength psi (psi = 0: the current model) has the
signature g = d e / d psi at psi = 0: how it would move every harmonic
coefficient of every loop (frequency x amplitude). Whatever part of g the
current parameters can mimic is projected out, g_perp = (I - J J^+) g; what
remains is what only E can explain. The score statistic

    LM = (g_perp . e)^2 / (g_perp . g_perp)                     (chi^2_1 under psi = 0)

is the chi^2 the effect would remove to first order, and
psi_1 = -(g_perp . e) / (g_perp . g_perp) its one-step estimate. Two effects
together remove the residual's projection on both signatures (:func:`joint_score`). Effects whose
shape parameters are undefined at psi = 0 (a relaxation time, a yield
displacement) are scored on their term's ``shape_grid`` and keep the best.
An effect whose signature the current model absorbs entirely
(|g_perp| / |g| below ``ABSORBED``) cannot be identified with this data set.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hysid.harmonic_fits import Fit, make_model
from hysid_model.effects import EFFECTS
from hysid_model.errors import HysidInputError
from hysid_model.frf import amplitude_levels
from hysid_model.harmonics import HarmonicObjective, Harmonics
from hysid_model.model import effect_term
from hysid_model.presets import PRESETS
from hysid_model.terms import Term, TermGroup
from hysid_model.user_terms import specs_of

ABSORBED = 1e-3
"""|g_perp| / |g| below this: the current model absorbs the effect (it is not identifiable)."""
STEP = 1e-6
"""Central-difference step of the strength, as a fraction of its bound range."""
STARTS = 3
"""Best shapes (by score) kept as starting points for the refit."""


@dataclass
class Candidate:
    """One effect's score against the current fit (best over its shape grid)."""

    effect: str
    score: float
    starts: list[tuple[dict[str, float], float]]
    """(shape, one-step strength) of the best-scoring shapes, best first."""
    physical: bool
    identifiable: bool
    absorbed_by: list[str]
    direction: np.ndarray
    """Unit vector of g_perp (whitened harmonic space) for the best shape."""
    norm: float
    """|g_perp| for the best shape (whitened residual per unit strength)."""
    n_shapes: int

    def __repr__(self) -> str:
        kind = "" if self.physical else ", unphysical"
        kind += "" if self.identifiable else f", not identifiable (absorbed by {', '.join(self.absorbed_by)})"
        return f"<Candidate {self.effect}: score {self.score:.4g}{kind}>"


def effects_in(fit: Fit) -> tuple[str, ...]:
    return PRESETS[fit.start] + fit.effects


def signature(fit: Fit, harmonics: Harmonics, effect: str, bounds: dict[str, tuple[float, float]]) -> tuple[np.ndarray, list[dict[str, float]], bool]:
    """d(whitened residual)/d(strength) at strength 0, ``(n_shapes, N)``, the shapes, and whether the strength is one-sided (>= 0)."""
    model = make_model(harmonics, fit.start, fit.effects + (effect,), bounds, fit.freed)
    term = effect_term(effect)
    objective = HarmonicObjective(harmonics, model)
    shapes = term.shape_grid(objective.objective.kin, model.names)
    base = {**{p.name: 0.5 * (p.lower + p.upper) for p in term.params}, **fit.params(), term.strength: 0.0}
    strength = model.names.index(term.strength)
    lo, hi = model.bounds[strength]
    h = STEP * (hi - lo)
    rows = []
    for shape in shapes:
        theta = model.from_dict({**base, **shape})
        up, down = theta.copy(), theta.copy()
        up[strength] += h
        down[strength] -= h
        rows += [up, down]
    white = objective.whitened(np.array(rows)).reshape(len(shapes), 2, -1)
    return (white[:, 0] - white[:, 1]) / (2.0 * h), shapes, lo == 0.0


def joint_score(a: Candidate, b: Candidate, residual: np.ndarray) -> tuple[float, np.ndarray]:
    """The chi^2 two effects remove together to first order (each at its best shape), and their joint
    one-step strengths: least squares of the residual on both projected signatures."""
    g = np.column_stack([a.direction * a.norm, b.direction * b.norm])
    step = np.linalg.lstsq(g, -residual, rcond=None)[0]
    after = residual + g @ step
    return float(residual @ residual - after @ after), step


def candidate_effects(extra: Term | TermGroup | str | Sequence[Term | TermGroup | str] | None = None) -> tuple[str, ...]:
    """The effects a diagnosis scores: the library's, then ``extra`` (a user's terms, :func:`hysid.term`, or their
    model strings ``module:attribute``), each of which must name its strength."""
    added = specs_of(extra, "candidates") if extra is not None else ()
    for spec in added:
        if not effect_term(spec).strength:
            raise HysidInputError(
                f"term {spec!r} names no strength (the parameter whose 0 switches it off), which a diagnosis tests; give hysid.term(..., strength=...)",
                param="candidates",
            )
    return tuple(EFFECTS) + tuple(s for s in added if s not in EFFECTS)


def score_candidates(fit: Fit, harmonics: Harmonics, bounds: dict[str, tuple[float, float]], effects: Sequence[str] = tuple(EFFECTS)) -> list[Candidate]:
    """Score every effect of ``effects`` (:func:`candidate_effects`) not yet in the model, best first; with loops at one
    amplitude, the amplitude slopes (in the model or not) are scored as not identifiable."""
    q, _ = np.linalg.qr(fit.jacobian)
    e = fit.residual
    out = []
    single = amplitude_levels(harmonics.loops.x0)[0].size == 1
    for effect in effects:
        partner = effect_term(effect).slope_of
        if single and partner:  # one amplitude: a slope of xi or wn with amplitude is xi0 or w0 again (fixed at 0 if in the model)
            out.append(
                Candidate(
                    effect=effect,
                    score=0.0,
                    starts=[],
                    physical=True,
                    identifiable=False,
                    absorbed_by=[partner],
                    direction=np.zeros_like(e),
                    norm=0.0,
                    n_shapes=0,
                )
            )
            continue
        if effect in effects_in(fit):
            continue
        g, shapes, one_sided = signature(fit, harmonics, effect, bounds)
        g_perp = g - (g @ q) @ q.T
        norm2 = np.sum(g_perp**2, axis=1)
        ratio = np.sqrt(norm2 / np.maximum(np.sum(g**2, axis=1), 1e-300))
        proj = g_perp @ e
        with np.errstate(divide="ignore", invalid="ignore"):
            lm = np.where(norm2 > 0, proj**2 / norm2, 0.0)
            step = np.where(norm2 > 0, -proj / norm2, 0.0)
        physical = (step > 0) | (not one_sided)
        identifiable = ratio >= ABSORBED
        usable = np.where(physical & identifiable, lm, -1.0)
        ranked = np.argsort(-usable) if np.any(usable >= 0) else np.argsort(-lm)
        best = int(ranked[0])
        absorbed_by: list[str] = []
        if not identifiable[best]:
            coef = np.linalg.lstsq(fit.jacobian, g[best], rcond=None)[0] * np.linalg.norm(fit.jacobian, axis=0)
            absorbed_by = [fit.model.names[i] for i in np.argsort(-np.abs(coef)) if abs(coef[i]) >= 0.2 * np.abs(coef).max()]
        direction = g_perp[best] / np.sqrt(norm2[best]) if norm2[best] > 0 else g_perp[best]
        out.append(
            Candidate(
                effect=effect,
                score=float(lm[best]),
                starts=[(shapes[i], float(step[i])) for i in ranked[:STARTS] if usable[i] >= 0 or i == best],
                physical=bool(physical[best]),
                identifiable=bool(identifiable[best]),
                absorbed_by=absorbed_by,
                direction=direction,
                norm=float(np.sqrt(norm2[best])),
                n_shapes=len(shapes),
            )
        )
    return sorted(out, key=lambda c: -(c.score if c.physical and c.identifiable else -1.0))
