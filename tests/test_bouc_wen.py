"""Bouc-Wen as practitioners use it (issue 21): the exponent n free, the mr_damper preset, starting points
read off the loops."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hysid.bench.objective import distorted_synth
from hysid.cli import main
from hysid_model import bouc_wen_orbit, waveform
from hysid_model.effects.bouc_wen import BoucWen, _any_exponent, _closed_form
from hysid_model.errors import HysidInputError
from hysid_model.kinematics import Kinematics
from hysid_model.model import Model, build_model, spec_of
from hysid_model.objective import Objective
from hysid_model.presets import PRESET_EXPLANATIONS, PRESETS
from hysid_model.problem import prepare_model
from hysid_model.synth import MEQ_KG, synth_loops
from island.config import CampaignConfig
from timedomain_reference import odd_periodic_orbit, periodic_steady_state, tabulated_drive

BASE = {"xi0": 0.01, "S_xi": 0.0, "w0": 2 * np.pi * 30.0, "S_w": 0.0}
EXPONENTS = (0.5, 0.7, 1.0, 1.5, 2.0, 3.0, 5.0, 20.0, 60.0)
SHAPES = ((1e-5, -0.9), (3e-4, 0.3), (2e-3, 3.0), (1e-2, -0.5), (1e-4, 10.0), (2e-5, 0.0), (5e-4, 1.0), (3e-4, 300.0), (1e-3, -0.2))
"""(bw_zy, bw_r): yield from 1/150 to 20 x the Synth amplitudes (0.5 to 1.5 mm), every shape of Fig. 2.6 (and r >> 1)."""


def free_exponent(spec: str) -> Model:
    return build_model(spec).fix(meq=MEQ_KG).vary("bw_n")


def population(model: Model) -> np.ndarray:
    """Every exponent with every shape (n = 1 among them: those take the closed form), and a delay."""
    rng = np.random.default_rng(3)
    rows = []
    for i, n in enumerate(EXPONENTS):
        for j, (zy, r) in enumerate(SHAPES[i % 3 :: 3]):
            values = {**BASE, "bw_k": rng.uniform(10.0, 500.0), "bw_zy": zy, "bw_r": r, "bw_n": n, "F_d": 0.2, "delay_s": 2e-4 * (j - 1)}
            rows.append([values[name] for name in model.names])
    return np.array(rows)


def relative_error(fast: np.ndarray, reference: np.ndarray) -> float:
    scale = np.abs(reference).max(axis=-1, keepdims=True)
    return float(np.max(np.abs(fast - reference) / np.where(scale > 0, scale, 1.0)))


@pytest.mark.parametrize("spec", ["baseline+bouc_wen", "thesis+bouc_wen+channel_delay", "thesis+bouc_wen+coulomb_friction+channel_delay"])
@pytest.mark.parametrize("which", ["ideal", "distorted"])
def test_tabulated_orbit_of_any_exponent_is_the_exact_reference(spec, which, request):
    """The compiled sampler (tables of the orbit, sample runs, the relaxing tail, the cycle mean, phases
    shifted by a delay) against the reference's exact solution per point, for n from 1/2 to 60."""
    loops = request.getfixturevalue(which)
    model = free_exponent(spec)
    fast, reference = Objective(loops, model), Objective(loops, model, compiled=False)
    assert fast.sampled.compiled
    pop = population(model)
    force = fast.memory_force(pop)
    assert relative_error(force, reference.memory_force(pop)) < 2e-8
    one = pop[:, model.names.index("bw_n")] == 1.0
    assert one.any() and not one.all()  # a mixed population: n = 1 by the closed form, the rest tabulated
    np.testing.assert_array_equal(force[one], fast.memory_force(pop[one]))


