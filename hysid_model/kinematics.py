"""What the prescribed motion of each loop gives a model's terms (:class:`Kinematics`).

A loop set (:meth:`hysid_model.loops.LoopSet.kinematics`) drives every term of a model
(:mod:`hysid_model.terms`) by the same motion: the thesis' ideal sine x = X0 sin(wt)
(Eq. 4.5) or, where measured, the displacement's harmonics (:mod:`hysid_model.waveform`).
Both the loops and the terms need it, so it lives below them.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from hysid_model import waveform

REVERSAL_TIE = 1e-9
"""A sample where |x'| (d x / d(wt)) is below this times X0 is at a reversal: its branch, not the sign of its
rounding-sized velocity, says whether it is loading (the first ``n_top`` samples of a loop) or unloading."""
CREEP = 1e-16
"""The least speed of a sample of a branch, as a share of the loop's velocity amplitude w X0 (:meth:`Kinematics.velocity`):
the size rounding gives a reversal's own velocity, so that a law's continuous part sees there what it saw before
(not smaller: a law |v|^a that a fit takes to a < 0 would blow up)."""


@dataclass(frozen=True)
class Kinematics:
    """What the prescribed motion of each loop gives a term: its fundamental amplitude X0, its
    frequency w and, where measured, its displacement harmonics (:mod:`hysid_model.waveform`).

    ``xh`` None is the thesis' x = X0 sin(wt) (Eq. 4.5).
    """

    x0: np.ndarray
    omega: np.ndarray
    xh: np.ndarray | None = None

    @property
    def harmonics(self) -> np.ndarray:
        """``(L, K)`` complex displacement harmonics (K = 1 for the ideal sine)."""
        return waveform.ideal(self.x0) if self.xh is None else self.xh

    def velocity(self, phase: np.ndarray, n_top: int | None = None) -> np.ndarray:
        """Velocity (m/s) at phases ``(L, N)`` or ``(P, L, N)``. Where ``n_top`` is given the phases are samples of
        each loop's branches, the first ``n_top`` loading: each moves in its branch's direction, at least at
        :data:`CREEP` w X0, so that a law that jumps at v = 0 (a friction's sgn v) takes its branch's side at a
        reversal as the extraction's one-sided fits there do (:mod:`hysid_model.resolution`), though the loading
        and the unloading sample at x_max share one phase, and though a reading of the displacement (its
        fundamental) may place a sample next to a reversal a hair past it."""
        v = self.omega[:, None] * self.displacement(phase, 1)
        if n_top is None:
            return v
        branch = np.where(np.arange(phase.shape[-1]) < n_top, 1.0, -1.0)
        return branch * np.maximum(np.abs(v), CREEP * (self.omega * self.x0)[:, None])

    @cached_property
    def orders(self) -> np.ndarray:
        """Harmonic orders k = 1..K of the displacement."""
        return np.arange(1, 1 + (1 if self.xh is None else self.xh.shape[1]))

    @cached_property
    def order_parts(self) -> tuple[list[tuple[str, str]], np.ndarray, np.ndarray]:
        """Per harmonic order the coefficient names (s_k, c_k), and the displacement harmonics' real and imaginary
        parts ``(K, 1, L)`` each (measured displacement only: :func:`linear_response`)."""
        assert self.xh is not None
        return [(f"s{k}", f"c{k}") for k in self.orders], self.xh.real.T[:, None, :].copy(), self.xh.imag.T[:, None, :].copy()

    def displacement(self, phase: np.ndarray, derivative: int = 0) -> np.ndarray:
        """d^n x / d(wt)^n at phases ``(L, N)`` or ``(P, L, N)``."""
        if self.xh is None:
            x0 = self.x0[:, None]
            return x0 * (np.sin(phase), np.cos(phase), -np.sin(phase))[derivative]
        return waveform.displacement(self.xh, phase, derivative)

    @cached_property
    def extremes(self) -> tuple[np.ndarray, np.ndarray]:
        """(x_min, x_max) of each loop's displacement, ``(L,)`` each."""
        return (-self.x0, self.x0) if self.xh is None else waveform.extremes(self.xh)

    @cached_property
    def reversals(self) -> tuple[np.ndarray, np.ndarray]:
        """Phases (theta_lo, theta_hi) of each loop's displacement minimum and maximum, ``(L,)`` each."""
        if self.xh is None:
            return np.full(self.x0.size, -0.5 * np.pi), np.full(self.x0.size, 0.5 * np.pi)
        return waveform.reversals(self.xh)

    def power_harmonics(self, power: int) -> np.ndarray:
        """Complex amplitudes of x^power at orders 1..power*K, ``(L, power*K)`` (x^power = sum Re[A_k e^{ik wt}] + mean)."""
        xh = self.harmonics
        top = power * xh.shape[1]
        samples = 2 * top + 2
        theta = np.broadcast_to(np.arange(samples) * (2 * np.pi / samples), (xh.shape[0], samples))
        spectrum = np.fft.rfft(waveform.displacement(xh, theta) ** power, axis=1) * (2.0 / samples)
        return spectrum[:, 1 : top + 1]
