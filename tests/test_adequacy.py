"""One verdict on adequacy (:mod:`hysid.adequacy`): ``fit``, ``campaign`` and ``diagnose`` judge a model on the same
loops alike, and what extraction cannot resolve at the motion reversals is no part of the model's error."""

from __future__ import annotations

import numpy as np
import pytest

import hysid
from hysid_model.datasets import load_dataset, write_dataset
from hysid_model.model import build_model
from hysid_model.synth import simulate_raw
from island.termination import Termination
from support import importable

MODULE = "hysid_test_fluid_damper"
SOURCE = '''
"""A fluid viscous damper's force law."""
import numpy as np
import hysid


def fluid_law(x, v, c04):
    """A fluid viscous damper: c |v|^0.4 sgn(v), a cusp at every motion reversal."""
    return c04 * np.sign(v) * np.abs(v) ** 0.4


fluid = hysid.term(fluid_law, name="fluid", units={"c04": "N (s/m)^0.4"}, bounds={"c04": (0.0, 1e6)})
'''
TRUTH = {"xi0": 0.01, "w0": 2 * np.pi * 2.0, "meq": 20.0, "c04": 2000.0}
"""A 20 kg fluid damper on a soft spring (2 Hz), 1-2 kN of fluid force at 1-4 Hz and 5-20 mm."""
SPEC = f"baseline+{MODULE}:fluid"


@pytest.fixture(scope="module")
def fluid_loops(tmp_path_factory):
    """Raw records of the fluid damper (5 N of force noise, 10 cycles at 2 kHz), loaded with the defaults."""
    with importable(tmp_path_factory.mktemp("fluidterms"), MODULE, SOURCE):
        model = build_model(SPEC)
        f, x0 = np.tile([1.0, 2.0, 4.0], 2), np.repeat([5e-3, 20e-3], 3)
        raw = simulate_raw(model, model.from_dict(TRUTH), f, x0, noise_n=5.0, seed=3, sample_rate_hz=2000.0, cycles=10)
        yield load_dataset(write_dataset(tmp_path_factory.mktemp("fluid") / "lab", raw, name="fluid"))


def test_a_cusp_at_the_reversals_leaves_out_the_four_reversal_samples_of_each_loop(fluid_loops):
    n = fluid_loops.n_samples
    assert n == 100 and "the force at the motion reversals is not resolved" in fluid_loops.meta["reversals"]
    kept = fluid_loops.kept()
    assert not kept[:, [0, n - 1, n, 2 * n - 1]].any() and kept.sum() == fluid_loops.n_loops * (2 * n - 4)


def test_a_smooth_force_keeps_every_sample(tmp_path):
    model = build_model("baseline+bouc_wen")
    truth = {"xi0": 0.05, "w0": 2 * np.pi * 15.0, "meq": 0.5, "bw_k": 2e4, "bw_zy": 2e-4, "bw_r": 0.5}
    raw = simulate_raw(model, model.from_dict(truth), np.array([8.0, 15.0, 25.0]), np.full(3, 1e-3), noise_n=0.05, seed=1, sample_rate_hz=4000.0, cycles=10)
    loops = load_dataset(write_dataset(tmp_path / "bw", raw, name="bw"))
    assert "the force at the motion reversals is resolved" in loops.meta["reversals"] and loops.kept().all()


@pytest.mark.slow
def test_the_true_law_is_adequate_and_a_missing_effect_found_by_fit_campaign_and_diagnose(fluid_loops):
    fit = hysid.fit(fluid_loops, SPEC)
    assert fit.adequacy.adequate and "adequacy: the model leaves only noise" in fit.summary()
    se = fit.stderr
    for name in ("w0", "meq", "c04"):
        assert abs(fit.params[name] - TRUTH[name]) < 4 * se[name], (name, fit.params[name], se[name])
    every = fluid_loops.subset(np.arange(fluid_loops.n_loops))
    every.meta = {**every.meta, "per_loop": {**every.meta["per_loop"], "reversals_resolved": [True] * every.n_loops}}
    assert not hysid.fit(every, SPEC).adequacy.adequate  # the extraction's bias at the reversals, judged as the model's
    plain = hysid.fit(fluid_loops, "baseline")
    assert not plain.adequacy.adequate and "warning: the model does not describe these loops" in plain.summary()
    campaign = hysid.campaign(fluid_loops, islands=2, model=SPEC, single_node=True, termination=Termination(budget=4000))
    diagnosis = hysid.diagnose(fluid_loops, candidates=f"{MODULE}:fluid", cross_validate=False)
    assert diagnosis.status == "adequate" and diagnosis.final.spec == SPEC
    assert campaign.fit.adequacy.adequate
    for verdict in (campaign.fit.adequacy, fit.adequacy):  # one rule, at the same optimum of the harmonics
        assert verdict.chi2_per_dof == pytest.approx(diagnosis.final.chi2 / diagnosis.final.dof, rel=1e-4)