@pytest.mark.parametrize("spec", ["baseline+bouc_wen", "thesis+bouc_wen+channel_delay"])
def test_candidates_that_share_an_orbit_share_it_and_each_force_is_its_own(spec, distorted):
    """Candidates that differ only outside (n, r, z_y) and the delay (a Jacobian's probes of xi0, w0 and k_bw)
    share one orbit: the same force where k_bw is the same, k_bw times it otherwise; and a candidate's force is
    the same bits alone as among others."""
    model = free_exponent(spec)
    fast = Objective(distorted, model)
    base = population(model)[4]
    rows = np.repeat(base[None, :], 5, axis=0)
    rows[1, model.names.index("xi0")] *= 1.5
    rows[2, model.names.index("w0")] *= 0.9
    rows[3, model.names.index("bw_k")] *= 2.0
    rows[4, model.names.index("bw_zy")] *= 1.1
    force = fast.memory_force(rows)
    np.testing.assert_array_equal(force[1], force[0])
    np.testing.assert_array_equal(force[2], force[0])
    np.testing.assert_allclose(force[3], 2.0 * force[0], rtol=1e-15, atol=1e-15 * np.abs(force[0]).max())
    assert np.abs(force[4] - force[0]).max() > 1e-3 * np.abs(force[0]).max()
    for i, row in enumerate(rows):
        np.testing.assert_array_equal(fast.memory_force(row[None, :])[0], force[i])
    reference = Objective(distorted, model, compiled=False)
    assert relative_error(force, reference.memory_force(rows)) < 2e-8


def test_exponent_one_by_the_general_solver_is_the_closed_form(ideal, distorted):
    for loops in (ideal, distorted):
        kin = Kinematics(loops.x0, loops.omega, loops.x_harmonics)
        _zy, _r = (np.array([[z], [z]]) for z in (3e-4, 0.7))
        v = {"bw_k": np.ones((2, 1)), "bw_zy": np.array([[3e-4], [2e-5]]), "bw_r": np.array([[0.7], [-0.6]]), "bw_n": np.ones((2, 1))}
        closed = _closed_form(v, kin, loops.phases())
        assert relative_error(_any_exponent(v, kin, loops.phases()), closed) < 1e-12


def test_travel_series_are_the_quadrature():
    """T_c(w) = int_0^w dv / (1 - c v^n) in each of its four forms against quadrature (in log v)."""
    from scipy.integrate import quad

    for n in (0.5, 1.0, 1.5, 2.0, 5.0, 20.0):
        a = 1.0 / n
        psi = bouc_wen_orbit.digamma(a)
        for c in (1.0, 0.9, 0.55, 0.3, -0.3, -0.6, -1.9, -2.5, -30.0, -1e4):
            for w in (1e-3, 0.3, 0.7, 0.95, 0.999, 1.0):
                if c * w**n < 1.0:
                    expected = quad(lambda u: np.exp(u) / (1.0 - c * np.exp(n * u)), -60.0, np.log(w), epsabs=0.0, epsrel=1e-13, limit=500)[0]  # noqa: B023 (called within this iteration)
                    assert bouc_wen_orbit.travel(w, c, n, a, psi) == pytest.approx(expected, rel=1e-11)


def sine_orbit(x0: float, zy: float, r: float, n: float, phase: np.ndarray) -> np.ndarray:
    """Eq. 2.1b integrated in time under x = X0 sin(theta) (:func:`odd_periodic_orbit`)."""
    gamma, beta = (1 + r) / (2 * zy**n), (1 - r) / (2 * zy**n)

    def rhs(theta: float, z: float) -> float:
        c = np.cos(theta)
        return x0 * c * (1.0 - abs(z) ** n * (gamma * np.sign(c * z) + beta))

    return odd_periodic_orbit(rhs, -0.5 * np.pi, (-zy, 0.0), phase)


