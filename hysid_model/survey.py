"""The equivalent-linear survey: what every loop says by itself, before any model (Figs. 4.6-4.8).

A practitioner's first look at a folder of loops, model-free except for the
mass. From each loop's first harmonics (force F1 against displacement X1, the
complex dynamic stiffness K = F1 / X1, the describing function of the loop; the
force's higher harmonics are fitted alongside so they do not leak into F1,
:func:`hysid_model.frf.force_harmonics`) and its area:

* dynamic stiffness k_dyn = Re(F1 / X1) (N/m), in phase with the displacement;
* equivalent viscous damping c_eq = Im(F1 / X1) / w (N s/m): the dashpot that,
  on the ideal sine, dissipates as much per cycle (E = pi c_eq w X0^2); on a
  distorted displacement it stays the linear damping, while E grows with the
  distortion's harmonics;
* energy dissipated per cycle E = the loop area (J), the closed integral of F dx:
  pi sum_k k Im(F_k conj(X_k)) over the displacement's harmonics (pi X0 a_c for the
  ideal sine; the force's other harmonics do no work);
* secant stiffness k_sec: the slope between the loop's two tips (N/m);
* with the equivalent mass m (known, or estimated from all loops at once from
  Re(F1/X1) = k - m w^2 with one k per amplitude level, as Eq. 4.6 gives):
  the storage stiffness k = k_dyn + m w^2, the loss factor eta = c_eq w / k,
  and each loop's natural frequency fn = sqrt(k / m) / 2 pi and damping ratio
  xi = c_eq / (2 m wn) (Eq. 2.4). Without a mass, eta uses k_dyn and fn, xi are
  unknown: the survey says so instead of guessing.

The same numbers seed and scale the fits: :meth:`Survey.oscillator` gives
xi, wn and their slopes with amplitude (Eq. 4.8, 4.9).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hysid_model.frf import amplitude_levels, force_harmonics
from hysid_model.loops import LoopSet
from hysid_model.terms import DataScale

MASS_SIGNIFICANCE = 3.0
"""An estimated mass counts only when it is this many standard errors above zero."""
SPAN = 1e-3
"""An amplitude level spans frequencies when its w^2 differ by this share of their mean (0.05 % in frequency): the
estimates of one frequency differ by far less, and an inertia read off such a span is noise."""


@dataclass
class Survey:
    """Per-loop equivalent-linear quantities (arrays ``(L,)``) and the mass they rest on."""

    loops: LoopSet
    k_dyn: np.ndarray
    c_eq: np.ndarray
    loss_factor: np.ndarray
    energy_per_cycle: np.ndarray
    k_secant: np.ndarray
    k_storage: np.ndarray
    fn_hz: np.ndarray
    xi: np.ndarray
    meq_kg: float | None
    mass_source: str
    """``known`` (given), ``estimated`` (from Re(F1/X1) = k - m w^2 over all loops) or ``unknown`` (with why)."""

    @property
    def has_mass(self) -> bool:
        return self.meq_kg is not None

    def rows(self) -> list[dict[str, float | None]]:
        """One dict per loop, the survey keys of ``hysid loops --json``."""
        keys = ("k_dyn", "c_eq", "loss_factor", "energy_per_cycle", "k_secant", "fn_hz", "xi")
        return [{k: _finite(getattr(self, k)[j]) for k in keys} for j in range(self.loops.n_loops)]

    def scale(self) -> DataScale:
        """The loops' scale, for data-derived search bounds (:meth:`hysid_model.terms.Term.data_bounds`)."""
        loops = self.loops
        finite = np.isfinite(self.fn_hz) & np.isfinite(self.xi)
        return DataScale(
            stiffness=float(np.median(np.abs(self.k_storage))),
            damping=float(np.median(np.abs(self.c_eq))),
            loss_factor=float(np.median(np.abs(self.loss_factor[np.isfinite(self.loss_factor)]))) if np.any(np.isfinite(self.loss_factor)) else 0.0,
            mass=self.meq_kg,
            wn=float(np.median(2 * np.pi * self.fn_hz[finite])) if np.any(finite) else None,
            xi=float(np.median(self.xi[finite])) if np.any(finite) else None,
            w_min=float(loops.omega.min()),
            w_max=float(loops.omega.max()),
            x_min=float(loops.x0.min()),
            x_max=float(loops.x0.max()),
            force=float(loops.peak_force.max()),
        )

    def oscillator(self) -> dict[str, float]:
        """xi0, S_xi, w0, S_w (Eq. 4.8, 4.9) and meq: a straight line through each amplitude level's wn and
        xi from its median storage stiffness and equivalent damping (constants with one level). Without a
        mass, the one of :attr:`DataScale.mass_scale` (the resonance mid-band) stands in."""
        m = self.meq_kg if self.meq_kg is not None else self.scale().mass_scale
        levels, index = amplitude_levels(self.loops.x0)
        k = np.array([np.median(self.k_storage[index == j]) for j in range(levels.size)])
        c = np.array([np.median(self.c_eq[index == j]) for j in range(levels.size)])
        wn = np.sqrt(np.maximum(k, 1e-12 * np.abs(k).max()) / m)
        (s_w, w0), (s_xi, xi0) = (_line(levels, y) for y in (wn, c / (2.0 * m * wn)))
        return {"xi0": max(xi0, 0.0), "S_xi": s_xi, "w0": w0, "S_w": s_w, "meq": float(m)}


