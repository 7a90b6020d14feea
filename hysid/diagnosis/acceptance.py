"""When a refit with a new effect is taken: the rules a diagnosis judges every contender by.

An effect is judged from its best fit (refitted from several starts,
:func:`hysid.diagnosis.refits.refit`), never from one poor optimum, and by what it
explains, not by how precisely one of its parameters is known there:

1. information: the BIC falls by at least ``BIC_MARGIN`` (:func:`judge`);
2. shape: no harmonic order the current model fits at the noise is made
   significantly worse (:func:`created_order`);
3. sign: a one-sided effect's strength ends positive;
4. degeneracy: a shape parameter the data push against a bound
   (:func:`binding`, :func:`degenerate`) means the effect turns into something
   else there; it is taken only if no other contender fits within
   ``BIC_MARGIN`` of it (:func:`degenerate_gives_way`, applied in :mod:`.selection`;
   then the bound is reported with the result);
5. share: it removes at least ``MIN_SHARE`` of the chi^2 above the noise floor;
6. visible error: the loop NRMSE and the energy dissipated per cycle get no
   worse beyond their noise (the whitened chi^2 weighs loops by their noise; a
   user reads the loops and their areas), :func:`visible_error`;
7. plausibility: every fitted value is physically possible
   (:mod:`hysid.diagnosis.plausible`);
8. held-out error: the leave-one-frequency-out error falls
   (:func:`held_out`, with three frequencies or more); judged last, on the
   contenders that pass the rest, in BIC order;
9. own shape: the effect explains what it should, the shape of its force in
   the residual, with one set of values for every loop (:func:`own_shape`):
   its added force, beyond what the model's spring, dashpot and other terms
   absorb, scaled loop by loop to fit what the model before leaves in that
   loop, would remove no more than ``OWN_SHAPE`` of what it removes at one
   strength beyond what the noise makes of it. A force of the wrong shape fits
   the residual on average and needs another strength at every amplitude and
   frequency: a cubic spring standing in for a dead zone (loop-by-loop
   strengths 13 % apart between amplitudes), an amplitude-dependent damping or
   a channel delay standing in for an orifice's v|v| (strengths of either
   sign). Two effects may be missing at once (Coulomb friction on a softening
   isolator: the friction's strength refitted loop by loop takes up how the
   stiffness changes with amplitude), so an effect this refuses is judged again
   with the forces of the step's other contenders projected out (not those of
   nearly its own shape), and refused only where it fails there too. Where it
   refuses a library effect, that effect leaves the residual to discovery
   (:mod:`.contest`); where it passes every other rule, discovery also starts
   from it (a second mechanism the library lacks beside it,
   :func:`hysid.diagnosis.contest.with_discovery`); where no law proposed from
   the data explains the loops better, or discovery is off, it is named after
   all as the library's best, with why it is not their exact shape
   (:func:`hysid.diagnosis.contest.with_refused`), and the loops stay
   unexplained. Discovery's proposals are judged by it too, with the library
   effects it refused alone on the same model as the contenders beside.

Where the truth lies outside the library, the effects it takes are not kept
as a substitute for a law the library lacks: discovery competes with them
(:mod:`.contest`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hysid.criteria import BIC_MARGIN, MIN_SHARE, MIN_Z, PARALLEL, SIGNIFICANCE
from hysid.diagnosis.metrics import cross_validated_rms, energy_error_pct, nrmse_pct
from hysid.diagnosis.plausible import implausible_values
from hysid.harmonic_fits import Fit
from hysid_model.harmonics import Harmonics
from hysid_model.model import effect_term
from hysid_model.uncertainty import jacobian_covariance

OWN_SHAPE = 0.003
"""Rule 9: the most a loop-by-loop strength may add to what an effect removes at one strength (less the L - 1 the
noise adds), as a share of it. Library effects at work: at most 8e-4 before that correction (Coulomb friction, a
cubic spring, a loss factor, Bouc-Wen, Bouc-Wen with Coulomb friction, a cubic spring with a loss factor, a Spencer
MR damper; six or nine loops, 1 % noise; a weak channel delay's is not significant), 1.5e-3 for Bouc-Wen on the
real friction damper (data/arts-friction-damper: no library effect is its exact shape, Bouc-Wen its best); effects
standing in for a law of ``hysid bench discovery`` the library lacks: 4e-3 to 0.7 (a cubic spring for a dead zone
or x^5, Coulomb friction or Bouc-Wen for |v|^0.35, Coulomb friction for Stribeck friction, an amplitude-dependent
damping, a loss factor, a Zener relaxation or a channel delay for v|v|, |v|^0.35 or tanh), but 3e-3 for a cubic
spring standing in for a one-sided stop and 1e-3 for an amplitude-dependent frequency after it for a dead zone
(these leave the residual unexplained: discovery runs and sets them aside, :mod:`.contest`). Judged again beside the
step's other contenders (:func:`own_shape`; the share of what the effect still removes there): Coulomb friction on
the softening isolator of tests/test_realdata.py 7.9e-2 alone, 3e-4 to 1e-3 beside an amplitude-dependent frequency,
an amplitude-dependent damping and Bouc-Wen (not significant; three noise draws), the amplitude-dependent frequency
4.9e-2 alone, 2e-4 at most beside; Bouc-Wen drawing one of two Jenkins sliders 9.8e-3 alone, 1.4e-3 beside (1 %
noise; 2.3e-3 at 3 %, not significant); the effects standing in for the other slider beside that Bouc-Wen (a loss
factor, a Zener relaxation, a force high-pass, an amplitude-dependent damping) 0.3-0.8 alone, 0.54-1.2 beside (1 %
and 3 %); a cubic spring for a dead zone 4.9e-2 alone, 8e-3 beside an amplitude-dependent frequency. (Each loop's column is
now projected as the whole force is, :func:`shape_gain`: Bouc-Wen on the real friction damper reads 2.1e-3 so.)"""
RANK_TOL = 1e-8
"""Singular values of the partners' unit forces (:func:`projected_out`) below this share of the largest are a force
already counted (two partners of one shape)."""
VISIBLE_Z = 3.0
"""Standard deviations (of what the force noise alone would make of it) a rise of the loop NRMSE or the energy
error must exceed to count: two models equally far from the truth differ in both by their noise only."""
VISIBLE_FLOOR_PCT = 1.0
"""A loop NRMSE or energy error that stays below this (per cent of the peak-to-peak force, of the energy per
cycle) is within what a user reads off a loop plot or its area: its rise does not count."""


def binding(fit: Fit, j: int) -> bool:
    """True if parameter ``j`` sits on a bound that the data push against (the fit wants out of the range).

    One-parameter score test at the bound: the chi^2 gradient 2 J^T e along
    parameter j, with the others free, gives LM = (J^T e)_j^2 [(J^T J)^-1]_jj;
    the bound binds if that points outward and exceeds MIN_Z^2. A weakly
    determined shape that merely wanders onto its bound does not bind.
    """
    name = fit.model.names[j]
    if name not in fit.model.at_bounds(fit.theta):
        return False
    lower, upper = fit.model.bounds[j]
    value = fit.theta[j]
    gradient = (fit.jacobian.T @ fit.residual)[j]
    lm = gradient**2 * jacobian_covariance(fit.jacobian)[j, j]
    outward = gradient > 0 if value - lower <= upper - value else gradient < 0
    return bool(outward and lm > MIN_Z**2)


def created_order(before: Fit, after: Fit) -> tuple[int, float, float] | None:
    """A harmonic order that ``before`` fits at the noise and ``after`` significantly worse, no longer at the
    noise (the family-wise ``SIGNIFICANCE`` of chi^2 over that order's coefficients): (order, chi^2 before,
    after), or None. An effect that buys a better first harmonic with content the loops do not have
    (a hysteretic spring fitting how a linear stiffness changes with amplitude) has the wrong shape."""
    from scipy.stats import chi2 as chi2_dist  # on first use: a fast CLI and island start

    orders = before.objective.harmonics.orders()
    n_loops = before.objective.harmonics.loops.n_loops
    r0, r1 = (f.residual.reshape(n_loops, -1) for f in (before, after))
    levels = np.unique(orders)
    for k in levels:
        n = int(np.count_nonzero(orders == k)) * n_loops
        c0, c1 = float(np.sum(r0[:, orders == k] ** 2)), float(np.sum(r1[:, orders == k] ** 2))
        limit = float(chi2_dist.isf(SIGNIFICANCE / levels.size, n))
        if c0 <= limit < c1 and c1 - c0 > limit - n:
            return int(k), c0, c1
    return None


def visible_error(before: Fit, after: Fit, harmonics: Harmonics) -> str | None:
    """Why ``after`` looks worse to a user than ``before``, or None: a loop NRMSE or energy error that rises by
    more than ``VISIBLE_Z`` times what the noise makes of the rise, to above ``VISIBLE_FLOOR_PCT``.

    For squared errors of two predictions p_a, p_b against data y = truth + e, the difference
    sum (p_a - y)^2 - (p_b - y)^2 varies with the noise e by 4 sum (p_a - p_b)^2 sigma^2; the
    loop NRMSE (a mean of per-loop square roots) and the energy error (the loop area, pi X0 c1,
    with the noise of c1) carry that through to first order."""
    data = before.objective.objective.y
    pa, pb = (f.objective.objective.predict(f.theta)[0] for f in (after, before))
    n = data.shape[1]
    span2 = (data.max(axis=1) - data.min(axis=1)) ** 2
    la, lb = (np.sum((p - data) ** 2, axis=1) / (n * span2) for p in (pa, pb))
    sigma = harmonics.sigma
    var = 4.0 * sigma**2 * np.sum((pa - pb) ** 2, axis=1) / (n * span2) ** 2
    base = np.maximum(np.sqrt(0.5 * (la + lb)), 1e-300)  # d sqrt(l) = dl / (2 sqrt(l)), at the middle of the two
    rise, spread = float(np.mean(np.sqrt(la) - np.sqrt(lb))), float(np.sqrt(np.sum(var / (4.0 * base**2)))) / la.size
    if rise > VISIBLE_Z * spread and np.mean(nrmse_pct(after)) > VISIBLE_FLOOR_PCT:
        return f"raises the loop NRMSE from {np.mean(nrmse_pct(before)):.4g} % to {np.mean(nrmse_pct(after)):.4g} % (by {rise / max(spread, 1e-300):.3g} x its noise)"
    energy = [harmonics.energy_per_cycle(harmonics.project(p)) for p in (pa, pb)]
    truth = harmonics.energy_per_cycle(harmonics.coef)
    noise = np.pi * harmonics.loops.x0 * harmonics.stderr[:, harmonics.names.index("c1")]
    rise = float(np.sum((energy[0] - truth) ** 2) - np.sum((energy[1] - truth) ** 2))
    spread = float(np.sqrt(4.0 * np.sum((energy[0] - energy[1]) ** 2 * noise**2)))
    if rise > VISIBLE_Z * spread and energy_error_pct(after, harmonics) > VISIBLE_FLOOR_PCT:
        return (
            f"raises the energy error from {energy_error_pct(before, harmonics):.4g} % to {energy_error_pct(after, harmonics):.4g} % "
            f"(by {rise / max(spread, 1e-300):.3g} x its noise)"
        )
    return None


def degenerate(after: Fit, effects: tuple[str, ...]) -> str | None:
    """Which shape parameter of ``effects`` the data push against a bound in ``after`` (rule 4), in words, or None."""
    names = after.model.names
    for effect in effects:
        term = effect_term(effect)
        for p in term.params:
            if p.name != term.strength and p.name in names and binding(after, names.index(p.name)):
                return f"{p.name} is pushed against its bound ({after.theta[names.index(p.name)]:.4g}): the effect degenerates here"
    return None


def degenerate_gives_way(bic: float, rivals: Sequence[float]) -> bool:
    """Rule 4's tie: whether a contender of BIC ``bic`` that degenerates (:func:`degenerate`) gives way to the
    ``rivals`` (the BICs of the contenders that pass every rule without degenerating): one of them fits within
    ``BIC_MARGIN`` of it, or better, and explains as much without turning into another effect."""
    return bool(rivals) and min(rivals) < bic + BIC_MARGIN


def partners(before: Fit, after: Fit, beside: Sequence[Fit], q: np.ndarray) -> np.ndarray:
    """The forces the contenders ``beside`` add to ``before`` at one strength (their refits' change of the whitened
    residual), with ``q`` (an orthonormal basis of ``before``'s Jacobian) projected out, each to unit length,
    ``(N, K)``: those not nearly parallel to the force ``after`` adds (|cos| at most ``PARALLEL``: one of nearly the
    same shape is an alternative to it, not a partner)."""
    own = after.residual - before.residual
    own = own - q @ (q.T @ own)
    own = own / max(float(np.linalg.norm(own)), 1e-300)
    forces = [b.residual - before.residual for b in beside]
    forces = [g / max(float(np.linalg.norm(g)), 1e-300) for g in (g - q @ (q.T @ g) for g in forces)]
    return np.column_stack([g for g in forces if abs(float(g @ own)) <= PARALLEL] or [np.zeros((own.size, 0))])


def projected_out(before: Fit, after: Fit, beside: Sequence[Fit]) -> np.ndarray:
    """An orthonormal basis of what rule 9 projects out (:func:`shape_gain`): ``before``'s Jacobian and the forces
    of the :func:`partners` among ``beside`` (two partners of one shape count once)."""
    q = np.linalg.qr(before.jacobian)[0]
    others = partners(before, after, beside, q)
    if others.shape[1] == 0:
        return q
    u, s, _ = np.linalg.svd(others, full_matrices=False)
    return np.column_stack([q, u[:, s > RANK_TOL * float(s.max())]])


def shape_gain(before: Fit, after: Fit, beside: Sequence[Fit] = ()) -> tuple[float, float, np.ndarray]:
    """Rule 9's measures (:func:`own_shape`): what the force ``after`` adds to ``before`` removes of what ``before``
    leaves when scaled loop by loop, beyond what it removes at one strength (a chi^2 of L - 1 degrees of freedom
    where its shape is the residual's); what it removes at one strength; and its loop-by-loop strengths (relative to
    its fitted one). All with ``before``'s Jacobian projected out, and the forces of the :func:`partners` among
    ``beside`` (one strength each): they are no part of the residual the effect's strength may take up."""
    q = projected_out(before, after, beside)
    n_loops = before.objective.harmonics.loops.n_loops
    change = after.residual - before.residual
    f, r = (u - q @ (q.T @ u) for u in (change, before.residual))
    blocks = f.size // n_loops
    loops = np.zeros((f.size, n_loops))
    for loop in range(n_loops):
        loops[loop * blocks : (loop + 1) * blocks, loop] = f[loop * blocks : (loop + 1) * blocks]
    loops -= q @ (q.T @ loops)
    one = float((f @ r) ** 2 / max(float(f @ f), 1e-300))
    strengths = np.linalg.lstsq(loops, r, rcond=None)[0]
    each = float(r @ r - np.sum((r - loops @ strengths) ** 2))
    return each - one, one, -strengths


def misfit(before: Fit, after: Fit, beside: Sequence[Fit] = ()) -> str | None:
    """Why the force ``after`` adds to ``before`` is not the shape of what is left, with the forces of the
    :func:`partners` among ``beside`` projected out (:func:`shape_gain`), or None (:func:`own_shape`)."""
    from scipy.stats import chi2 as chi2_dist  # on first use: a fast CLI and island start

    n_loops = before.objective.harmonics.loops.n_loops
    if n_loops < 2:
        return None
    gain, one, strengths = shape_gain(before, after, beside)
    if gain - (n_loops - 1) <= OWN_SHAPE * one or gain <= chi2_dist.isf(SIGNIFICANCE, n_loops - 1):
        return None
    return (
        f"is not the shape of what is left: loop by loop it would need {np.min(strengths):.3g} to {np.max(strengths):.3g} times "
        f"its strength (and remove {100 * gain / max(one, 1e-300):.2g} % more)"
    )


def own_shape(before: Fit, after: Fit, beside: Sequence[Fit] = ()) -> str | None:
    """Why the force ``after`` adds to ``before`` is not the shape of what ``before`` leaves (rule 9), or None.

    In whitened harmonic coordinates, with the column space of ``before``'s Jacobian Q projected out
    (P = I - Q Q^T: the spring, dashpot, mass and effects the model has), f = P (e_after - e_before) is the
    effect's added force and r = P e_before what it is meant to explain. At one strength it removes
    (f.r)^2 / f.f; scaled loop by loop (f_l, zero outside loop l), what the L columns P f_l remove together. Their
    difference is a chi^2 of L - 1 degrees of freedom where the effect's shape is the residual's (the strengths
    differ by noise); it must not exceed both the family-wise ``SIGNIFICANCE`` level of that chi^2 and, less its
    mean L - 1, ``OWN_SHAPE`` of the one-strength removal (a share: a strong effect's small misfit of the data's
    extraction is no wrong shape).

    Two effects may be missing at once: on a softening isolator with Coulomb friction, the friction's strength
    refitted loop by loop takes up how the stiffness changes with amplitude until the amplitude-dependent frequency
    is in the model. So an effect refused so is judged again with the forces of the contenders ``beside`` (the other
    library effects refitted on ``before`` in the same step, one strength each; not those nearly parallel to its
    own, :func:`partners`) projected out with Q, and refused only if it fails there too."""
    alone = misfit(before, after)
    if alone is None or (beside and misfit(before, after, beside) is None):
        return None
    return alone


def judge(before: Fit, after: Fit, effects: tuple[str, ...], harmonics: Harmonics, own: bool = True, beside: Sequence[Fit] = ()) -> str | None:
    """Why ``after`` (``before`` plus ``effects``) is not taken by rules 1-3, 5-7 and 9 of the module docstring, or None;
    without rule 9 where not ``own``; rule 9 with the forces of the contenders ``beside`` projected out (:func:`own_shape`)."""
    delta = after.bic - before.bic
    if delta > -BIC_MARGIN:
        return f"BIC changes by only {delta:+.1f}"
    created = created_order(before, after)
    if created is not None:
        k, c0, c1 = created
        return f"adds order-{k} content the loops do not have (chi^2 of order {k}: {c0:.4g} -> {c1:.4g})"
    names, values, bounds = after.model.names, after.theta, after.model.bounds
    for effect in effects:
        term = effect_term(effect)
        if term.strength in names:
            i = names.index(term.strength)
            if bounds[i, 0] == 0.0 and values[i] <= 0.0:
                return f"{term.strength} has the unphysical sign"
    excess = before.chi2 - before.dof
    if excess > 0 and before.chi2 - after.chi2 < MIN_SHARE * excess:
        return f"removes only {100 * (before.chi2 - after.chi2) / excess:.0f}% of the chi^2 above the noise floor"
    worse = visible_error(before, after, harmonics)
    if worse is not None:
        return worse
    wrong = own_shape(before, after, beside) if own else None
    if wrong is not None:
        return wrong
    impossible = implausible_values(after, harmonics.loops)
    if impossible:
        name, why = next(iter(impossible.items()))
        return f"{name}: {why}"
    return None


def held_out(before: Fit, after: Fit, harmonics: Harmonics) -> str | None:
    """Why ``after`` predicts held-out frequencies no better than ``before`` (rule 8), or None (also with
    fewer than three frequencies, where there is nothing to hold out)."""
    old, new = cross_validated_rms(before, harmonics), cross_validated_rms(after, harmonics)
    if old is None or new is None or new < old:
        return None
    return f"predicts held-out frequencies no better (leave-one-frequency-out whitened RMS {old:.4g} -> {new:.4g})"
