"""The Bouc-Wen hysteretic spring, Eq. 2.1: a force with memory."""

from __future__ import annotations

import math

import numpy as np

from hysid_model.params import Parameter
from hysid_model.terms import DataScale, Kinematics, ModalState, Term, Values

BISECTIONS = 60
"""Bisection steps for the orbit's peak state (to double precision)."""
MEAN_SAMPLES = 512
"""Phases per cycle over which the orbit's mean is taken under a measured displacement."""


def _relax(rate: np.ndarray, length: np.ndarray) -> np.ndarray:
    """(1 - exp(-rate length)) / rate: z after ``length`` of travel from 0 under dz/dx = 1 - rate z (limit: length)."""
    safe = np.where(rate == 0.0, 1.0, rate)
    return np.where(rate == 0.0, length, -np.expm1(-safe * length) / safe)


def _negative_run(rate: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """Travel over which z climbs from -depth to 0 under dz/dx = 1 - rate z: log(1 + rate depth) / rate."""
    safe = np.where(rate == 0.0, 1.0, rate)
    return np.where(rate == 0.0, depth, np.log1p(safe * depth) / safe)


def _loading(travel: np.ndarray, z_max: np.ndarray, run: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """z on the loading branch after ``travel`` = x + X0 from the reversal at -X0, where z = -z_max.

    Both pieces are computed everywhere; the one not taken may overflow (e.g.
    exp(-a travel) for a < 0 far beyond the zero crossing): callers ignore
    floating-point warnings.
    """
    climbing = -z_max * np.exp(-a * travel) + _relax(a, travel)
    return np.where(travel < run, climbing, _relax(b, np.maximum(travel - run, 0.0)))


def loading_orbit(x0: np.ndarray, gamma: np.ndarray, beta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Peak state z_max of the periodic orbit under x = X0 sin(wt), n = 1, and the travel at which z crosses 0.

    On loading (x' > 0) Eq. 2.1b with A = 1, n = 1 reads dz/dx = 1 - b z with
    b = gamma + beta for z >= 0 and 1 - a z with a = gamma - beta for z < 0; the
    orbit is odd, so loading runs from z = -z_max at x = -X0 to z_max at X0.
    z climbs to 0 over run = log(1 + a z_max) / a and then relaxes towards 1/b,
    so z_max solves 1 - b z_max = exp(b run - 2 b X0); the left side minus the
    right falls monotonically from 1 - exp(-2 b X0) > 0 at 0 to below 0 at 1/b,
    and bisection finds the root.
    """
    a, b = gamma - beta, gamma + beta
    lo = np.zeros(np.broadcast(x0, a, b).shape)
    hi = np.broadcast_to(1.0 / b, lo.shape).copy()
    with np.errstate(all="ignore"):
        for _ in range(BISECTIONS):
            z_max = 0.5 * (lo + hi)
            above = 1.0 - b * z_max < np.exp(b * _negative_run(a, z_max) - 2.0 * b * x0)
            hi = np.where(above, z_max, hi)
            lo = np.where(above, lo, z_max)
        z_max = 0.5 * (lo + hi)
        return z_max, _negative_run(a, z_max)


class BoucWen(Term):
    """The hysteretic part of Eq. 2.1: a force k_bw z with z' = A x' - gamma |x'| |z|^(n-1) z - beta x' |z|^n.

    Eq. 2.1b prints the last term as ``a x``; the Bouc-Wen law has A x' (z is a
    'fictitious displacement' driven by the velocity). Since k_bw and A trade
    off (only k_bw A is identifiable) A = 1, and n = 1. The shape is set by
    the yield displacement z_y = 1 / (gamma + beta) (|z| < z_y, the force
    saturates at k_bw z_y) and r = (gamma - beta) / (gamma + beta): Fig. 2.6
    (a) is r > 0, (b) r = 0, (c) -1 < r < 0; r > 1 means beta < 0. At r = -1
    (gamma = 0) the law loses its hysteresis (dz/dx is the same both ways) and
    the orbit is ill-posed, so r >= -0.9. The oscillator keeps its linear
    spring, the alpha wn^2 x of Eq. 2.1a; k_bw is the (1 - alpha) wn^2 part times
    the mass.

    The law is rate independent, so under x = X0 sin(wt) the state is a
    function of the phase only, and for n = 1 its periodic orbit is piecewise
    exponential in x (:func:`loading_orbit`): the steady state is evaluated
    exactly; the tests integrate Eq. 2.1b over cycles to the same orbit.
    """

    id = "bouc_wen"
    memory = True
    strength = "bw_k"
    explanation = (
        "A Bouc-Wen hysteretic spring (Eq. 2.1): a force k z whose internal displacement z follows the "
        "motion with memory and saturates at the yield displacement z_y, giving smooth, rate-independent "
        "loops between a spring (z_y >> X0) and dry friction (z_y << X0)."
    )
    params = (
        Parameter("bw_k", "N/m", 0.0, 1.0e9, "stiffness of the hysteretic spring ((1 - alpha) k)", physical=(0.0, math.inf)),
        Parameter("bw_zy", "m", 1.0e-9, 1.0, "yield displacement 1 / (gamma + beta)", physical=(0.0, math.inf)),
        Parameter("bw_r", "1", -0.9, 3.0, "shape (gamma - beta) / (gamma + beta)", physical=(-0.9, math.inf)),
    )

    def data_bounds(self, scale: DataScale) -> dict[str, tuple[float, float]]:
        """Hysteretic stiffness up to 10 x the survey's, yield from 1/1000 of the smallest to 10 x the largest amplitude."""
        return {"bw_k": (0.0, 10.0 * scale.stiffness), "bw_zy": (1e-3 * scale.x_min, 10.0 * scale.x_max)}

    def shape_grid(self, kin: Kinematics) -> list[dict[str, float]]:
        """Yield displacements from 3 % to 100 % of the median amplitude, times three shapes r."""
        x0 = float(np.median(kin.x0))
        return [{"bw_zy": f * x0, "bw_r": r} for f in (0.03, 0.1, 0.3, 1.0) for r in (-0.5, 0.5, 2.0)]

    def time_force(self, v: Values, state: ModalState, kin: Kinematics, phase: np.ndarray) -> np.ndarray:
        """k_bw z on the periodic orbit; being rate independent, z depends only on the travel since the
        last reversal, so the orbit of a sine with the same extremes holds for any measured displacement
        whose branches are monotonic."""
        gamma = (1.0 + v["bw_r"]) / (2.0 * v["bw_zy"])
        beta = (1.0 - v["bw_r"]) / (2.0 * v["bw_zy"])
        x_min, x_max = kin.extremes
        half_span = 0.5 * (x_max - x_min)
        spans, which = np.unique(half_span, return_inverse=True)
        z_max, run = (a[:, which.reshape(-1)] for a in loading_orbit(spans[None, :], gamma, beta))
        a, b = (gamma - beta)[:, :, None], (gamma + beta)[:, :, None]
        z_max, run = z_max[:, :, None], run[:, :, None]
        def z(phase: np.ndarray) -> np.ndarray:
            x = kin.displacement(phase)
            loading = kin.displacement(phase, 1) >= 0.0
            with np.errstate(all="ignore"):
                up = _loading(x - x_min[:, None], z_max, run, a, b)
                down = -_loading(x_max[:, None] - x, z_max, run, a, b)
            return np.where(loading, up, down)

        state_z = z(phase)
        if kin.xh is not None:  # the orbit of an asymmetric waveform has a mean: removed, as from the loops
            grid = np.broadcast_to(np.linspace(0.0, 2 * np.pi, MEAN_SAMPLES, endpoint=False), (kin.x0.size, MEAN_SAMPLES))
            state_z = state_z - z(grid).mean(axis=-1, keepdims=True)
        return v["bw_k"][:, :, None] * state_z
