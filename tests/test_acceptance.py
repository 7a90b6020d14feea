"""Every acceptance rule of ``hysid diagnose`` (hysid/diagnosis/acceptance.py, plausible.py) on real fits, each
tested both ways so that a rule reversed or dropped fails a test; all in the fast lane.

The loops are simulated far from the thesis' beams: a 2 kg, 18 Hz oscillator
with 2 % damping and a hidden Coulomb friction, 3 amplitudes x 5 frequencies
from 6 to 40 Hz, 1 % force noise, extracted from raw records as real data are.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from hysid.criteria import BIC_MARGIN
from hysid.diagnosis.acceptance import binding, held_out, judge, visible_error
from hysid.diagnosis.plausible import MAX_DELAY_S, implausible_effect, implausible_values, mass_note
from hysid.diagnosis.refits import refit
from hysid.diagnosis.scoring import score_candidates
from hysid.harmonic_fits import Fit, initial_fit, make_model, profile_errors, soft_bounds
from hysid_model.datasets import load_dataset, write_dataset
from hysid_model.harmonics import HarmonicObjective, Harmonics
from hysid_model.model import build_model
from hysid_model.synth import simulate_raw

TRUTH = {"xi0": 0.02, "w0": 2 * np.pi * 18.0, "meq": 2.0, "F_d": 6.0}
FREQS = np.array([6.0, 11.0, 18.0, 27.0, 40.0])
AMPS = np.array([0.5e-3, 1e-3, 2e-3])


@pytest.fixture(scope="module")
def harmonics(tmp_path_factory) -> Harmonics:
    model = build_model("baseline+coulomb_friction")
    f, x0 = np.tile(FREQS, AMPS.size), np.repeat(AMPS, FREQS.size)
    raw = simulate_raw(model, model.from_dict(TRUTH), f, x0, noise_n=0.4, seed=11, sample_rate_hz=4000.0, cycles=6)
    where = tmp_path_factory.mktemp("friction") / "d"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        write_dataset(where, raw, name="friction")
        return Harmonics.from_loops(load_dataset(where, n_points=48))


@pytest.fixture(scope="module")
def fits(harmonics):
    """The baseline, and the baseline plus the hidden friction refitted from the diagnosis' starts."""
    start = initial_fit(harmonics, "baseline")
    candidate = next(c for c in score_candidates(start, harmonics, soft_bounds(start.model)) if c.effect == "coulomb_friction")
    return start, refit(start, harmonics, (candidate,), soft_bounds(start.model))


def at(harmonics: Harmonics, spec: str, values: dict[str, float], bounds: dict | None = None) -> Fit:
    """A fit object of ``spec`` at ``values`` (not necessarily an optimum), as the rules see one."""
    model = make_model(harmonics, "baseline", tuple(spec.split("+")[1:]), {}).with_bounds(bounds or {})
    objective = HarmonicObjective(harmonics, model)
    theta = model.from_dict(values)
    return Fit(tuple(spec.split("+")[1:]), "baseline", objective, theta, objective.weighted_residuals(theta), objective.jacobian(theta))


def test_the_bic_margin_takes_a_real_effect_and_not_a_null_change(fits, harmonics):
    start, friction = fits
    assert friction.bic - start.bic < -BIC_MARGIN
    assert judge(start, friction, ("coulomb_friction",), harmonics) is None
    assert "BIC changes by only" in judge(friction, friction, ("coulomb_friction",), harmonics)


def test_held_out_frequencies_must_be_predicted_better(fits, harmonics):
    start, friction = fits
    assert held_out(start, friction, harmonics) is None
    assert "held-out" in held_out(friction, start, harmonics)


def test_a_visible_error_that_rises_beyond_its_noise_rejects(fits, harmonics):
    start, friction = fits
    assert visible_error(start, friction, harmonics) is None
    assert "raises the" in visible_error(friction, start, harmonics)
    twin = at(harmonics, "baseline+coulomb_friction", {**friction.params(), "F_d": friction.params()["F_d"] * (1 + 1e-4)})
    assert visible_error(friction, twin, harmonics) is None  # a difference far below the noise is no rise


