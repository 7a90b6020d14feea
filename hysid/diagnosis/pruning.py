"""The last step of a diagnosis: terms whose strength is consistent with zero are dropped from the final model.

A diagnosis adds effects one by one and never takes one back, and a start
model (``thesis``) brings its amplitude slopes whether the loops need them or
not. At the end, each term other than the oscillator whose strength (the
parameter whose 0 switches it off: S_xi, S_w, F_d, bw_k, ...) lies within
``Z`` standard errors of zero is a candidate; the one closest to zero is
dropped and the model refitted from the values it had, as long as the BIC
does not rise (dropping a parameter that explains less than its ln N is what
the BIC prefers). What is dropped, and what stays although consistent with
zero (the oscillator's own parameters, or a term whose removal the BIC does
not take), the summary says.
"""

from __future__ import annotations

import numpy as np

from hysid.harmonic_fits import Fit, fit_objective, make_model, soft_bounds
from hysid_model.harmonics import HarmonicObjective, Harmonics
from hysid_model.terms import Oscillator

Z = 2.0
"""A parameter within this many standard errors of zero is consistent with zero."""


def zero_like(values: dict[str, float], stderr: dict[str, float]) -> dict[str, float]:
    """The parameters of ``values`` consistent with zero given their ``stderr``, each with |value| / standard
    error (0 for a value of exactly 0, a physical bound)."""
    out = {}
    for name, value in values.items():
        se = stderr.get(name, np.nan)
        if value == 0.0:
            out[name] = 0.0
        elif np.isfinite(se) and se > 0 and abs(value) < Z * se:
            out[name] = float(abs(value) / se)
    return out


def without(fit: Fit, harmonics: Harmonics, term_id: str) -> Fit:
    """``fit`` refitted without the term ``term_id``, from its own values of the others."""
    effects = tuple(t.spec for t in fit.model.terms if not isinstance(t, Oscillator) and t.id != term_id)
    model = make_model(harmonics, "baseline", effects, soft_bounds(fit.model), [n for n in fit.freed])
    values = dict(zip(fit.model.names, fit.theta))
    start = np.clip(np.array([values.get(n, 0.5 * (lo + hi)) for n, (lo, hi) in zip(model.names, model.bounds)]), model.bounds[:, 0], model.bounds[:, 1])
    return fit_objective(HarmonicObjective(harmonics, model), "baseline", effects, [start])


def prune(fit: Fit, harmonics: Harmonics) -> tuple[Fit, dict[str, str]]:
    """``fit`` without the terms whose strength is consistent with zero where the BIC does not rise (see the
    module docstring), and for each term dropped why."""
    dropped: dict[str, str] = {}
    tried: set[str] = set()
    while True:
        zeros = zero_like(fit.params(), fit.model.as_dict(fit.stderr))
        terms = [(zeros[t.strength], t) for t in fit.model.terms if not isinstance(t, Oscillator) and t.strength in zeros and t.id not in tried]
        if not terms:
            return fit, dropped
        z, term = min(terms, key=lambda item: item[0])
        tried.add(term.id)
        i = fit.model.names.index(term.strength)
        reduced = without(fit, harmonics, term.id)
        if reduced.bic > fit.bic:
            continue
        dropped[term.id] = (
            f"{term.strength} = {fit.theta[i]:.4g} +- {fit.stderr[i]:.2g} is consistent with zero ({z:.2g} standard errors); "
            f"without it the BIC changes by {reduced.bic - fit.bic:+.1f}"
        )
        fit = reduced
