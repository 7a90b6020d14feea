"""Rules of hysid/identifiability.py: a parameter correlated beyond CORRELATION_LIMIT (0.999) with another gets its
error from its profile, not from the curvature; and a parameter that trades off with others names them, the one it
trades off with most first, leaving out those below PARTICIPATION of that."""

from __future__ import annotations

import numpy as np
import pytest

from hysid.identifiability import CORRELATION_LIMIT, assess, crossing, partners, unseen
from hysid_model.objective import Objective
from hysid_model.problem import build_objective
from hysid_model.synth import MEQ_KG, TRUE_PARAMS, synth_loops


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


def test_a_profile_due_gives_the_half_width_where_the_objective_rises_one_unit(thesis):
    """xi0 and w0 handed over correlated beyond the limit, with errors 10^5 times too small: their profiles (the
    others refitted) rise by one unit (10^-6 of the noiseless objective's scale) at sqrt(unit [(J^T J)^-1]_ii), the
    curvature of this locally quadratic problem, and replace the handed errors; S_xi and S_w keep theirs."""
    objective, theta = thesis
    jac = objective.jacobian(theta)
    se = np.sqrt(np.diag(np.linalg.inv(jac.T @ jac)))
    correlation = np.eye(4)
    correlation[0, 2] = correlation[2, 0] = 0.9995
    found = assess(objective, theta, correlation * np.outer(se, se) * 1e-10, lambda model: Objective(objective.loops, model), 1e-6)
    assert sorted(found.profiled) == ["w0", "xi0"] and found.not_identifiable == {} and found.unprofiled == []
    np.testing.assert_allclose(np.sqrt(np.diag(found.full)), np.sqrt(1e-6) * se * [1, 1e-2, 1, 1e-2], rtol=1e-3)
    np.testing.assert_allclose(found.correlation[0, 2], 0.9995, rtol=1e-9)  # its correlations kept


def test_the_directions_the_jacobian_does_not_see_are_found_at_unit_column_scale():
    """Columns b and c of very different scale that move the residuals alike: the one direction unseen is
    (b - c) / sqrt(2) in column-scaled coordinates; a Jacobian of full rank has none."""
    a, b = np.eye(5)[:2]
    directions, scale = unseen(np.column_stack([a, 1e-6 * b, 1e6 * b]))
    np.testing.assert_allclose(scale, [1.0, 1e-6, 1e6])
    assert directions.shape == (3, 1)
    np.testing.assert_allclose(np.abs(directions[:, 0]), [0.0, np.sqrt(0.5), np.sqrt(0.5)], atol=1e-9)
    assert directions[1, 0] * directions[2, 0] < 0
    assert unseen(np.column_stack([a, b + 1e-3 * a]))[0].shape == (2, 0)


def test_the_crossing_of_a_quadratic_rise_is_exact():
    """A rise (d / 0.3)^2 crosses one unit at 0.3, from any two points of it."""
    for near, far in ((0.1, 0.5), (0.0, 2.0), (0.29, 0.31)):
        assert crossing(near, (near / 0.3) ** 2, far, (far / 0.3) ** 2) == pytest.approx(0.3, rel=1e-12)


def test_a_parameter_whose_profile_is_flat_over_its_range_is_not_identifiable():
    """Three amplitudes at one frequency (25 Hz) and the mass fitted: the loops fix the stiffness meq w0^2 and the
    damping 2 meq xi0 w0 there, not the mass apart from w0; the mass's profile stays within a unit over its range,
    so it is named not identifiable (with what it trades off with) and gets no error."""
    loops = synth_loops(0.0, n_points=5, params={**TRUE_PARAMS, "S_xi": 0.0, "S_w": 0.0}).subset([0, 40, 80])
    loops.meq_kg = None
    objective = build_objective(loops, "baseline")
    theta = objective.model.from_dict({**TRUE_PARAMS, "meq": MEQ_KG})
    jac = objective.jacobian(theta)
    found = assess(objective, theta, np.linalg.pinv(jac.T @ jac) * 1e-6, lambda model: Objective(loops, model), 1e-6)
    assert found.not_identifiable == {"meq": "trades off with w0: its profile is flat over its range (the data determine only a combination)"}
    assert np.isnan(found.stderr[2]) and np.isfinite(found.stderr[:2]).all() and found.flat.shape == (3, 1)