def check_against_time_integration(n: float, zy: float, r: float) -> None:
    data = synth_loops(0.0, 0, 48).subset([0, 50, 100])  # X0 = 0.5, 1 and 1.5 mm
    model = free_exponent("baseline+bouc_wen")
    on, off = (Objective(data, model).predict(model.from_dict({**BASE, "bw_k": k, "bw_zy": zy, "bw_r": r, "bw_n": n}))[0] for k in (1.0, 0.0))
    for j, x0 in enumerate(data.x0):
        expected = sine_orbit(x0, zy, r, n, data.phases()[j])
        np.testing.assert_allclose((on - off)[j], expected, rtol=0, atol=1e-6 * np.abs(expected).max())


@pytest.mark.parametrize("n, zy, r", [(2.0, 1e-4, 0.5), (0.5, 3e-4, -0.5), (5.0, 1e-5, 1.0)])
def test_orbit_of_any_exponent_is_the_time_integration_of_eq_2_1(n, zy, r):
    """The compiled objective's Bouc-Wen force within 1e-6 of its scale of the orbit integrated in time."""
    check_against_time_integration(n, zy, r)


@pytest.mark.slow
@pytest.mark.parametrize("n", [0.5, 1.5, 2.0, 3.0, 5.0])
def test_orbit_is_the_time_integration_across_yield_and_shape(n):
    """Yield displacements from 1/150 to 20 x the amplitude (the loops hold three), r across its range."""
    for zy, r in ((1e-5, -0.9), (1e-4, 0.0), (1e-3, 1.0), (1e-2, 3.0), (3e-4, -0.5)):
        check_against_time_integration(n, zy, r)


@pytest.mark.slow
def test_any_exponent_on_a_measured_waveform_is_the_time_domain_steady_state(distorted):
    """Eq. 2.1b with n = 2.5 over cycles of each loop's own distorted displacement, the cycle mean removed
    (within the cycle mean's accuracy, as for n = 1)."""
    loops = distorted.subset([0, 3, 9])
    model = free_exponent("baseline+bouc_wen")
    values = {"xi0": 0.0, "w0": 100.0, "bw_k": 1e4, "bw_zy": 1e-4, "bw_r": 0.5, "bw_n": 2.5}
    on, off = (Objective(loops, model).predict(model.from_dict(values | {"bw_k": k}))[0] for k in (1e4, 0.0))
    gamma, beta = (1 + values["bw_r"]) / (2 * values["bw_zy"] ** 2.5), (1 - values["bw_r"]) / (2 * values["bw_zy"] ** 2.5)
    xh, steps = loops.x_harmonics, 1 << 14
    velocity = tabulated_drive(lambda theta: waveform.displacement(xh, np.broadcast_to(theta, (loops.n_loops, theta.size)), 1)[None, :, None], steps)

    def rhs(theta, z):
        dx = velocity(theta)
        return dx - gamma * np.abs(dx) * np.abs(z) ** 1.5 * z - beta * dx * np.abs(z) ** 2.5

    grid = np.linspace(0.0, 2 * np.pi, 4096, endpoint=False)
    phases = np.concatenate([loops.phases(), np.broadcast_to(grid, (loops.n_loops, grid.size))], axis=1)
    z = periodic_steady_state(rhs, np.zeros((1, loops.n_loops, 1)), phases[:, None, :], steps_per_cycle=steps, max_cycles=400)[0][:, 0]
    n = 2 * loops.n_samples
    expected = values["bw_k"] * (z[:, :n] - z[:, n:].mean(axis=1, keepdims=True))
    np.testing.assert_allclose(on - off, expected, atol=2e-5 * np.abs(expected).max())


def test_exponent_is_fixed_at_one_unless_freed_and_bounded_below_by_one_half(ideal):
    model = build_model("thesis+bouc_wen")
    assert model.fixed["bw_n"] == 1.0 and "bw_n" not in model.names
    freed = prepare_model(ideal, "thesis+bouc_wen", bounds={"bw_n": (1.0, 4.0)})
    assert "bw_n" in freed.names and freed.bounds[freed.names.index("bw_n")].tolist() == [1.0, 4.0]
    with pytest.raises(HysidInputError, match="physical range"):
        model.fix(bw_n=0.3)
    with pytest.raises(HysidInputError, match="physical range"):
        model.vary("bw_n").with_bounds({"bw_n": (0.2, 3.0)})
    soft = prepare_model(ideal, model.vary("bw_n"))
    p = next(p for p in soft.parameters if p.name == "bw_n")
    assert p.soft and p.widened(False, True).upper == 60.0 and p.widened(True, False).lower == 0.5


