"""Test reference: periodic steady states of terms with memory by time integration.

The library evaluates memory terms from exact orbits (e.g. Bouc-Wen with
n = 1); the tests check those against this brute-force integration.

Memoryless terms have a closed-form steady state under x = X0 sin(wt)
(Eq. 4.5, 4.6, 4.10). A term with internal state z (e.g. the Bouc-Wen model
of section 2.1) obeys dz/dt = g(t, z) instead; written in the phase
theta = wt it is dz/dtheta = g / w, driven with period 2 pi. Its steady-state
force on the branch samples is z on the periodic orbit, which
:func:`periodic_steady_state` finds by integrating whole cycles with fixed-step
RK4 until the state at theta = 0 repeats, vectorized over any batch (e.g.
candidates x loops).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

TWO_PI = 2.0 * np.pi

Rhs = Callable[[float, np.ndarray], np.ndarray]


class SteadyStateError(RuntimeError):
    """The integration did not settle on a periodic orbit within the allowed cycles."""


def _rk4_cycle(rhs: Rhs, z: np.ndarray, k1: np.ndarray, steps: int, record: Callable | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Integrate one cycle theta = 0..2 pi in ``steps`` RK4 steps.

    ``k1`` is rhs(0, z). Returns the final state, rhs there (the next cycle's
    k1, rhs being 2 pi-periodic) and the largest |z| met on the grid.
    ``record(j, z_j, f_j, z_j+1, f_j+1)`` is called for every step if given.
    """
    h = TWO_PI / steps
    amplitude = np.abs(z)
    for j in range(steps):
        theta = TWO_PI * j / steps
        k2 = rhs(theta + 0.5 * h, z + (0.5 * h) * k1)
        k3 = rhs(theta + 0.5 * h, z + (0.5 * h) * k2)
        k4 = rhs(theta + h, z + h * k3)
        z_next = z + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        k1_next = rhs(TWO_PI * (j + 1) / steps, z_next)
        if record is not None:
            record(j, z, k1, z_next, k1_next)
        np.maximum(amplitude, np.abs(z_next), out=amplitude)
        z, k1 = z_next, k1_next
    return z, k1, amplitude


def _hermite_recorder(phase: np.ndarray, steps: int, out: np.ndarray) -> Callable:
    """A ``record`` callback that fills ``out`` (S, N*K) with the cubic Hermite
    interpolant of the RK4 grid at ``phase`` (N*K phases in [0, 2 pi), sample k
    of batch element n at flat position n*K + k)."""
    h = TWO_PI / steps
    k_count = phase.shape[-1]
    flat = phase.reshape(-1)
    u = flat / h
    step = np.clip(np.floor(u).astype(np.int64), 0, steps - 1)
    u = u - step
    order = np.argsort(step, kind="stable")
    bounds = np.searchsorted(step[order], np.arange(steps + 1))
    u = u[order]
    h00 = (1.0 + 2.0 * u) * (1.0 - u) ** 2
    h10 = h * u * (1.0 - u) ** 2
    h01 = u**2 * (3.0 - 2.0 * u)
    h11 = -h * u**2 * (1.0 - u)
    element = order // k_count

    def record(j: int, z0: np.ndarray, f0: np.ndarray, z1: np.ndarray, f1: np.ndarray) -> None:
        seg = slice(bounds[j], bounds[j + 1])
        if seg.start == seg.stop:
            return
        n = element[seg]
        s0, d0, s1, d1 = (a.reshape(a.shape[0], -1)[:, n] for a in (z0, f0, z1, f1))
        out[:, order[seg]] = h00[seg] * s0 + h10[seg] * d0 + h01[seg] * s1 + h11[seg] * d1

    return record


def periodic_steady_state(
    rhs: Rhs,
    z0: np.ndarray,
    phase_out: np.ndarray,
    *,
    steps_per_cycle: int = 1024,
    max_cycles: int = 400,
    tol: float = 1e-10,
) -> np.ndarray:
    """Integrate dz/dtheta = rhs(theta, z) over whole cycles of the phase theta = w t, z of shape
    (S, *batch) (S state components; batch e.g. (P, L)), with fixed-step RK4, until the state at
    theta = 0 (mod 2 pi) repeats within tol (relative), and return z over the final cycle at
    phase_out (broadcastable to batch + (K,), any phases, taken mod 2 pi) as an array
    (S, *batch, K) by cubic Hermite interpolation of the RK4 grid.

    ``rhs`` must be 2 pi-periodic in theta and return an array shaped like z.
    "Repeats within tol" is checked per state component and batch element,
    |z(2 pi m) - z(2 pi (m-1))| <= tol * max |z| over that cycle; the returned
    cycle is the one after the first that passes. Batch elements whose state
    turns non-finite (e.g. a candidate with absurd parameters) stop counting
    and come back as NaN, so that they cannot stall a whole population.

    Raises :class:`SteadyStateError` if some element still changes after
    ``max_cycles`` cycles.
    """
    if steps_per_cycle < 2 or max_cycles < 1 or not tol > 0:
        raise ValueError("periodic_steady_state needs steps_per_cycle >= 2, max_cycles >= 1 and tol > 0")
    z = np.array(z0, dtype=float)
    if z.ndim < 1:
        raise ValueError("z0 must have shape (S, *batch)")
    batch = z.shape[1:]
    phase = np.asarray(phase_out, dtype=float)
    if phase.ndim < 1:
        raise ValueError("phase_out must end in the axis of output phases (K,)")
    phase = np.mod(np.broadcast_to(phase, batch + phase.shape[-1:]), TWO_PI)
    k1 = np.asarray(rhs(0.0, z), dtype=float)
    if k1.shape != z.shape:
        raise ValueError(f"rhs returned shape {k1.shape} for a state of shape {z.shape}")
    with np.errstate(all="ignore"):
        for _cycle in range(1, max_cycles + 1):
            start = z
            z, k1, amplitude = _rk4_cycle(rhs, z, k1, steps_per_cycle)
            change = np.abs(z - start)
            settled = (change <= tol * amplitude) | ~np.isfinite(change)
            if np.all(settled):
                break
        else:
            worst = np.max((change / amplitude)[~settled])
            raise SteadyStateError(
                f"no periodic steady state after {max_cycles} cycles: the state at phase 0 still changes by "
                f"{worst:.3g} of its amplitude per cycle (tol {tol:g}) in {int(np.sum(~settled))} of {settled.size} "
                "state values; raise max_cycles or check the term's damping"
            )
        out = np.full((z.shape[0], phase.size), np.nan)
        _rk4_cycle(rhs, z, k1, steps_per_cycle, _hermite_recorder(phase, steps_per_cycle, out))
    return out.reshape(z.shape + phase.shape[-1:])


