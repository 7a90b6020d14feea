"""A faithful port of the thesis' MATLAB objective (Appendix A): the reference implementation.

The thesis evaluates a candidate p = [xi0, S_xi, w0, S_w] loop by loop
(``erreval``): it samples the closed-form steady state of Eq. 4.5/4.10,
x = Xpk sin(wt) and F = Xpk Meq ((wn^2 - w^2) sin(wt) + 2 xi wn w cos(wt)) with
xi = xi0 + S_xi Xpk (Eq. 4.8) and wn = w0 + S_w Xpk (Eq. 4.9), on the time grid
``0:1e-4:tspan`` (tspan = 0.4 s); cuts the last loading and unloading branch
out of that record (``getloopdisp``); interpolates them linearly at the trial
branch displacements (``interp1``, NaN outside, one NaN dropped at each end);
and sums the squared force errors (``leastsqdisp``, Eq. 3.3, Fig. 5.1). The GA
then weights every loop by ``amplitudescaling = maxFall/maxF(j)`` and divides
by its number of samples ``NOS``.

This module repeats exactly that, candidate by candidate and loop by loop. It
is the reference the vectorized :class:`hysid_model.objective.Objective` is
checked against and the "expensive objective" of the benchmarks; the only
liberty taken is that ``getloopdisp``'s sample-by-sample walk is done on runs of
equal step direction (same indices, numpy instead of a scalar loop).
Where the MATLAB code stops with an error (an index running off the record,
no case of ``getloopdisp`` matching, indistinct ``interp1`` abscissae) the port
raises :class:`ThesisPortError`; the thesis' GA caught such errors and drew a
new chromosome, :class:`ThesisObjective` scores the candidate ``inf``.
"""

from __future__ import annotations

import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.loops import LoopSet
from hysid_model.model import Model
from hysid_model.objective import ModelSpace, loop_weights

THESIS_TSPAN_S = 0.4
"""``tspan=.4*ones(1,120)`` of the GA and PSO programs."""
THESIS_DT_S = 1e-4
"""Step of erreval's time grid ``t=0:1e-4:tspan``."""


class ThesisPortError(RuntimeError):
    """The MATLAB code would stop with an error at this point."""


def time_grid(tspan: float = THESIS_TSPAN_S, dt: float = THESIS_DT_S) -> np.ndarray:
    """MATLAB's ``0:dt:tspan`` (the colon operator's count, with its round-off tolerance)."""
    count = int(np.floor(tspan / dt + 1e-10)) + 1
    return np.arange(count) * dt


def interp1_linear(x: np.ndarray, y: np.ndarray, xq: np.ndarray) -> np.ndarray:
    """MATLAB ``interp1(x, y, xq, 'linear')``: NaN outside [min x, max x]; x is sorted first."""
    order = np.argsort(x, kind="stable")
    xs = x[order]
    if xs.size < 2 or np.any(np.diff(xs) <= 0):
        raise ThesisPortError("interp1: the data abscissae should be distinct (and at least two)")
    return np.interp(xq, xs, y[order], left=np.nan, right=np.nan)


def _walk(steps: np.ndarray, starts: np.ndarray, pos: int, run: int, direction: float) -> tuple[int, int, int]:
    """One ``while hys1(NR-i,1) <op> hys1(NR-i-1,1), i=i+1; end`` of getloopdisp.

    ``pos`` is the 0-based row NR-i, ``run`` the run of equal step signs that
    holds the step from row pos-1 to pos. Returns the new (pos, run) and the
    number of rows walked.
    """
    if pos < 1:
        raise ThesisPortError("getloopdisp: ran off the start of the record (index 0)")
    if steps[starts[run]] != direction:
        return pos, run, 0
    new_pos = int(starts[run])
    if new_pos < 1:
        raise ThesisPortError("getloopdisp: ran off the start of the record (index 0)")
    return new_pos, run - 1, pos - new_pos


