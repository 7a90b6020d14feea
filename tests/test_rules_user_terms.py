"""The strength rule of hysid_model/user_terms.py: a user term's strength is the parameter whose 0 switches it off,
so its search bounds must hold 0 (on either end, or inside); bounds that do not are a one-line error naming the
strength. A term of one parameter whose bounds hold 0 has it as its strength by default, one whose bounds do not has
no strength (it cannot be a diagnosis' candidate)."""

from __future__ import annotations

import pytest

import hysid
from hysid_model.errors import HysidInputError


def spring(name: str, bounds: tuple[float, float], strength: str | None = "c"):
    return hysid.term(lambda x, v, c: c * x, name=name, units={"c": "N/m"}, bounds={"c": bounds}, strength=strength)


@pytest.mark.parametrize("bounds", [(0.0, 1.0), (-1.0, 0.0), (-1.0, 2.0)])
def test_strength_bounds_that_hold_zero_are_taken(bounds):
    assert spring(f"rule_ok_{abs(hash(bounds))}", bounds).strength == "c"
    assert spring(f"rule_default_{abs(hash(bounds))}", bounds, strength=None).strength == "c"


@pytest.mark.parametrize("bounds", [(1.0, 2.0), (-2.0, -1.0), (1e-9, 1.0), (-1.0, -1e-9)])
def test_strength_bounds_that_leave_zero_out_are_a_one_line_error(bounds):
    with pytest.raises(HysidInputError) as info:
        spring(f"rule_bad_{abs(hash(bounds))}", bounds)
    assert str(info.value) == f"strength='c': its bounds {bounds[0]:g}:{bounds[1]:g} must hold 0, where the term is off"
    assert (info.value.param, info.value.value) == ("strength", "c")
    assert spring(f"rule_none_{abs(hash(bounds))}", bounds, strength=None).strength == ""


def test_a_strength_must_name_a_parameter_and_two_parameters_have_none_by_default():
    with pytest.raises(HysidInputError) as info:
        spring("rule_unknown", (0.0, 1.0), strength="k")
    assert str(info.value) == "strength='k': is no parameter of term 'rule_unknown' (c)"
    with pytest.raises(HysidInputError) as two:
        hysid.term(lambda x, v, c, d: c * x + d, name="rule_unknown_two", units={"c": "N/m", "d": "N"}, bounds={"c": (0.0, 1.0), "d": (0.0, 1.0)}, strength="k")
    assert str(two.value) == "strength='k': is no parameter of term 'rule_unknown_two' (c, d)"
    two = hysid.term(lambda x, v, c, d: c * x + d * x**3, name="rule_two", units={"c": "N/m", "d": "N/m^3"}, bounds={"c": (0.0, 1.0), "d": (0.0, 1.0)})
    assert two.strength == ""
    assert (
        hysid.term(
            lambda x, v, c, d: d * (x + c * x**3), name="rule_two_d", units={"c": "1/m^2", "d": "N/m"}, bounds={"c": (1.0, 2.0), "d": (0.0, 1.0)}, strength="d"
        ).strength
        == "d"
    )  # only the strength must hold 0