def test_shape_grid_tries_exponents_only_where_n_is_free(ideal):
    kin = Kinematics(ideal.x0, ideal.omega)
    fixed, free = BoucWen().shape_grid(kin), BoucWen().shape_grid(kin, free=("bw_k", "bw_zy", "bw_r", "bw_n"))
    assert len(fixed) == 12 and all("bw_n" not in s for s in fixed)
    assert len(free) == 24 and {s["bw_n"] for s in free} == {1.0, 2.0}
    assert [{k: v for k, v in s.items() if k != "bw_n"} for s in free[::2]] == fixed


def test_mr_damper_preset_frees_the_exponent_and_is_listed():
    model = build_model("mr_damper")
    assert PRESETS["mr_damper"] == ("bouc_wen",) and model.names == ["xi0", "w0", "meq", "bw_k", "bw_zy", "bw_r", "bw_n"]
    assert build_model("mr_damper+coulomb_friction").names[-2:] == ["bw_n", "F_d"]
    with pytest.raises(HysidInputError, match="already in the model"):
        build_model("mr_damper+bouc_wen")
    assert set(PRESET_EXPLANATIONS) == set(PRESETS)


def test_hysid_models_lists_the_mr_damper(capsys):
    assert main(["models"]) == 0
    out = capsys.readouterr().out
    assert "model mr_damper:" in out and "Spencer" in out and "bw_n [1] in [1, 6]" in out
    assert "bw_n [1] fixed at 1 (search [1, 6] when freed)" in out


@pytest.mark.parametrize("how", ["mr_damper", "mr_damper+coulomb_friction", "freed", "pinned"])
def test_model_strings_rebuild_the_same_model_in_another_process(how, ideal):
    """A campaign sends its model string, bounds (soft ones marked) and fixed values to its islands: the island
    rebuilds the same search space."""
    model = {"freed": build_model("thesis+bouc_wen").vary("bw_n"), "pinned": build_model("mr_damper").fix(bw_n=2.0)}.get(how, how)
    config = CampaignConfig.create(ideal, name="bw", model=model)
    island = CampaignConfig.from_dict(config.as_dict()).objective(ideal).model
    assert island.names == list(config.bounds) and island.fixed == config.fixed
    assert [(p.lower, p.upper, p.soft) for p in island.parameters] == [(*config.bounds[n], n in config.soft) for n in island.names]
    assert ("bw_n" in island.names) == (how != "pinned")


def test_spec_of_names_the_preset_that_frees_the_exponent():
    terms = build_model("baseline+bouc_wen").terms
    assert spec_of(terms) == "baseline+bouc_wen"
    freed = Model(terms, overrides={"bw_n": build_model("mr_damper").parameters[-1]})
    assert freed.spec == "mr_damper" and build_model(freed.spec).names == freed.names


def simulated(truth: dict[str, float], loops, xi: float = 0.02, noise: float = 0.0, seed: int = 0):
    """``loops`` with the force of the oscillator plus a Bouc-Wen spring of parameters ``truth``, and Gaussian
    noise of ``noise`` times the largest force."""
    model = free_exponent("baseline+bouc_wen")
    force = Objective(loops, model).predict(model.from_dict({**BASE, "xi0": xi, **truth}))[0]
    sigma = noise * np.abs(force).max()
    force = force + sigma * np.random.default_rng(seed).standard_normal(force.shape)
    n = loops.n_samples
    top, bottom = loops.top.copy(), loops.bottom.copy()
    top[:, :, 1], bottom[:, :, 1] = force[:, :n], force[:, n:]
    return replace(loops, top=top, bottom=bottom, sigma=np.full(loops.n_loops, max(sigma, 1e-12)))


