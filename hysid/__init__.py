"""hysid: identify how a material or structure dissipates and stores energy from hysteresis loops.

The front door for Python (the ``hysid`` command line does the same):

    import hysid
    loops = hysid.load("synth", noise_pct=10)              # or a dataset directory, a loops file, .mat/.lvm files
    result = hysid.fit(loops, "thesis", algo="pso")         # GA or PSO, then a least-squares polish
    result.params, result.stderr                            # identified parameters, standard errors
    print(result.summary())                                 # and result.to_dict(), result.write_report("out")
    diagnosis = hysid.diagnose(loops, "baseline")           # which physical effect is the model missing?
    campaign = hysid.campaign(loops, "thesis", islands=4)   # cooperating GA/PSO islands over Zenoh

``fit``, ``diagnose`` and ``campaign`` take ``(loops, model, ...)`` in that order, every other argument
a keyword.

Models are data: ``hysid.models.thesis + hysid.effects.coulomb_friction``, with
``.fix(meq=...)`` for known values and ``.with_bounds({...})``; ``hysid.term(fn, ...)``
makes a force law of your own a term like the library's. Bad input
raises :class:`HysidInputError` with one line naming what is wrong; doubtful
input warns with :class:`HysidWarning`.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from hysid import effects, models
    from hysid.campaigns import CampaignResult, campaign
    from hysid.diagnosis.result import Diagnosis
    from hysid.diagnosis.selection import diagnose
    from hysid.fit_result import FitResult
    from hysid.fitting import fit
    from hysid_model.datasets import load_dataset as load
    from hysid_model.errors import HysidInputError, HysidWarning
    from hysid_model.loops import LoopSet
    from hysid_model.model import Model
    from hysid_model.params import Parameter
    from hysid_model.user_terms import term
    from island.migration import Migration
    from island.termination import Termination

_EXPORTS = {
    "effects": ("hysid.effects", None),
    "models": ("hysid.models", None),
    "CampaignResult": ("hysid.campaigns", "CampaignResult"),
    "campaign": ("hysid.campaigns", "campaign"),
    "Diagnosis": ("hysid.diagnosis.result", "Diagnosis"),
    "diagnose": ("hysid.diagnosis.selection", "diagnose"),
    "FitResult": ("hysid.fit_result", "FitResult"),
    "fit": ("hysid.fitting", "fit"),
    "load": ("hysid_model.datasets", "load_dataset"),
    "HysidInputError": ("hysid_model.errors", "HysidInputError"),
    "HysidWarning": ("hysid_model.errors", "HysidWarning"),
    "LoopSet": ("hysid_model.loops", "LoopSet"),
    "Model": ("hysid_model.model", "Model"),
    "Parameter": ("hysid_model.params", "Parameter"),
    "term": ("hysid_model.user_terms", "term"),
    "Migration": ("island.migration", "Migration"),
    "Termination": ("island.termination", "Termination"),
}
"""The front door's names and where they live; imported on first use, so that ``import hysid`` (and the
command line's start, which Ctrl-C may interrupt) stays light until something is used."""


def __getattr__(name: str) -> Any:
    if name == "__version__":  # importlib.metadata is slow to import: only when asked
        from importlib.metadata import PackageNotFoundError, version

        try:
            globals()[name] = version("hysid")
        except PackageNotFoundError:  # running from a source tree that was never installed
            globals()[name] = "0+unknown"
        return globals()[name]
    if name not in _EXPORTS:
        raise AttributeError(f"module 'hysid' has no attribute {name!r}")
    module, attr = _EXPORTS[name]
    value = import_module(module) if attr is None else getattr(import_module(module), attr)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(list(globals()) + list(_EXPORTS))


__all__ = sorted(_EXPORTS) + ["__version__"]
