"""Rules of hysid/identifiability.py: a parameter correlated beyond CORRELATION_LIMIT (0.999) with another gets its
error from its profile, not from the curvature; and a parameter that trades off with others names them, the one it
trades off with most first, leaving out those below PARTICIPATION of that."""

from __future__ import annotations

import numpy as np
import pytest

from hysid.identifiability import BISECTIONS, CORRELATION_LIMIT, GROWTH, MAX_STEPS, assess, crossing, partners, side_width, unseen
from hysid_model.objective import Objective
from hysid_model.problem import build_objective
from hysid_model.synth import MEQ_KG, TRUE_PARAMS, synth_loops


@pytest.fixture(scope="module")
def thesis():
    """The thesis model on six noiseless Synth loops at the truth: every parameter seen by the Jacobian."""
    objective = build_objective(synth_loops(0.0, n_points=5).subset([0, 25, 50, 70, 95, 119]), "thesis")
    return objective, objective.model.from_dict(TRUE_PARAMS)


@pytest.fixture(scope="module")
def one_frequency():
    """Three amplitudes of the linear Synth oscillator at one frequency (25 Hz), noiseless, the mass fitted: the
    baseline's objective, its optimum (the truth) and its Jacobian there."""
    loops = synth_loops(0.0, n_points=5, params={**TRUE_PARAMS, "S_xi": 0.0, "S_w": 0.0}).subset([0, 40, 80])
    loops.meq_kg = None
    objective = build_objective(loops, "baseline")
    theta = objective.model.from_dict({**TRUE_PARAMS, "meq": MEQ_KG})
    jac = objective.jacobian(theta)
    return loops, objective, theta, jac


@pytest.mark.parametrize(("r", "profiled"), [(0.998, False), (0.99905, True), (0.9995, True), (-0.9995, True), (0.99995, True)])
def test_a_correlation_beyond_the_limit_sends_both_parameters_to_their_profile(thesis, r, profiled):
    """xi0 and w0 correlated at ``r`` in the covariance the caller hands over: beyond 0.999 either way both are due
    a profile (named in ``unprofiled`` where profiles are left out), below it neither is."""
    objective, theta = thesis
    se = np.array([1e-4, 0.1, 1.0, 10.0])
    correlation = np.eye(4)
    correlation[0, 2] = correlation[2, 0] = r
    found = assess(objective, theta, correlation * np.outer(se, se), lambda model: Objective(objective.loops, model), 1.0, profiles=False)
    assert found.unprofiled == (["xi0", "w0"] if profiled else []) and pytest.approx(0.999) == CORRELATION_LIMIT


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
    jac = np.column_stack([0.8 * b + 0.5 * c, 1e-6 * b, 1e6 * c, np.zeros(6)])  # b below unit scale, d seen by nothing
    assert partners(jac, 0, names) == ["b", "c"]
    e = np.eye(6)[3]
    jac = np.column_stack([0.5 * b + 0.5 * c + 0.5 * d + 0.1 * e, b, c, d, e])  # e: 0.2 of the largest, above PARTICIPATION
    assert partners(jac, 0, names + ["e"])[-1] == "e"
    assert partners(np.column_stack([b]), 0, ["a"]) == []  # nothing to trade off with


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


def test_a_parameter_whose_profile_is_flat_over_its_range_is_not_identifiable(one_frequency):
    """Three amplitudes at one frequency (25 Hz) and the mass fitted: the loops fix the stiffness meq w0^2 and the
    damping 2 meq xi0 w0 there, not the mass apart from w0; the mass's profile stays within a unit over its range,
    so it is named not identifiable (with what it trades off with) and gets no error."""
    loops, objective, theta, jac = one_frequency
    found = assess(objective, theta, np.linalg.pinv(jac.T @ jac) * 1e-6, lambda model: Objective(loops, model), 1e-6)
    assert found.not_identifiable == {"meq": "trades off with w0: its profile is flat over its range (the data determine only a combination)"}
    assert np.isnan(found.stderr[2]) and np.isfinite(found.stderr[:2]).all() and found.flat.shape == (3, 1)
    conditional = np.diag(np.diag(np.linalg.pinv(jac.T @ jac))) * 1e-6  # no correlation shown: the unseen direction decides
    assert assess(objective, theta, conditional, lambda model: Objective(loops, model), 1e-6).not_identifiable.keys() == {"meq"}
    assert assess(objective, theta[None, :], conditional, lambda model: Objective(loops, model), 1e-6, profiles=False).unprofiled == [
        "w0",
        "meq",
    ]  # a theta of shape (1, D) is read as (D,)


