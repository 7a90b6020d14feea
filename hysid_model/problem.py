"""The identification problem: loops, a model with its bounds and fixed values, loop weights -> an objective.

The one place where a model meets a loop set (``hysid fit``, campaigns and
their islands, the diagnosis and the benches all come here):

* the model is a string (``"thesis+coulomb_friction"``) or a
  :class:`~hysid_model.model.Model`;
* a mass the dataset knows (``LoopSet.meq_kg``, from ``dataset.toml``) becomes
  the fixed parameter ``meq``, unless the caller fixes or bounds ``meq`` itself
  (bounds mean: fit it);
* bounds, one rule for every model and every command: each term derives its
  parameters' bounds from the loops' equivalent-linear survey with generous
  margins (:meth:`hysid_model.terms.Term.data_bounds`), the others keep their
  term's default (Bouc-Wen's shape r from -0.9 to 3); these are *soft*, a fit
  that ends on one widens it within the parameter's physical range (r >= -0.9)
  and refits. The dataset's own bounds (``[bounds]``
  of ``dataset.toml``; Table 5.4 for the Synth set and the thesis' own ``.mat``
  loops) and the caller's ``bounds`` are hard; ``fixed`` values come last;
* loops at a single amplitude level cannot tell the amplitude slopes S_xi,
  S_w (Eq. 4.8, 4.9) from xi0 and w0: unless the caller bounds them (a
  dataset's bounds only say where they lie), they are fixed at 0 (:func:`single_amplitude_slopes`), so xi0
  and w0 are the damping ratio and natural frequency at that amplitude;
* the starting point (:func:`starting_point`) is the survey's linear estimate
  of xi, wn and their slopes (Eq. 4.8, 4.9), every effect switched off;
* the loop weights of Eq. 3.3 are the thesis' (Appendix A) or maximum
  likelihood (1/sigma^2), by default ML when every loop's noise is known;
* the displacement is each loop's measured waveform where the loops carry it
  (``displacement="measured"``), the same samples driven by its fundamental alone
  where the harmonics are the displacement sensor's (``"fundamental"``), or the
  ideal sine of Eq. 4.5 (``"sine"``, as the thesis assumed); see :data:`DISPLACEMENTS`.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.frf import amplitude_levels
from hysid_model.loops import LoopSet
from hysid_model.model import Model, as_model
from hysid_model.objective import WEIGHTS, Objective
from hysid_model.survey import survey
from hysid_model.synth import BOUNDS as TABLE_5_4
from hysid_model.thesis_port import ThesisObjective

DISPLACEMENTS = ("measured", "fundamental", "sine")
"""How the model sees each loop's displacement: its measured harmonics are the motion (``measured``); they are
the sensor's distortion and the motion is their fundamental (``fundamental``: the harmonics only place the
samples at their phases); or the ideal sine X0 sin(wt) of Eq. 4.5 on the samples as they are (``sine``, the
thesis' assumption). ``hysid.motion`` decides between the first two from the data."""
OBJECTIVES = ("closed_form", "thesis_port")
"""``closed_form``: the vectorized objective of Eq. 3.3 (:class:`~hysid_model.objective.Objective`);
``thesis_port``: the thesis' own loop-by-loop ``erreval`` (the expensive objective of the benchmarks)."""

Bounds = Mapping[str, tuple[float, float]]


def resolve_weights(loops: LoopSet, weights: str | None) -> str:
    """The loop weights to use: as asked, else ML (1/sigma^2) when every loop's sigma is known, else the thesis'."""
    if weights is None:
        return "ml" if loops.has_sigma else "thesis"
    if weights not in WEIGHTS:
        raise HysidInputError(f"unknown weights; choose one of {', '.join(WEIGHTS)}", param="weights", value=weights)
    return weights


def displaced(loops: LoopSet, displacement: str) -> LoopSet:
    """``loops`` with the displacement the model should see (see :data:`DISPLACEMENTS`)."""
    if displacement not in DISPLACEMENTS:
        raise HysidInputError(f"choose one of {', '.join(DISPLACEMENTS)}", param="displacement", value=displacement)
    if not loops.measured_displacement:
        return loops
    if displacement == "sine":
        return loops.as_ideal_sine()
    return loops if loops.motion == displacement else loops.with_motion(displacement)


def dataset_bounds(loops: LoopSet) -> dict[str, tuple[float, float]]:
    """The bounds a dataset gives: its ``[bounds]``; Table 5.4 for the thesis' own loops."""
    given = loops.meta.get("bounds") or (TABLE_5_4 if loops.meta.get("format") == "thesis-mat" else {})
    return {name: (float(b[0]), float(b[1])) for name, b in given.items()}


def prepare_model(
    loops: LoopSet,
    model: str | Model = "thesis",
    *,
    bounds: Bounds | None = None,
    fixed: Mapping[str, float] | None = None,
    derived: Bounds | None = None,
) -> Model:
    """``model`` ready for ``loops``: the known mass fixed, soft bounds from the data (or ``derived``,
    e.g. a campaign's, as they were: its parameters were searched, so one that is fixed by default, such
    as a freed Bouc-Wen exponent, is searched again), the dataset's and the caller's hard ``bounds``,
    then ``fixed`` values."""
    m = as_model(model)
    bounds, fixed = dict(bounds or {}), dict(fixed or {})
    if derived is not None:
        m = m.vary(*(n for n in derived if n in m.fixed and n not in fixed))
    if loops.meq_kg is not None and "meq" in m.names and "meq" not in bounds and "meq" not in fixed:
        m = m.fix(meq=loops.meq_kg)
    given = dataset_bounds(loops)
    if derived is None:
        scale = survey(loops, m.fixed.get("meq")).scale()
        derived = {name: pair for t in m.terms for name, pair in t.data_bounds(scale).items()}
        derived |= {p.name: (p.lower, p.upper) for p in m.parameters if p.name not in derived}  # a term's default: a guess as well
    soft = {n: b for n, b in derived.items() if n in m.names and n not in given and n not in bounds}
    m = m.with_bounds(soft, soft=True).with_bounds({n: b for n, b in given.items() if n in m.names})
    unseen = {n: 0.0 for n in single_amplitude_slopes(loops, m) if n not in bounds and n not in fixed}
    return m.with_bounds(bounds).vary(*(n for n in bounds if n in m.fixed and n not in fixed)).fix({**unseen, **fixed})


def single_amplitude_slopes(loops: LoopSet, model: Model) -> list[str]:
    """The searched amplitude slopes of ``model`` (S_xi, S_w: terms with ``amplitude_slope``) when ``loops``
    hold a single amplitude level (:func:`~hysid_model.frf.amplitude_levels`), else none."""
    if amplitude_levels(loops.x0)[0].size > 1:
        return []
    return [p.name for t in model.terms if t.slope_of for p in t.params if p.name in model.names]


def starting_point(loops: LoopSet, model: Model) -> np.ndarray:
    """The survey's linear estimate in ``model``'s parameters (Eq. 4.8, 4.9; effects off), inside its bounds."""
    estimate = survey(loops, model.fixed.get("meq")).oscillator()
    values = {p.name: 0.0 if p.lower <= 0.0 <= p.upper else 0.5 * (p.lower + p.upper) for p in model.parameters}
    values.update({k: v for k, v in estimate.items() if k in values and np.isfinite(v)})
    return np.clip(model.from_dict(values), model.bounds[:, 0], model.bounds[:, 1])


def build_objective(
    loops: LoopSet,
    model: str | Model = "thesis",
    weights: str | None = None,
    *,
    bounds: Bounds | None = None,
    fixed: Mapping[str, float] | None = None,
    derived: Bounds | None = None,
    kind: str = "closed_form",
    displacement: str = "measured",
) -> Objective | ThesisObjective:
    """The objective of Eq. 3.3 for ``model`` on ``loops`` (see the module docstring)."""
    loops = displaced(loops, displacement)
    if kind not in OBJECTIVES:
        raise HysidInputError(f"choose one of {', '.join(OBJECTIVES)}", param="objective", value=kind)
    m = prepare_model(loops, model, bounds=bounds, fixed=fixed, derived=derived)
    resolved = resolve_weights(loops, weights)
    if kind == "thesis_port":
        if m.spec != "thesis" or resolved != "thesis" or "meq" not in m.fixed:
            raise HysidInputError(f"{loops.name}: the thesis_port objective is the thesis model with the thesis weights and a known mass")
        return ThesisObjective(loops, m)
    return Objective(loops, m, weights=resolved)
