"""What a result hands its writers: small typed records of what it estimated, defined below both.

A result (:class:`hysid.fitting.FitResult`, :class:`hysid.diagnosis.result.Diagnosis`) builds the record; the
writers of :mod:`hysid.report` take it (or the result's JSON document, ``to_dict()``) and never import the
result, as pymoo's and lmfit's results hand their reports what they print.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from hysid_model.effective import OperatingPoint
from hysid_model.frf import HalfPower
from hysid_model.modal import AmplitudeResult
from hysid_model.model import Model


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