def test_a_parameter_handed_over_without_variance_is_not_taken_for_correlated(thesis):
    """A covariance whose row and column of S_w are zero (its correlations 0/0): only the parameters correlated
    beyond the limit are due a profile, S_w not."""
    objective, theta = thesis
    cov = np.diag([1e-8, 1e-2, 1.0, 0.0])
    cov[0, 2] = cov[2, 0] = 0.9995 * np.sqrt(1e-8)
    with np.errstate(all="raise"):
        assert assess(objective, theta, cov, lambda model: Objective(objective.loops, model), 1.0, profiles=False).unprofiled == ["xi0", "w0"]


def probed(rise, step: float, room: float) -> tuple[float | None, list[float]]:
    """:func:`side_width` of ``rise`` and the distances it probed, in order."""
    probes: list[float] = []

    def recorded(d: float) -> float:
        probes.append(float(d))
        return rise(d)

    return side_width(recorded, step, room), probes


def test_a_profile_side_grows_by_growth_to_its_bound_then_probes_the_quadratic_crossing():
    """A quadratic rise (d / 0.3)^2 from a step of 10^-3: steps x4 until the rise passes a unit (1.024), then the
    quadratic's crossing, exact here (0.3). With the crossing at 5 the sixth growing step (the MAX_STEPS - 1-th
    probe) goes to the bound (10) instead of x4; a rise that never reaches a unit stops there: None."""
    width, probes = probed(lambda d: (d / 0.3) ** 2, 1e-3, 10.0)
    assert width == pytest.approx(0.3, rel=1e-12) and probes == pytest.approx([1e-3 * GROWTH**k for k in range(6)] + [0.3], rel=1e-12)
    width, probes = probed(lambda d: (d / 5.0) ** 2, 1e-3, 10.0)
    assert width == pytest.approx(5.0, rel=1e-12) and probes == pytest.approx([1e-3 * GROWTH**k for k in range(6)] + [10.0, 5.0], rel=1e-12)
    width, probes = probed(lambda d: 1e-3 * d, 0.01, 10.0)
    assert width is None and probes == pytest.approx([0.01 * GROWTH**k for k in range(5)] + [10.0], rel=1e-12)
    assert len(probes) == MAX_STEPS - 1 and MAX_STEPS == 7 and GROWTH == 4.0


def test_a_profile_side_shrinks_from_a_step_too_long_until_below_a_unit():
    """From a step of 50 where the rise is far above a unit: steps /4 until it is below (0.195), then the crossing."""
    width, probes = probed(lambda d: (d / 0.3) ** 2, 50.0, 100.0)
    assert width == pytest.approx(0.3, rel=1e-12) and probes == pytest.approx([50.0 / GROWTH**k for k in range(5)] + [0.3], rel=1e-12)
    width, probes = probed(lambda d: (d / 0.3) ** 2, 0.3, 10.0)  # a unit exactly at the step: one below it, then the crossing
    assert width == pytest.approx(0.3, rel=1e-12) and probes == pytest.approx([0.3, 0.075, 0.3], rel=1e-12)
    width, probes = probed(lambda d: 0.5 + 1e-6 * d, 1e-3, 10.0)  # above a unit nowhere: up to the bound, None
    assert width is None and probes[-1] == 10.0


