"""Shared fixtures."""

import pytest

from hysid_model.model import build_model
from hysid_model.objective import Objective
from hysid_model.synth import MEQ_KG, synth_loops


@pytest.fixture(scope="module")
def synth():
    """The thesis model and its objective on the noiseless Synth set."""
    model = build_model("thesis").fix(meq=MEQ_KG)
    return model, Objective(synth_loops(0), model)
