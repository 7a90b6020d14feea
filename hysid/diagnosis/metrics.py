"""How large the gap between model and data is, in four currencies.

* whitened RMS: sqrt(chi^2 / dof) on the harmonic coefficients, 1 = noise floor;
* loop NRMSE: RMS force error over both branches / peak-to-peak force, in %,
  averaged over the loops;
* energy error: the energy dissipated per cycle is the loop area pi X0 c1;
  relative RMS error of the model's area over all loops, in %;
* leave-one-frequency-out cross-validation: refit without all loops at one
  frequency, predict them; the whitened RMS of those predictions over every
  frequency in turn (the error the model makes where it was not fitted).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hysid.diagnosis.fitting import Fit
from hysid_model.harmonics import HarmonicObjective, Harmonics
from island.polish import polish

CV_NFEV = 50
"""Residual evaluations for each cross-validation refit (it starts at the full fit)."""


@dataclass
class GapMetrics:
    """The gap of one model to the data, in the four currencies of the module docstring."""

    spec: str
    whitened_rms: float
    nrmse_pct: float
    energy_error_pct: float
    cv_whitened_rms: float | None

    def as_dict(self) -> dict[str, Any]:
        return {"model": self.spec, "whitened_rms": self.whitened_rms, "loop_nrmse_pct": self.nrmse_pct,
                "energy_error_pct": self.energy_error_pct, "cv_whitened_rms": self.cv_whitened_rms}


def nrmse_pct(fit: Fit) -> np.ndarray:
    """Per loop: RMS force error / peak-to-peak force, in %."""
    residual = fit.objective.objective.residuals(fit.theta)
    forces = fit.objective.objective.y
    return 100.0 * np.sqrt(np.mean(residual**2, axis=1)) / (forces.max(axis=1) - forces.min(axis=1))


def energy_error_pct(fit: Fit, harmonics: Harmonics) -> float:
    """Relative RMS error of the energy dissipated per cycle over all loops, in %."""
    model = harmonics.energy_per_cycle(harmonics.project(fit.objective.objective.predict(fit.theta)[0]))
    data = harmonics.energy_per_cycle(harmonics.coef)
    return float(100.0 * np.sqrt(np.sum((model - data) ** 2) / np.sum(data**2)))


def frequency_groups(harmonics: Harmonics) -> list[np.ndarray]:
    """Loop indices per distinct frequency (within 0.1 %)."""
    freq = harmonics.loops.freq_hz
    keys = np.round(np.log(freq) / np.log1p(1e-3)).astype(int)
    return [np.flatnonzero(keys == k) for k in np.unique(keys)]


def cross_validated_rms(fit: Fit, harmonics: Harmonics) -> float | None:
    """Leave-one-frequency-out whitened RMS of the held-out predictions, or None with under 3 frequencies."""
    groups = frequency_groups(harmonics)
    if len(groups) < 3:
        return None
    chi2, count = 0.0, 0
    for held in groups:
        train = np.setdiff1d(np.arange(harmonics.loops.n_loops), held)
        theta = polish(HarmonicObjective(harmonics.subset(train), fit.model), fit.theta, max_nfev=CV_NFEV).theta
        residual = HarmonicObjective(harmonics.subset(held), fit.model).whitened(theta)
        chi2 += float(np.sum(residual**2))
        count += residual.size
    return float(np.sqrt(chi2 / count))


def gap_metrics(fit: Fit, harmonics: Harmonics, cross_validate: bool = True) -> GapMetrics:
    return GapMetrics(
        spec=fit.spec,
        whitened_rms=fit.whitened_rms,
        nrmse_pct=float(np.mean(nrmse_pct(fit))),
        energy_error_pct=energy_error_pct(fit, harmonics),
        cv_whitened_rms=cross_validated_rms(fit, harmonics) if cross_validate else None,
    )


def loop_whitened_rms(fit: Fit, harmonics: Harmonics) -> np.ndarray:
    """Per loop: RMS of its whitened harmonic residuals (1 = noise), for the residual maps."""
    return np.sqrt(np.mean(fit.residual.reshape(harmonics.loops.n_loops, -1) ** 2, axis=1))
