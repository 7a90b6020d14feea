"""The rule of hysid/motion.py by which the data choose the displacement reading: a reading is taken only where
its BIC is lower by at least BIC_MARGIN; within the margin the measured waveform is kept."""

from __future__ import annotations

import pytest

from hysid.diagnosis.criteria import BIC_MARGIN
from hysid.motion import decide


@pytest.mark.parametrize(("ahead", "reading"), [
    (BIC_MARGIN + 1.0, "fundamental"),
    (BIC_MARGIN, "fundamental"),
    (BIC_MARGIN - 1.0, "measured"),
    (0.5, "measured"),
    (-(BIC_MARGIN - 1.0), "measured"),
    (-BIC_MARGIN, "measured"),
    (-(BIC_MARGIN + 1.0), "measured"),
])
def test_the_sensor_reading_needs_a_bic_lower_by_the_margin(ahead, reading):
    """``ahead``: how much lower the fundamental (sensor) reading's BIC is than the measured one's."""
    choice = decide({"measured": 500.0, "fundamental": 500.0 - ahead}, "baseline", [])
    assert (choice.displacement, choice.decided_by) == (reading, "data")
    assert ("cannot tell" in choice.reason) == (abs(ahead) < BIC_MARGIN)
    assert choice.delta_bic == pytest.approx(-ahead)
