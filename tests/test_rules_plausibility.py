"""The unit-slip rule of hysid_model/plausibility.py: a loop whose amplitude X0, or whose force per displacement
F1/X0, lies more than UNIT_GAP (15x) away from every other loop's is named as a unit slip; a sweep whose loops
differ by less (an amplitude sweep of a decade) is not."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from hysid_model.errors import HysidWarning
from hysid_model.plausibility import UNIT_GAP, Clipping, Measured, warn_loops


def slips(x0: list[float], force: list[float]) -> dict[str, str]:
    """The unit-slip warnings of a set of loops with amplitudes ``x0`` (m) and force amplitudes ``force`` (N): code -> message."""
    n = len(x0)
    measured = Measured(np.full(n, 10.0), np.array(x0), np.array(force), np.zeros(n), np.zeros(n), np.zeros(n), np.zeros((n, 2)))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warn_loops([f"r{i}" for i in range(n)], measured, [Clipping()] * n, "set")
    return {w.message.code: str(w.message) for w in caught if isinstance(w.message, HysidWarning) and w.message.code.startswith("unit_slip")}


@pytest.mark.parametrize("gap", [20.0, 100.0, 1000.0])
def test_an_amplitude_more_than_the_unit_gap_from_the_others_is_a_displacement_slip(gap):
    """Three loops near 1 mm and one ``gap`` times larger (20x, 100x, mm under a metre header: 1000x), each with the
    same stiffness: the far loop is named, as a displacement slip only (its force per displacement moves with it)."""
    x0 = [1.0e-3, 1.2e-3, 1.1e-3, gap * 1.1e-3]
    found = slips(x0, [1e4 * x for x in x0])
    assert set(found) == {"unit_slip_displacement"} and "in r3 (" in found["unit_slip_displacement"]
    assert f"more than {UNIT_GAP:g}x" in found["unit_slip_displacement"]


def test_a_force_per_displacement_more_than_the_unit_gap_away_is_a_force_slip():
    """Same amplitudes, one loop's force 20x (a 15x gap crossed; kN under a newton header would be 1000x)."""
    x0 = [1.0e-3, 1.2e-3, 1.1e-3, 1.05e-3]
    force = [10.0, 12.0, 11.0, 20 * 10.5]
    found = slips(x0, force)
    assert set(found) == {"unit_slip_force"} and "in r3 (" in found["unit_slip_force"]


def test_loops_within_the_unit_gap_of_a_neighbour_are_no_slip():
    """An amplitude sweep 1-10 mm in steps (each within 15x of its neighbour, the whole span more than 15x is no
    slip either), and a single loop 12x from the others: no unit-slip warning."""
    sweep = [1e-3, 3e-3, 10e-3, 30e-3]
    assert slips(sweep, [1e4 * x for x in sweep]) == {}
    near = [1.0e-3, 1.1e-3, 12 * 1.1e-3]
    assert slips(near, [1e4 * x for x in near]) == {}
    assert slips([1.0e-3, 1.1e-3, 1.05e-3], [10.0, 11.0, 12 * 11.0]) == {}
