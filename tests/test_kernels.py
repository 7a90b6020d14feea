"""Compiled per-sample forces (hysid_model/bouc_wen_kernels.py, shifted_kernels.py, squares_kernels.py, sampled.py) against the numpy reference path and
against exact or time-domain forms (issue 11: fast nonlinear and memory terms)."""

from __future__ import annotations

import numpy as np
import pytest

from hysid_model import bouc_wen_kernels, waveform
from hysid_model.effects.bouc_wen import loading_orbit
from hysid_model.harmonics import HarmonicObjective, Harmonics
from hysid_model.loops import LoopSet
from hysid_model.model import build_model
from hysid_model.objective import Objective
from hysid_model.synth import MEQ_KG, TRUE_PARAMS
from support import cell_average
from timedomain_reference import affine_periodic_orbit, periodic_steady_state, tabulated_drive

BASE = {**TRUE_PARAMS}
SHAPES = [(3e-4, 0.3), (1e-5, -0.8), (5e-3, 1.0), (2e-4, 2.5), (1e-4, 0.0), (2e-6, -0.5), (0.5, 2.0)]
"""(bw_zy, bw_r): sharp and soft yield, every shape of Fig. 2.6, r = 0 (a = 0) and r < 0."""


def population(model, rng, n: int = 12) -> np.ndarray:
    """Candidates around the Synth truth with every per-sample effect switched on (the SHAPES for Bouc-Wen)."""
    rows = []
    for i in range(n):
        zy, r = SHAPES[i % len(SHAPES)]
        values = {
            **BASE,
            "bw_k": rng.uniform(10.0, 500.0),
            "bw_zy": zy,
            "bw_r": r,
            "F_d": rng.uniform(0.01, 1.0),
            "f_c": rng.uniform(0.5, 20.0),
            "delay_s": rng.uniform(-1e-3, 1e-3),
        }
        rows.append([values[name] for name in model.names])
    return np.array(rows)


def relative_error(fast: np.ndarray, reference: np.ndarray) -> float:
    """Largest |fast - reference| per candidate and loop relative to that loop's largest |reference|."""
    scale = np.abs(reference).max(axis=-1, keepdims=True)
    return float(np.max(np.abs(fast - reference) / np.where(scale > 0, scale, 1.0)))


EXACT = [
    "baseline+bouc_wen",
    "thesis+bouc_wen",
    "thesis+bouc_wen+channel_delay",
    "thesis+coulomb_friction+channel_delay",
    "thesis+bouc_wen+coulomb_friction+channel_delay",
]


@pytest.mark.parametrize("spec", EXACT)
@pytest.mark.parametrize("which", ["ideal", "distorted"])
def test_compiled_force_is_the_numpy_reference_to_1e_10(spec, which, request):
    loops = request.getfixturevalue(which)
    model = build_model(spec).fix(meq=MEQ_KG)
    fast, reference = Objective(loops, model), Objective(loops, model, compiled=False)
    assert fast.sampled is not None and fast.sampled.compiled and reference.sampled is None
    pop = population(model, np.random.default_rng(1))
    force = fast.predict(pop)
    assert relative_error(force, reference.predict(pop)) < 1e-10
    np.testing.assert_allclose(fast(pop), reference(pop), rtol=1e-10)
    assert relative_error(force - fast.predict(pop * np.where(np.isin(model.names, ["bw_k", "F_d"]), 0.0, 1.0)), force) > 1e-3


def test_orbit_by_newton_is_the_bisection_of_loading_orbit():
    rng = np.random.default_rng(0)
    spans = np.array([1e-6, 5e-4, 1e-3, 2.5e-3, 0.3])
    zy = np.exp(rng.uniform(np.log(1e-9), np.log(1.0), 400))
    r = np.concatenate([[0.0, -0.9, 3.0, 1.0], rng.uniform(-0.9, 3.0, 396)])
    gamma, beta = (1 + r) / (2 * zy), (1 - r) / (2 * zy)
    a, b = gamma - beta, gamma + beta
    z_max, run = np.empty((a.size, spans.size)), np.empty((a.size, spans.size))
    bouc_wen_kernels.bouc_wen_orbit(spans, a, b, z_max, run)
    expected_z, expected_run = loading_orbit(spans[None, :], gamma[:, None], beta[:, None])
    # bisection compares 1 - b z with exp(b run - 2 b S): both near 1 when b S is small, so it resolves z to ~eps / b
    resolution = 4e-16 / b[:, None]
    assert np.all(np.abs(z_max - expected_z) <= 1e-12 * expected_z + resolution)
    assert np.all(np.abs(run - expected_run) <= 1e-12 * np.abs(expected_run) + 4 * resolution)


