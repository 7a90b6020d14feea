"""The Bouc-Wen hysteretic spring, Eq. 2.1: a force with memory."""

from __future__ import annotations

import math
from collections.abc import Callable, Collection
from typing import TYPE_CHECKING

import numpy as np

from hysid_model.kinematics import Kinematics
from hysid_model.params import Parameter
from hysid_model.terms import DataScale, ModalState, Term, Values

if TYPE_CHECKING:
    from hysid_model.loops import LoopSet

BISECTIONS = 60
"""Bisection steps for the orbit's peak state (to double precision)."""
MEAN_SAMPLES = 256
"""Phases per cycle over which the orbit's mean is taken under a measured displacement (trapezoid rule:
within 1e-5 of z_max for yield displacements down to 1 % of X0 under 10 % distortion, the curvature
jumps at the reversals and zero crossings of z limiting it; 512 phases gain a factor 20 at twice the cost)."""


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
    off (only k_bw A is identifiable) A = 1. The shape is set by the yield
    displacement z_y = (gamma + beta)^(-1/n) (|z| < z_y, the force saturates at
    k_bw z_y for every n; k_bw is the stiffness right where z = 0), by
    r = (gamma - beta) / (gamma + beta): Fig. 2.6 (a) is r > 0, (b) r = 0,
    (c) -1 < r < 0; r > 1 means beta < 0, and by the exponent n, the sharpness of
    the knee between the two (n -> inf: elastic-perfectly plastic). At r = -1
    (gamma = 0) the law loses its hysteresis (dz/dx is the same both ways) and
    the orbit is ill-posed, so r >= -0.9. The oscillator keeps its linear
    spring, the alpha wn^2 x of Eq. 2.1a; k_bw is the (1 - alpha) wn^2 part times
    the mass.

    The exponent ``bw_n`` is fixed at n = 1 (the thesis' form) unless a model
    frees it (``model.vary("bw_n")``, bounds for it, or the ``mr_damper``
    preset); practitioners' fits of MR dampers and wire-rope isolators take n
    from about 1 to 6. Its physical range is n >= 1/2: the law is well posed
    for any n > 0 (dz/dx = 1 where z = 0, so the orbit crosses it however
    rough |z|^n is), but below n = 1 the tangent stiffness falls with an
    infinite slope after every zero crossing of z, the references use n >= 1
    (OpenSees: 'usually greater or equal to 1'), and as n -> 0 z creeps
    towards z_y over a travel of z_y / n, so that k_bw, z_y and n trade off;
    1/2 is as low as hysid's solver is verified.

    The law is rate independent, so under x = X0 sin(wt) the state is a
    function of the phase only. For n = 1 the periodic orbit is piecewise
    exponential in x (:func:`loading_orbit`), evaluated in closed form; for
    any other n each branch is an autonomous ODE in the travel whose orbit
    :mod:`hysid_model.bouc_wen_orbit` finds (exactly per point here, from
    tables in the compiled sampler). The tests integrate Eq. 2.1b over cycles
    to the same orbits.
    """

    id = "bouc_wen"
    memory = True
    strength = "bw_k"
    explanation = (
        "A Bouc-Wen hysteretic spring (Eq. 2.1): a force k z whose internal displacement z follows the "
        "motion with memory and saturates at the yield displacement z_y, giving smooth, rate-independent "
        "loops between a spring (z_y >> X0) and dry friction (z_y << X0); the exponent n (fixed at 1 "
        "unless freed) sets how sharp the knee between the two is."
    )
    params = (
        Parameter("bw_k", "N/m", 0.0, 1.0e9, "stiffness of the hysteretic spring ((1 - alpha) k)", physical=(0.0, math.inf)),
        Parameter("bw_zy", "m", 1.0e-9, 1.0, "yield displacement (gamma + beta)^(-1/n)", physical=(0.0, math.inf)),
        Parameter("bw_r", "1", -0.9, 3.0, "shape (gamma - beta) / (gamma + beta)", physical=(-0.9, math.inf)),
        Parameter("bw_n", "1", 1.0, 6.0, "exponent n of Eq. 2.1b", vary=False, value=1.0, physical=(0.5, math.inf)),
    )

    def data_bounds(self, scale: DataScale) -> dict[str, tuple[float, float]]:
        """Hysteretic stiffness up to 10 x the survey's or the stiffness that carries the largest peak force at a
        yield of 1 % of the smallest amplitude, whichever is higher (a damper whose force is mostly friction-like
        has a small dynamic stiffness but a stiff, early-yielding hysteretic spring), yield from 1/1000 of the
        smallest to 10 x the largest amplitude; the shape r from -0.9 to 3 and the exponent (where it is free) from 1 to 6, soft: a fit that
        ends on 3 (a knee sharper than r = 3 draws, beta < 0) or on 6 (or 1) widens it."""
        return {
            "bw_k": (0.0, max(10.0 * scale.stiffness, scale.force / (0.01 * scale.x_min))),
            "bw_zy": (1e-3 * scale.x_min, 10.0 * scale.x_max),
            "bw_n": (1.0, 6.0),
        }

    def shape_grid(self, kin: Kinematics, free: Collection[str] = ()) -> list[dict[str, float]]:
        """Yield displacements from 3 % to 100 % of the median amplitude, times three shapes r; times the
        exponents 1 and 2 where n is free."""
        x0 = float(np.median(kin.x0))
        shapes = [{"bw_zy": f * x0, "bw_r": r} for f in (0.03, 0.1, 0.3, 1.0) for r in (-0.5, 0.5, 2.0)]
        return [{**s, "bw_n": n} for s in shapes for n in (1.0, 2.0)] if "bw_n" in free else shapes

    def time_force(self, v: Values, state: ModalState, kin: Kinematics, phase: np.ndarray, n_top: int | None = None) -> np.ndarray:
        """k_bw z on the periodic orbit; being rate independent, z depends only on the travel since the
        last reversal, so the orbit of a sine with the same extremes holds for any measured displacement
        whose branches are monotonic. Candidates with n = 1 take the closed form, the others
        :func:`hysid_model.bouc_wen_orbit.bouc_wen_exact`. z is continuous at a reversal: the branches
        (``n_top``) do not matter."""
        one = v["bw_n"][:, 0] == 1.0
        if one.all():
            return _closed_form(v, kin, phase)
        out = np.empty((one.size,) + phase.shape[-2:])
        for mask, part in ((one, _closed_form), (~one, _any_exponent)):
            if mask.any():
                out[mask] = part({name: value[mask] for name, value in v.items()}, kin, phase[mask] if phase.ndim == 3 else phase)
        return out

    def sampler(self, kin: Kinematics, phase: np.ndarray, n_top: int | None = None) -> BoucWenSampler:
        return BoucWenSampler(kin, phase)

    def data_starts(self, loops: LoopSet, free: Collection[str] = ()) -> list[dict[str, float]]:
        """bw_k, bw_zy, bw_r (and bw_n where it is free) read off the loops' shape, up to 6 starts, best first;
        none where no loop is saturated above its noise (:mod:`hysid_model.effects.bouc_wen_starts`)."""
        from hysid_model.effects.bouc_wen_starts import read_starts

        return read_starts(loops, "bw_n" in free)


def _closed_form(v: Values, kin: Kinematics, phase: np.ndarray) -> np.ndarray:
    """k_bw z on the n = 1 orbit (:func:`loading_orbit`) at ``phase`` ``(L, N)`` or ``(P, L, N)``."""
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

    return v["bw_k"][:, :, None] * _centred(z, kin, phase)


def _any_exponent(v: Values, kin: Kinematics, phase: np.ndarray) -> np.ndarray:
    """k_bw z on the orbit of any exponent, exactly per point (:func:`hysid_model.bouc_wen_orbit.bouc_wen_exact`)."""
    from hysid_model import bouc_wen_orbit

    x_min, x_max = kin.extremes
    spans, which = np.unique(0.5 * (x_max - x_min), return_inverse=True)
    columns = [np.ascontiguousarray(v[name][:, 0], dtype=float) for name in ("bw_n", "bw_r", "bw_zy")]

    def z(phase: np.ndarray) -> np.ndarray:
        travel, sign = travels(kin, phase)
        shape = (columns[0].size,) + travel.shape[-2:]
        out = np.empty(shape)
        bouc_wen_orbit.bouc_wen_exact(
            *columns,
            spans.astype(float),
            which.reshape(-1).astype(np.int64),
            np.ascontiguousarray(np.broadcast_to(travel, shape)),
            np.ascontiguousarray(np.broadcast_to(sign, shape)),
            out,
        )
        return out

    return v["bw_k"][:, :, None] * _centred(z, kin, phase)


def _centred(z: Callable[[np.ndarray], np.ndarray], kin: Kinematics, phase: np.ndarray) -> np.ndarray:
    """z at ``phase``; under a measured displacement less its cycle mean (the orbit of an asymmetric waveform
    has one: removed, as from the loops)."""
    state = z(phase)
    if kin.xh is not None:
        state = state - z(mean_grid(kin.x0.size)).mean(axis=-1, keepdims=True)
    return state


def mean_grid(n_loops: int) -> np.ndarray:
    """The uniform phases ``(L, MEAN_SAMPLES)`` over which the orbit's cycle mean is taken."""
    return np.broadcast_to(np.linspace(0.0, 2 * np.pi, MEAN_SAMPLES, endpoint=False), (n_loops, MEAN_SAMPLES))


def travels(kin: Kinematics, phase: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Travel since the last reversal and branch sign (+1 loading, x' >= 0; -1 unloading) at ``phase`` ``(L, N)``."""
    x_min, x_max = kin.extremes
    x = kin.displacement(phase)
    loading = kin.displacement(phase, 1) >= 0.0
    return np.where(loading, x - x_min[:, None], x_max[:, None] - x), np.where(loading, 1.0, -1.0)


def travel_runs(travel: np.ndarray, sign: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The samples ``(L, N)`` as runs for :func:`hysid_model.bouc_wen_kernels.bouc_wen_samples`: ``runs`` ``(R, 5)``
    (loop, first sample, stride, count, sign), each run's uniform travel ``step`` (NaN if it is not on one),
    ``spread`` (twice its largest offset from the grid) and every sample's ``deviation`` from its run's grid.

    A run is a stretch of consecutive samples (stride +-1) of one branch whose travel rises by the same
    step within 1e-9 of it: a branch resampled on linspace(x_min, x_max) is one run, the other samples
    (e.g. a turning point that the velocity's sign puts on the other branch) runs of their own.
    """
    runs, steps, spreads = [], [], []
    deviation = np.zeros_like(travel)
    for l in range(travel.shape[0]):
        for s in (1.0, -1.0):
            idx = np.flatnonzero(sign[l] == s)
            idx = idx[np.argsort(travel[l, idx], kind="stable")]
            t = travel[l, idx]
            dt = np.diff(t)
            dx = float(np.median(dt)) if dt.size else np.nan
            link = (np.abs(np.diff(idx)) == 1) & (np.abs(dt - dx) <= 1e-9 * dx) if dx > 0 else np.zeros(dt.size, dtype=bool)
            i = 0
            while i < idx.size:
                j = i
                while j < link.size and link[j] and (j == i or idx[j + 1] - idx[j] == idx[i + 1] - idx[i]):
                    j += 1
                count = j - i + 1
                stride = int(idx[i + 1] - idx[i]) if count > 1 else 1
                offset = t[i : j + 1] - t[i] - dx * np.arange(count) if count > 2 else np.zeros(count)
                deviation[l, idx[i : j + 1]] = offset
                runs.append((l, int(idx[i]), stride, count, int(s)))
                steps.append(dx if count > 2 else np.nan)
                spreads.append(2.0 * float(np.abs(offset).max()))
                i = j + 1
    return np.array(runs, dtype=np.int64).reshape(-1, 5), np.array(steps), np.array(spreads), deviation


class BoucWenSampler:
    """:meth:`BoucWen.time_force` at fixed phases through the compiled kernels of :mod:`hysid_model.bouc_wen_kernels`
    and :mod:`hysid_model.shifted_kernels` (n = 1) and :mod:`hysid_model.bouc_wen_tables` (any other n).

    What depends only on the loops is prepared once: each sample's travel since
    the last reversal, the samples of each branch by increasing travel and the
    uniform travel grid they lie on (a loop resampled on linspace(x_min, x_max)
    does), the distinct half spans (one orbit each) and, under a measured
    displacement, the nodes of the cycle mean.
    """

    def __init__(self, kin: Kinematics, phase: np.ndarray) -> None:
        from hysid_model import bouc_wen_kernels, shifted_kernels

        self.kernels = bouc_wen_kernels
        self.shifted = shifted_kernels
        self.kin = kin
        self.phase = np.ascontiguousarray(np.broadcast_to(phase, (kin.x0.size, phase.shape[-1])), dtype=float)
        x_min, x_max = kin.extremes
        self.x_min, self.x_max = np.ascontiguousarray(x_min, dtype=float), np.ascontiguousarray(x_max, dtype=float)
        spans, which = np.unique(0.5 * (x_max - x_min), return_inverse=True)
        self.spans, self.which = spans.astype(float), which.reshape(-1).astype(np.int64)
        travel, sign = travels(kin, self.phase)
        self.travel = np.ascontiguousarray(travel)
        self.runs, self.step, self.spread, self.deviation = travel_runs(travel, sign)
        self.loop_runs = np.searchsorted(self.runs[:, 0], np.arange(travel.shape[0] + 1)).astype(np.int64)
        n_loops = travel.shape[0]
        if kin.xh is None:
            self.mean_nodes = None
        else:
            node_travel, node_sign = travels(kin, mean_grid(n_loops))
            order = np.lexsort((node_travel, node_sign < 0), axis=-1)
            self.mean_nodes = (np.ascontiguousarray(np.take_along_axis(node_travel, order, axis=1)), np.count_nonzero(node_sign > 0, axis=1).astype(np.int64))
        self._motion: tuple[np.ndarray, np.ndarray] | None = None

    def _orbit(self, v: Values) -> tuple[np.ndarray, ...]:
        """(z_max, run, a, b, k, mean) of candidates ``v``: the orbit of each distinct span, and its cycle mean per loop."""
        gamma = (1.0 + v["bw_r"][:, 0]) / (2.0 * v["bw_zy"][:, 0])
        beta = (1.0 - v["bw_r"][:, 0]) / (2.0 * v["bw_zy"][:, 0])
        a, b = np.ascontiguousarray(gamma - beta), np.ascontiguousarray(gamma + beta)
        k = np.ascontiguousarray(v["bw_k"][:, 0], dtype=float)
        n_pop = a.size
        z_max, run = np.empty((n_pop, self.spans.size)), np.empty((n_pop, self.spans.size))
        self.kernels.bouc_wen_orbit(self.spans, a, b, z_max, run)
        mean = np.zeros((n_pop, self.which.size))
        if self.mean_nodes is not None:
            self.kernels.bouc_wen_mean(z_max, run, self.which, a, b, *self.mean_nodes, mean)
        return z_max, run, a, b, k, mean

    def _samples(self) -> tuple[np.ndarray, ...]:
        return (self.travel, self.runs, self.loop_runs, self.step, self.spread, self.deviation)

    SHAPE = ("bw_n", "bw_r", "bw_zy")
    """The parameters z depends on; the force k_bw z is linear in k_bw."""

    def add(self, v: Values, shift: np.ndarray | None, out: np.ndarray) -> None:
        """Add the force k_bw z of candidates ``v`` to ``out`` ``(P, L, N)``, at the phases less ``shift`` ``(P, L)`` if given.

        Each distinct orbit (n, r, z_y, and shift) is computed once, at k_bw = 1, and scaled by each candidate's
        k_bw: a Jacobian's probes of every other parameter share their point's orbit (8 of the 14 probes of the
        ``mr_damper`` preset), and a candidate's force does not depend on the others it is evaluated with."""
        first = inverse = np.arange(out.shape[0])
        if out.shape[0] > 1:
            keys = np.column_stack([v[name][:, 0] for name in self.SHAPE] + ([] if shift is None else [shift]))
            _, unique, shared = np.unique(keys, axis=0, return_index=True, return_inverse=True)
            if unique.size < out.shape[0]:  # else each orbit in the candidates' own order, with nothing to gather
                first, inverse = unique, shared.reshape(-1)
        shapes: Values = {name: v[name][first] for name in self.SHAPE}
        shapes["bw_k"] = np.ones((first.size, 1))
        unit = np.zeros((first.size,) + out.shape[1:])
        self._add_orbits(shapes, None if shift is None else shift[first], unit)
        if first.size < out.shape[0]:
            unit = unit[inverse]
        unit *= v["bw_k"][:, 0, None, None]
        out += unit

    def _add_orbits(self, v: Values, shift: np.ndarray | None, out: np.ndarray) -> None:
        """The closed form for candidates with n = 1, the tabulated orbit (:mod:`hysid_model.bouc_wen_tables`) for the others."""
        one = v["bw_n"][:, 0] == 1.0
        if one.all() or not one.any():
            (self._add_one if one.all() else self._add_any)(v, shift, out)
            return
        for mask, add in ((one, self._add_one), (~one, self._add_any)):
            part = np.zeros((int(mask.sum()),) + out.shape[1:])
            add({name: value[mask] for name, value in v.items()}, None if shift is None else shift[mask], part)
            out[mask] += part

    def _motion_tables(self) -> tuple[np.ndarray, np.ndarray]:
        if self._motion is None:
            self._motion = self.shifted.motion_tables(self.kin.harmonics, self.phase)
        return self._motion

    def _add_one(self, v: Values, shift: np.ndarray | None, out: np.ndarray) -> None:
        z_max, run, a, b, k, mean = self._orbit(v)
        if shift is None:
            self.kernels.bouc_wen_samples((z_max, run, self.which, a, b, k, mean), *self._samples(), out)
            return
        self.shifted.bouc_wen_shifted(
            (z_max, run, self.which, a, b, k, mean), np.ascontiguousarray(shift, dtype=float), *self._motion_tables(), self.x_min, self.x_max, out
        )

    def _add_any(self, v: Values, shift: np.ndarray | None, out: np.ndarray) -> None:
        from hysid_model import bouc_wen_tables

        columns = tuple(np.ascontiguousarray(v[name][:, 0], dtype=float) for name in ("bw_n", "bw_r", "bw_zy", "bw_k"))
        if self.mean_nodes is None:
            mean = (np.zeros((self.which.size, 0)), np.zeros(self.which.size, dtype=np.int64))
        else:
            mean = self.mean_nodes
        if shift is None:
            bouc_wen_tables.bouc_wen_samples(columns, self.spans, self.which, *self._samples(), *mean, out)
            return
        bouc_wen_tables.bouc_wen_shifted(
            columns, self.spans, self.which, *mean, np.ascontiguousarray(shift, dtype=float), self._motion_tables(), (self.x_min, self.x_max), out
        )