READABLE = [
    ({"bw_k": 2e4, "bw_zy": 1e-4, "bw_r": 0.5, "bw_n": 1.0}, 0.02, 0.0),
    ({"bw_k": 2e4, "bw_zy": 1e-4, "bw_r": 0.0, "bw_n": 2.0}, 0.1, 0.05),
    ({"bw_k": 5e3, "bw_zy": 2e-4, "bw_r": 1.0, "bw_n": 3.0}, 0.02, 0.01),
    ({"bw_k": 1e5, "bw_zy": 3e-5, "bw_r": -0.5, "bw_n": 1.5}, 0.02, 0.01),
    ({"bw_k": 1e4, "bw_zy": 5e-5, "bw_r": 2.0, "bw_n": 5.0}, 0.05, 0.01),
    ({"bw_k": 1e4, "bw_zy": 5e-5, "bw_r": -0.8, "bw_n": 1.0}, 0.02, 0.01),
    ({"bw_k": 2e4, "bw_zy": 1e-5, "bw_r": 0.5, "bw_n": 2.0}, 0.02, 0.01),
]
"""(truth, damping ratio, noise): sharp and soft knees, every shape, light and heavy damping, up to 5 % noise,
and yield from 1/150 of the amplitude (below the sample spacing) to 1/5."""


@pytest.mark.parametrize("truth, xi, noise", READABLE)
def test_starts_read_off_the_loops_land_near_the_truth(truth, xi, noise):
    """Loops at three amplitudes and 15 frequencies: the first start within a factor of 2 of bw_k and bw_zy, with n
    free and fixed at 1; where n is free the starts carry it (n = 1 and 2 among them)."""
    loops = simulated(truth, synth_loops(0.0, 0, 60).subset(np.arange(0, 120, 8)), xi, noise)
    for free in (("bw_n",), ()):
        starts = BoucWen().data_starts(loops, free=free)
        assert 2 <= len(starts) <= 6
        first = starts[0]
        assert 0.5 < first["bw_k"] / truth["bw_k"] < 2.0 and 0.5 < first["bw_zy"] / truth["bw_zy"] < 2.0
        assert all(np.isfinite(list(s.values())).all() and s["bw_k"] > 0 and s["bw_zy"] > 0 and s["bw_r"] >= -0.9 for s in starts)
        if free:
            assert {1.0, 2.0} <= {s["bw_n"] for s in starts}
        else:
            assert all("bw_n" not in s for s in starts)


def test_starts_on_a_measured_waveform(distorted):
    truth = {"bw_k": 5e3, "bw_zy": 5e-5, "bw_r": -0.5, "bw_n": 1.0}
    first = BoucWen().data_starts(simulated(truth, distorted_synth().subset(np.arange(0, 120, 6)), 0.03), free=("bw_n",))[0]
    assert 0.5 < first["bw_k"] / truth["bw_k"] < 2.0 and 0.5 < first["bw_zy"] / truth["bw_zy"] < 2.0


@pytest.mark.parametrize("truth", [{"bw_k": 2e4, "bw_zy": 5e-3, "bw_r": 0.5, "bw_n": 2.0}, {"bw_k": 20.0, "bw_zy": 1e-4, "bw_r": 0.5, "bw_n": 2.0}])
def test_nearly_linear_loops_give_no_starts(truth):
    """A yield displacement 5 x the largest amplitude (the spring merely stiffens the loops) or hysteresis below
    the noise: nothing to read, no starts."""
    loops = simulated(truth, synth_loops(0.0, 0, 60).subset(np.arange(0, 120, 8)), noise=0.01)
    assert BoucWen().data_starts(loops, free=("bw_n",)) == []
    assert build_model("baseline").terms[0].data_starts(loops) == []