def test_samples_off_a_uniform_grid_take_their_own_exponential(ideal):
    """Loops sampled at random displacements (no uniform travel grid) and one with a hole in its grid."""
    rng = np.random.default_rng(3)
    x = np.sort(rng.uniform(-1.0, 1.0, (ideal.n_loops, ideal.n_samples)), axis=1) * ideal.x0[:, None]
    x[:, [0, -1]] = ideal.x0[:, None] * [-1.0, 1.0]
    x[0] = np.delete(np.linspace(-1, 1, ideal.n_samples + 1), 7) * ideal.x0[0]
    loops = LoopSet("random-x", ideal.freq_hz, ideal.x0, np.stack([x, ideal.top[:, :, 1]], -1), np.stack([x, ideal.bottom[:, :, 1]], -1), ideal.sigma)
    model = build_model("thesis+bouc_wen").fix(meq=MEQ_KG)
    fast = Objective(loops, model)
    sampler = fast.sampled.samplers[0]
    assert np.isnan(sampler.step[sampler.runs[:, 0] > 0]).all() and (sampler.runs[sampler.runs[:, 0] == 0, 3] > 2).sum() >= 3
    pop = population(model, rng)
    assert relative_error(fast.predict(pop), Objective(loops, model, compiled=False).predict(pop)) < 1e-10


def test_velocity_sign_through_the_high_pass_is_the_exact_exponential_step_response(ideal):
    """Eq. 4.1-4.2: a single-pole high-pass on the friction's square wave, exactly; the numpy reference
    sums 128 harmonics and agrees within its truncation."""
    model = build_model("baseline+coulomb_friction+charge_amplifier_highpass").fix(meq=MEQ_KG)
    f_c, fd = 3.0, 1.0
    values = {"xi0": 0.0, "w0": 100.0, "F_d": fd, "f_c": f_c}
    theta = model.from_dict(values)
    jump = Objective(ideal, model).predict(theta)[0] - Objective(ideal, model).predict(model.from_dict(values | {"F_d": 0.0}))[0]
    tau, w, n = 1.0 / (2 * np.pi * f_c), ideal.omega[:, None], ideal.n_samples
    sign = np.where(np.arange(2 * n) < n, 1.0, -1.0)
    phase = ideal.phases()
    since_jump = np.where(sign > 0, np.mod(phase + np.pi / 2, 2 * np.pi), np.mod(phase - np.pi / 2, 2 * np.pi)) / w
    exact = sign * fd * 2.0 / (1.0 + np.exp(-np.pi / (w * tau))) * np.exp(-since_jump / tau)
    np.testing.assert_allclose(jump, exact, rtol=0, atol=1e-12 * fd)
    reference = (
        Objective(ideal, model, compiled=False).predict(theta)[0] - Objective(ideal, model, compiled=False).predict(model.from_dict(values | {"F_d": 0.0}))[0]
    )
    np.testing.assert_allclose(reference, exact, atol=5e-3 * (2 * np.pi * f_c / w).max())


def test_velocity_sign_through_a_high_pass_of_vanishing_cut_off_is_the_plain_square_wave(ideal):
    """A cut-off so low (f_c = 1e-18 Hz) that exp(-rho 2 pi) rounds to 1: the step response is the square wave itself
    (up -> 2 T2 / 2 pi, down -> 2 T1 / 2 pi, a sign of amplitude F_d), not a division by zero (a polish of a
    diagnosis' refit stepped f_c there and stopped the whole diagnosis with ZeroDivisionError)."""
    model = build_model("baseline+coulomb_friction+charge_amplifier_highpass").fix(meq=MEQ_KG)
    values = {"xi0": 0.0, "w0": 100.0, "F_d": 1.0}
    objective = Objective(ideal, model)
    jump = {
        f_c: objective.predict(model.from_dict(values | {"f_c": f_c}))[0] - objective.predict(model.from_dict(values | {"F_d": 0.0, "f_c": f_c}))[0]
        for f_c in (0.0, 1e-18)
    }
    assert np.all(np.isfinite(jump[1e-18]))
    np.testing.assert_allclose(jump[1e-18], jump[0.0], rtol=0, atol=1e-12)


