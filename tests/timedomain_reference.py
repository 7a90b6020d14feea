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


def _rk4_step(rhs: Rhs, theta: float | np.ndarray, z: np.ndarray, k1: np.ndarray, h: float) -> np.ndarray:
    """One classical RK4 step of dz/dtheta = rhs from ``theta`` (``k1`` = rhs(theta, z))."""
    k2 = rhs(theta + 0.5 * h, z + (0.5 * h) * k1)
    k3 = rhs(theta + 0.5 * h, z + (0.5 * h) * k2)
    k4 = rhs(theta + h, z + h * k3)
    return z + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def _rk4_cycle(rhs: Rhs, z: np.ndarray, k1: np.ndarray, steps: int, grid: list | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Integrate one cycle theta = 0..2 pi in ``steps`` RK4 steps.

    ``k1`` is rhs(0, z). Returns the final state, rhs there (the next cycle's
    k1, rhs being 2 pi-periodic) and the largest |z| met on the grid.
    ``grid``, if given, receives (z_j, rhs_j) at every grid phase j = 0..steps.
    """
    h = TWO_PI / steps
    amplitude = np.abs(z)
    if grid is not None:
        grid.append((z, k1))
    for j in range(steps):
        z_next = _rk4_step(rhs, TWO_PI * j / steps, z, k1, h)
        k1_next = rhs(TWO_PI * (j + 1) / steps, z_next)
        if grid is not None:
            grid.append((z_next, k1_next))
        np.maximum(amplitude, np.abs(z_next), out=amplitude)
        z, k1 = z_next, k1_next
    return z, k1, amplitude


def _hermite(z: np.ndarray, f: np.ndarray, phase: np.ndarray) -> np.ndarray:
    """The cubic Hermite interpolant of an RK4 grid, z and its slope f = rhs at the phases 2 pi j / steps ``(steps + 1,
    S, *batch)``, at ``phase`` ``(*batch, K)`` in [0, 2 pi): ``(S, *batch, K)``."""
    steps = z.shape[0] - 1
    h = TWO_PI / steps
    u = phase / h
    step = np.clip(np.floor(u).astype(np.int64), 0, steps - 1)[None]
    u = (u - step[0])[None]
    z, f = np.moveaxis(z, 0, -1), np.moveaxis(f, 0, -1)  # (S, *batch, steps + 1)

    def at(a: np.ndarray, j: np.ndarray) -> np.ndarray:
        return np.take_along_axis(a, np.broadcast_to(j, a.shape[:-1] + j.shape[-1:]), axis=-1)

    h00, h10, h01, h11 = (1.0 + 2.0 * u) * (1.0 - u) ** 2, h * u * (1.0 - u) ** 2, u**2 * (3.0 - 2.0 * u), -h * u**2 * (1.0 - u)
    return h00 * at(z, step) + h10 * at(f, step) + h01 * at(z, step + 1) + h11 * at(f, step + 1)


def tabulated_drive(drive: Callable[[np.ndarray], np.ndarray], steps_per_cycle: int) -> Callable[[float], np.ndarray]:
    """A drive of the phase alone (e.g. the measured x'(theta)), vectorized over phases on its last axis, computed once
    on every phase an RK4 cycle of ``steps_per_cycle`` steps visits (the whole and half steps), for an ``rhs`` that
    would otherwise recompute it in each of its 4 x steps calls per cycle: returns theta -> drive(theta) by lookup."""
    half = 2 * steps_per_cycle
    table = np.ascontiguousarray(np.moveaxis(drive(TWO_PI * np.arange(half + 1) / half), -1, 0))

    def at(theta: float) -> np.ndarray:
        j = round(theta * half / TWO_PI)
        if abs(theta * half / TWO_PI - j) > 1e-6 or not 0 <= j <= half:
            raise ValueError(f"phase {theta!r} is not on the RK4 grid of {steps_per_cycle} steps per cycle")
        return table[j]

    return at


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
        grid: list = []
        _rk4_cycle(rhs, z, k1, steps_per_cycle, grid)
        return _hermite(np.stack([g[0] for g in grid]), np.stack([g[1] for g in grid]), phase)


def affine_periodic_orbit(rhs: Rhs, shape: tuple[int, ...], phase_out: np.ndarray, *, steps_per_cycle: int, tol: float = 1e-10) -> np.ndarray:
    """:func:`periodic_steady_state` of an affine law dz/dtheta = a(theta) z + b(theta) (a linear filter driven by the
    motion) on the same RK4 grid, without its Python loop over steps: each RK4 step is then an affine map
    z_j+1 = A_j z_j + B_j, found for every step at once by stepping 0 and 1 (``rhs`` vectorized over an array of
    phases ``(steps, 1, ...)`` in front of the state's ``shape``), the cycle's fixed point z_0 = B / (1 - A) of their
    composition z_N = A z_0 + B is the periodic orbit, and the orbit is checked to close within ``tol`` of its largest
    |z| (:class:`SteadyStateError` if not). Returns z at ``phase_out`` (broadcastable to shape[1:] + (K,)) by the
    same cubic Hermite interpolation, ``(*shape, K)``."""
    steps = steps_per_cycle
    theta = (TWO_PI * np.arange(steps + 1) / steps).reshape((steps + 1,) + (1,) * len(shape))

    def step(z0: float) -> np.ndarray:
        z = np.full((steps,) + shape, z0)
        return _rk4_step(rhs, theta[:-1], z, rhs(theta[:-1], z), TWO_PI / steps)

    offset = step(0.0)
    gain = step(1.0) - offset

    def run(z0: np.ndarray) -> np.ndarray:
        z = np.empty((steps + 1,) + shape)
        z[0] = z0
        for j in range(steps):
            z[j + 1] = gain[j] * z[j] + offset[j]
        return z

    z = run(run(np.zeros(shape))[-1] / (1.0 - np.prod(gain, axis=0)))
    if not np.all(np.abs(z[-1] - z[0]) <= tol * np.abs(z).max(axis=0)):
        raise SteadyStateError("the affine law's RK4 cycle has no periodic orbit within tol: is it damped?")
    phase = np.mod(np.broadcast_to(np.asarray(phase_out, dtype=float), shape[1:] + np.shape(phase_out)[-1:]), TWO_PI)
    return _hermite(z, rhs(theta, z), phase)


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
