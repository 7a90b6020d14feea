"""What a result hands its writers: small typed records of what it estimated, defined below both.

A result (:class:`hysid.fitting.FitResult`, :class:`hysid.diagnosis.result.Diagnosis`) builds the record; the
writers of :mod:`hysid.report` take it (or the result's JSON document, ``to_dict()``) and never import the
result, as pymoo's and lmfit's results hand their reports what they print.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from hysid.adequacy import Adequacy
from hysid_model.effective import OperatingPoint
from hysid_model.frf import HalfPower
from hysid_model.modal import AmplitudeResult
from hysid_model.loops import LoopSet
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
    :meth:`hysid.fitting.FitResult.record`, a campaign's by its fit's."""

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
