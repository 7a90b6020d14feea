"""The effect library: every term against an independent form of its equation, and the harmonics."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hysid_model import waveform
from hysid_model.effects import EFFECTS
from hysid_model.harmonics import HarmonicObjective, Harmonics, estimate_sigma
from hysid_model.model import build_model
from hysid_model.objective import Objective
from hysid_model.synth import MEQ_KG, TRUE_PARAMS, model_force, simulate_raw, synth_loops, thesis_force
from island.polish import polish
from support import cell_average
from timedomain_reference import periodic_steady_state

LIBRARY = {
    "amplitude_dependent_frequency",
    "amplitude_dependent_damping",
    "charge_amplifier_highpass",
    "transducer_mass",
    "coulomb_friction",
    "hysteretic_damping",
    "cubic_stiffness",
    "bouc_wen",
    "zener_thermoelastic",
    "channel_delay",
}
BASE = {"xi0": 0.01, "w0": 2 * np.pi * 30.0}


def loops(n_points: int = 48, every: int = 13):
    """A few noiseless Synth loops (all three amplitudes, spread over the band)."""
    return synth_loops(0.0, 0, n_points).subset(np.arange(0, 120, every))


def predict(spec: str, values: dict[str, float], data) -> np.ndarray:
    model = build_model(spec).fix(meq=MEQ_KG)
    return Objective(data, model).predict(model.from_dict(values))[0]


def effect_values(effect: str, strength: float) -> dict[str, float]:
    term = EFFECTS[effect]()
    return {**BASE, **{p.name: 0.5 * (p.lower + p.upper) for p in term.params}, term.strength: strength}


def test_library_holds_the_ten_effects():
    assert set(EFFECTS) == LIBRARY


@pytest.mark.parametrize("effect", sorted(LIBRARY))
def test_each_effect_is_a_model_term_that_vanishes_at_zero_strength(effect):
    term = EFFECTS[effect]()
    assert term.explanation and term.id == effect
    names = [p.name for p in term.params]
    assert term.strength in names
    assert all(p.lower < p.upper and p.unit for p in term.params)
    data = loops()
    base = predict("baseline", BASE, data)
    off = predict(f"baseline+{effect}", effect_values(effect, 0.0), data)
    np.testing.assert_allclose(off, base, rtol=0, atol=1e-12 * np.abs(base).max())
    strength = next(p for p in term.params if p.name == term.strength)
    on = predict(f"baseline+{effect}", effect_values(effect, strength.lower + 1e-3 * (strength.upper - strength.lower)), data)
    assert np.all(np.isfinite(on)) and np.abs(on - base).max() > 1e-9 * np.abs(base).max()


def test_thesis_plus_effect_builds_and_fits_through_the_objective():
    model = build_model("thesis+coulomb_friction").fix(meq=MEQ_KG)
    assert model.names == ["xi0", "S_xi", "w0", "S_w", "F_d"]
    objective = Objective(synth_loops(0.0, 0, 32), model)
    assert objective(model.from_dict({**TRUE_PARAMS, "F_d": 0.0}))[0] == pytest.approx(0.0, abs=1e-20)


def test_coulomb_dissipates_4_fd_x0_per_cycle_eq_2_5():
    data = loops(n_points=4000, every=40)
    n = data.n_samples
    friction = predict("baseline+coulomb_friction", {**BASE, "xi0": 0.0, "F_d": 0.3}, data) - predict("baseline", {**BASE, "xi0": 0.0}, data)
    x = data.top[:, :, 0]
    area = np.trapezoid(friction[:, :n] - friction[:, n:], x, axis=1)
    np.testing.assert_allclose(area, 4 * 0.3 * data.x0, rtol=1e-12)


def test_hysteretic_loop_area_is_rate_independent_eq_2_3():
    data = loops(every=7)
    h = Harmonics.from_loops(data)
    force = predict("baseline+hysteretic_damping", {**BASE, "xi0": 0.0, "eta": 0.02}, data)
    area = h.energy_per_cycle(h.project(force))
    k = MEQ_KG * BASE["w0"] ** 2
    np.testing.assert_allclose(area, np.pi * 0.02 * k * data.x0**2, rtol=1e-10)


def test_cubic_stiffness_is_k3_x_cubed():
    data = loops()
    extra = predict("baseline+cubic_stiffness", {**BASE, "k3": 2e7}, data) - predict("baseline", BASE, data)
    x = np.concatenate([data.top[:, :, 0], data.bottom[:, :, 0]], axis=1)
    np.testing.assert_allclose(extra, 2e7 * x**3, atol=1e-12)


def test_transducer_mass_adds_its_inertia_force_eq_2_13():
    data = loops()
    extra = predict("baseline+transducer_mass", {**BASE, "m_t": 0.005}, data) - predict("baseline", BASE, data)
    acceleration = -data.x0[:, None] * data.omega[:, None] ** 2 * np.sin(data.phases())
    np.testing.assert_allclose(extra, 0.005 * acceleration, atol=1e-12)


def test_charge_amplifier_gain_and_phase_follow_eq_4_1_and_4_2():
    data = loops()
    h = Harmonics.from_loops(data)
    f_c = 3.0
    tc = 1.0 / (2 * np.pi * f_c)
    plain = h.project(predict("baseline", BASE, data))
    filtered = h.project(predict("baseline+charge_amplifier_highpass", {**BASE, "f_c": f_c}, data))
    first = lambda c: c[:, h.names.index("c1")] - 1j * c[:, h.names.index("s1")]
    ratio = first(filtered) / first(plain)
    wt = 2 * np.pi * data.freq_hz * tc
    np.testing.assert_allclose(np.abs(ratio), wt / np.sqrt(1 + wt**2), rtol=1e-10)
    np.testing.assert_allclose(np.angle(ratio), np.arctan(1 / wt), rtol=1e-10)


def test_charge_amplifier_on_a_friction_jump_is_the_exponential_step_response():
    data = loops(n_points=64, every=20)
    f_c, fd = 3.0, 1.0
    jump = predict("baseline+coulomb_friction+charge_amplifier_highpass", {**BASE, "F_d": fd, "f_c": f_c}, data) - predict(
        "baseline+charge_amplifier_highpass", {**BASE, "f_c": f_c}, data
    )
    tau = 1.0 / (2 * np.pi * f_c)
    w = data.omega[:, None]
    n = data.n_samples
    sign = np.where(np.arange(2 * n) < n, 1.0, -1.0)
    phase = data.phases()
    since_jump = np.where(sign > 0, np.mod(phase + np.pi / 2, 2 * np.pi), np.mod(phase - np.pi / 2, 2 * np.pi)) / w
    exact = sign * fd * 2.0 / (1.0 + np.exp(-np.pi / (w * tau))) * np.exp(-since_jump / tau)
    np.testing.assert_allclose(jump, exact, atol=5e-3 * (2 * np.pi * f_c / w).max())


def test_channel_delay_shifts_the_whole_force():
    """F(t - delay) at every sample, except that the friction's jumps, where the delay moves them into a
    sample's cell, are averaged over the cell (so that the force is smooth in the delay)."""
    data = loops(every=17)
    delay = 4e-4
    values = {**BASE, "F_d": 0.05}
    delayed = predict("baseline+coulomb_friction+channel_delay", {**values, "delay_s": delay}, data)
    model = build_model("baseline+coulomb_friction").fix(meq=MEQ_KG)
    theta = model.from_dict(values)
    phase = data.phases()
    shifted = np.stack([model_force(model, theta, f, a, p - 2 * np.pi * f * delay) for f, a, p in zip(data.freq_hz, data.x0, phase)])
    lag = (data.omega * delay)[:, None]

    def sign(t: np.ndarray) -> np.ndarray:
        return np.where(np.cos(t - lag) >= 0.0, 1.0, -1.0)

    reversals = np.array([-0.5 * np.pi, 0.5 * np.pi])
    cells = waveform.sample_cells(phase, data.n_samples, *np.broadcast_to(reversals[:, None], (2, data.n_loops)))
    averaged = cell_average(sign, phase, *cells, reversals[None, :] + lag)
    assert np.count_nonzero(averaged != sign(phase)) >= data.n_loops  # a jump sits in a cell of every loop
    np.testing.assert_allclose(delayed, shifted + values["F_d"] * (averaged - sign(phase)), atol=1e-12)


