"""Search bounds that the physics does not set are guesses: an optimum on one widens it and is searched again, in
fit, campaign and diagnose alike, so that hysid reaches what an outside multi-start least-squares fit reaches inside
the same physical ranges; and the diagnosis finds a delaying chain with a Bouc-Wen spring behind a distorting sensor."""

from __future__ import annotations

import numpy as np
import pytest

import hysid
from hysid_model.datasets import load_dataset, write_dataset
from hysid_model.harmonics import HarmonicObjective, Harmonics
from hysid_model.model import build_model
from hysid_model.objective import Objective
from hysid_model.problem import displaced, prepare_model
from hysid_model.synth import simulate_raw, synth_loops
from island.polish import polish

SHARP = {"xi0": 10.7, "w0": 5.35, "meq": 7.0, "bw_k": 1.0e6, "bw_zy": 0.3e-3, "bw_r": 39.0, "bw_n": 2.6}
"""An MR damper at high control as a real one fits: 800 N s/m, a negligible spring (200 N/m), 7 kg, a 300 N Bouc-Wen
force yielding at 0.3 mm with the shape r = 39 (a knee right after each reversal), far above r's default bound of 3."""
WIRE_ROPE = {"xi0": 0.04, "w0": 2 * np.pi * 18.0, "meq": 0.3, "bw_k": 4.0e4, "bw_zy": 0.4e-3, "bw_r": -0.5, "bw_n": 1.5, "delay_s": 3e-4}
"""A wire-rope-like isolator carrying 0.3 kg: a softening Bouc-Wen spring (r = -0.5, n = 1.5) and a 0.3 ms channel delay."""


def test_a_default_bound_the_physics_does_not_set_is_soft_and_widens_by_decades():
    model = prepare_model(synth_loops(n_points=20), "thesis+bouc_wen")
    r = next(p for p in model.parameters if p.name == "bw_r")
    assert r.soft and (r.lower, r.upper) == (-0.9, 3.0) and r.physical == (-0.9, np.inf)
    assert r.widened(False, True).upper == 30.0 and r.widened(True, False).lower == -0.9  # never past the physical range
    theta = model.from_dict({**dict(zip(model.names, model.bounds.mean(axis=1))), "bw_r": 3.0})
    assert model.bound_kinds(theta) == {"bw_r": "default upper bound 3"}
    wider, changed = model.widen_at(theta)
    assert changed == {"bw_r": (-0.9, 30.0)} and wider.bound_kinds(theta) == {}
    xi = next(p for p in model.parameters if p.name == "xi0")  # Table 5.4 for the Synth set: given, never widened
    assert not xi.soft and model.widen_at(model.from_dict({**dict(zip(model.names, model.bounds.mean(axis=1))), "xi0": 0.1}))[1] == {}


def outside_least_squares(objective: Objective, starts: int = 8, seed: int = 1) -> tuple[float, np.ndarray]:
    """scipy least_squares from ``starts`` random points (log-uniform for the positive scales) inside the physical
    ranges: r from -0.9, n from 0.5, k_bw from 0 (each up to a finite end), as an outside fit would; the best."""
    from scipy.optimize import least_squares

    model = objective.model
    wide = model.with_bounds({"bw_r": (-0.9, 100.0), "bw_n": (0.5, 10.0)})
    outside = Objective(objective.loops, wide, weights=objective.weights)
    lower, upper = wide.bounds[:, 0], wide.bounds[:, 1]
    scale = np.array([name in ("xi0", "w0", "meq", "bw_k", "bw_zy") for name in wide.names])
    rng = np.random.default_rng(seed)
    best = (np.inf, lower)
    for _ in range(starts):
        u = rng.random(lower.size)
        floor = np.maximum(lower, 1e-6 * upper)
        start = np.where(scale, floor * (upper / floor) ** u, lower + u * (upper - lower))
        found = least_squares(outside.weighted_residuals, start, bounds=(lower, upper), method="trf", x_scale="jac", max_nfev=400)
        if float(found.fun @ found.fun) < best[0]:
            best = (float(found.fun @ found.fun), found.x)
    return best[0], wide.as_dict(best[1])