def test_the_physical_sign_of_a_one_sided_strength(fits, harmonics):
    """A refit that gains only from the other parameters, its friction at 0, is not a friction: the gain is
    the start's poor optimum (here, a stiffness 5 % off), not the effect."""
    start, friction = fits
    poor = at(harmonics, "baseline", {**start.params(), "w0": 0.95 * start.params()["w0"]})
    off = at(harmonics, "baseline+coulomb_friction", {**start.params(), "F_d": 0.0})
    on = at(harmonics, "baseline+coulomb_friction", friction.params())
    assert off.bic < poor.bic - BIC_MARGIN
    assert "unphysical sign" in judge(poor, off, ("coulomb_friction",), harmonics)
    assert judge(poor, on, ("coulomb_friction",), harmonics) is None


def test_a_bound_binds_only_where_the_data_push_outward(harmonics):
    """A stiffness capped below what the loops need: its bound binds (the data push outward); the same model
    with the cap above the optimum, sitting on its lower bound, does not (the data push inward)."""
    base = initial_fit(harmonics, "baseline")
    w0 = base.params()["w0"]
    low = at(harmonics, "baseline", {**base.params(), "w0": 0.8 * w0}, {"w0": (0.5 * w0, 0.8 * w0)})
    high = at(harmonics, "baseline", {**base.params(), "w0": 0.8 * w0}, {"w0": (0.8 * w0, 2 * w0)})
    j = low.model.names.index("w0")
    assert binding(low, j) and not binding(high, j)


def test_a_force_high_pass_is_impossible_where_the_force_keeps_its_mean(harmonics):
    loops = harmonics.loops
    assert implausible_effect("charge_amplifier_highpass", loops) is None
    per_loop = dict(loops.meta["per_loop"])
    per_loop["force_mean_n"] = list(0.2 * np.asarray(per_loop["force_amplitude_n"]))
    preloaded = loops.subset(np.arange(loops.n_loops))
    preloaded.meta = {**loops.meta, "per_loop": per_loop}
    assert "passes DC" in implausible_effect("charge_amplifier_highpass", preloaded)
    assert implausible_effect("coulomb_friction", preloaded) is None


def test_a_delay_longer_than_any_measurement_chain_is_implausible(fits, harmonics):
    _, friction = fits
    params = friction.params()
    short = at(harmonics, "baseline+coulomb_friction+channel_delay", {**params, "delay_s": 1e-4})
    long = at(harmonics, "baseline+coulomb_friction+channel_delay", {**params, "delay_s": -2 * MAX_DELAY_S}, {"delay_s": (-0.02, 0.02)})
    assert implausible_values(short, harmonics.loops) == {}
    assert "beyond what a measurement chain adds" in implausible_values(long, harmonics.loops)["delay_s"]


def test_a_mass_far_above_the_loops_inertia_is_named(fits, harmonics):
    _, friction = fits
    model, theta = friction.model, friction.theta
    assert mass_note(model, theta, harmonics.loops) is None
    heavy = theta.copy()
    heavy[model.names.index("meq")] = 100.0 * TRUTH["meq"]
    assert "far above what the loops' inertia supports" in mass_note(model, heavy, harmonics.loops)
    assert mass_note(model.fix(meq=200.0), np.delete(heavy, model.names.index("meq")), harmonics.loops) is None


def test_the_delay_error_comes_from_its_profile(fits, harmonics):
    """The profile's half-width, not the curvature at the optimum: the chi^2 rises by about one unit (times
    chi^2/dof) when the delay is moved by it with the rest refitted."""
    _start, friction = fits
    candidate = next(c for c in score_candidates(friction, harmonics, soft_bounds(friction.model)) if c.effect == "channel_delay")
    delayed = profile_errors(refit(friction, harmonics, (candidate,), soft_bounds(friction.model)))
    se = delayed.errors()["delay_s"]
    assert se == delayed.profiled["delay_s"] and np.isfinite(se) and se > 0
    i = delayed.model.names.index("delay_s")
    moved = HarmonicObjective(harmonics, delayed.model.fix(delay_s=float(delayed.theta[i] + se)))
    from island.polish import polish

    rise = polish(moved, np.delete(delayed.theta, i), max_nfev=400).fitness - delayed.chi2
    assert 0.3 * max(1.0, delayed.whitened_rms**2) < rise < 3.0 * max(1.0, delayed.whitened_rms**2)