def delayed_friction_loops(delay: float, noise: float = 0.01):
    """Synth loops (every amplitude, the band) of an oscillator with friction recorded ``delay`` late, with noise."""
    model = build_model("baseline+coulomb_friction+channel_delay").fix(meq=MEQ_KG)
    truth = {**BASE, "F_d": 0.5, "delay_s": delay}
    base = synth_loops(0.0, 0, 40).subset(np.arange(0, 120, 8))
    force = Objective(base, model).predict(model.from_dict(truth))[0] + noise * np.random.default_rng(4).standard_normal((base.n_loops, 2 * base.n_samples))
    n = base.n_samples
    top, bottom = base.top.copy(), base.bottom.copy()
    top[:, :, 1], bottom[:, :, 1] = force[:, :n], force[:, n:]
    return replace(base, top=top, bottom=bottom, sigma=np.full(base.n_loops, noise)), model, model.from_dict(truth)


@pytest.mark.parametrize("compiled", [True, False])
def test_chi2_is_continuously_differentiable_in_the_channel_delay(compiled):
    """A delay moves sgn(x')'s jumps across the samples; averaged over the samples' cells they change chi^2
    smoothly: one-sided slopes agree at delays across a period, at 0 (every jump on a turning point) and where
    a jump sits exactly on a sample of one loop."""
    loops, model, truth = delayed_friction_loops(3e-4)
    objective = Objective(loops, model, "ml", compiled=compiled)
    i = model.names.index("delay_s")
    phase, w = loops.phases()[0], loops.omega[0]
    on_samples = [(phase[k] + 0.5 * np.pi) / w for k in (1, 2)] + [(phase[loops.n_samples + k] - 0.5 * np.pi) / w for k in (-2, -3)]
    delays = np.concatenate([np.linspace(-6e-4, 9e-4, 11), [0.0], on_samples])
    h = 1e-9
    probes = np.repeat(truth[None, :], 3 * delays.size, axis=0)
    probes[:, i] = (delays[:, None] + [-h, 0.0, h]).reshape(-1)
    left, centre, right = objective(probes).reshape(-1, 3).T
    slope_left, slope_right = (centre - left) / h, (right - centre) / h
    scale = np.abs(slope_right).max()
    np.testing.assert_allclose(slope_left, slope_right, rtol=0, atol=1e-5 * scale)
    assert np.abs(slope_right).min() < 0.1 * scale  # the minimum near the true delay is among them