@pytest.mark.slow
def test_a_sharp_kneed_mr_damper_is_fitted_as_well_as_outside_least_squares_by_fit_campaign_and_diagnose(tmp_path):
    model = build_model("mr_damper")
    f, x0 = np.tile([1.0, 2.5, 5.0], 2), np.repeat([5e-3, 15e-3], 3)
    raw = simulate_raw(model, model.from_dict(SHARP), f, x0, noise_n=5.0, seed=2, sample_rate_hz=2000.0, cycles=6)
    loops = load_dataset(write_dataset(tmp_path / "mr", raw, name="mr"), n_points=48)
    fit = hysid.fit(loops, "mr_damper")
    reference, where = outside_least_squares(fit.objective())
    assert where["bw_r"] > 10.0 and fit.params["bw_r"] > 10.0 and "bw_r" not in fit.at_bounds
    assert fit.fitness <= reference * (1 + 1e-6), (fit.fitness, reference, fit.params, where)
    assert [w["param"] for w in fit.settings["bounds_widened"]].count("bw_r") >= 1
    assert "note: search bounds widened within the physical ranges" in fit.summary() and "bw_r [-0.9, 3] -> [-0.9, " in fit.summary()
    campaign = hysid.campaign(loops, islands=2, model="mr_damper", single_node=True)
    assert campaign.fit.fitness <= reference * (1 + 1e-6) and "bw_r" in [w["param"] for w in campaign.fit.settings["bounds_widened"]]
    diagnosis = hysid.diagnose(loops, cross_validate=False)
    assert diagnosis.final.effects == ("bouc_wen",), diagnosis.summary()  # nothing the truth lacks
    harmonics = Harmonics.from_loops(displaced(loops, fit.settings["displacement"]))
    on_harmonics = HarmonicObjective(harmonics, diagnosis.final.model)
    referenced = polish(on_harmonics, np.clip(diagnosis.final.model.from_dict(where), *diagnosis.final.model.bounds.T)).fitness
    assert diagnosis.final.chi2 <= referenced * (1 + 1e-6) + np.log(diagnosis.final.n) * (7 - diagnosis.final.model.dim)


@pytest.mark.slow
def test_a_wire_rope_isolator_behind_a_delaying_chain_and_a_distorting_sensor_is_diagnosed_to_its_floor(tmp_path):
    model = build_model("mr_damper+channel_delay")
    f, x0 = np.tile([10.0, 20.0, 30.0], 2), np.repeat([0.5e-3, 2e-3], 3)
    raw = simulate_raw(model, model.from_dict(WIRE_ROPE), f, x0, noise_n=0.05, seed=7, sample_rate_hz=5000.0, cycles=8, sensor={2: 0.05, 3: 0.03})
    loops = load_dataset(write_dataset(tmp_path / "wire", raw, name="wire"), n_points=48)
    diagnosis = hysid.diagnose(loops)
    harmonics = Harmonics.from_loops(displaced(loops, "fundamental"))
    truth = prepare_model(harmonics.loops, "mr_damper+channel_delay")
    floor = polish(HarmonicObjective(harmonics, truth), truth.from_dict(WIRE_ROPE)).fitness
    floor_rms = np.sqrt(floor / (harmonics.n_coefficients - truth.dim))
    assert diagnosis.motion.displacement == "fundamental", diagnosis.summary()
    assert diagnosis.final.whitened_rms <= 1.2 * floor_rms, diagnosis.summary()
    assert diagnosis.final.params()["meq"] == pytest.approx(WIRE_ROPE["meq"], rel=0.1)
    assert set(diagnosis.final.effects) <= {"bouc_wen", "channel_delay"}
