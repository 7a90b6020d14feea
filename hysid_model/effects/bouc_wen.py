"""The Bouc-Wen hysteretic spring, Eq. 2.1: a force with memory."""

from __future__ import annotations

import numpy as np

from hysid_model.params import Parameter
from hysid_model.terms import Kinematics, ModalState, Term, Values
from hysid_model.timedomain import periodic_steady_state

STEPS_PER_CYCLE = 256
"""RK4 steps per cycle; a multiple of 4 puts the velocity reversals on the grid."""


def _relax(rate: np.ndarray, length: np.ndarray) -> np.ndarray:
    """(1 - exp(-rate length)) / rate, with its limit ``length`` at rate 0."""
    safe = np.where(rate == 0.0, 1.0, rate)
    return np.where(rate == 0.0, length, -np.expm1(-safe * length) / safe)


def _negative_run(rate: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """Displacement over which z climbs from -depth to 0 under dz/dx = 1 - rate z: log(1 + rate depth) / rate."""
    safe = np.where(rate == 0.0, 1.0, rate)
    return np.where(rate == 0.0, depth, np.log1p(safe * depth) / safe)


def loading_state_at_zero(x0: np.ndarray, gamma: np.ndarray, beta: np.ndarray) -> np.ndarray:
    """z at x = 0 on the loading branch of the periodic orbit, exact for n = 1.

    On loading dz/dx = 1 - (gamma + beta) z for z >= 0 and 1 - (gamma - beta) z
    for z < 0, and the orbit is odd: it starts at x = -X0 from z = -z_max and
    ends at X0 in z_max. z_max solves that by bisection (it lies in
    [0, 1 / (gamma + beta)]); the integrator starts from the result.
    """
    a, b = gamma - beta, gamma + beta
    lo = np.zeros(np.broadcast(x0, a, b).shape)
    hi = np.broadcast_to(np.minimum(1.0 / b, 2.0 * x0), lo.shape).copy()
    for _ in range(60):
        z_max = 0.5 * (lo + hi)
        run = _negative_run(a, z_max)
        end = np.where(run < 2.0 * x0, _relax(b, np.maximum(2.0 * x0 - run, 0.0)), -z_max * np.exp(-a * 2.0 * x0) + _relax(a, 2.0 * x0))
        too_high = z_max > end
        hi = np.where(too_high, z_max, hi)
        lo = np.where(too_high, lo, z_max)
    z_max = 0.5 * (lo + hi)
    run = _negative_run(a, z_max)
    return np.where(run < x0, _relax(b, np.maximum(x0 - run, 0.0)), -z_max * np.exp(-a * x0) + _relax(a, x0))


class BoucWen(Term):
    """The hysteretic part of Eq. 2.1: a force k_bw z with z' = A x' - gamma |x'| |z|^(n-1) z - beta x' |z|^n.

    Eq. 2.1b prints the last term as ``a x``; the Bouc-Wen law has A x' (z is a
    'fictitious displacement' driven by the velocity). Since k_bw and A trade
    off (only k_bw A is identifiable) A = 1, and n = 1. The shape is set by
    the yield displacement z_y = 1 / (gamma + beta) (|z| < z_y, the force
    saturates at k_bw z_y) and r = (gamma - beta) / (gamma + beta) in [-1, 1]
    (Fig. 2.6: r > 0 for beta - gamma < 0). The oscillator keeps its linear
    spring, the alpha wn^2 x of Eq. 2.1a; k_bw is the (1 - alpha) wn^2 part times
    the mass. Under x = X0 sin(wt) the state depends on the phase only (the law
    is rate independent); :func:`periodic_steady_state` integrates it from the
    exact n = 1 orbit state at phase 0.
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
        Parameter("bw_k", "N/m", 0.0, 1.0e9, "stiffness of the hysteretic spring ((1 - alpha) k)"),
        Parameter("bw_zy", "m", 1.0e-9, 1.0, "yield displacement 1 / (gamma + beta)"),
        Parameter("bw_r", "1", -1.0, 1.0, "shape (gamma - beta) / (gamma + beta)"),
    )

    def shape_grid(self, kin: Kinematics) -> list[dict[str, float]]:
        """Yield displacements from 3 % to 100 % of the median amplitude, times three shapes."""
        x0 = float(np.median(kin.x0))
        return [{"bw_zy": f * x0, "bw_r": r} for f in (0.03, 0.1, 0.3, 1.0) for r in (-0.5, 0.0, 0.5)]

    def time_force(self, v: Values, state: ModalState, kin: Kinematics, phase: np.ndarray) -> np.ndarray:
        gamma = (1.0 + v["bw_r"]) / (2.0 * v["bw_zy"])
        beta = (1.0 - v["bw_r"]) / (2.0 * v["bw_zy"])
        n_pop = gamma.shape[0]
        if phase.ndim == 2:
            rows, inverse = np.unique(np.column_stack([kin.x0, phase]), axis=0, return_inverse=True)
            x0, out_phase = rows[:, 0], rows[:, 1:]
        else:
            x0, out_phase, inverse = kin.x0, phase, np.arange(kin.x0.size)
        amp = x0[None, :]

        def rhs(theta: float, z: np.ndarray) -> np.ndarray:
            c = np.cos(theta)
            return amp * (c * (1.0 - beta * np.abs(z)) - gamma * abs(c) * z)

        z0 = loading_state_at_zero(amp, gamma, beta)[None]
        z = periodic_steady_state(rhs, z0, out_phase, steps_per_cycle=STEPS_PER_CYCLE, tol=1e-9)[0]
        z = z[:, inverse.reshape(-1)] if phase.ndim == 2 else z
        return v["bw_k"][:, :, None] * np.broadcast_to(z, (n_pop,) + z.shape[1:])