def test_a_polish_recovers_a_known_channel_delay():
    loops, model, truth = delayed_friction_loops(3e-4)
    objective = Objective(loops, model, "ml")
    i = model.names.index("delay_s")
    for start in (0.0, 1e-4, 6e-4):
        theta = truth.copy()
        theta[[i, model.names.index("F_d")]] = start, 0.3
        found = polish(objective, theta).theta
        jacobian = objective.jacobian(found)
        stderr = np.sqrt(np.linalg.inv(jacobian.T @ jacobian)[i, i])
        assert 1e-7 < stderr < 2e-5 and abs(found[i] - 3e-4) < 3 * stderr


def test_zener_loss_factor_is_eq_2_6_and_peaks_at_w_tau_1():
    data = loops(every=3)
    h = Harmonics.from_loops(data)
    tau, delta = 1.0 / (2 * np.pi * 30.0), 0.01
    extra = h.project(predict("baseline+zener_thermoelastic", {**BASE, "zener_delta": delta, "zener_tau": tau}, data) - predict("baseline", BASE, data))
    k = MEQ_KG * BASE["w0"] ** 2
    wt = data.omega * tau
    np.testing.assert_allclose(extra[:, h.names.index("c1")] / (k * data.x0), delta * wt / (1 + wt**2), rtol=1e-8)
    np.testing.assert_allclose(extra[:, h.names.index("s1")] / (k * data.x0), delta * wt**2 / (1 + wt**2), rtol=1e-8)


@pytest.mark.parametrize(
    "zy, r", [(3e-4, 0.3), (1e-5, -0.8), pytest.param(5e-3, 1.0, marks=pytest.mark.slow), (2e-4, 2.5), (1e-4, 0.0)]
)  # the large zy: over 3 s
def test_bouc_wen_orbit_is_the_periodic_steady_state_of_eq_2_1(zy, r):
    data = loops(every=50)
    force = predict("baseline+bouc_wen", {**BASE, "bw_k": 1.0, "bw_zy": zy, "bw_r": r}, data) - predict("baseline", BASE, data)
    gamma, beta = (1 + r) / (2 * zy), (1 - r) / (2 * zy)
    x0 = data.x0[:, None]

    def rhs(theta, z):
        c = np.cos(theta)
        return x0[None] * (c * (1 - beta * np.abs(z)) - gamma * abs(c) * z)

    z = periodic_steady_state(rhs, np.zeros((1, data.n_loops, 1)), data.phases()[:, None, :], steps_per_cycle=4096, max_cycles=2000)[0][:, 0]
    np.testing.assert_allclose(force, z, atol=3e-5 * np.abs(z).max())