def getloopdisp_indices(hys1: np.ndarray) -> tuple[int, int, int, int]:
    """``getloopdisp``'s TOPmin, TOPmax, BOTmin, BOTmax as 0-based inclusive row indices.

    Walking back from the end of the record [x, F] it finds the ends F1..F4 of
    the last monotone runs of x (skipping repeated x at each turn, F1f..F3f),
    then picks the last complete loading (top) and unloading (bottom) branch
    according to the direction of x and F at the last sample.
    """
    x = hys1[:, 0]
    nr = x.size
    if nr < 2:
        raise ThesisPortError("getloopdisp: the record needs at least two samples")
    steps = np.sign(np.diff(x))  # steps[k-1]: sign(x[k] - x[k-1])
    starts = np.concatenate([[0], np.flatnonzero(steps[1:] != steps[:-1]) + 1])
    pos, run = nr - 1, starts.size - 1
    pos, run, _ = _walk(steps, starts, pos, run, 0.0)
    ends, flats = [], []  # F1..F4 and F1f..F3f: after each monotone run (down, up, down, up), the repeated x at its turn
    for k, direction in enumerate((-1.0, 1.0, -1.0, 1.0)):
        pos, run, _ = _walk(steps, starts, pos, run, direction)
        ends.append(pos)
        if k < 3:
            pos, run, flat = _walk(steps, starts, pos, run, 0.0)
            flats.append(flat)
    f1, f2, f3, f4 = ends
    f1f, f2f, f3f = flats
    x_end, x_prev = x[-1], x[-2]
    f_end, f_prev = hys1[-1, 1], hys1[-2, 1]
    force_moves = f_end < f_prev or f_end > f_prev  # the MATLAB cases test F for < and > only
    if x_end < x_prev and force_moves:  # cases 1 and 4: ends unloading; top is the run before
        return f2, f1 - f1f, f3, f2 - f2f
    if x_end > x_prev and force_moves:  # cases 2 and 3: ends loading; take the complete run before
        return f4, f3 - f3f, f3, f2 - f2f
    raise ThesisPortError("getloopdisp: the last two samples match none of its four cases (equal x or F)")


