"""A loop's force as harmonics of the phase (steps 4 and 6 of :mod:`hysid_model.extraction`, for
:mod:`hysid_model.branches`): their design rows, the force's smooth part (harmonics 0..K and a jump at the
reversals) that widened windows are fitted around, and the branch values of a record whose samples fall on too
few distinct phases for local fits (the harmonics below the sample rate's Nyquist order, at the branch phases).
"""

from __future__ import annotations

from functools import reduce

import numpy as np

DISTINCT = 1e-3
"""Sample phases closer than this fraction of a window apart count as one in the force's harmonics (averaged
first: a rate locked to the excitation repeats them, so the cost does not grow with the cycles)."""
CHUNK = 1 << 16
"""Samples whose harmonic design rows are built at once (:func:`smooth_part`)."""


def harmonic_design(theta: np.ndarray, harmonics: int) -> np.ndarray:
    """Rows 1, sin(k theta), cos(k theta) for k = 1..harmonics, ``(2 harmonics + 1, N)`` (angle-sum recurrence)."""
    design = np.empty((2 * harmonics + 1, theta.size))
    design[0] = 1.0
    np.sin(theta, out=design[1])
    np.cos(theta, out=design[2])
    s1, c1 = design[1], design[2]
    for k in range(2, harmonics + 1):
        s, c = design[2 * k - 3], design[2 * k - 2]
        np.multiply(s, c1, out=design[2 * k - 1])
        design[2 * k - 1] += c * s1
        np.multiply(c, c1, out=design[2 * k])
        design[2 * k] -= s * s1
    return design


def smooth_part(
    theta: np.ndarray,
    harmonics: int,
    gram: np.ndarray,
    projection: np.ndarray,
    psi: np.ndarray,
    hi: float,
    force: np.ndarray,
    at_branches: np.ndarray,
    design: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(the force less its smooth part, the smooth part at the 2n branch samples).

    The smooth part is the least-squares fit of the force's harmonics 0..K (``harmonics``; the samples at phases
    ``theta``, whose design rows give ``gram`` = design design^T and ``projection`` = design force;
    ``at_branches`` ``(2K + 1, 2n)`` at the branch samples, top then bottom) and of sgn(x'), +1 on the loading
    half cycle (half-cycle phases ``psi`` below ``hi``) and -1 on the unloading one: a friction jump at the
    reversals, which harmonics alone would ring around. The branch values are the local fits of what is left,
    plus the smooth part: a local quadratic is then biased only by what the smooth part misses (force content
    above order K other than a jump at the reversals), so its windows may widen without bias where a record's
    few distinct sample phases need it, and the force's harmonics (:func:`harmonic_branches`) are those of a
    force without the jump. The design rows are rebuilt ``CHUNK`` samples at a time, so the memory stays that of
    a few copies of the record; a record of at most ``CHUNK`` samples may pass its ``design`` rows, built already.
    """
    side = np.where(psi < hi, 1.0, -1.0)
    blocks = [slice(i, i + CHUNK) for i in range(0, theta.size, CHUNK)]
    rows = (lambda b: design[:, b]) if design is not None else (lambda b: harmonic_design(theta[b], harmonics))
    cross = reduce(np.add, (rows(b) @ side[b] for b in blocks))
    full = np.block([[gram, cross[:, None]], [cross[None, :], np.array([[float(side.size)]])]])
    coef = np.linalg.lstsq(full, np.append(projection, side @ force), rcond=None)[0]
    residual = force - coef[-1] * side
    for b in blocks:
        residual[b] -= coef[:-1] @ rows(b)
    n = at_branches.shape[1] // 2
    return residual, coef[:-1] @ at_branches + coef[-1] * np.repeat([1.0, -1.0], n)


def harmonic_branches(
    ps: np.ndarray, ys: np.ndarray, sample_phases: np.ndarray, h: float, samples_per_cycle: float
) -> tuple[np.ndarray, np.ndarray, float, float, int]:
    """Branch values of a record with few distinct sample phases: the force's harmonics 0..K by least
    squares over every sample (K below the sample rate's Nyquist order and the distinct phases'),
    evaluated at the branch phases.

    Exact for a force without content above order K, whatever the phases; content above K (a
    friction jump) is smoothed, as the samples themselves cannot resolve it. Samples at one phase
    (within ``DISTINCT``) are averaged first, so the cost does not grow with the cycles. The 2n values
    then carry 2K + 1 independent numbers: their variance factors are scaled by 2n / (2K + 1), so
    that the loop's sigma gives chi^2 and the Fisher information of the raw samples.
    """
    key = np.concatenate([[0], np.cumsum(np.diff(ps) > DISTINCT * h)])
    count = np.bincount(key).astype(float)
    phase = np.bincount(key, ps) / count
    mean = np.bincount(key, ys) / count
    k = int(max(1, min((samples_per_cycle - 1) // 2, (count.size - 1) // 2)))
    design = harmonic_design(phase, k)  # (2k + 1, distinct)
    gram_inv = np.linalg.inv((design * count) @ design.T)
    coef = gram_inv @ (design @ (count * mean))
    within = float(np.sum(ys * ys) - np.sum(count * mean * mean))
    between = float(np.sum(count * (mean - coef @ design) ** 2))
    sigma_raw = float(np.sqrt(max(within + between, 0.0) / max(ys.size - (2 * k + 1), 1)))
    at = harmonic_design(sample_phases, k)
    var = np.einsum("in,ij,jn->n", at, gram_inv, at)
    overlap = max(1.0, sample_phases.size / (2 * k + 1))
    return coef @ at, var * overlap, sigma_raw, overlap, k