def test_a_wall_after_a_flat_profile_is_bracketed_by_halving_after_the_quadratic_guess():
    """Flat up to 2, then a wall: the quadratic guess (the first probe of the bracket) falls short, so the bracket is
    halved geometrically (each probe the geometric mean of the nearest points below and above a unit) until its ends
    are within 2 %, or BISECTIONS probes; the crossing lies in the last bracket, at the wall."""
    rise = lambda d: 0.0 if d < 2.0 else 1e4 * (d - 2.0) ** 2 + 1e-3
    width, probes = probed(rise, 0.01, 10.0)
    grown = [0.01 * GROWTH**k for k in range(5)]
    assert probes[:5] == pytest.approx(grown, rel=1e-12)
    assert probes[5] == pytest.approx(crossing(0.64, 0.0, 2.56, rise(2.56)), rel=1e-12)
    for k in range(6, len(probes)):
        below = max(p for p in probes[:k] if rise(p) < 1.0)
        above = min(p for p in probes[:k] if rise(p) >= 1.0)
        assert probes[k] == pytest.approx(np.sqrt(below * above), rel=1e-12)
    assert len(probes) <= 5 + BISECTIONS
    below = max(p for p in probes if rise(p) < 1.0)
    above = min(p for p in probes if rise(p) >= 1.0)
    assert below < width < above and 1.98 < width < 2.05 and (above / below < 1.02 or len(probes) == 5 + BISECTIONS)


@pytest.mark.parametrize("height", [1.0, 1.5, 4.0])
def test_a_profile_that_rises_a_unit_at_every_distance_probed_ends_at_the_quadratic_crossing_from_the_optimum(height):
    """A rise of ``height`` (one unit or more) however close to the optimum: the step shrinks by GROWTH at most
    MAX_STEPS - 1 times without finding a point below a unit, and the half-width is where a quadratic through the
    optimum (rise 0) and the last point crosses a unit."""
    width, probes = probed(lambda d: height, 1.0, 10.0)
    last = GROWTH ** -(MAX_STEPS - 1)
    assert probes == pytest.approx([1.0 / GROWTH**k for k in range(MAX_STEPS)], rel=1e-12)
    assert width == pytest.approx(last / np.sqrt(height), rel=1e-12)


def test_a_bracket_already_within_two_percent_is_not_probed_again():
    """From a step of 0.995 with the bound at 1 the first growing step reaches the bound: the bracket 0.995-1 is within
    2 %, so the crossing is taken from its ends (exact for the quadratic rise (d / 0.998)^2), without another probe."""
    width, probes = probed(lambda d: (d / 0.998) ** 2, 0.995, 1.0)
    assert probes == pytest.approx([0.995, 1.0], rel=1e-12) and width == pytest.approx(0.998, rel=1e-12)


@pytest.mark.parametrize("height", [1.0, 1.5])
def test_a_plateau_of_one_unit_or_more_is_reached_where_it_begins(height):
    """Flat up to 2, a plateau of ``height`` up to 2.5, then 100: a rise of exactly one unit (or 1.5) has reached
    the unit, so the bracket closes on 2, the plateau's start, not on the wall at 2.5."""
    rise = lambda d: 0.0 if d < 2.0 else (height if d < 2.5 else 100.0)
    width, probes = probed(rise, 0.01, 10.0)
    assert 1.95 < width < 2.05 and any(2.0 <= p < 2.5 for p in probes)


def test_a_jacobian_column_that_moves_nothing_keeps_unit_scale_and_is_the_unseen_direction():
    """Column b is all zeros (its parameter moves no residual): its scale is 1, not 0 (no division by zero), and the
    one direction unseen is b's own axis."""
    a = np.eye(5)[0]
    directions, scale = unseen(np.column_stack([2.0 * a, np.zeros(5)]))
    np.testing.assert_array_equal(scale, [2.0, 1.0])
    assert directions.shape == (2, 1)
    np.testing.assert_allclose(np.abs(directions[:, 0]), [0.0, 1.0], atol=1e-12)


@pytest.mark.parametrize(("gap", "is_unseen"), [(1e-9, True), (4e-9, False)])
def test_a_direction_is_unseen_below_rank_tol_of_the_largest_eigenvalue(gap, is_unseen):
    """Two unit columns at an angle t with 1 - cos t = ``gap``: the Gram matrix's eigenvalues are 1 +- cos t, about 2
    and ``gap``; the direction (a - b) is unseen where ``gap`` is below RANK_TOL (10^-9) times 2, seen above it."""
    a, b = np.eye(4)[:2]
    t = np.arccos(1.0 - gap)
    directions, _ = unseen(np.column_stack([a, np.cos(t) * a + np.sin(t) * b]))
    assert directions.shape == (2, 1 if is_unseen else 0)


