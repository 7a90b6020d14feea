"""The least-squares polish (island.polish) on the real Synth objective."""

from __future__ import annotations

import numpy as np
import pytest

from hysid_model.model import build_model
from hysid_model.objective import Objective
from hysid_model.synth import MEQ_KG, TRUE_PARAMS, synth_loops
from island.polish import polish


class CountingObjective(Objective):
    """The real objective, counting the residual and Jacobian calls the polish makes."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.residual_calls = 0
        self.jacobian_calls = 0

    def weighted_residuals(self, theta):
        self.residual_calls += 1
        return super().weighted_residuals(theta)

    def jacobian(self, theta, weighted=True):
        self.jacobian_calls += 1
        return super().jacobian(theta, weighted)


def synth_objective(noise_pct=0.0, bounds=None):
    model = build_model("thesis").fix(meq=MEQ_KG).with_bounds(bounds or {})
    return model, CountingObjective(synth_loops(noise_pct, seed=4), model)


def test_reaches_the_noiseless_optimum_from_a_heuristic_quality_start():
    model, objective = synth_objective()
    truth = model.from_dict(TRUE_PARAMS)
    start = truth * np.array([1.05, 0.6, 1.0003, 1.04])  # the spread a thesis-budget GA/PSO leaves
    result = polish(objective, start)
    assert result.success and result.message
    assert np.all(np.abs(result.theta / truth - 1) < 1e-9)
    assert result.fitness < 1e-25 < objective(start)[0]
    assert result.evaluations == objective.residual_calls + 2 * 4 * objective.jacobian_calls
    assert objective.jacobian_calls > 0


def test_stays_in_bounds_and_stops_on_the_bound_that_excludes_the_truth():
    model, objective = synth_objective(bounds={"w0": (150.0, 185.0)})
    start = model.from_dict({"xi0": 0.004, "S_xi": -0.3, "w0": 184.0, "S_w": -1200.0})
    result = polish(objective, start)
    lower, upper = model.bounds[:, 0], model.bounds[:, 1]
    assert np.all((result.theta >= lower) & (result.theta <= upper))
    assert result.theta[2] == pytest.approx(185.0, abs=1e-6)
    assert result.fitness <= objective(start)[0]


def test_never_worse_than_the_start_on_noisy_data():
    model, objective = synth_objective(noise_pct=10.0)
    start = model.from_dict({"xi0": 0.0045, "S_xi": -0.5, "w0": 189.2, "S_w": -1300.0})
    result = polish(objective, start)
    assert result.success
    assert result.fitness < objective(start)[0]
    assert result.fitness == pytest.approx(objective(result.theta)[0], rel=1e-9)
    truth = model.from_dict(TRUE_PARAMS)
    assert abs(result.theta[2] / truth[2] - 1) < 1e-3


def test_max_nfev_caps_the_work():
    model, objective = synth_objective()
    start = model.from_dict({"xi0": 0.01, "S_xi": 1.0, "w0": 195.0, "S_w": 0.0})
    result = polish(objective, start, max_nfev=2)
    assert not result.success
    assert objective.residual_calls <= 3
    assert result.fitness <= objective(start)[0]


def test_start_outside_the_bounds_is_clipped_in():
    model, objective = synth_objective()
    start = model.from_dict({"xi0": -0.5, "S_xi": -0.4, "w0": 189.0, "S_w": -1256.0})
    result = polish(objective, start)
    assert result.theta[0] >= 0.0 and np.isfinite(result.fitness)


def test_the_solves_run_every_blas_library_on_one_thread_and_give_the_threads_back():
    """numpy's and scipy's own OpenBLAS are both held to one thread inside, both as they were after."""
    import scipy.linalg  # noqa: F401  (scipy's own BLAS loaded)
    from threadpoolctl import threadpool_info

    from hysid_model.blas import one_blas_thread

    before = {i["filepath"]: i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}
    with one_blas_thread():
        inside = {i["filepath"]: i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}
    after = {i["filepath"]: i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}
    assert set(inside) >= set(before) and set(inside.values()) == {1}
    assert after == before
