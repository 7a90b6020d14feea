"""Rules of hysid/diagnosis/acceptance.py on small inputs: rule 5 (a refit must remove at least MIN_SHARE of the
chi^2 above the noise floor, however much its BIC falls) and rule 4's tie (a contender that degenerates gives way
to another that fits within BIC_MARGIN of it).

The loops: 15 of the Synth grid from a linear oscillator (the Synth set's damping and frequency, no amplitude
dependence), 20 points per branch, 1 % force noise; their harmonics are a few hundred whitened coefficients."""

from __future__ import annotations

import numpy as np
import pytest

from hysid.diagnosis.acceptance import degenerate_gives_way, judge
from hysid.diagnosis.criteria import BIC_MARGIN, MIN_SHARE
from hysid.diagnosis.fitting import Fit, make_model
from hysid_model.harmonics import HarmonicObjective, Harmonics
from hysid_model.synth import TRUE_PARAMS, synth_loops

TRUTH = {"xi0": TRUE_PARAMS["xi0"], "w0": TRUE_PARAMS["w0"]}


@pytest.fixture(scope="module")
def harmonics() -> Harmonics:
    loops = synth_loops(1.0, n_points=20, params={**TRUE_PARAMS, "S_xi": 0.0, "S_w": 0.0})
    return Harmonics.from_loops(loops.subset(np.arange(0, loops.n_loops, 8)))


def at(harmonics: Harmonics, effects: tuple[str, ...], values: dict[str, float]) -> Fit:
    """A fit of the baseline plus ``effects`` at ``values``, as the rules see one."""
    model = make_model(harmonics, "baseline", effects, {})
    objective = HarmonicObjective(harmonics, model)
    theta = model.from_dict(values)
    return Fit(effects, "baseline", objective, theta, objective.weighted_residuals(theta), objective.jacobian(theta))


def share(before: Fit, after: Fit) -> float:
    return (before.chi2 - after.chi2) / (before.chi2 - before.dof)


def test_a_refit_that_removes_less_than_its_share_of_the_excess_is_not_taken(harmonics):
    """The start 1 % off in w0 leaves a chi^2 far above its noise floor. A friction refit that moves w0 a tenth of
    the way back lowers the BIC by thousands yet removes about 10 % of that excess: not taken (rule 5); one that
    moves it a fifth of the way removes about 36 %: taken. A friction of 10^-4 N adds no order the loops lack."""
    poor = at(harmonics, (), {**TRUTH, "w0": 0.99 * TRUTH["w0"]})
    little = at(harmonics, ("coulomb_friction",), {**TRUTH, "w0": 0.9905 * TRUTH["w0"], "F_d": 1e-4})
    more = at(harmonics, ("coulomb_friction",), {**TRUTH, "w0": 0.992 * TRUTH["w0"], "F_d": 1e-4})
    assert little.bic < poor.bic - 100 * BIC_MARGIN and more.bic < little.bic
    assert 0.05 < share(poor, little) < MIN_SHARE < share(poor, more) < 0.5
    assert "removes only 10% of the chi^2 above the noise floor" in judge(poor, little, ("coulomb_friction",), harmonics)
    assert judge(poor, more, ("coulomb_friction",), harmonics) is None


@pytest.mark.parametrize(("rivals", "gives_way"), [
    ([], False),
    ([1000.0 + BIC_MARGIN + 1.0], False),
    ([1000.0 + BIC_MARGIN - 1.0], True),
    ([1000.0 + 1.0], True),
    ([1000.0 - 50.0], True),
    ([1030.0, 1000.0 + BIC_MARGIN - 0.5], True),
])
def test_a_degenerate_contender_gives_way_to_one_within_the_bic_margin(rivals, gives_way):
    """A contender of BIC 1000 that degenerates is taken only where every rival that passes without degenerating
    fits worse by BIC_MARGIN or more: a rival within the margin (or better) explains as much without degenerating."""
    assert degenerate_gives_way(1000.0, rivals) is gives_way
