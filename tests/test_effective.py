"""Names and tables an engineer can use: the effective stiffness and equivalent damping of the whole model at each
amplitude and frequency (hysid_model/effective.py), models named by their terms, terms consistent with zero dropped
from a diagnosis' final model."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest
from scipy.special import gamma

import hysid
from hysid.bench import coverage
from hysid.report.amplitudes import resonance_note
from hysid_model.effective import effective_table, loop_effective
from hysid_model.model import build_model
from hysid_model.model_names import model_name, named
from hysid_model.survey import survey
from support import DAMPER

NO_ERROR = lambda grads: np.zeros(len(grads))


def test_a_linear_oscillator_has_k_eff_k_minus_m_w2_and_xi_eq_c_w_over_2_k_eff():
    model = build_model("baseline")
    m, k, c = 2.0, 8e4, 300.0
    theta = model.from_dict({"xi0": c / (2 * math.sqrt(k * m)), "w0": math.sqrt(k / m), "meq": m})
    points = effective_table(model, theta, NO_ERROR, np.array([5.0, 25.0, 40.0]), np.array([1e-3, 1e-3, 2e-3]))
    for p in points:
        w = 2 * math.pi * p.freq_hz
        assert p.values["k_eff"] == pytest.approx(k - m * w**2, rel=1e-9)
        assert p.values["energy"] == pytest.approx(math.pi * c * w * p.x0**2, rel=1e-4)
        if k > m * w**2:
            assert p.values["xi_eq"] == pytest.approx(c * w / (2 * (k - m * w**2)), rel=1e-4)
        else:  # above the resonance no energy is stored: none given
            assert math.isnan(p.values["xi_eq"])


def test_a_band_across_the_resonance_is_said_and_its_frequency_given():
    """k_eff = k - m w^2 passes zero at the resonance sqrt(k/m) / 2 pi: the tables say so (and where), a band
    below it says nothing."""
    model = build_model("baseline")
    m, k, c = 0.04, 1430.0, 0.06
    theta = model.from_dict({"xi0": c / (2 * math.sqrt(k * m)), "w0": math.sqrt(k / m), "meq": m})
    fn = math.sqrt(k / m) / (2 * math.pi)
    across = effective_table(model, theta, NO_ERROR, np.linspace(25.0, 34.0, 10), np.full(10, 1e-3))
    note = resonance_note(across)
    assert note is not None and f"{fn:.4g} Hz" in note, (note, fn)
    assert resonance_note(effective_table(model, theta, NO_ERROR, np.linspace(5.0, 15.0, 6), np.full(6, 1e-3))) is None


def test_a_fluid_damper_written_as_a_users_term_gets_its_energy_per_cycle():
    """F = c_f |v|^0.4 sgn(v): no force at the peak displacement (v = 0), so k_eff is the spring minus the inertia,
    and E_d = 4 c_f w^0.4 X0^1.4 int_0^(pi/2) cos^1.4 = 2 sqrt(pi) c_f w^0.4 X0^1.4 Gamma(1.2) / Gamma(1.7)."""
    specimen = coverage.specimens()["fluid_damper"]
    model = specimen.model()
    truth = specimen.truth
    points = effective_table(model, model.from_dict(truth), NO_ERROR, np.array([1.0, 3.0]), np.array([10e-3, 20e-3]))
    m, w0 = truth["meq"], truth["w0"]
    for p in points:
        w, x0 = 2 * math.pi * p.freq_hz, p.x0
        fluid = 2 * math.sqrt(math.pi) * truth["c_f"] * w**0.4 * x0**1.4 * gamma(1.2) / gamma(1.7)
        assert p.values["energy"] == pytest.approx(fluid + math.pi * 2 * truth["xi0"] * m * w0 * w * x0**2, rel=2e-3)
        assert p.values["k_eff"] == pytest.approx(m * (w0**2 - w**2), rel=1e-5) and p.values["xi_eq"] > 0.5


@pytest.fixture(scope="module")
def bearing():
    """An elastomeric bearing (Bouc-Wen n = 2 beside 200 kg, 10 Hz) fitted with mr_damper (the polish from the truth)."""
    specimen = coverage.specimens()["bearing"]
    loops = coverage.loops_of(specimen, 11)
    return specimen, coverage.fitted(specimen, loops, 11)


@pytest.mark.slow  # a memory model polished and profiled (about 3 s)
def test_a_bearing_fitted_with_mr_damper_is_named_by_its_terms_and_gets_its_effective_stiffness(bearing, tmp_path):
    specimen, result = bearing
    assert model_name(result.model) == "baseline + bouc_wen (bw_n free)"
    text = result.summary()
    assert "baseline + bouc_wen (bw_n free) [model string mr_damper]" in text and "magnetorheological" not in text.lower()
    device = specimen.model()
    truth = effective_table(device, device.from_dict(specimen.truth), NO_ERROR, [p.freq_hz for p in result.effective], [p.x0 for p in result.effective])
    k_eff, xi_eq = ([p.values[q] for p in result.effective] for q in ("k_eff", "xi_eq"))
    assert k_eff[0] > 2.0 * k_eff[-1] and xi_eq[-1] > 5 * xi_eq[0]  # softening and more damping with amplitude (3.2e6 ->
    assert result.amplitudes[0].values["k"] == result.amplitudes[-1].values["k"]  # 1.4e6 N/m, 0.02 -> 0.2) where the spring is flat
    for p, t in zip(result.effective, truth):
        for q in ("k_eff", "xi_eq", "energy"):
            assert abs(p.values[q] - t.values[q]) < 4 * p.stderr[q], (p.x0, p.freq_hz, q)
    _own_k, own_xi = loop_effective(result.loops, survey(result.loops).energy_per_cycle)
    assert np.median(np.abs(own_xi / np.array([p.values["xi_eq"] for p in result.effective]) - 1)) < 0.05  # the loops agree
    with open(result.to_csv(tmp_path)["amplitudes"], newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 12 and all(float(r["m_kg_stderr"]) > 0 and float(r["k_eff_n_per_m_stderr"]) > 0 for r in rows)
    assert "effective stiffness k_eff" in text


FRICTION_START = {"xi0": 0.0, "w0": 1e-3, "meq": 550.0, "F_d": 2400.0, "bw_k": 2.4e6, "bw_zy": 3.2e-3, "bw_r": -0.6}
"""Where ``hysid fit`` of baseline+coulomb_friction+bouc_wen ends on the real friction damper (memetic islands, 25 s)."""


@pytest.mark.slow  # a memory model polished on the real loops (about 4 s)
def test_the_real_friction_damper_gets_the_effective_stiffness_and_damping_of_its_loops():
    """The ARTS-Lab friction damper (baseline + coulomb_friction + bouc_wen): k_eff and xi_eq of the whole model
    follow each loop's own (within 30 %, the median within 15 %, where the model misses the loops by 9 x the
    noise); its spring and dashpot alone, the old table, say xi = 0."""
    result = coverage.polished(hysid.load(DAMPER), "baseline+coulomb_friction+bouc_wen", FRICTION_START)
    own_k, own_xi = loop_effective(result.loops, survey(result.loops).energy_per_cycle)
    point = [min(result.effective, key=lambda p: abs(p.x0 / x0 - 1) + abs(p.freq_hz / f - 1)) for x0, f in zip(result.loops.x0, result.loops.freq_hz)]
    for own, q in ((own_k, "k_eff"), (own_xi, "xi_eq")):
        deviation = np.abs(np.array([p.values[q] for p in point]) / own - 1)
        assert np.median(deviation) < 0.15 and deviation.max() < 0.3, (q, deviation)
    assert all(p.stderr["k_eff"] > 0 and p.values["xi_eq"] > 0.3 for p in result.effective)
    assert max(a.values["xi"] for a in result.amplitudes) < 1e-3


def test_presets_are_named_by_their_terms():
    assert named(build_model("baseline")) == "baseline"
    assert named(build_model("thesis")) == "baseline + amplitude_dependent_damping + amplitude_dependent_frequency [model string thesis]"
    assert named(build_model("baseline+coulomb_friction")) == "baseline + coulomb_friction"


@pytest.mark.slow  # a diagnosis (about 4 s)
def test_a_diagnosis_from_thesis_drops_the_slopes_a_linear_bearing_does_not_need(tmp_path):
    specimen = coverage.specimens()["linear_bearing"]
    diagnosis = hysid.diagnose(coverage.loops_of(specimen, 2), "thesis", cross_validate=False)
    assert set(diagnosis.pruned) == {"amplitude_dependent_damping", "amplitude_dependent_frequency"}
    assert diagnosis.final.spec == "baseline" and diagnosis.status == "adequate"
    assert len(diagnosis.gap) == len(diagnosis.fits()) and diagnosis.fits()[-1][0].startswith("- ")
    text = diagnosis.summary()
    assert "dropped from the final model: amplitude_dependent_damping (S_xi = " in text and "S_w" not in diagnosis.params
    assert "effective stiffness" in text and diagnosis.tables()["amplitudes"][0]["k_eff_n_per_m_stderr"] > 0
    k = next(r for r in diagnosis.tables()["parameters"] if r["parameter"] == "k")
    assert k["value"] == pytest.approx(specimen.truth["meq"] * specimen.truth["w0"] ** 2, rel=0.01) and k["stderr"] > 0
    assert "dropped from the final model" in diagnosis.write_report(tmp_path / "d").read_text()
    assert (tmp_path / "d" / "effective.png").stat().st_size > 20_000
