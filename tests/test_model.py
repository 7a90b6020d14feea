"""Models as composable terms: presets, parameter order and bounds, the mass, physical form."""

import numpy as np
import pytest

from hysid_model.effects import EFFECTS
from hysid_model.errors import HysidInputError
from hysid_model.model import build_model, from_physical, to_physical
from hysid_model.problem import prepare_model
from hysid_model.synth import MEQ_KG, TRUE_PARAMS, synth_loops


def test_presets_follow_the_thesis_chromosome_order():
    assert build_model("thesis").fix(meq=MEQ_KG).names == ["xi0", "S_xi", "w0", "S_w"]
    assert build_model("baseline").fix(meq=MEQ_KG).names == ["xi0", "w0"]


def test_every_parameter_has_a_unit_and_bounds():
    model = build_model("thesis+coulomb_friction").fix(meq=MEQ_KG)
    for p in model.parameters:
        assert p.unit and p.lower < p.upper
    assert model.bounds.shape == (model.dim, 2)


def test_the_mass_is_a_parameter_fixed_when_known_and_the_dataset_fixes_it_one_way():
    assert build_model("thesis").names[-1] == "meq"
    known = build_model("thesis").fix(meq=MEQ_KG)
    assert "meq" not in known.names and known.fixed == {"meq": MEQ_KG}
    assert "meq" in known.vary("meq").names
    loops = synth_loops(0.0)
    assert prepare_model(loops, "thesis").fixed == {"meq": MEQ_KG}  # the dataset's known mass
    assert "meq" in prepare_model(loops, "thesis", bounds={"meq": (0.01, 0.1)}).names  # bounds given: fitted
    assert "meq" in prepare_model(loops.with_meq(None), "thesis").names  # unknown: fitted


def test_models_compose_in_python_as_in_the_model_string():
    composed = build_model("thesis") + EFFECTS["coulomb_friction"]()
    assert composed.spec == "thesis+coulomb_friction" and composed.names == build_model("thesis+coulomb_friction").names
    with pytest.raises(HysidInputError, match="already in the model"):
        composed + EFFECTS["coulomb_friction"]()
    bounded = composed.with_bounds({"F_d": (0.0, 5.0)})
    assert bounded.bounds[-1].tolist() == [0.0, 5.0] and composed.bounds[-1].tolist() != [0.0, 5.0]  # never in place


@pytest.mark.parametrize(
    "spec, message",
    [("nonsense", "must start with"), ("thesis+magic", "unknown effect 'magic'"), ("thesis+amplitude_dependent_damping", "already in the model")],
)
def test_bad_model_specs_name_the_problem(spec, message):
    with pytest.raises(HysidInputError, match=message):
        build_model(spec).fix(meq=MEQ_KG)


def test_bounds_override_checks_names():
    model = build_model("thesis").fix(meq=MEQ_KG).with_bounds({"w0": (150.0, 250.0)})
    assert model.bounds[2].tolist() == [150.0, 250.0]
    with pytest.raises(HysidInputError, match="unknown parameter"):
        model.with_bounds({"omega": (1.0, 2.0)})
    with pytest.raises(HysidInputError, match=r"bounds -0.1:0.1 reach outside the physical range \[0, inf\)"):
        model.with_bounds({"xi0": (-0.1, 0.1)})
    with pytest.raises(HysidInputError, match=r"1.5 is outside the physical range \[0, 1\] of relaxation strength"):
        build_model("thesis+zener_thermoelastic").fix(zener_delta=1.5)


def test_modal_values_follow_eq_4_8_and_4_9():
    model = build_model("thesis").fix(meq=MEQ_KG)
    theta = model.from_dict(TRUE_PARAMS)
    state = model.modal(theta, [0.5e-3, 1.5e-3])
    np.testing.assert_allclose(state.xi, [0.0042 - 0.4 * 0.5e-3, 0.0042 - 0.4 * 1.5e-3])
    np.testing.assert_allclose(state.wn, [189.1239 - 1256.64 * 0.5e-3, 189.1239 - 1256.64 * 1.5e-3])
    np.testing.assert_allclose(state.m, MEQ_KG)


def test_physical_form_round_trips():
    model = build_model("thesis").fix(meq=MEQ_KG)
    state = model.modal(model.from_dict(TRUE_PARAMS), [0.5e-3, 1.0e-3, 1.5e-3])
    phys = to_physical(state)
    np.testing.assert_allclose(phys["k"], MEQ_KG * state.wn**2)
    np.testing.assert_allclose(phys["c"], 2 * MEQ_KG * state.xi * state.wn)
    back = from_physical(phys["k"], phys["c"], phys["m"])
    np.testing.assert_allclose(back.xi, state.xi, rtol=1e-12)
    np.testing.assert_allclose(back.wn, state.wn, rtol=1e-12)
    with pytest.raises(HysidInputError, match="positive"):
        from_physical(-1.0, 0.1, 1.0)
