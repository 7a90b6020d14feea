"""The vectorized objective (Eq. 3.3, Fig. 5.1): closed form, weights, jacobian, robustness."""

from __future__ import annotations

import numpy as np
import pytest

from hysid_model.errors import HysidInputError
from hysid_model.model import build_model
from hysid_model.objective import Objective
from hysid_model.synth import MEQ_KG, TRUE_PARAMS, synth_loops

TRUTH = np.array([TRUE_PARAMS[k] for k in ("xi0", "S_xi", "w0", "S_w")])


@pytest.fixture(scope="module")
def noisy():
    return synth_loops(10.0, seed=4)


def random_population(obj: Objective, count: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    low, span = obj.bounds[:, 0], obj.bounds[:, 1] - obj.bounds[:, 0]
    return low + span * rng.random((count, obj.dim))


@pytest.mark.parametrize(
    ("spec", "meq", "weights"),
    [
        ("thesis", MEQ_KG, "thesis"),
        ("thesis", MEQ_KG, "ml"),
        ("baseline", None, "thesis"),
        ("thesis+coulomb_friction", MEQ_KG, "thesis"),  # sgn correlates with c1: off-diagonal Gram terms
        ("thesis+cubic_stiffness", MEQ_KG, "ml"),
    ],
)
def test_gram_closed_form_equals_the_per_sample_sum(noisy, spec, meq, weights):
    """sum_j w_j sum_n (F_model - F_measured)^2 summed sample by sample equals the Gram form,
    for a population spanning more than one evaluation block."""
    model = build_model(spec) if meq is None else build_model(spec).fix(meq=meq)
    obj = Objective(noisy, model, weights=weights)
    pop = np.vstack([random_population(obj, 150, seed=1), obj.bounds.mean(axis=1)])
    pop[-1] = [TRUE_PARAMS.get(name, x) for name, x in zip(obj.model.names, pop[-1])]
    assert not obj.model.has_memory and len(obj.features) >= 2
    direct = np.array([np.sum(obj.loop_weight[:, None] * (obj.predict(p)[0] - obj.y) ** 2) for p in pop])
    np.testing.assert_allclose(obj(pop), direct, rtol=1e-10)


def test_weights(noisy):
    n = noisy.n_samples
    peak = np.maximum(np.abs(noisy.top[:, :, 1]).max(axis=1), np.abs(noisy.bottom[:, :, 1]).max(axis=1))
    thesis = Objective(noisy, build_model("thesis").fix(meq=MEQ_KG))
    np.testing.assert_allclose(thesis.loop_weight, peak.max() / peak / (2 * n), rtol=1e-15)
    ml = Objective(noisy, build_model("thesis").fix(meq=MEQ_KG), weights="ml")
    np.testing.assert_allclose(ml.loop_weight, 1.0 / noisy.sigma**2, rtol=1e-15)
    # at the truth the ML objective is a chi-square with 2n degrees of freedom per loop
    chi2 = ml(TRUTH)[0]
    dof = 2 * n * noisy.n_loops
    assert abs(chi2 - dof) < 5 * np.sqrt(2 * dof)


def test_ml_weights_without_sigma_name_the_fix():
    clean = synth_loops(0.0)
    with pytest.raises(HysidInputError) as info:
        Objective(clean, build_model("thesis").fix(meq=MEQ_KG), weights="ml")
    message = str(info.value)
    assert "sigma" in message and "use the thesis weights" in message and clean.name in message
    assert "\n" not in message
    with pytest.raises(HysidInputError, match="unknown weights"):
        Objective(clean, build_model("thesis").fix(meq=MEQ_KG), weights="l1")


def test_jacobian_matches_finite_differences(noisy):
    obj = Objective(noisy, build_model("thesis").fix(meq=MEQ_KG))
    theta = TRUTH * np.array([1.1, 0.9, 1.001, 1.05])
    jac = obj.jacobian(theta)
    assert jac.shape == (2 * noisy.n_samples * noisy.n_loops, 4)
    span = obj.bounds[:, 1] - obj.bounds[:, 0]
    for d in range(4):
        h = np.zeros(4)
        h[d] = 1e-5 * span[d]
        numeric = (obj.weighted_residuals(theta + h) - obj.weighted_residuals(theta - h)) / (2 * h[d])
        np.testing.assert_allclose(jac[:, d], numeric, rtol=1e-5, atol=1e-7 * np.abs(numeric).max())
    # the gradient of the objective is 2 J^T r
    gradient = 2 * jac.T @ obj.weighted_residuals(theta)
    for d in range(4):
        h = np.zeros(4)
        h[d] = 1e-6 * span[d]
        numeric = (obj(theta + h)[0] - obj(theta - h)[0]) / (2 * h[d])
        assert gradient[d] == pytest.approx(numeric, rel=1e-4)
    assert np.sum(obj.weighted_residuals(theta) ** 2) == pytest.approx(obj(theta)[0], rel=1e-12)


def test_non_finite_parameters_give_inf(noisy):
    obj = Objective(noisy, build_model("thesis").fix(meq=MEQ_KG))
    pop = random_population(obj, 6, seed=2)
    pop[1, 0] = np.nan
    pop[3, 2] = np.inf
    pop[4, 3] = -np.inf
    fitness = obj(pop)
    assert np.all(np.isinf(fitness[[1, 3, 4]])) and np.all(fitness[[1, 3, 4]] > 0)
    assert np.all(np.isfinite(fitness[[0, 2, 5]]))


@pytest.mark.parametrize(("spec", "count"), [("thesis", 200), ("thesis+bouc_wen", 8)])
def test_population_and_single_vector_calls_agree(noisy, spec, count):
    loops = noisy if spec == "thesis" else noisy.subset(np.arange(0, 120, 15))
    obj = Objective(loops, build_model(spec).fix(meq=MEQ_KG))
    pop = random_population(obj, count, seed=3)
    fitness = obj(pop)
    assert fitness.shape == (count,) and obj.evaluations == count
    singles = np.array([obj(p)[0] for p in pop[::7]])
    assert obj.evaluations == count + singles.size
    np.testing.assert_allclose(singles, fitness[::7], rtol=1e-13)
    np.testing.assert_allclose(obj(pop[::-1])[::-1], fitness, rtol=1e-13)
    assert obj(np.empty((0, obj.dim))).shape == (0,)
