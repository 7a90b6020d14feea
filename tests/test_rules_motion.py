"""The rules of hysid/motion.py by which the data choose the displacement reading: a reading is taken only where
its BIC is lower by at least BIC_MARGIN; within the margin the measured waveform is kept; the choice says why, with
the orders' evidence. A record is distorted when its displacement carries a harmonic beyond the fundamental, and
the readings are compared with the linear start within the model (thesis where it has both amplitude slopes)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hysid.criteria import BIC_MARGIN
from hysid.motion import decide, distorted, linear_start
from hysid_model.model import build_model
from hysid_model.synth import synth_loops

EVIDENCE = [
    {"order": 3, "displacement_share": 0.05, "force_share": 0.0012, "response": 0.024},
    {"order": 5, "displacement_share": 0.02, "force_share": 0.0004, "response": 0.02},
]


@pytest.mark.parametrize(
    ("ahead", "reading"),
    [
        (BIC_MARGIN + 1.0, "fundamental"),
        (BIC_MARGIN, "fundamental"),
        (BIC_MARGIN - 1.0, "measured"),
        (0.5, "measured"),
        (-(BIC_MARGIN - 1.0), "measured"),
        (-BIC_MARGIN, "measured"),
        (-(BIC_MARGIN + 1.0), "measured"),
    ],
)
def test_the_sensor_reading_needs_a_bic_lower_by_the_margin(ahead, reading):
    """``ahead``: how much lower the fundamental (sensor) reading's BIC is than the measured one's."""
    choice = decide({"measured": 500.0, "fundamental": 500.0 - ahead}, "baseline", EVIDENCE)
    assert (choice.displacement, choice.decided_by, choice.model, choice.orders) == (reading, "data", "baseline", EVIDENCE)
    assert ("cannot tell" in choice.reason) == (abs(ahead) < BIC_MARGIN)
    assert choice.delta_bic == pytest.approx(-ahead) and choice.chi2 == {"measured": 500.0, "fundamental": 500.0 - ahead}


def test_the_reason_gives_the_orders_and_the_bic_difference():
    sensor = decide({"measured": 530.0, "fundamental": 500.0}, "thesis", EVIDENCE)
    assert sensor.reason == (
        "the force does not respond to the displacement's harmonics (order 3: x 5 %, F 0.12 %, order 5: x 2 %, "
        "F 0.04 %): driven by the fundamental the thesis model fits better, BIC lower by 30"
    )
    motion = decide({"measured": 500.0, "fundamental": 530.0}, "thesis", EVIDENCE)
    assert motion.reason == (
        "the force responds to the displacement's harmonics (order 3: x 5 %, F 0.12 %, order 5: x 2 %, "
        "F 0.04 %): driven by them the thesis model fits better, BIC lower by 30"
    )
    tie = decide({"measured": 500.0, "fundamental": 503.0}, "baseline", EVIDENCE)
    assert tie.reason == "the data cannot tell sensor distortion from motion (BIC differs by +3, less than 10); the measured waveform is kept"
    assert decide({"measured": 500.0, "fundamental": 500.0}, "baseline", []).as_dict()["delta_bic"] == 0.0
    four = EVIDENCE + [{"order": k, "displacement_share": 0.01, "force_share": 0.001, "response": 0.1} for k in (7, 9)]
    assert "order 7: x 1 %, F 0.1 %)" in decide({"measured": 530.0, "fundamental": 500.0}, "thesis", four).reason  # the first three orders
    assert "order 9" not in decide({"measured": 530.0, "fundamental": 500.0}, "thesis", four).reason


def test_a_displacement_with_a_harmonic_beyond_its_fundamental_is_distorted():
    loops = synth_loops(0.0, n_points=5).subset([0, 1])
    assert not distorted(loops)  # no waveform: the ideal sine
    pure = np.zeros((2, 3), dtype=complex)
    pure[:, 0] = loops.x0
    assert not distorted(replace(loops, x_harmonics=pure))
    second = pure.copy()
    second[1, 1] = 1e-9j * loops.x0[1]
    assert distorted(replace(loops, x_harmonics=second))


def test_the_readings_are_compared_with_the_linear_start_within_the_model():
    assert linear_start(build_model("thesis+coulomb_friction")) == "thesis"
    assert linear_start(build_model("baseline+amplitude_dependent_damping")) == "baseline"  # one slope is not the thesis' pair
    assert linear_start(build_model("thesis").fix(S_w=0.0)) == "thesis"  # fixed, still the thesis model's