def getloopdisp(hys1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``[top, bot] = getloopdisp(hys1)``: the last loading and unloading branch of a record [x, F]."""
    top_min, top_max, bot_min, bot_max = getloopdisp_indices(hys1)
    return hys1[top_min : top_max + 1], hys1[bot_min : bot_max + 1]


def _trim_nan_ends(y: np.ndarray) -> np.ndarray:
    """erreval's "Remove Nan's": drop the first sample if NaN, then the last if NaN (one each)."""
    keep = np.ones(y.size, dtype=bool)
    if np.isnan(y[0]):
        keep[0] = False
    remaining = np.flatnonzero(keep)
    if remaining.size == 0:
        raise ThesisPortError("erreval: index 0 after removing the only (NaN) sample")
    if np.isnan(y[remaining[-1]]):
        keep[remaining[-1]] = False
    return keep


def leastsqdisp(a: np.ndarray, b: np.ndarray) -> float:
    """``leastsqdisp(A, B)``: sum of (A(:,2) - B)^2, the OLS error of Eq. 3.3."""
    if a.shape[0] != b.shape[0]:
        raise ThesisPortError("Least-squares error: both matrices must have the same dimensions")
    return float(np.sum((a[:, 1] - b) ** 2))


def erreval_points(
    hexp_t: np.ndarray,
    hexp_b: np.ndarray,
    p: np.ndarray,
    ef: float,
    xpk: float,
    meq: float,
    tspan: float = THESIS_TSPAN_S,
    dt: float = THESIS_DT_S,
) -> tuple[np.ndarray, np.ndarray]:
    """erreval up to the interpolation: which trial samples it keeps and the model force there.

    Returns ``keep`` (bool) and ``ymod`` (model force, NaN where interp1 gave
    NaN), both over the top samples followed by the bottom samples.
    """
    w = 2.0 * np.pi * ef
    t = time_grid(tspan, dt)
    xi = p[0] + p[1] * xpk  # Eq. 4.8
    wn = p[2] + p[3] * xpk  # Eq. 4.9
    sin_wt = np.sin(w * t)
    x = xpk * sin_wt  # Eq. 4.5
    fcf = xpk * meq * ((wn**2 - w**2) * sin_wt + 2.0 * xi * wn * w * np.cos(w * t))  # Eq. 4.10
    model_t, model_b = getloopdisp(np.column_stack([x, fcf]))
    ymod_t = interp1_linear(model_t[:, 0], model_t[:, 1], hexp_t[:, 0])
    ymod_b = interp1_linear(model_b[:, 0], model_b[:, 1], hexp_b[:, 0])
    keep = np.concatenate([_trim_nan_ends(ymod_t), _trim_nan_ends(ymod_b)])
    return keep, np.concatenate([ymod_t, ymod_b])


def erreval(
    hexp_t: np.ndarray, hexp_b: np.ndarray, p: np.ndarray, ef: float, xpk: float, meq: float, tspan: float = THESIS_TSPAN_S, dt: float = THESIS_DT_S
) -> float:
    """``fitness = erreval(HexpT, HexpB, p, ef, Xpk, Meq, tspan)``: one loop's OLS force error.

    NaN if an interpolated model force other than the first or last of a
    branch is NaN (the MATLAB code sums it as it is).
    """
    keep, ymod = erreval_points(hexp_t, hexp_b, p, ef, xpk, meq, tspan, dt)
    return leastsqdisp(np.concatenate([hexp_t, hexp_b])[keep], ymod[keep])


def reinterpolate(hexp_to: np.ndarray, hexp_bo: np.ndarray, ints: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """``reinterpolate(HexpTo, HexpBo, ints)``: each branch resampled on ``ints`` evenly spaced x (linear)."""

    def resample(branch: np.ndarray) -> np.ndarray:
        x = np.linspace(branch[:, 0].min(), branch[:, 0].max(), ints)
        # the queries span exactly [min x, max x], so interp1's 'extrap' never extrapolates
        return np.column_stack([x, interp1_linear(branch[:, 0], branch[:, 1], x)])

    return resample(hexp_to), resample(hexp_bo)


def centercurveloop(hexp_to: np.ndarray, hexp_bo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``centercurveloop``: shift a loop so x and F run symmetrically about zero."""
    both = np.concatenate([hexp_to, hexp_bo])
    xmax, xmin = both[:, 0].max(), both[:, 0].min()
    fmax, fmin = both[:, 1].max(), both[:, 1].min()
    dx = xmax - (xmax - xmin) / 2.0
    df = fmax - (fmax - fmin) / 2.0
    shift = np.array([dx, df])
    return hexp_to - shift, hexp_bo - shift


class ThesisObjective(ModelSpace):
    """The GA's fitness loop (Appendix A) with the interface of :class:`~hysid_model.objective.Objective`.

    fitness(p) = sum_j loopsweights(j) * erreval(loop j, p) / NOS_j, with
    loopsweights = maxFall / maxF_j (``loop_weights(loops, "thesis")`` holds
    the division by NOS too) and Xpk_j = max |x| over both branches of loop j.
    Parameters are the thesis chromosome [xi0, S_xi, w0, S_w] of ``model`` (the
    thesis model, its bounds in force), whose Meq is fixed (known).
    (The GA program took maxF before adding its synthetic noise; a loop set
    holds the measured branches only, so maxF is taken from those, as hysid does.)
    """

    def __init__(self, loops: LoopSet, model: Model, tspan: float = THESIS_TSPAN_S, dt: float = THESIS_DT_S) -> None:
        if model.names != ["xi0", "S_xi", "w0", "S_w"] or "meq" not in model.fixed:
            raise HysidInputError(f"the thesis' erreval takes the thesis model with a known mass, not {model!r}")
        self.loops = loops
        self.model = model
        self.meq_kg = model.fixed["meq"]
        self.tspan = float(tspan)
        self.dt = float(dt)
        self.loop_weight = loop_weights(loops, "thesis")
        self.xpk = np.maximum(np.abs(loops.top[:, :, 0]).max(axis=1), np.abs(loops.bottom[:, :, 0]).max(axis=1))
        self.evaluations = 0

    def points(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Kept samples and model force of every loop, each ``(L, 2n)`` ordered like ``LoopSet.forces()``."""
        p = np.asarray(theta, dtype=float).reshape(-1)
        lp = self.loops
        out = [erreval_points(lp.top[j], lp.bottom[j], p, lp.freq_hz[j], self.xpk[j], self.meq_kg, self.tspan, self.dt) for j in range(lp.n_loops)]
        return np.stack([k for k, _ in out]), np.stack([y for _, y in out])

    def fitness(self, theta: np.ndarray) -> float:
        """One candidate, loop by loop as the GA does; inf where the MATLAB code would fail."""
        p = np.asarray(theta, dtype=float).reshape(-1)
        lp = self.loops
        total = 0.0
        with np.errstate(all="ignore"):
            try:
                for j in range(lp.n_loops):
                    err = erreval(lp.top[j], lp.bottom[j], p, lp.freq_hz[j], self.xpk[j], self.meq_kg, self.tspan, self.dt)
                    total += self.loop_weight[j] * err
            except ThesisPortError:
                return np.inf
        return total if np.isfinite(total) else np.inf

    def __call__(self, pop: np.ndarray) -> np.ndarray:
        """Fitness of each row of a ``(P, 4)`` population (or one ``(4,)`` vector), one by one."""
        pop = np.atleast_2d(np.asarray(pop, dtype=float))
        if pop.shape[1] != self.dim:
            raise HysidInputError(f"expected {self.dim} parameters ({', '.join(self.model.names)}), got {pop.shape[1]}")
        self.evaluations += pop.shape[0]
        return np.array([self.fitness(p) for p in pop])