@pytest.mark.slow
def test_velocity_sign_through_delay_and_high_pass_on_a_measured_waveform_is_the_time_domain_filter(distorted):
    """The high-pass state integrated in time (tau dl/dt + l = u, y = u - l) over the distorted waveform's own
    reversals, delayed: the compiled force matches to the integration's accuracy (the exact form is
    checked to 1e-12 on the ideal sine above); where the delay moves a jump of u into a sample's cell, the
    sample sees u averaged over the cell with its hat function (here by quadrature)."""
    loops = distorted.subset([0, 5])
    model = build_model("baseline+coulomb_friction+charge_amplifier_highpass+channel_delay").fix(meq=MEQ_KG)
    values = {"xi0": 0.0, "w0": 100.0, "F_d": 0.7, "f_c": 4.0, "delay_s": 3e-4}
    on = Objective(loops, model).predict(model.from_dict(values))[0]
    off = Objective(loops, model).predict(model.from_dict(values | {"F_d": 0.0}))[0]
    xh = loops.x_harmonics
    lo, hi = waveform.reversals(xh)
    rho = (2 * np.pi * values["f_c"] / loops.omega)[None, :, None]

    def square(theta):
        return np.where(np.mod(theta - lo[None, :, None], 2 * np.pi) < (hi - lo)[None, :, None], 1.0, -1.0)

    def rhs(theta, state):  # the low-pass part l of the high-pass: dl/dtheta = rho (u - l)
        return rho * (square(theta) - state)

    shifted = loops.phases() - loops.omega[:, None] * values["delay_s"]
    steps = 1 << 15
    low = affine_periodic_orbit(rhs, (1, loops.n_loops, 1), shifted[:, None, :], steps_per_cycle=steps, tol=1e-8)[0][:, 0]  # the filter is linear
    cells = waveform.sample_cells(loops.phases(), loops.n_samples, lo, hi)
    jumps = np.stack([lo, hi], axis=1) + loops.omega[:, None] * values["delay_s"]
    expected = values["F_d"] * (
        cell_average(lambda t: square(t[None] - loops.omega[None, :, None] * values["delay_s"])[0], loops.phases(), *cells, jumps) - low
    )
    # RK4 steps across the square wave's jumps are first-order accurate: ~rho h of the jump (h = 2 pi / 2^15)
    np.testing.assert_allclose(on - off, expected, rtol=0, atol=5e-5 * values["F_d"])


@pytest.mark.slow
def test_bouc_wen_on_a_measured_waveform_is_the_time_domain_steady_state(distorted):
    """Eq. 2.1b integrated over cycles of each loop's own distorted displacement: the compiled objective's force
    (with the orbit's cycle mean removed) is that steady state, within the accuracy of the cycle mean."""
    loops = distorted.subset([0, 3, 9])
    model = build_model("baseline+bouc_wen").fix(meq=MEQ_KG)
    values = {"xi0": 0.0, "w0": 100.0, "bw_k": 1e4, "bw_zy": 2e-4, "bw_r": 0.5}
    force = Objective(loops, model).predict(model.from_dict(values))[0] - Objective(loops, model).predict(model.from_dict(values | {"bw_k": 0.0}))[0]
    gamma, beta = (1 + values["bw_r"]) / (2 * values["bw_zy"]), (1 - values["bw_r"]) / (2 * values["bw_zy"])
    xh, steps = loops.x_harmonics, 1 << 14
    velocity = tabulated_drive(lambda theta: waveform.displacement(xh, np.broadcast_to(theta, (loops.n_loops, theta.size)), 1)[None, :, None], steps)

    def rhs(theta, z):
        dx = velocity(theta)
        return dx - gamma * np.abs(dx) * z - beta * dx * np.abs(z)

    grid = np.linspace(0.0, 2 * np.pi, 4096, endpoint=False)
    phases = np.concatenate([loops.phases(), np.broadcast_to(grid, (loops.n_loops, grid.size))], axis=1)
    z = periodic_steady_state(rhs, np.zeros((1, loops.n_loops, 1)), phases[:, None, :], steps_per_cycle=steps, max_cycles=400)[0][:, 0]
    n = 2 * loops.n_samples
    expected = values["bw_k"] * (z[:, :n] - z[:, n:].mean(axis=1, keepdims=True))
    np.testing.assert_allclose(force, expected, atol=2e-5 * np.abs(expected).max())


def test_a_memory_term_behind_a_gain_stays_on_the_reference_path(ideal):
    model = build_model("thesis+bouc_wen+charge_amplifier_highpass").fix(meq=MEQ_KG)
    fast, reference = Objective(ideal, model), Objective(ideal, model, compiled=False)
    assert not fast.sampled.compiled
    pop = population(model, np.random.default_rng(5), 4)
    np.testing.assert_array_equal(fast.predict(pop), reference.predict(pop))


def test_harmonic_objective_whitens_the_compiled_memory_force(ideal):
    ideal = ideal.subset(np.arange(10))
    ideal.sigma[:] = 1e-3 * ideal.peak_force
    model = build_model("thesis+bouc_wen+coulomb_friction+channel_delay").fix(meq=MEQ_KG)
    harmonics = Harmonics.from_loops(ideal)
    objective = HarmonicObjective(harmonics, model)
    pop = population(model, np.random.default_rng(7), 6)
    reference = harmonics.whiten(Objective(ideal, model, compiled=False).predict(pop)) - objective.target
    np.testing.assert_allclose(objective.whitened(pop), reference, rtol=0, atol=1e-10 * np.abs(reference).max())
