"""The warning rules of hysid_model/plausibility.py on what the checks measured of a set's loops: a loop whose
amplitude X0, or whose force per displacement F1/X0, lies more than UNIT_GAP (15x) away from every other loop's is
named as a unit slip (a sweep whose loops differ by less is not); a displacement THD above THD_WARN, a clipped loop
and an amplitude drift above DRIFT_WARN are each named in one line, loop by loop up to NAMED loops, then counted."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from hysid_model.errors import HysidWarning
from hysid_model.plausibility import UNIT_GAP, Clipping, Measured, amplitude_drift, warn_loops


def warned(
    x0: list[float], force: list[float], thd: list[float] | None = None, drift: list[list[float]] | None = None, clips: list[Clipping] | None = None
) -> dict[str, str]:
    """The warnings (code -> message) about a set of loops ``r0, r1, ...`` with amplitudes ``x0`` (m), force amplitudes
    ``force`` (N), displacement THD ``thd``, drifts ``drift`` (displacement, force) and ``clips``."""
    n = len(x0)
    measured = Measured(
        np.full(n, 10.0),
        np.array(x0),
        np.array(force),
        np.zeros(n),
        np.zeros(n) if thd is None else np.array(thd),
        np.zeros(n),
        np.zeros((n, 2)) if drift is None else np.array(drift),
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warn_loops([f"r{i}" for i in range(n)], measured, clips or [Clipping()] * n, "set")
    ours = [w for w in caught if isinstance(w.message, HysidWarning)]
    return {w.message.code + ("_force" if "the force amplitude drifts" in str(w.message) else ""): str(w.message) for w in ours}


def slips(x0: list[float], force: list[float]) -> dict[str, str]:
    return {code: text for code, text in warned(x0, force).items() if code.startswith("unit_slip")}


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
    assert found == {
        "unit_slip_force": "set: force per displacement far (more than 15x) from the other loops' in r3 (X0 = 1.05 mm) "
        "against X0 = 1-1.2 mm: a unit slip of the force (kN under a _n header, or N under _kn)? correct those records "
        "(force_unit in dataset.toml would change every record)"
    }
    x0 = [1.0e-3, 1.2e-3, 1.1e-3, 20 * 1.1e-3]
    assert slips(x0, [1e4 * x for x in x0]) == {
        "unit_slip_displacement": "set: amplitude far (more than 15x) from the other loops' in r3 (X0 = 22 mm) against X0 = 1-1.2 mm: "
        "a unit slip of the displacement (mm under a _m header, or m under _mm)? correct those records "
        "(displacement_unit in dataset.toml would change every record)"
    }


def test_a_real_displacement_slip_is_named_once_and_a_loop_below_the_others_too():
    """Millimetres under a metre header in one loop: its X0 reads 1000x, its force not, so F1/X0 falls 1000x too; it
    is one displacement slip, not also a force slip. A loop 20x below the others (metres under a mm header) and one
    of two loops 20x apart are named as well."""
    x0 = [1.0e-3, 1.2e-3, 1.1e-3, 1.05]
    assert list(slips(x0, [10.0, 12.0, 11.0, 10.5])) == ["unit_slip_displacement"]
    low = slips([1e-3 / 20, 1.0e-3, 1.2e-3, 1.1e-3], [10.0 / 20, 10.0, 12.0, 11.0])
    assert "in r0 (X0 = 0.05 mm) against X0 = 1-1.2 mm" in low["unit_slip_displacement"]
    assert list(slips([1e-3, 20e-3], [10.0, 200.0])) == ["unit_slip_displacement"]


def test_loops_within_the_unit_gap_of_a_neighbour_are_no_slip():
    """An amplitude sweep 1-10 mm in steps (each within 15x of its neighbour, the whole span more than 15x is no
    slip either), and a single loop 12x from the others: no unit-slip warning."""
    sweep = [1e-3, 3e-3, 10e-3, 30e-3]
    assert slips(sweep, [1e4 * x for x in sweep]) == {}
    near = [1.0e-3, 1.1e-3, 12 * 1.1e-3]
    assert slips(near, [1e4 * x for x in near]) == {}
    assert slips([1.0e-3, 1.1e-3, 1.05e-3], [10.0, 11.0, 12 * 11.0]) == {}
    assert slips([1.0, 1.0, 15.0], [1e4, 1e4, 1.5e5]) == {}  # exactly 15x is not more than 15x


def test_a_distorted_displacement_is_named_loop_by_loop_then_counted():
    few = warned([1e-3] * 3, [10.0] * 3, thd=[0.01, 0.08, 20.0])
    assert few == {
        "distortion": "set: displacement THD above 5 % in r1 (8 %), r2 (2e+03 %): the shaker does not impose a pure sine, "
        "or the sensor distorts; the loops keep the measured waveform, and fit, campaign and diagnose decide "
        "from the force whether it is the motion (displacement_model)"
    }
    five = warned([1e-3] * 6, [10.0] * 6, thd=[0.06, 0.07, 0.08, 0.09, 0.1, 0.01])
    assert "in r0 (6 %), r1 (7 %), r2 (8 %), r3 (9 %), r4 (10 %): " in five["distortion"]  # up to NAMED, one by one
    many = warned([1e-3] * 7, [10.0] * 7, thd=[0.07, 0.06, 0.08, 0.09, 0.1, 0.11, 0.01])
    assert many["distortion"].startswith("set: displacement THD above 5 % in 6 of 7 records (6 % in r1 to 11 % in r5): ")
    every = warned([1e-3] * 6, [10.0] * 6, thd=[0.06, 0.07, 0.08, 0.09, 0.1, 0.11])
    assert "in all 6 records (6 % in r0 to 11 % in r5)" in every["distortion"]
    assert warned([1e-3] * 3, [10.0] * 3, thd=[0.05, 0.04, 0.0]) == {}


def test_a_drift_of_either_amplitude_above_five_percent_is_named():
    found = warned([1e-3] * 3, [10.0] * 3, drift=[[0.0, 0.0], [20.0, 0.05], [0.0, 0.1]])
    assert found == {
        "drift": "set: the displacement amplitude drifts over the steady window by r1 (2e+03 %); each loop averages its cycles",
        "drift_force": "set: the force amplitude drifts over the steady window by r2 (10 %); each loop averages its cycles",
    }


def test_clipped_loops_are_named_with_their_level_and_cause():
    found = warned([1e-3] * 3, [10.0] * 3, clips=[Clipping(), Clipping("displacement", 0.9e-3), Clipping("force", 12.5)])
    assert found == {
        "clipping": "set: clipped: r1: displacement flat at +0.9 mm, X0 = 1 mm; r2: force flat at +12.5 N "
        "(a stroke or sensor limit? a load cell or its amplifier at the end of its range?)"
    }
    many = warned([1e-3] * 7, [10.0] * 7, clips=[Clipping("velocity", 0.05 + 0.01 * i) for i in range(6)] + [Clipping("force", 3.0)])
    assert many == {
        "clipping": "set: clipped: force in r6 (flat at +3 N); velocity in 6 of 7 records (flattened at 0.05 m/s in r0 to "
        "flattened at 0.1 m/s in r5) (a load cell or its amplifier at the end of its range? a speed limit?)"
    }
    five = warned([1e-3] * 5, [10.0] * 5, clips=[Clipping("force", 3.0 + i) for i in range(5)])
    assert five["clipping"].startswith("set: clipped: r0: force flat at +3 N; r1: force flat at +4 N; ")
    stroke = warned([1e-3] * 6, [10.0] * 6, clips=[Clipping("displacement", (0.9 + 0.01 * i) * 1e-3) for i in range(6)])
    assert stroke == {"clipping": "set: clipped: displacement in all 6 records (flat at +0.9 mm in r0 to flat at +0.95 mm in r5) (a stroke or sensor limit?)"}


def test_the_drift_is_the_change_of_a_straight_line_through_the_cycles_over_their_mean():
    """1.0, 1.1, 1.2 over three cycles (or mm: 1.0e-3, ...): a change of 0.2 on a mean of 1.1; a constant amplitude, a
    zero one, one of zero mean and a single cycle do not drift."""
    np.testing.assert_allclose(
        amplitude_drift(np.array([[1.0, 1.1, 1.2], [2.0, 2.0, 2.0], [0.0, 0.0, 0.0], [-1.2, -1.1, -1.0], [1.0e-3, 1.1e-3, 1.2e-3]])),
        [0.2 / 1.1, 0.0, 0.0, 0.2 / 1.1, 0.2 / 1.1],
        rtol=1e-12,
    )
    np.testing.assert_allclose(amplitude_drift(np.array([[1.0e-3, 1.2e-3]])), [0.2 / 1.1], rtol=1e-12)  # two cycles: their line
    np.testing.assert_array_equal(amplitude_drift(np.array([[1.0], [2.0]])), [0.0, 0.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a row of mean zero has no relative drift, and no division by zero either
        np.testing.assert_array_equal(amplitude_drift(np.array([[-1.0, 0.0, 1.0]])), [0.0])
