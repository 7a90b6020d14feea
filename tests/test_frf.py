"""Compliance from the loops' first harmonic and the half-power estimate of Eq. 2.7 on the Synth set."""

from __future__ import annotations

import numpy as np
import pytest

from hysid_model.frf import (
    amplitude_levels,
    compliance,
    first_harmonic,
    half_power,
    half_power_by_amplitude,
    model_compliance,
)
from hysid_model.model import build_model
from hysid_model.synth import MEQ_KG, TRUE_PARAMS, synth_loops


def true_modal(x0: float) -> tuple[float, float]:
    """xi and wn (rad/s) of Table 5.3's parameters at amplitude x0 (Eq. 4.8, 4.9)."""
    return TRUE_PARAMS["xi0"] + TRUE_PARAMS["S_xi"] * x0, TRUE_PARAMS["w0"] + TRUE_PARAMS["S_w"] * x0


@pytest.fixture(scope="module")
def clean():
    return synth_loops(0.0)


def test_first_harmonic_is_the_force_amplitude_of_eq_4_10(clean):
    f1 = first_harmonic(clean)
    xi, wn = np.array([true_modal(a) for a in clean.x0]).T
    w = clean.omega
    expected = MEQ_KG * clean.x0 * np.hypot(wn**2 - w**2, 2 * xi * wn * w)
    np.testing.assert_allclose(np.abs(f1), expected, rtol=1e-9)
    # the phase of Eq. 4.6: F = m X0 [(wn^2 - w^2) sin + 2 xi wn w cos], so Re F1 = m X0 (wn^2 - w^2)
    np.testing.assert_allclose(f1.real, MEQ_KG * clean.x0 * (wn**2 - w**2), rtol=1e-7, atol=1e-12)


def test_model_compliance_matches_the_loops(clean):
    model = build_model("thesis").fix(meq=MEQ_KG)
    theta = model.from_dict(TRUE_PARAMS)
    comp = compliance(clean)
    for level in (0.5e-3, 1.0e-3, 1.5e-3):
        m = np.isclose(clean.x0, level)
        np.testing.assert_allclose(model_compliance(model, theta, level, clean.freq_hz[m]), comp[m], rtol=1e-9)


def test_half_power_recovers_the_true_damping_at_each_amplitude(clean):
    estimates = half_power_by_amplitude(clean)
    assert [round(hp.x0 * 1e3, 6) for hp in estimates] == [0.5, 1.0, 1.5]
    for hp in estimates:
        xi, wn = true_modal(hp.x0)
        assert hp.ok, hp.note
        assert hp.n_loops == 40
        assert abs(hp.xi - xi) <= hp.resolution
        # the local quadratic in w^2 is exact for a 1-DOF FRF, leaving Eq. 2.7's O(xi^2) approximation
        assert hp.xi == pytest.approx(xi, rel=1e-3)
        assert hp.f_peak_hz == pytest.approx(wn / (2 * np.pi), abs=1e-3)
        assert hp.f1_hz < hp.f_peak_hz < hp.f2_hz
        assert hp.peak_compliance == pytest.approx(1.0 / (MEQ_KG * 2 * xi * wn**2), rel=1e-3)


def test_half_power_on_a_coarser_sweep_stays_within_its_resolution(clean):
    level = np.isclose(clean.x0, 1.0e-3)
    keep = np.flatnonzero(level)[::3]
    coarse = half_power(clean.freq_hz[keep], compliance(clean)[keep], 1.0e-3)
    fine = half_power_by_amplitude(clean)[1]
    xi, _ = true_modal(1.0e-3)
    assert coarse.ok
    assert coarse.resolution > 2 * fine.resolution
    assert abs(coarse.xi - xi) <= coarse.resolution


def test_half_power_with_noise_is_close_to_the_true_damping():
    for hp in half_power_by_amplitude(synth_loops(10.0, seed=4)):
        xi, _ = true_modal(hp.x0)
        assert abs(hp.xi - xi) <= hp.resolution
        assert hp.xi == pytest.approx(xi, rel=0.1)


def test_half_power_needs_the_peak_inside_the_sweep(clean):
    below = clean.freq_hz < 29.7
    hps = half_power_by_amplitude(clean.subset(np.flatnonzero(below)))
    for hp in hps:
        assert not hp.ok
        assert np.isnan(hp.xi)
        assert "edge" in hp.note
    narrow = (clean.freq_hz > 29.85) & (clean.freq_hz < 30.25) & np.isclose(clean.x0, 0.5e-3)
    hp = half_power_by_amplitude(clean.subset(np.flatnonzero(narrow)))[0]
    assert not hp.ok and "-3 dB" in hp.note


def test_amplitude_levels_group_measured_amplitudes():
    x0 = np.array([1.0e-3, 0.498e-3, 1.49e-3, 0.502e-3, 1.01e-3, 1.51e-3])
    levels, index = amplitude_levels(x0)
    np.testing.assert_allclose(levels, [0.5e-3, 1.005e-3, 1.5e-3])
    assert index.tolist() == [1, 0, 2, 0, 1, 2]


def test_a_peak_sharper_than_the_sweep_gives_a_note_not_nan():
    """A 0.5 kg, 2e4 N/m specimen damped by 0.12 N s/m (xi 6e-4) on a 7-point sweep: the parabola through the three
    points around the peak can dip below zero (a negative 1/|H|^2: peak compliance NaN, which the half-power figure
    could not draw) and the -3 dB crossings fell on the wrong side of the peak (f1 above it, xi 4 times the
    truth). With the force clipped at a third of the largest, the clipped loops' compliance flattens the sweep:
    an estimate then brackets its peak, or there is none."""
    f = np.array([25.37, 27.28, 28.9, 30.49, 32.04, 34.49, 36.22])
    w = 2 * np.pi * f
    force = np.hypot(2e4 - 0.5 * w**2, 0.1213 * w) * 1e-3
    hp = half_power(f, 1e-3 / force, 1e-3)
    assert not hp.ok and "do not bracket the peak" in hp.note and np.isnan(hp.xi)
    for level in np.linspace(0.1, 1.0, 19) * force.max():
        hp = half_power(f, 1e-3 / np.minimum(force, level), 1e-3)
        assert np.isfinite(hp.peak_compliance) and hp.peak_compliance > 0
        assert not hp.ok or (hp.f1_hz < hp.f_peak_hz < hp.f2_hz and hp.xi > 0), (level, hp)