def affine_periodic_start(rhs: Rhs, shape: tuple[int, ...], steps_per_cycle: int) -> np.ndarray:
    """The periodic state at theta = 0 of a one-component affine law dz/dtheta = a(theta) z + b(theta) (a linear filter
    driven by the motion), by shooting: a cycle of RK4 maps z0 to A z0 + B, two cycles (from 0 and from 1) give A and
    B, and the fixed point B / (1 - A) is the orbit of the same grid. A start for :func:`periodic_steady_state`, which
    then still checks that the state repeats, instead of waiting out ~1 / (2 pi rho) cycles of decay per e-fold."""
    zero, one = np.zeros(shape), np.ones(shape)
    b = _rk4_cycle(rhs, zero, np.asarray(rhs(0.0, zero), dtype=float), steps_per_cycle)[0]
    a = _rk4_cycle(rhs, one, np.asarray(rhs(0.0, one), dtype=float), steps_per_cycle)[0] - b
    return b / (1.0 - a)


ScalarRhs = Callable[[float, float], float]


def _half_period(rhs: ScalarRhs, theta0: float, z0: float, rtol: float, atol: float) -> list:
    """Dense solutions of dz/dtheta = rhs over [theta0, theta0 + pi] from z0, restarted at every zero of z
    (where a law like |z|^n is not smooth) so that no step straddles one."""
    from scipy.integrate import solve_ivp

    def crossing(theta: float, z: np.ndarray) -> float:
        return z[0]

    crossing.terminal = True
    pieces, start, z = [], theta0, z0
    while True:
        with np.errstate(all="ignore"):  # a rejected trial step may overflow
            sol = solve_ivp(
                lambda t, y: [rhs(t, y[0])],
                (start, theta0 + np.pi),
                [z],
                method="DOP853",
                rtol=rtol,
                atol=atol,
                dense_output=True,
                events=crossing if z != 0.0 else None,
            )
        pieces.append((start, sol.t[-1], sol.sol))
        if sol.status != 1:
            return pieces
        start, z = float(sol.t_events[0][0]), 0.0
        if start >= theta0 + np.pi:
            return pieces


def odd_periodic_orbit(
    rhs: ScalarRhs, theta0: float, bracket: tuple[float, float], phase_out: np.ndarray, *, rtol: float = 1e-12, atol: float = 1e-15
) -> np.ndarray:
    """The periodic orbit of a scalar dz/dtheta = rhs(theta, z) that is odd, rhs(theta + pi, -z) = -rhs(theta, z)
    (e.g. a rate-independent law driven by x = X0 sin(theta)), so that z(theta + pi) = -z(theta): its state z0 at
    ``theta0`` solves z0 + z(theta0 + pi; z0) = 0, found by Brent's method in ``bracket`` with each half period
    integrated by an adaptive 8th-order Runge-Kutta method (scipy's DOP853, restarted at every zero of z),
    or ``bracket[0]`` where that end already maps onto itself within rounding (a saturated orbit).
    Returns z at ``phase_out`` (any phases).

    Unlike :func:`periodic_steady_state` it does not wait for transients to die out: an orbit that forgets its
    start slowly (weak hysteresis) is found as accurately as any."""
    from scipy.optimize import brentq

    def end(z0: float) -> float:
        _start, stop, sol = _half_period(rhs, theta0, z0, rtol, atol)[-1]
        return float(sol(stop)[0])

    lo, hi = bracket
    if lo + end(lo) >= 0.0:  # saturated: the orbit is at the bracket's end to double precision
        z0 = lo
    else:
        z0 = brentq(lambda z: z + end(z), lo, hi, xtol=1e-15 * max(abs(lo), abs(hi)), rtol=1e-15)
    pieces = _half_period(rhs, theta0, z0, rtol, atol)
    phase = np.mod(np.asarray(phase_out, dtype=float) - theta0, 2.0 * np.pi)
    second = phase >= np.pi
    local = theta0 + np.where(second, phase - np.pi, phase)
    out = np.empty(local.shape)
    for lo, hi, sol in pieces:
        inside = (local >= lo) & (local <= hi)
        out[inside] = sol(local[inside])[0]
    return np.where(second, -out, out)
