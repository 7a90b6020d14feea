"""hysid_model: physics and data for hysteresis-loop identification.

Data flows one way: files -> loops (:mod:`hysid_model.loops`) -> model terms
(:mod:`hysid_model.terms`, :mod:`hysid_model.model`) -> the problem and its
objective (:mod:`hysid_model.problem`, :mod:`hysid_model.objective`) ->
uncertainty (:mod:`hysid_model.uncertainty`). Users start at :mod:`hysid`.
"""

from hysid_model.errors import HysidInputError
from hysid_model.loops import LoopSet
from hysid_model.model import Model, build_model
from hysid_model.objective import Objective

__all__ = ["HysidInputError", "LoopSet", "Model", "Objective", "build_model"]
