"""Models as composable terms: presets, parameter order and bounds, the mass, physical form."""

import numpy as np
import pytest

from hysid_model.errors import HysidInputError
from hysid_model.model import build_model, from_physical, to_physical
from hysid_model.synth import MEQ_KG, TRUE_PARAMS


def test_presets_follow_the_thesis_chromosome_order():
    assert build_model("thesis", MEQ_KG).names == ["xi0", "S_xi", "w0", "S_w"]
    assert build_model("baseline", MEQ_KG).names == ["xi0", "w0"]


def test_every_parameter_has_a_unit_and_bounds():
    model = build_model("thesis+coulomb_friction", MEQ_KG)
    for p in model.parameters:
        assert p.unit and p.lower < p.upper
    assert model.bounds.shape == (model.dim, 2)


def test_unknown_mass_is_fitted_and_can_be_fitted_on_request():
    assert build_model("thesis", None).names[-1] == "meq"
    assert "meq" in build_model("thesis", MEQ_KG, fit_mass=True).names
    assert "meq" not in build_model("thesis", MEQ_KG).names


@pytest.mark.parametrize(
    "spec, message",
    [("nonsense", "must start with"), ("thesis+magic", "unknown effect 'magic'"), ("thesis+amplitude_dependent_damping", "already in the model")],
)
def test_bad_model_specs_name_the_problem(spec, message):
    with pytest.raises(HysidInputError, match=message):
        build_model(spec, MEQ_KG)


def test_bounds_override_checks_names():
    model = build_model("thesis", MEQ_KG)
    model.set_bounds({"w0": (150.0, 250.0)})
    assert model.bounds[2].tolist() == [150.0, 250.0]
    with pytest.raises(HysidInputError, match="unknown parameter"):
        model.set_bounds({"omega": (1.0, 2.0)})


def test_modal_values_follow_eq_4_8_and_4_9():
    model = build_model("thesis", MEQ_KG)
    theta = model.from_dict(TRUE_PARAMS)
    state = model.modal(theta, [0.5e-3, 1.5e-3], MEQ_KG)
    np.testing.assert_allclose(state.xi, [0.0042 - 0.4 * 0.5e-3, 0.0042 - 0.4 * 1.5e-3])
    np.testing.assert_allclose(state.wn, [189.1239 - 1256.64 * 0.5e-3, 189.1239 - 1256.64 * 1.5e-3])
    np.testing.assert_allclose(state.m, MEQ_KG)


def test_physical_form_round_trips():
    model = build_model("thesis", MEQ_KG)
    state = model.modal(model.from_dict(TRUE_PARAMS), [0.5e-3, 1.0e-3, 1.5e-3], MEQ_KG)
    phys = to_physical(state)
    np.testing.assert_allclose(phys["k"], MEQ_KG * state.wn**2)
    np.testing.assert_allclose(phys["c"], 2 * MEQ_KG * state.xi * state.wn)
    back = from_physical(phys["k"], phys["c"], phys["m"])
    np.testing.assert_allclose(back.xi, state.xi, rtol=1e-12)
    np.testing.assert_allclose(back.wn, state.wn, rtol=1e-12)
    with pytest.raises(HysidInputError, match="positive"):
        from_physical(-1.0, 0.1, 1.0)
