"""What a result hands its writers: small typed records of what it estimated, defined below both.

A result (:class:`hysid.fit_result.FitResult`, :class:`hysid.diagnosis.result.Diagnosis`) builds the record; the
writers of :mod:`hysid.report` take it (or the result's JSON document, ``to_dict()``) and never import the
result, as pymoo's and lmfit's results hand their reports what they print.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hysid.adequacy import Adequacy
from hysid_model.discovery.proposal import Law
from hysid_model.effective import OperatingPoint
from hysid_model.frf import HalfPower
from hysid_model.loops import LoopSet
from hysid_model.modal import AmplitudeResult
from hysid_model.model import Model
from hysid_model.notices import Notice
from island.run import RunResult


@dataclass(frozen=True)
class Estimates:
    """A model's parameters as estimated, and what follows from them at the loops' amplitudes and frequencies."""

    model: Model
    params: Mapping[str, float]
    """Every searched parameter's value."""
    stderr: Mapping[str, float]
    """Their standard errors (NaN: not determined by the data)."""
    combinations: Mapping[str, tuple[float, float]]
    """The stiffness k = meq w0^2 and damping coefficient c = 2 xi0 meq w0 the data determine best: (value, standard error)."""
    effective: Sequence[OperatingPoint]
    """The whole model's effective stiffness, equivalent damping and energy per cycle at each amplitude and frequency."""
    at_bounds: Sequence[str] = ()
    """The parameters that ended on a bound (a fit's; a diagnosis lists its own in its document)."""
    levels: Sequence[AmplitudeResult] = ()
    """The oscillator's xi, fn, k, c, m at each amplitude level (Table 5.3; a fit's)."""
    half_power: Sequence[HalfPower] = ()
    """The half-power damping at each amplitude level (Eq. 2.7; a fit's)."""


@dataclass(frozen=True)
class FitRecord:
    """What a fit's writers read (its summary, Markdown report and notebook view): built by
    :meth:`hysid.fit_result.FitResult.record`, a campaign's by its fit's."""

    loops: LoopSet
    estimates: Estimates
    theta: np.ndarray
    """The best run's parameter vector."""
    weights: str
    runs: Sequence[RunResult]
    best: int
    """The index of the best run."""
    evaluations: int
    settings: dict[str, Any]
    quality: dict[str, float | None]
    adequacy: Adequacy | None
    displacement_model: dict[str, Any] | None
    not_identifiable: dict[str, str]
    stderr_method: str
    correlation: np.ndarray
    judgments: Sequence[Notice]
    """The fit's own warnings (:func:`hysid.report.text.fit_warnings`)."""
    warnings: list[dict[str, str]]
    """Every warning: those of the data, those raised while fitting, then the judgments."""
    raised: list[dict[str, str]]
    """The warnings raised while fitting."""
    report: str | None


@dataclass(frozen=True)
class FitCurves:
    """What a fit's figures draw beyond its record: the model's force at every sample of every loop, and the force the
    objective fits (both ``(loops, 2 x samples)``)."""

    predicted: np.ndarray
    measured: np.ndarray


@dataclass(frozen=True)
class DiagnosisRecord:
    """What a diagnosis' writers read beyond its JSON document: built by
    :meth:`hysid.diagnosis.result.Diagnosis.record`."""

    estimates: Estimates
    """The final model's."""
    loops: LoopSet
    labels: list[str]
    """What was fitted at the start and after each step (the document's ``gap`` entries, in order)."""
    bic: list[float]
    """The BIC of each of those fits."""
    start: str
    """The model the diagnosis started from, as the user named it."""
    orders: int
    """The highest harmonic order the loops are reduced to."""
    coefficients: int
    """The harmonic coefficients per loop."""
    raised: list[dict[str, str]]
    """The warnings raised while diagnosing."""
    report: str | None
    laws: list[tuple[Law, int]] = field(default_factory=list)
    """The law and number of each force term proposed from the data (the document's ``proposed`` entries, in order)."""


@dataclass(frozen=True)
class DiagnosisCurves:
    """What a diagnosis' figures draw beyond its record: each loop's whitened RMS (1 = noise) and the model's force
    at every sample (``(loops, 2 x samples)``), of the start model and of the final one."""

    start_rms: np.ndarray
    final_rms: np.ndarray
    start_force: np.ndarray
    final_force: np.ndarray
    proposed: list[ProposedForce] = field(default_factory=list)
    """Each force term proposed from the data, as its figure draws it."""


@dataclass(frozen=True)
class ProposedForce:
    """A force term proposed from the data, as its figure draws it: the loops' displacement and velocity at their
    samples, the term's force there and what the final model leaves of the measured force without it (each
    ``(loops, 2 x samples)``)."""

    name: str
    notation: str
    x: np.ndarray
    v: np.ndarray
    force: np.ndarray
    left_over: np.ndarray


@dataclass(frozen=True)
class ReproductionCurves:
    """What the thesis reproduction's figures draw beyond its document: the thesis-faithful runs of each (algorithm,
    noise %), and at each noise % the loops of the first thesis-faithful PSO run with its model's force."""

    runs: dict[tuple[str, int], list[RunResult]]
    loops: dict[int, tuple[LoopSet, np.ndarray]]