def test_bouc_wen_through_the_charge_amplifier_matches_spectral_filtering():
    data = loops(every=50)
    values = {**BASE, "bw_k": 50.0, "bw_zy": 2e-4, "bw_r": 0.5, "f_c": 5.0}
    filtered = predict("baseline+bouc_wen+charge_amplifier_highpass", values, data) - predict(
        "baseline+charge_amplifier_highpass", values | {"bw_k": 0.0}, data
    )
    model = build_model("baseline+bouc_wen").fix(meq=MEQ_KG)
    theta = model.from_dict({k: v for k, v in values.items() if k != "f_c"})
    theta_off = model.from_dict({k: v for k, v in values.items() if k != "f_c"} | {"bw_k": 0.0})
    grid = np.linspace(0, 2 * np.pi, 8192, endpoint=False)
    for j, (f, a) in enumerate(zip(data.freq_hz, data.x0)):
        u = model_force(model, theta, f, a, grid) - model_force(model, theta_off, f, a, grid)
        spectrum = np.fft.rfft(u)
        k = np.arange(spectrum.size)
        gain = 1j * k * f / (1j * k * f + values["f_c"])
        coef = spectrum * gain * np.where(k == 0, 1.0, 2.0) / grid.size
        exact = np.real(np.exp(1j * np.outer(data.phases()[j], k)) @ coef)
        np.testing.assert_allclose(filtered[j], exact, atol=2e-3 * np.abs(exact).max())


def test_simulate_raw_reproduces_the_thesis_force_eq_4_10():
    model = build_model("thesis").fix(meq=MEQ_KG)
    records = simulate_raw(model, model.from_dict(TRUE_PARAMS), np.array([29.0, 31.0]), np.array([1e-3, 1.5e-3]), noise_n=0.0, x_noise=0.0, seed=3)
    for rec in records:
        w = 2 * np.pi * rec.freq_hz
        c, s = np.linalg.lstsq(np.column_stack([np.cos(w * rec.t), np.sin(w * rec.t)]), rec.x, rcond=None)[0]
        start = np.arctan2(c, s) / w
        np.testing.assert_allclose(rec.force, thesis_force(rec.t + start, rec.freq_hz, rec.x0, TRUE_PARAMS, MEQ_KG), atol=1e-12)


def test_harmonics_are_exact_for_a_band_limited_force_and_whiten_noise():
    data = loops(every=11)
    phase = data.phases()
    clean = 0.3 + 2.0 * np.sin(phase) - 0.7 * np.cos(3 * phase) + 0.1 * np.sin(7 * phase)
    n = data.n_samples
    rng = np.random.default_rng(1)
    white = []
    for _ in range(200):
        noisy = clean + 0.01 * rng.standard_normal(clean.shape)
        data.top[:, :, 1], data.bottom[:, :, 1] = noisy[:, :n], noisy[:, n:]
        data.sigma[:] = 0.01
        h = Harmonics.from_loops(data)
        white.append((h.coef - h.project(clean)) / h.stderr)
    white = np.array(white)
    assert abs(white.mean()) < 0.02 and white.std() == pytest.approx(1.0, abs=0.02)
    data.top[:, :, 1], data.bottom[:, :, 1] = clean[:, :n], clean[:, n:]
    h = Harmonics.from_loops(data)
    expected = np.zeros_like(h.coef)
    for name, value in (("dc", 0.3), ("s1", 2.0), ("c3", -0.7), ("s7", 0.1)):
        expected[:, h.names.index(name)] = value
    np.testing.assert_allclose(h.coef, expected, atol=1e-12)


def test_estimate_sigma_from_second_differences():
    data = synth_loops(1.0, 4, 100)
    ratio = estimate_sigma(data) / data.sigma
    assert np.median(ratio) == pytest.approx(1.0, abs=0.05)


def test_harmonic_objective_polishes_to_the_thesis_parameters():
    data = synth_loops(0.0, 0, 32).subset(np.arange(0, 120, 3))
    data.sigma[:] = 1e-3 * data.peak_force
    model = build_model("thesis").fix(meq=MEQ_KG)
    objective = HarmonicObjective(Harmonics.from_loops(data), model)
    truth = model.from_dict(TRUE_PARAMS)
    assert objective(truth)[0] == pytest.approx(0.0, abs=1e-16)
    result = polish(objective, truth * np.array([1.3, 0.8, 1.01, 0.9]))
    np.testing.assert_allclose(result.theta, truth, rtol=1e-6)