def test_a_variance_rounding_left_below_zero_counts_as_zero(thesis):
    """S_w's variance handed over as -10^-30 (a covariance's rounding): its error is 0 and nothing warns or fails
    (numpy errors raised); only the parameters correlated beyond the limit are due a profile."""
    objective, theta = thesis
    cov = np.diag([1e-8, 1e-2, 1.0, -1e-30])
    cov[0, 2] = cov[2, 0] = 0.9995 * np.sqrt(1e-8)
    with np.errstate(all="raise"):
        found = assess(objective, theta, cov, lambda model: Objective(objective.loops, model), 1.0, profiles=False)
    assert found.unprofiled == ["xi0", "w0"]


def test_a_profiled_error_is_never_below_the_curvatures(thesis):
    """xi0 and w0 handed over correlated beyond the limit with errors 10 times the curvature's: their profiles rise
    a unit sooner, and the error kept is the larger, the one handed over; no direction is flat."""
    objective, theta = thesis
    jac = objective.jacobian(theta)
    se = np.sqrt(np.diag(np.linalg.inv(jac.T @ jac))) * 1e-3 * 10.0
    correlation = np.eye(4)
    correlation[0, 2] = correlation[2, 0] = 0.9995
    found = assess(objective, theta, correlation * np.outer(se, se), lambda model: Objective(objective.loops, model), 1e-6)
    assert found.profiled == pytest.approx({"xi0": se[0], "w0": se[2]}, rel=1e-12)
    assert found.flat.shape == (4, 0) and found.not_identifiable == {}


def test_a_quantity_along_a_flat_direction_has_no_error_and_one_across_it_has(one_frequency):
    """The mass of three amplitudes at one frequency (25 Hz) is not identifiable (it trades off with w0): a quantity
    that moves with the mass alone has no error (NaN); the dynamic stiffness meq (w0^2 - w^2) at 25 Hz, which the
    loops determine, has one."""
    loops, objective, theta, jac = one_frequency
    found = assess(objective, theta, np.linalg.pinv(jac.T @ jac) * 1e-6, lambda model: Objective(loops, model), 1e-6)
    w0, meq, w = theta[1], theta[2], 2.0 * np.pi * 25.0
    mass_alone, stiffness = found.propagate(np.array([[0.0, 0.0, 1.0], [0.0, 2.0 * meq * w0, w0**2 - w**2]]))
    assert np.isnan(mass_alone) and np.isfinite(stiffness) and stiffness > 0


def first_targets(objective, theta, loops, cov, unit):
    """The first value each profiled parameter of ``objective`` is held at by :func:`assess` (its profile's first
    probe, on the lower side first), from the models ``rebuild`` is handed."""
    first: dict[str, float] = {}

    def rebuild(model):
        for name, value in model.fixed.items():
            if name in objective.model.names:
                first.setdefault(name, value)
        return Objective(loops, model)

    assess(objective, theta, cov, rebuild, unit)
    return first


def test_a_profile_starts_one_curvature_error_away_or_else_half_the_room_to_the_farther_bound(thesis, one_frequency):
    """xi0 and w0 handed over correlated beyond the limit with errors se: each profile's first probe is se below the
    optimum. On the one-frequency specimen w0 lies in the direction the Jacobian does not see, so its error says
    nothing: its first step is half the room to its farther bound (155 rad/s of 311), and as the lower bound is
    nearer (89 rad/s), the bound itself."""
    objective, theta = thesis
    jac = objective.jacobian(theta)
    se = np.sqrt(np.diag(np.linalg.inv(jac.T @ jac))) * 1e-5
    correlation = np.eye(4)
    correlation[0, 2] = correlation[2, 0] = 0.9995
    first = first_targets(objective, theta, objective.loops, correlation * np.outer(se, se), 1e-6)
    assert first == pytest.approx({"xi0": theta[0] - se[0], "w0": theta[2] - se[2]}, rel=1e-12)
    loops, objective, theta, jac = one_frequency
    lower, upper = objective.model.bounds[1]
    assert 0.5 * max(theta[1] - lower, upper - theta[1]) > theta[1] - lower
    assert first_targets(objective, theta, loops, np.linalg.pinv(jac.T @ jac) * 1e-6, 1e-6)["w0"] == lower
