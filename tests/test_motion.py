"""Sensor distortion or motion (hysid/motion.py): the data decide which displacement drives the model.

A specimen far from the thesis' beams (0.5 kg, 40 Hz, 3 % damping, driven at
15-55 Hz) is recorded twice with the same displacement harmonics (10 % second,
5 % third): once as the sensor's distortion of a pure-sine motion (the force
follows the sine), once as the motion itself (the force follows the whole
waveform). Each must be read its own way, and the mass, stiffness and damping
recovered within their standard errors.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

import hysid
from hysid.cli import main
from hysid.motion import choose_motion, confirm_motion
from hysid_model.datasets import write_dataset
from hysid_model.model import build_model, to_physical
from hysid_model.synth import simulate_raw
from island.memetic import BUDGET
from island.termination import Termination
from support import DAMPER

HARMONICS = {2: 0.10, 3: 0.05}
TRUTH = {"xi0": 0.03, "w0": 2 * np.pi * 40.0, "meq": 0.5}
DAMPER_BUDGET = 2000
"""The evaluation budget of the campaign on the real friction damper."""


def records(where: str, seed: int = 3):
    model = build_model("baseline")
    theta = model.from_dict(TRUTH)
    f, x0 = np.repeat([15.0, 25.0, 35.0, 45.0, 55.0], 2), np.tile([0.5e-3, 1e-3], 5)
    kind = {"sensor": HARMONICS} if where == "sensor" else {"distortion": HARMONICS}
    return simulate_raw(model, theta, f, x0, noise_n=0.5, seed=seed, sample_rate_hz=5000.0, cycles=10, **kind)


def loops_of(where: str, tmp_path, seed: int = 3):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        write_dataset(tmp_path / where, records(where, seed), name=where)
        return hysid.load(tmp_path / where)


@pytest.fixture(scope="module")
def sensor(tmp_path_factory) -> tuple:
    """The sensor's dataset directory, its loops, the data's choice and the baseline fitted to them by the GA (shared:
    each test reads them, none changes them)."""
    where = tmp_path_factory.mktemp("motion")
    loops = loops_of("sensor", where)
    return where / "sensor", loops, choose_motion(loops, "baseline"), hysid.fit(loops, "baseline", algo="ga")


@pytest.fixture(scope="module")
def damper_campaign(tmp_path_factory) -> tuple:
    """The real friction damper searched by a campaign of 2 islands with an evaluation budget of :data:`DAMPER_BUDGET`, its database,
    and the campaign's result rebuilt from that database (shared by the two tests of a campaign's refit)."""
    db = tmp_path_factory.mktemp("damper") / "c.sqlite"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = hysid.campaign(hysid.load(DAMPER), "baseline+bouc_wen", islands=2, single_node=True, db=db, termination=Termination(budget=DAMPER_BUDGET))
        return result, hysid.CampaignResult.from_database(db)


def physical(values: dict[str, float]) -> dict[str, float]:
    state = build_model("baseline").modal(build_model("baseline").from_dict(values), 1e-3)
    return {k: float(v[0]) for k, v in to_physical(state).items()}


@pytest.mark.slow  # over 3 s (fast lane, 2 cores, 2026-11-29)
@pytest.mark.parametrize("where, reading", [("sensor", "fundamental"), ("motion", "measured")])
def test_the_data_decide_and_the_fit_recovers_mass_stiffness_and_damping(where, reading, tmp_path, sensor):
    if where == "sensor":
        _, loops, choice, result = sensor
    else:
        loops = loops_of(where, tmp_path)
        choice, result = choose_motion(loops, "baseline"), hysid.fit(loops, "baseline", algo="ga")
    assert choice.displacement == reading and choice.decided_by == "data"
    assert (choice.delta_bic < 0) == (reading == "fundamental") and abs(choice.delta_bic) > 1000
    assert result.displacement_model["displacement"] == reading
    for name, true in TRUTH.items():
        assert abs(result.params[name] - true) < 4 * result.stderr[name], (name, result.params[name], true, result.stderr[name])
    fitted, true = physical(result.params), physical(TRUTH)
    for name in ("k", "c", "m"):
        assert fitted[name] == pytest.approx(true[name], rel=0.02)


@pytest.mark.slow  # over 3 s (fast lane, 2 cores, 2026-11-29)
def test_the_other_reading_is_many_standard_errors_off(sensor):
    """Reading the sensor's harmonics as motion drives the model with content the force does not have: the
    mass comes out far off (the failure this module exists to prevent)."""
    _, loops, _, _ = sensor
    wrong = hysid.fit(loops, "baseline", displacement="measured", algo="ga")
    assert wrong.displacement_model["decided_by"] == "user"
    assert abs(wrong.params["meq"] - TRUTH["meq"]) > 20 * wrong.stderr["meq"]


def test_evidence_order_by_order(tmp_path, sensor):
    """The evidence says, order by order, how strongly the force carries the displacement's harmonics."""
    motion = choose_motion(loops_of("motion", tmp_path), "baseline")
    for choice, far in ((sensor[2], False), (motion, True)):
        shares = {e["order"]: e for e in choice.orders}
        assert shares[2]["displacement_share"] == pytest.approx(0.10, rel=0.01)
        assert (shares[2]["response"] > 1.0) == far


