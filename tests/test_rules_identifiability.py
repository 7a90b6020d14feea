"""Rules of hysid/identifiability.py: a parameter correlated beyond CORRELATION_LIMIT (0.999) with another gets its
error from its profile, not from the curvature; and a parameter that trades off with others names them, the one it
trades off with most first, leaving out those below PARTICIPATION of that."""

from __future__ import annotations

import numpy as np
import pytest

from hysid.identifiability import CORRELATION_LIMIT, assess, partners
from hysid_model.objective import Objective
from hysid_model.problem import build_objective
from hysid_model.synth import TRUE_PARAMS, synth_loops


@pytest.fixture(scope="module")
def thesis():
    """The thesis model on six noiseless Synth loops at the truth: every parameter seen by the Jacobian."""
    objective = build_objective(synth_loops(0.0, n_points=5).subset([0, 25, 50, 70, 95, 119]), "thesis")
    return objective, objective.model.from_dict(TRUE_PARAMS)


@pytest.mark.parametrize(("r", "profiled"), [(0.998, False), (0.99905, True), (0.9995, True), (-0.9995, True), (0.99995, True)])
def test_a_correlation_beyond_the_limit_sends_both_parameters_to_their_profile(thesis, r, profiled):
    """xi0 and w0 correlated at ``r`` in the covariance the caller hands over: beyond 0.999 either way both are due
    a profile (named in ``unprofiled`` where profiles are left out), below it neither is."""
    objective, theta = thesis
    se = np.array([1e-4, 0.1, 1.0, 10.0])
    correlation = np.eye(4)
    correlation[0, 2] = correlation[2, 0] = r
    found = assess(objective, theta, correlation * np.outer(se, se), lambda model: Objective(objective.loops, model), 1.0, profiles=False)
    assert found.unprofiled == (["xi0", "w0"] if profiled else []) and CORRELATION_LIMIT == pytest.approx(0.999)


def test_a_parameter_names_what_it_trades_off_with_the_strongest_first():
    """Column a is 0.8 of b's direction and 0.5 of c's (c scaled 10^6: only directions count): a trades off with b,
    then c; d (orthogonal) is not named. With c's share below PARTICIPATION of b's only b is named."""
    b, c, d = np.eye(6)[:3]
    names = ["a", "b", "c", "d"]
    jac = np.column_stack([0.8 * b + 0.5 * c, b, 1e6 * c, d])
    assert partners(jac, 0, names) == ["b", "c"]
    jac = np.column_stack([0.5 * b + 0.8 * c, b, 1e6 * c, d])
    assert partners(jac, 0, names) == ["c", "b"]
    jac = np.column_stack([0.8 * b + 0.05 * c, b, c, d])
    assert partners(jac, 0, names) == ["b"]
