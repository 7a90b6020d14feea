"""The rule of hysid_model/model.py that names a parameter's bound: a value on a bound is on the side it is
nearer to, and the bound is named by what set it (a physical limit, the term's default, or given)."""

from __future__ import annotations

from hysid_model.model import build_model


def test_a_value_on_a_bound_is_named_on_the_side_it_sits_on():
    """w0 searched in a given [120, 250] rad/s: at 120 it is on the lower bound, at 250 on the upper one; a damping
    ratio of 0 is on its physical limit, which is an answer and not a search artifact (left out of at_bounds)."""
    model = build_model("baseline").with_bounds({"w0": (120.0, 250.0)})
    low = model.from_dict({"xi0": 0.0, "w0": 120.0, "meq": 1.0})
    high = model.from_dict({"xi0": 0.01, "w0": 250.0, "meq": 1.0})
    assert model.bound_kinds(low) == {"xi0": "physical lower bound 0", "w0": "given lower bound 120"}
    assert model.bound_kinds(high) == {"w0": "given upper bound 250"}
    assert model.at_bounds(low) == ["w0"] and model.at_bounds(high) == ["w0"]
    top = model.from_dict({"xi0": 0.1, "w0": 200.0, "meq": 1.0})
    assert model.bound_kinds(top) == {"xi0": "default upper bound 0.1"} and model.at_bounds(top) == ["xi0"]


def test_a_bound_from_the_data_is_named_data_derived_and_one_off_the_bounds_is_not_named():
    model = build_model("baseline").with_bounds({"w0": (120.0, 250.0), "meq": (0.5, 2.0)}, soft=True)
    theta = model.from_dict({"xi0": 0.05, "w0": 250.0, "meq": 0.5})
    assert model.bound_kinds(theta) == {"w0": "data-derived upper bound 250", "meq": "data-derived lower bound 0.5"}
    inside = model.from_dict({"xi0": 0.05, "w0": 250.0 * (1 - 1e-4), "meq": 0.5 * (1 + 1e-3)})
    assert model.bound_kinds(inside) == {} and model.at_bounds(inside) == []


def test_a_default_lower_bound_is_named_default_and_a_theta_row_reads_as_the_vector():
    model = build_model("baseline")
    theta = model.from_dict({"xi0": 0.01, "w0": 100.0, "meq": 1.0})
    assert model.bound_kinds(theta) == {"w0": "default lower bound 100"}
    assert model.bound_kinds(theta[None, :]) == {"w0": "default lower bound 100"} and model.at_bounds(theta[None, :]) == ["w0"]