def test_forced_readings_and_data_without_distortion(sensor):
    _, loops, _, _ = sensor
    for asked in ("measured", "fundamental", "sine"):
        choice = choose_motion(loops, "baseline", asked)
        assert (choice.displacement, choice.decided_by) == (asked, "user")
    assert choose_motion(hysid.load("synth"), "thesis").displacement == "sine"
    with pytest.raises(hysid.HysidInputError, match="displacement"):
        choose_motion(loops, "baseline", "wobbly")


def test_confirmation_with_the_fitted_model_keeps_a_right_reading(sensor):
    _, loops, choice, result = sensor
    assert confirm_motion(loops, result.model, result.theta, choice) is None


@pytest.mark.slow  # over 3 s
def test_cli_fit_and_diagnose_say_which_and_why(tmp_path, capsys, sensor):
    data = str(sensor[0])
    assert main(["fit", data, "--model", "baseline", "--algo", "ga", "--no-figures", "--out", str(tmp_path / "fit")]) == 0
    out = capsys.readouterr().out
    assert "displacement model: the motion is the fundamental" in out and "does not respond" in out
    document = json.loads((tmp_path / "fit" / "result.json").read_text())
    assert document["displacement_model"]["displacement"] == "fundamental"
    assert main(["diagnose", data, "--json", "--no-figures", "--out", str(tmp_path / "diag")]) == 0
    diagnosis = json.loads(capsys.readouterr().out)
    assert diagnosis["displacement_model"]["displacement"] == "fundamental" and diagnosis["status"] == "adequate"
    assert diagnosis["steps"] == []
    assert (
        main(["fit", data, "--model", "baseline", "--algo", "ga", "--displacement", "measured", "--json", "--no-figures", "--out", str(tmp_path / "f2")]) == 0
    )
    assert json.loads(capsys.readouterr().out)["displacement_model"]["decided_by"] == "user"


@pytest.mark.slow  # over 3 s
def test_a_campaign_reads_the_displacement_as_fit_does_and_keeps_it_in_its_database(tmp_path, sensor):
    _, loops, _, _ = sensor
    db = tmp_path / "c.sqlite"
    result = hysid.campaign(
        loops,
        "baseline",
        islands=2,
        single_node=True,
        db=db,
        seed=1,
        options={"pso": {"initial_population": 300, "population": 30, "iterations": 8}, "ga": {"initial_population": 300, "population": 30, "iterations": 8}},
    )
    assert result.fit.displacement_model["displacement"] == "fundamental"
    assert result.to_dict()["displacement_model"]["decided_by"] == "data"
    assert abs(result.fit.params["meq"] - TRUTH["meq"]) < 4 * result.fit.stderr["meq"]
    again = hysid.CampaignResult.from_database(db)
    assert again.fit.displacement_model["displacement"] == "fundamental"
    assert again.fit.params["meq"] == pytest.approx(result.fit.params["meq"], rel=1e-6)


@pytest.mark.slow  # about 13 s
def test_a_campaign_confirms_the_reading_with_its_fitted_model_as_fit_does(damper_campaign):
    """The real friction damper: the linear start reads its displacement harmonics as the sensor's, the fitted
    Bouc-Wen model as motion. fit refits under the model's reading; a campaign (and its result rebuilt from the
    database) must end at the same optimum, not at the linear start's reading."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        loops = hysid.load(DAMPER)
        fit = hysid.fit(loops, "baseline+bouc_wen")
        start = choose_motion(loops, "baseline+bouc_wen")
    result, again = damper_campaign
    assert start.displacement == "fundamental" and fit.displacement_model["displacement"] == "measured"
    for campaign in (result.fit, again.fit):
        assert campaign.displacement_model["displacement"] == "measured" and campaign.displacement_model["decided_by"] == "data"
        assert "searched again under this one" in campaign.displacement_model["reason"]
        assert campaign.fitness == pytest.approx(fit.fitness, rel=1e-6)
    assert [r.label for r in result.fit.runs][-1] == "refit under the measured reading"


@pytest.mark.slow  # a campaign on the real damper: 40 s on a loaded machine
def test_a_campaigns_refit_under_the_other_reading_spends_the_campaigns_budget_not_fits(damper_campaign):
    """The rule: a campaign's refit under the reading its fitted model prefers searches within the campaign's own
    evaluation budget (:data:`DAMPER_BUDGET`), as its islands did, not within ``hysid fit``'s default (:data:`island.memetic.BUDGET`).
    The friction damper read as the linear start reads it, searched again as its Bouc-Wen fit reads it."""
    result, _ = damper_campaign
    refit = result.fit.runs[-1]
    assert refit.label == "refit under the measured reading"
    searched = refit.history[-1]["evaluations"]  # the memetic search's, before its polish
    assert DAMPER_BUDGET <= searched < BUDGET / 2
