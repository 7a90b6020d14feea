"""How large the gap between model and data is, in four currencies.

* whitened RMS: sqrt(chi^2 / dof) on the harmonic coefficients, 1 = noise floor;
* loop NRMSE: RMS force error over both branches / peak-to-peak force, in %,
  averaged over the loops;
* energy error: the energy dissipated per cycle is the loop area pi X0 c1;
  relative RMS error of the model's area over all loops, in %;
* leave-one-frequency-out cross-validation: refit without all loops at one
  frequency, predict them; the whitened RMS of those predictions over every
  frequency in turn (the error the model makes where it was not fitted).

A physical model rarely reaches the noise floor of a real specimen, so the
gap is also held against two references that need no physical model
(:func:`references`): what an independent linear fit per loop reaches (each
loop's own offset and first harmonic: only the loop's distortion is left),
and the scatter between repeated tests at the same frequency and amplitude,
where a dataset has them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hysid.harmonic_fits import Fit
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
        return {
            "model": self.spec,
            "whitened_rms": self.whitened_rms,
            "loop_nrmse_pct": self.nrmse_pct,
            "energy_error_pct": self.energy_error_pct,
            "cv_whitened_rms": self.cv_whitened_rms,
        }


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


SAME_AMPLITUDE = 0.02
"""Repeated tests: loops at the same frequency (within 0.1 %) and amplitude (within this)."""


@dataclass
class References:
    """Whitened RMS levels a model of these loops can be held against (1 is the noise floor)."""

    linear_per_loop: float
    """Each loop fitted on its own by an offset and a linear spring, dashpot and mass (:func:`linear_per_loop`):
    what no equivalent-linear description beats."""
    repeatability: float | None
    """The scatter between repeated tests at one setting (None: the dataset has no repeats)."""
    repeats: int
    """Loops that have a repeat."""

    def reached(self, whitened_rms: float, adequate: bool) -> str:
        """The lowest reference ``whitened_rms`` reaches: noise floor, repeatability, linear per loop, or none."""
        if adequate:
            return "noise floor"
        if self.repeatability is not None and whitened_rms <= REACHED * self.repeatability:
            return "repeatability"
        if whitened_rms <= REACHED * self.linear_per_loop:
            return "linear per loop"
        return "none"

    def as_dict(self) -> dict[str, Any]:
        return {"noise_floor": 1.0, "linear_per_loop": self.linear_per_loop, "repeatability": self.repeatability, "repeated_loops": self.repeats}


REACHED = 1.1
"""A model reaches a reference when its whitened RMS is within 10 % of it."""


def repeat_groups(harmonics: Harmonics) -> list[np.ndarray]:
    """Loop indices of repeated tests: same frequency and amplitude, two loops or more."""
    out = []
    for group in frequency_groups(harmonics):
        x0 = harmonics.loops.x0[group]
        keys = np.round(np.log(x0) / np.log1p(SAME_AMPLITUDE)).astype(int)
        out += [group[keys == k] for k in np.unique(keys) if np.count_nonzero(keys == k) > 1]
    return out


def references(harmonics: Harmonics) -> References:
    """The model-free references of :class:`References` on the whitened harmonic coefficients."""
    white = harmonics.whiten(harmonics.loops.forces())
    linear = linear_per_loop(harmonics, white)
    groups = repeat_groups(harmonics)
    if not groups:
        return References(linear, None, 0)
    spread = sum(float(np.sum((white[g] - white[g].mean(axis=0)) ** 2)) for g in groups)
    dof = sum((g.size - 1) * white.shape[1] for g in groups)
    # the scatter of a loop about the mean of n repeats is (n-1)/n of its own: dof counts that
    return References(linear, float(np.sqrt(spread / dof)), int(sum(g.size for g in groups)))


def linear_per_loop(harmonics: Harmonics, white: np.ndarray) -> float:
    """Whitened RMS of each loop fitted on its own by an offset and a linear spring, dashpot and mass
    (:func:`linear_per_loop_residual`)."""
    residual, used = linear_per_loop_residual(harmonics, white)
    return float(np.sqrt(np.sum(residual**2) / max(residual.size - used, 1)))


def linear_per_loop_residual(harmonics: Harmonics, white: np.ndarray) -> tuple[np.ndarray, int]:
    """What each loop fitted on its own by an offset and a linear spring, dashpot and mass leaves, ``(L, M)``, and
    the parameters that fit used (their rank, summed over the loops): F = a0 + k x + c dx/dt + m d^2x/dt^2 on its
    measured displacement (on the ideal sine k and m are one stiffness k - m w^2). In whitened coordinates a
    coefficient vector a maps to R a / sigma (Phi = Q R, :class:`hysid_model.harmonics.Harmonics`), so the
    residual is ``white`` less its projection there."""
    names, loops = harmonics.names, harmonics.loops
    xh = loops.displacement_harmonics()
    out, used = np.empty_like(white), 0
    for j in range(loops.n_loops):
        order = np.arange(1, xh.shape[1] + 1)
        columns = []
        for factor in (np.ones(order.size), 1j * order * loops.omega[j], -((order * loops.omega[j]) ** 2)):
            a = np.zeros(len(names))
            for k, value in zip(order, factor * xh[j]):  # x = Re sum X_k e^{ik wt}: s_k = -Im X_k, c_k = Re X_k
                if f"s{k}" in names:
                    a[names.index(f"s{k}")], a[names.index(f"c{k}")] = -value.imag, value.real
            columns.append(a)
        dc = np.zeros(len(names))
        dc[names.index("dc")] = 1.0
        basis = harmonics.r[j] @ np.column_stack([dc, *columns]) / harmonics.sigma[j]
        coef, _, rank, _ = np.linalg.lstsq(basis, white[j], rcond=None)
        out[j] = white[j] - basis @ coef
        used += int(rank)
    return out, used


def frequency_groups(harmonics: Harmonics) -> list[np.ndarray]:
    """Loop indices per distinct frequency (within 0.1 %)."""
    freq = harmonics.loops.freq_hz
    keys = np.round(np.log(freq) / np.log1p(1e-3)).astype(int)
    return [np.flatnonzero(keys == k) for k in np.unique(keys)]


def cross_validated_rms(fit: Fit, harmonics: Harmonics) -> float | None:
    """Leave-one-frequency-out whitened RMS of the held-out predictions, or None with under 3 frequencies
    (computed once per fit: the acceptance rules and the gap table both ask)."""
    if "rms" not in fit.held_out:
        fit.held_out["rms"] = _cross_validated_rms(fit, harmonics)
    return fit.held_out["rms"]


def _cross_validated_rms(fit: Fit, harmonics: Harmonics) -> float | None:
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
