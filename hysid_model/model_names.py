"""A model named by its terms, as an engineer reads it: ``baseline + bouc_wen (bw_n free)``.

A model string (:attr:`hysid_model.model.Model.spec`) starts with the preset
that rebuilds the model (``mr_damper``: the oscillator plus a Bouc-Wen spring
with its exponent free); a preset's name says what it was made for, not what
the device is (an elastomeric bearing fitted with ``mr_damper`` is no
magnetorheological damper). Reports name a model by what it holds: the
oscillator (``baseline``: mass, spring, dashpot), then every other term, with
the parameters searched that the term fixes by default.
"""

from __future__ import annotations

from hysid_model.model import Model, spec_of
from hysid_model.terms import Oscillator


def model_name(model: Model) -> str:
    """``model`` named by its terms (see the module docstring)."""
    parts = ["baseline"]
    for term in model.terms:
        if isinstance(term, Oscillator):
            continue
        freed = [p.name for p in term.params if not p.vary and p.name in model.names]
        parts.append(term.spec + (f" ({', '.join(freed)} free)" if freed else ""))
    return " + ".join(parts)


def named(model: Model) -> str:
    """The name and, where it differs, the model string that rebuilds it (:func:`hysid_model.model.spec_of`: its
    preset frees what it searches): ``baseline + bouc_wen (bw_n free) [model string mr_damper]``."""
    name = model_name(model)
    spec = spec_of(model.terms, model.names)
    return name if name.replace(" + ", "+") == spec else f"{name} [model string {spec}]"
