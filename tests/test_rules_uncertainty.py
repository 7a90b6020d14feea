"""The rules of hysid_model/uncertainty.py: an information matrix is inverted at unit diagonal (so that parameters of
very different magnitude keep their weakly determined directions), and an unknown noise is the residuals' RMS with
the parameters fitted counted (its square unbiased at the optimum)."""

from __future__ import annotations

import warnings

import numpy as np

from hysid_model.problem import build_objective
from hysid_model.synth import TRUE_PARAMS, synth_loops
from hysid_model.uncertainty import jacobian_covariance, noise_sigma, scaled_inverse
from test_uncertainty import noisy


def test_the_inverse_of_an_information_matrix_over_30_decades_is_exact():
    """Parameters 10^15 apart in scale (a stiffness next to a yield displacement), correlated at 0.5: the inverse
    is D^-1 C^-1 D^-1 to rounding. A pseudo-inverse of the unscaled matrix cuts the weak direction off (its
    eigenvalue is 10^-30 of the largest) and reports the small parameter 10^25 times too precise."""
    correlation = np.array([[1.0, 0.5], [0.5, 1.0]])
    scale = np.diag([1e10, 1e-5])
    exact = np.linalg.inv(scale) @ np.linalg.inv(correlation) @ np.linalg.inv(scale)
    np.testing.assert_allclose(scaled_inverse(scale @ correlation @ scale), exact, rtol=1e-9)


def test_a_singular_information_matrix_gets_the_pseudo_inverse_of_its_scaled_form():
    """Two parameters the data see only together (perfectly correlated), 10^6 apart in scale: the pseudo-inverse
    at unit diagonal, finite, with the combination the data do see kept (M X M = M)."""
    scale = np.diag([1e3, 1e-3])
    matrix = scale @ np.ones((2, 2)) @ scale
    inverse = scaled_inverse(matrix)
    np.testing.assert_allclose(inverse, np.linalg.inv(scale) @ np.full((2, 2), 0.25) @ np.linalg.inv(scale), rtol=1e-9)
    np.testing.assert_allclose(matrix @ inverse @ matrix, matrix, rtol=1e-9)


def test_an_unknown_noise_is_the_residual_rms_over_the_degrees_of_freedom_left():
    """Two loops of 4 points per branch (N = 16 samples) of a linear oscillator, the baseline's D = 2 parameters
    fitted (the mass known), a noise per loop stated nowhere. The data are the truth plus a residual e that the
    parameters cannot reduce (orthogonal to every column of the Jacobian, so the truth stays the optimum): each
    loop's sigma^2 is its share |e_j|^2 / n_j scaled by N / (N - D), since a residual's expected sum of squares is
    sigma^2 (N - D), the D directions the fit absorbs taken out (without the correction: 7/8 of it)."""
    base = synth_loops(0.0, n_points=4, params={**TRUE_PARAMS, "S_xi": 0.0, "S_w": 0.0}).subset([0, 119])
    clean = build_objective(base, "baseline")
    truth = clean.model.from_dict(TRUE_PARAMS)
    away = (np.abs(clean.y) < 0.9 * base.peak_force[:, None]).reshape(-1)  # e leaves each peak (the weights) as it is
    jac = clean.jacobian(truth, weighted=True) * away[:, None]
    q = np.linalg.qr(jac)[0]
    z = np.random.default_rng(5).standard_normal(away.size) * np.repeat([1.0, 3.0], away.size // 2) * away
    e = ((z - q @ (q.T @ z)) * 1e-3 / np.repeat(np.sqrt(clean.loop_weight), away.size // 2)).reshape(2, -1)
    loops = base.subset([0, 1])
    n = base.n_samples
    loops.top, loops.bottom = loops.top.copy(), loops.bottom.copy()
    loops.top[:, :, 1] += e[:, :n]
    loops.bottom[:, :, 1] += e[:, n:]
    objective = build_objective(loops, "baseline")
    gradient = objective.jacobian(truth, weighted=True).T @ objective.weighted_residuals(truth)
    assert np.all(np.abs(gradient) < 1e-6 * np.linalg.norm(jac, axis=0) * np.linalg.norm(e))  # the truth is the optimum
    expected = np.sum(e**2, axis=1) / (2 * n) * 16 / (16 - 2)
    np.testing.assert_allclose(noise_sigma(objective, truth) ** 2, expected, rtol=1e-9)
    loops.sigma = np.array([0.0, np.inf])  # a sigma of 0 or not finite is no stated noise either
    np.testing.assert_allclose(noise_sigma(build_objective(loops, "baseline"), truth) ** 2, expected, rtol=1e-9)
    stated = noise_sigma(build_objective(noisy(base, np.array([0.5, 2.0]), np.random.default_rng(0), known=True), "baseline"), truth)
    np.testing.assert_array_equal(stated, [0.5, 2.0])  # a stated sigma is kept


def test_a_parameter_without_information_gets_none_in_the_inverse():
    """A zero row and column (the data do not see the parameter at all): the pseudo-inverse is 0 there, the others
    are inverted as if it were absent, and nothing is divided by zero."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        np.testing.assert_array_equal(scaled_inverse(np.diag([4.0, 0.0])), [[0.25, 0.0], [0.0, 0.0]])


def test_the_covariance_of_a_jacobian_is_the_inverse_of_its_gram_matrix():
    jac = np.array([[1.0, 2e-6], [0.5, 1e-6], [0.0, 3e-6]]) * [1e4, 1.0]
    np.testing.assert_allclose(jacobian_covariance(jac), np.linalg.inv(jac.T @ jac), rtol=1e-9)


def test_with_one_degree_of_freedom_left_the_noise_is_the_residual_rms_over_it():
    """One loop of 2 points per branch (N = 4), the baseline's 3 parameters with the mass unknown: sigma^2 is the
    residual's sum of squares over N - D = 1 (never over less than one)."""
    loops = noisy(synth_loops(0.0, n_points=2).subset([0]), np.array([0.01]), np.random.default_rng(2), known=False)
    loops.meq_kg = None
    objective = build_objective(loops, "baseline")
    theta = objective.model.from_dict({**TRUE_PARAMS, "meq": 1.0})
    assert objective.keep.sum() == 4 and objective.dim == 3
    np.testing.assert_allclose(noise_sigma(objective, theta) ** 2, objective.per_loop_sse(theta), rtol=1e-12)
