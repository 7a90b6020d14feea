"""Whether the force samples in a phase window determine a local quadratic (:mod:`hysid_model.branches`): the
window's Gram matrix from prefix sums of the sorted sample phases' powers (:class:`PhaseSums`), its branch value's
variance factor v = [(U^T U)^-1]_00, and the test against as many samples spread evenly (``CONDITION``,
``MIN_SAMPLES``), so that windows are chosen before the one pass that fits them.
"""

from __future__ import annotations

from math import comb

import numpy as np

CONDITION = 4.0
"""A window is used when its branch value's variance is at most this many times that of as many samples spread
evenly over it. Samples bunched on two or three phases (a sample rate that is a ratio of small integers times the
frequency repeats a few phases, each smeared a little by the frequency's error) fail it, however many they are."""
MIN_SAMPLES = 20
"""Fewest samples in a window. A few samples at random phases (a short record) determine a quadratic by chance
well or badly, and the worst windows then set the loop's sigma: the variance factor of 6 random samples is 3.8
times that of evenly spread ones on average (17 times for one window in a hundred), of 20 samples 1.1 (1.8)."""


_BINOMIAL = np.array([[comb(p, k) for p in range(5)] for k in range(5)], dtype=float)
"""``[k, p]``: C(p, k), 0 for k > p (:meth:`PhaseSums.moments`)."""
_POWER_OF_SUMS = np.repeat(np.arange(5)[:, None], 5, axis=1)
_POWER_OF_SHIFT = np.maximum(np.arange(5)[None, :] - np.arange(5)[:, None], 0)


def concatenated_ranges(first: np.ndarray, stop: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(owner, position) of every element of the ranges [first_j, stop_j)."""
    counts = stop - first
    owner = np.repeat(np.arange(first.size), counts)
    position = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts - first, counts)
    return owner, position


class PhaseSums:
    """Prefix sums of the powers 0..4 of the sorted sample phases, each about the centre of its block of phases
    (blocks ``h`` wide): the local-quadratic Gram matrix of any window from the few blocks it spans, to choose
    windows before the one pass that fits them.

    Powers of the phases themselves (up to 2 pi) summed over a long record lose the digits that a window h wide
    needs (the variance came out 30 % off at 100 points per branch, and meaningless at 300); about their block's
    centre they stay below (h/2)^k.
    """

    def __init__(self, ps: np.ndarray, h: float) -> None:
        self.ps, self.h = ps, h
        n_blocks = int((ps[-1] - ps[0]) / h) + 1
        self.edges = np.searchsorted(ps, ps[0] + h * np.arange(n_blocks + 1))
        self.edges[-1] = ps.size
        self.ref = ps[0] + h * (np.arange(n_blocks) + 0.5)
        d = (ps - np.repeat(self.ref, np.diff(self.edges))) / h
        self.cum = np.empty((5, ps.size + 1))
        self.cum[:, 0] = 0.0
        self.cum[0, 1:] = np.arange(1, ps.size + 1)
        power = d.copy()
        for k in range(1, 5):
            np.cumsum(power, out=self.cum[k, 1:])
            if k < 4:
                power *= d

    def moments(self, centre: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """``(5, W)``: sum u^p, p = 0..4, u = (phase - centre) / h, over the samples in each window [lo, hi): per
        block spanned, the block's sums shifted from its centre to the window's (binomial expansion), all orders
        in a few whole-array operations (a record's windows are chosen in about seven such calls)."""
        a, b = np.searchsorted(self.ps, lo), np.searchsorted(self.ps, hi)
        first = np.searchsorted(self.edges, a, side="right") - 1
        stop = np.where(b > a, np.searchsorted(self.edges, b - 1, side="right"), first)
        owner, block = concatenated_ranges(first, stop)
        begin, end = np.maximum(a[owner], self.edges[block]), np.minimum(b[owner], self.edges[block + 1])
        s = self.cum[:, end] - self.cum[:, begin]
        e = (self.ref[block] - centre[owner]) / self.h
        powers = np.empty_like(s)
        for m in range(5):
            powers[m] = e**m
        terms = _BINOMIAL[:, :, None] * s[_POWER_OF_SUMS] * powers[_POWER_OF_SHIFT]  # [k, p]: C(p, k) s_k e^(p - k), 0 for k > p
        shifted = terms[0] + terms[1]
        for k in range(2, 5):
            shifted += terms[k]
        bins = (np.arange(5)[:, None] * centre.size + owner).ravel()
        return np.bincount(bins, shifted.ravel(), minlength=5 * centre.size).reshape(5, centre.size)

    def variance(self, centre: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """[(U^T U)^-1]_00 of the windows [lo, hi) about ``centre`` (inf where the samples do not determine a quadratic)."""
        return _inverse_00(self.moments(centre, lo, hi))

    def conditioned(self, centre: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(whether the windows [lo, hi) hold ``MIN_SAMPLES`` samples that determine a local quadratic about ``centre``
        nearly as well as as many samples spread evenly over the window (``CONDITION``), their :meth:`variance`)."""
        m = self.moments(centre, lo, hi)
        a, b = (lo - centre) / self.h, (hi - centre) / self.h
        span = np.maximum(b - a, 1e-300)
        even = _inverse_00([(b ** (p + 1) - a ** (p + 1)) / ((p + 1) * span) for p in range(5)])
        v = _inverse_00(m)
        with np.errstate(invalid="ignore"):
            return (m[0] >= MIN_SAMPLES) & (v * m[0] <= CONDITION * even), v


def _inverse_00(m: np.ndarray | list[np.ndarray]) -> np.ndarray:
    """[M^-1]_00 of the 3 x 3 moment matrices M_ij = m_(i+j) (Cramer's rule; inf where M is singular)."""
    minor = m[2] * m[4] - m[3] * m[3]
    det = m[0] * minor - m[1] * (m[1] * m[4] - m[2] * m[3]) + m[2] * (m[1] * m[3] - m[2] * m[2])
    with np.errstate(divide="ignore", invalid="ignore"):
        v = minor / det
    return np.where(np.isfinite(v) & (det > 0) & (v > 0), v, np.inf)
