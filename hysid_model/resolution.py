"""Whether extraction resolves a record's force at the motion reversals (step 4 of :mod:`hysid_model.extraction`).

A branch value at a reversal is a one-sided local-quadratic fit of the force
over a phase window ``END_WINDOW`` interior widths wide (:mod:`hysid_model.branches`).
A smooth force is a quadratic there, and its value is unbiased. A force with a
cusp at the reversal, as a fluid damper's c |v|^alpha with alpha < 1, is not:
the fitted value is off by about c (w X0 W)^alpha times a constant, a bias that
a long record's many cycles make many times its noise (c |v|^0.4 at 100
points per branch: 50 standard errors at each of the four reversal samples,
4.9 x the noise in the loop's RMS residual), and a jump that a channel delay
moves just past the reversal is smeared the same way. A model would then be
judged against an extraction error, not against the device; more points per
branch shrink the window but hardly the bias (as W^alpha, while the noise
grows as W^-1/2).

The finer extraction tells: each reversal value is fitted again on the half
window. For a smooth force both agree within the noise of their difference
(the half window's variance less the whole one's: the whole window's fit is
the efficient one of the nested pair); a cusp or a smeared jump makes them
differ. :func:`reversal_steps` gives these differences in standard errors, and
:func:`reversals_resolved` tests a whole set's (a device's law is the same in
every loop): where they are grossly more than noise, the four reversal samples of each
loop are left out of what the model must explain (:meth:`hysid_model.loops.LoopSet.kept`),
for ``hysid fit``, campaigns and the diagnosis alike.
"""

from __future__ import annotations

import numpy as np

from hysid_model.branches import phase_windows
from hysid_model.phase_sums import CONDITION, MIN_SAMPLES

ALPHA = 1e-3
"""Level at which a set's reversal differences are taken to be more than noise."""
GROSS = 4.0
"""...and the mean squared difference (in standard errors) beyond which they are gross. A mild excess (differences of
about 1.5 standard errors: a Bouc-Wen knee or a friction jump near the reversal at 100 points per branch) is a bias of
a few standard errors at four of the 2n samples of a loop, within what the true law fits to the noise floor, and those
samples carry most of what tells a friction jump from a hysteretic spring: they are kept. A cusp is gross (a fluid
damper's |v|^0.4: 177), as is a smeared jump (Coulomb friction behind a 0.2 ms delay: 5,233)."""


def _one_sided(ps: np.ndarray, ys: np.ndarray, centre: float, lo: float, hi: float, width: float) -> tuple[float, float]:
    """(value at ``centre``, variance factor [(U^T U)^-1]_00) of the local quadratic in u = (phase - centre) / width
    over the samples with phases in [lo, hi); NaN where they do not determine it (``MIN_SAMPLES``, ``CONDITION``)."""
    a, b = np.searchsorted(ps, lo), np.searchsorted(ps, hi)
    if b - a < MIN_SAMPLES:
        return np.nan, np.nan
    u = (ps[a:b] - centre) / width
    design = np.stack([np.ones_like(u), u, u * u], axis=1)
    s, t = (lo - centre) / width, (hi - centre) / width
    even = [(t ** (p + 1) - s ** (p + 1)) / ((p + 1) * (t - s)) for p in range(5)]
    try:
        inverse = np.linalg.inv(design.T @ design)
        ideal = np.linalg.inv(np.array([[even[i + j] for j in range(3)] for i in range(3)]))[0, 0]
    except np.linalg.LinAlgError:
        return np.nan, np.nan
    factor = float(inverse[0, 0])
    if not (factor > 0 and factor * (b - a) <= CONDITION * ideal):
        return np.nan, np.nan
    return float((inverse @ (design.T @ ys[a:b]))[0]), factor


def reversal_steps(
    psi: np.ndarray, force: np.ndarray, sample_phases: np.ndarray, reversal: tuple[float, float], guard: float, sigma_raw: float, order: np.ndarray
) -> np.ndarray:
    """``(4,)``: each of the four reversal values (loading at the minimum and at the maximum, unloading at the
    minimum and at the maximum) less its fit on the half window, in standard errors of that difference; NaN
    where the samples do not determine the narrower fit. ``psi``: the samples' half-cycle phases and ``force``
    their force (centred); ``sample_phases`` the 2n branch phases; ``reversal`` = (lo, hi); ``guard``: samples
    this close to a reversal are left out (:func:`hysid_model.branches.reversal_guard`); ``order``: the stable argsort
    of ``psi``, as :func:`hysid_model.branches.branch_values` sorts them."""
    n = sample_phases.size // 2
    _, start, width, half_lo, half_hi, h = phase_windows(sample_phases, *reversal)
    ps, ys = psi[order], force[order]
    out = np.full(4, np.nan)
    for k, i in enumerate((0, n - 1, n, 2 * n - 1)):
        centre, forward = float(sample_phases[i]), start[i] == 0.0
        fits = []
        for w in (width[i] * h, 0.5 * width[i] * h):
            g = min(guard, 0.5 * h)
            lo, hi = (centre + g, centre + w) if forward else (centre - w, centre - g)
            fits.append(_one_sided(ps, ys, centre, max(lo, half_lo[i] + g), min(hi, half_hi[i] - g), w))
        (v0, f0), (v1, f1) = fits
        if np.isfinite(v0) and np.isfinite(v1) and f1 > f0:
            out[k] = (v0 - v1) / (sigma_raw * np.sqrt(f1 - f0))
    return out


def reversals_resolved(steps: list[np.ndarray]) -> tuple[bool, str]:
    """Whether the reversal differences ``steps`` of a set's records (:func:`reversal_steps`) are noise (chi^2
    at ``ALPHA``), and in words what follows for the fits."""
    from scipy.stats import chi2 as chi2_dist  # on first use: a fast CLI and island start

    z = np.concatenate([np.ravel(s) for s in steps]) if steps else np.zeros(0)
    z = z[np.isfinite(z)]
    if z.size == 0:
        return True, "the force at the motion reversals cannot be tested against a finer extraction (too few samples there)"
    chi2 = float(np.sum(z * z))
    if chi2_dist.sf(chi2, z.size) > ALPHA or chi2 <= GROSS * z.size:
        return True, f"the force at the motion reversals is resolved (fits on half windows agree within a mild bias: chi^2/dof {chi2 / z.size:.3g})"
    return False, (
        f"the force at the motion reversals is not resolved (fits on half windows differ: chi^2/dof {chi2 / z.size:.3g}; "
        "a cusp such as a fluid damper's |v|^alpha, or a jump a delay moves past the reversal): the four reversal "
        "samples of each loop are left out of the fits"
    )
