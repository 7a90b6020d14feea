"""``hysid bench discovery`` (hysid/bench/discovery.py, discovery_cases.py): the shape error's definition on known
cases, the formula's evaluation, the shared Markdown document, and one hidden law end to end."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hysid.bench import write_section
from hysid.bench.discovery import formula_force, loop_motion, run, shape_error
from hysid.bench.discovery_cases import LAWS
from hysid_model.errors import HysidInputError


def motion(freqs=(4.0, 9.0, 17.0), amps=(1e-3, 4e-3), samples=256):
    """The sine motion of a grid of loops, as the bench takes it from a loop set."""
    return loop_motion(np.tile(freqs, len(amps)), np.repeat(amps, len(freqs)), samples)


def test_a_difference_a_spring_and_a_dashpot_absorb_has_no_shape_error():
    """One spring and one dashpot over all loops absorb the difference: 0, whatever the law."""
    x, v = motion()
    for law in LAWS.values():
        truth = law.force(x, v, **law.truth)
        assert shape_error(truth, truth + 3.1e4 * x - 57.0 * v, x, v) < 1e-10, law.name


def test_proposing_nothing_scores_the_law_s_own_figure():
    """With nothing proposed the error is the part of the law no spring and dashpot absorb, over its RMS: 1 for an
    even law (x^2 is orthogonal to x and v over whole cycles); sqrt(1 - 8 / pi^2) for a Coulomb force on one loop
    (a dashpot takes the square wave's fundamental, 8 / pi^2 of its power)."""
    x, v = motion()
    assert shape_error(2.0e7 * x**2, 0.0, x, v) == pytest.approx(1.0, abs=1e-12)
    one_x, one_v = motion((9.0,), (2e-3,), 4096)
    assert shape_error(30.0 * np.sign(one_v), 0.0, one_x, one_v) == pytest.approx(np.sqrt(1.0 - 8.0 / np.pi**2), abs=1e-3)
    # a proposal of the right shape at the wrong size leaves that share of the law's own figure
    truth = 2.0e7 * x**2
    assert shape_error(truth, 0.8 * truth, x, v) == pytest.approx(0.2, abs=1e-12)
    # across loops one dashpot cannot follow a force that does not grow with the velocity: more than one loop's figure
    coulomb = shape_error(30.0 * np.sign(v), 0.0, x, v)
    assert np.sqrt(1.0 - 8.0 / np.pi**2) + 0.05 < coulomb < 1.0


def test_a_formula_is_a_numpy_expression_in_x_and_v_and_nothing_else():
    x, v = motion()
    np.testing.assert_allclose(
        formula_force("120.0 * (np.abs(v) ** 0.35 * np.sign(v))", x, v), LAWS["fluid_viscous"].force(x, v, **LAWS["fluid_viscous"].truth)
    )
    assert formula_force("2.5", x, v).shape == x.shape
    with pytest.raises(NameError):
        formula_force("__import__('os').getcwd()", x, v)


def test_benches_sharing_a_document_each_rewrite_their_own_section(tmp_path):
    doc = tmp_path / "VALIDATION.md"
    write_section(doc, "validation", "# Validation\n\ntable one")
    write_section(doc, "discovery", "## Discovery\n\nfirst")
    write_section(doc, "validation", "# Validation\n\ntable two")
    write_section(doc, "discovery", "## Discovery\n\nsecond")
    text = doc.read_text()
    assert text.index("table two") < text.index("second")
    assert "table one" not in text and "first" not in text and text.count("<!-- bench discovery -->") == 1


def test_an_unknown_law_or_control_is_one_clear_error_before_anything_runs():
    with pytest.raises(HysidInputError, match="unknown law 'nonsense'"):
        run(laws=("nonsense",))
    with pytest.raises(HysidInputError, match="unknown control 'coulomb'"):
        run(laws=(), controls=("coulomb",))


@pytest.mark.slow  # two diagnoses of 4 loops, one of a control
def test_one_hidden_law_end_to_end(tmp_path, capsys):
    """``hysid bench discovery --quick`` on the orifice law: both diagnoses, the floor near the noise, every proposal's
    formula a force at the loops' motion, and the Markdown section with its row."""
    from hysid.cli import main

    doc = tmp_path / "VALIDATION.md"
    assert (
        main(
            [
                "bench",
                "discovery",
                "--quick",
                "--laws",
                "orifice",
                "--noise",
                "1",
                "--controls",
                "no_effect",
                "--seeds",
                "1",
                "--no-real",
                "--markdown",
                str(doc),
                "--json",
            ]
        )
        == 0
    )
    result = json.loads(capsys.readouterr().out)
    rows = result["laws"]
    assert [(r["law"], r["noise_pct"]) for r in rows] == [("orifice", 1.0)]
    for r in rows:
        assert r["loops"] == 4 and r["baseline"]["cpu_s"] > 0 and r["discovery"]["cpu_s"] > 0
        assert 0.05 * r["noise_pct"] < r["floor_nrmse_pct"] < r["noise_pct"]
        assert r["nothing_proposed_shape_error"] > 0.2  # v |v| is no dashpot: the case asks a question
        if not r["proposed"]:
            assert r["proposed_shape_error"] == pytest.approx(r["nothing_proposed_shape_error"])
        if not r["proposed"] and not r["discovery"]["named"]:
            assert r["shape_error"] == pytest.approx(r["nothing_proposed_shape_error"]) and r["n_params"] == 0
    (control,) = result["controls"]
    assert control["seeds"] == 1 and len(control["draws"]) == 1
    text = doc.read_text()
    assert "| `orifice`: c v \\|v\\| | 1 % |" in text and "## Discovery" in text