def _finite(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def _line(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """(slope, intercept) of y on x; slope 0 with a single point."""
    if x.size < 2:
        return 0.0, float(y[0])
    slope, intercept = np.polyfit(x, y, 1)
    return float(slope), float(intercept)


def loop_area(loops: LoopSet) -> np.ndarray:
    """Energy dissipated per cycle (J): the loop's area, the closed integral of F dx over the displacement's harmonics."""
    xh = loops.displacement_harmonics()
    k = np.arange(1, xh.shape[1] + 1)
    fk = -1j * force_harmonics(loops, xh.shape[1])  # F = Re sum F_k e^{ik theta}: F_k = a_c - i a_s
    return np.pi * np.sum(k * np.imag(fk * np.conj(xh)), axis=1)


def secant_stiffness(loops: LoopSet) -> np.ndarray:
    """Slope between the loop's tips (N/m): the mean force of both branches at each end of the stroke."""
    f_hi = 0.5 * (loops.top[:, -1, 1] + loops.bottom[:, -1, 1])
    f_lo = 0.5 * (loops.top[:, 0, 1] + loops.bottom[:, 0, 1])
    return (f_hi - f_lo) / (loops.top[:, -1, 0] - loops.top[:, 0, 0])


def inertia(loops: LoopSet, k_dyn: np.ndarray) -> tuple[float, float, np.ndarray] | None:
    """(m, its standard error, each amplitude level's own m) from k_dyn = k_level - m w^2 (one k per amplitude
    level, one m for all), or None where no amplitude level spans frequencies. The standard error grows to the
    levels' disagreement: a frequency dependence that is not inertia (friction, rate effects) makes them differ."""
    levels, index = amplitude_levels(loops.x0)
    w2 = loops.omega**2
    spanning = [k for k in range(levels.size) if np.ptp(w2[index == k]) > SPAN * np.mean(w2[index == k])]
    if not spanning:
        return None
    design = np.column_stack([(index == k).astype(float) for k in range(levels.size)] + [-w2])
    scale = np.abs(design).max(axis=0)
    coef, *_ = np.linalg.lstsq(design / scale, k_dyn, rcond=None)
    coef = coef / scale
    resid = k_dyn - design @ coef
    dof = max(k_dyn.size - design.shape[1], 1)
    cov = np.linalg.pinv(design.T @ design) * float(resid @ resid) / dof
    m, se = float(coef[-1]), float(np.sqrt(max(cov[-1, -1], 0.0)))
    per_level = np.array([-np.polyfit(w2[index == k], k_dyn[index == k], 1)[0] for k in spanning])
    if per_level.size > 1:
        se = max(se, float(np.std(per_level, ddof=1) / np.sqrt(per_level.size)))
    return m, se, per_level


def estimate_mass(loops: LoopSet, k_dyn: np.ndarray) -> tuple[float | None, str]:
    """m of :func:`inertia`, or None and why not: the mass counts when it is ``MASS_SIGNIFICANCE`` standard
    errors above zero and every amplitude level that spans frequencies sees a positive one."""
    found = inertia(loops, k_dyn)
    if found is None:
        return None, "unknown: every amplitude has a single frequency, so stiffness and inertia cannot be told apart"
    m, se, per_level = found
    if not (m > MASS_SIGNIFICANCE * se and np.all(per_level > 0)):
        estimates = ", ".join(f"{v:.3g}" for v in per_level)
        return None, f"unknown: the loops do not show a consistent inertia (estimate {m:.3g} +- {se:.2g} kg; per amplitude {estimates} kg)"
    return m, "estimated"


def dynamic_stiffness(loops: LoopSet) -> np.ndarray:
    """Each loop's complex dynamic stiffness K = F1 / X1 (N/m), ``(L,)``: Re K = k - m w^2, Im K = c_eq w."""
    return -1j * force_harmonics(loops, 1)[:, 0] / loops.displacement_harmonics()[:, 0]


def survey(loops: LoopSet, meq_kg: float | None = None) -> Survey:
    """The survey of ``loops``; the mass is ``meq_kg``, else the loop set's, else estimated (see the module docstring)."""
    w = loops.omega
    dynamic = dynamic_stiffness(loops)
    k_dyn, c_eq = dynamic.real, dynamic.imag / w
    energy = loop_area(loops)
    mass = meq_kg if meq_kg is not None else loops.meq_kg
    source = "known"
    if mass is None:
        mass, source = estimate_mass(loops, k_dyn)
    nan = np.full(loops.n_loops, np.nan)
    if mass is None:
        k_storage, fn, xi = k_dyn, nan, nan
    else:
        k_storage = k_dyn + mass * w**2
        with np.errstate(invalid="ignore", divide="ignore"):
            wn = np.where(k_storage > 0, np.sqrt(np.maximum(k_storage, 0.0) / mass), np.nan)
            fn, xi = wn / (2 * np.pi), c_eq / (2 * mass * wn)
    with np.errstate(invalid="ignore", divide="ignore"):
        loss = c_eq * w / k_storage
    return Survey(
        loops=loops,
        k_dyn=k_dyn,
        c_eq=c_eq,
        loss_factor=loss,
        energy_per_cycle=energy,
        k_secant=secant_stiffness(loops),
        k_storage=k_storage,
        fn_hz=fn,
        xi=xi,
        meq_kg=mass,
        mass_source=source,
    )
