"""Every loop reduced to its harmonics, with their noise (the diagnosis' data).

Referenced to the measured displacement x = X0 sin(wt) (Eq. 4.5), the force of
a loop is F(wt) = a0 + sum_k [s_k sin(k wt) + c_k cos(k wt)] + higher orders.
``s_k`` is the part in phase with the displacement (springs, inertia), ``c_k``
the quadrature part (in phase with the velocity); only c1 dissipates energy,
pi X0 c1 per cycle. Orders 0-7 are fitted by least squares to the samples of
both branches. The same projection is applied to the model's force, so content
above order 7 (a friction jump) aliases identically into data and model.

With independent force noise of standard deviation sigma_j per sample, the
coefficients of loop j have covariance sigma_j^2 (Phi^T Phi)^-1. With
Phi = Q R (QR), ``Q^T f / sigma_j`` are the whitened coefficients: unit
variance, independent, and ``||Q^T (model - data)||^2 / sigma_j^2`` is the
loop's chi^2 on its 15 harmonic coefficients. Samples that extraction could not
resolve (:meth:`hysid_model.loops.LoopSet.kept`) are left out of the projection. :class:`HarmonicObjective` fits
a model on them (the sum of squares is that chi^2 over all loops).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from hysid_model.basis import design_matrix, harmonic_names
from hysid_model.errors import HysidInputError
from hysid_model.loops import LoopSet, at_loops
from hysid_model.model import Model
from hysid_model.objective import ModelSpace, Objective

MAX_ORDER = 7
ROBUST_SCALE = 1.4826
"""MAD -> standard deviation for Gaussian noise."""


def estimate_sigma(loops: LoopSet) -> np.ndarray:
    """Force-noise std of each loop from second differences along each branch.

    d_i = F_{i+1} - 2 F_i + F_{i-1} has variance 6 sigma^2 for white noise and
    hardly sees the smooth loop shape (nor a friction jump, which lies between
    the branches); the median makes the few samples at the turning points,
    where F(x) is steep, irrelevant.
    """
    d2 = np.concatenate([np.diff(loops.top[:, :, 1], 2, axis=1), np.diff(loops.bottom[:, :, 1], 2, axis=1)], axis=1)
    sigma = ROBUST_SCALE * np.median(np.abs(d2), axis=1) / np.sqrt(6.0)
    return np.maximum(sigma, 1e-12 * np.maximum(loops.peak_force, 1e-300))


@dataclass
class Harmonics:
    """Harmonic coefficients ``coef`` (L, M) of every loop, named ``names``, with their noise."""

    loops: LoopSet
    names: list[str]
    coef: np.ndarray
    sigma: np.ndarray
    sigma_known: np.ndarray
    q: np.ndarray
    r: np.ndarray

    PER_LOOP: ClassVar[tuple[str, ...]] = ("coef", "sigma", "sigma_known", "q", "r")
    """The array fields indexed ``[loop, ...]`` (:meth:`subset` takes them at the loops it keeps)."""

    @classmethod
    def from_loops(cls, loops: LoopSet, max_order: int = MAX_ORDER) -> Harmonics:
        """Reduce ``loops``; sigma is the loop set's where known, else :func:`estimate_sigma`."""
        names = harmonic_names(max_order)
        if loops.n_samples * 2 <= len(names):
            raise HysidInputError(f"{loops.name}: {loops.n_samples} samples per branch are too few for harmonics up to order {max_order}")
        phi = design_matrix(names, loops.phases(), loops.n_samples) * loops.kept()[:, :, None]  # samples left out weigh nothing
        q, r = np.linalg.qr(phi)
        known = np.isfinite(loops.sigma) & (loops.sigma > 0)
        sigma = np.where(known, loops.sigma, estimate_sigma(loops))
        coef = np.linalg.solve(r, np.einsum("lnm,ln->lm", q, loops.forces())[..., None])[..., 0]
        return cls(loops=loops, names=names, coef=coef, sigma=sigma, sigma_known=known, q=q, r=r)

    def __repr__(self) -> str:
        return f"<Harmonics of {self.loops.name}: {self.coef.shape[0]} loops x {self.coef.shape[1]} coefficients ({self.names[0]} .. {self.names[-1]})>"

    @property
    def n_coefficients(self) -> int:
        return int(self.coef.size)

    @property
    def covariance(self) -> np.ndarray:
        """``(L, M, M)``: sigma^2 (R^T R)^-1."""
        r_inv = np.linalg.inv(self.r)
        return self.sigma[:, None, None] ** 2 * np.einsum("lij,lkj->lik", r_inv, r_inv)

    @property
    def stderr(self) -> np.ndarray:
        return np.sqrt(np.einsum("lii->li", self.covariance))

    def whiten(self, force: np.ndarray) -> np.ndarray:
        """Whitened harmonic coordinates Q^T f / sigma of forces ``(..., L, 2n)`` -> ``(..., L, M)``."""
        return np.einsum("lnm,...ln->...lm", self.q, force) / self.sigma[:, None]

    def project(self, force: np.ndarray) -> np.ndarray:
        """Harmonic coefficients of forces ``(..., L, 2n)`` sampled like the loops -> ``(..., L, M)``."""
        qf = np.einsum("lnm,...ln->...lm", self.q, force)
        return np.linalg.solve(self.r, qf[..., None])[..., 0]

    def orders(self) -> np.ndarray:
        """Harmonic order of every coefficient, ``(M,)``."""
        return np.array([0 if n == "dc" else int(n[1:]) for n in self.names])

    def energy_per_cycle(self, coef: np.ndarray) -> np.ndarray:
        """Energy dissipated per cycle, the loop area pi X0 c1 (J), from coefficients ``(..., L, M)``."""
        return np.pi * self.loops.x0 * coef[..., self.names.index("c1")]

    def subset(self, index: np.ndarray) -> Harmonics:
        """These harmonics at the loops ``index`` (:func:`~hysid_model.loops.at_loops`)."""
        idx = np.asarray(index, dtype=int)
        return at_loops(self, idx, self.PER_LOOP, loops=self.loops.subset(idx))


class HarmonicObjective(ModelSpace):
    """Chi^2 of a model on the whitened harmonic coefficients of all loops; lower is better.

    Same contract as :class:`hysid_model.objective.Objective` (``__call__`` on a
    population, ``weighted_residuals``, ``jacobian``, ``bounds``), so the
    optimizers and the polish step run on it unchanged. The closed-form
    features are whitened once, Q^T Phi / sigma, so they cost O(L x 15 x
    features) per candidate; the per-sample force of a model with memory is
    evaluated on the samples (compiled, :mod:`hysid_model.sampled`) and whitened.
    """

    JACOBIAN_STEP = 1e-6
    """Central-difference step relative to max(|theta|, 1e-3 x the bound range), kept inside the bounds."""

    def __init__(self, harmonics: Harmonics, model: Model) -> None:
        self.harmonics = harmonics
        self.model = model
        self.objective = Objective(harmonics.loops, model, weights="thesis")
        self.target = harmonics.whiten(harmonics.loops.forces())
        self.design = np.matmul(harmonics.q.transpose(0, 2, 1), self.objective.phi) / harmonics.sigma[:, None, None]
        self.evaluations = 0

    def whitened(self, pop: np.ndarray) -> np.ndarray:
        """Whitened residual coefficients (model - data), ``(P, L, M)``: the closed-form features through
        the whitened design, plus the per-sample force (memory terms) whitened sample by sample."""
        pop = np.atleast_2d(np.asarray(pop, dtype=float))
        coefs = self.model.coefficients(pop, self.objective.kin)
        a = np.stack([coefs[name] for name in self.objective.features], axis=-1)
        out = np.matmul(a.transpose(1, 0, 2), self.design.transpose(0, 2, 1)).transpose(1, 0, 2) - self.target
        memory = self.objective.memory_force(pop)
        if memory is not None:
            out += np.matmul(memory.transpose(1, 0, 2), self.harmonics.q).transpose(1, 0, 2) / self.harmonics.sigma[:, None]
        return out

    def __call__(self, pop: np.ndarray) -> np.ndarray:
        pop = np.atleast_2d(np.asarray(pop, dtype=float))
        self.evaluations += pop.shape[0]
        with np.errstate(all="ignore"):
            chi2 = np.sum(self.whitened(pop) ** 2, axis=(1, 2))
        return np.where(np.isfinite(chi2), chi2, np.inf)

    def weighted_residuals(self, theta: np.ndarray) -> np.ndarray:
        """Flat whitened residuals; their sum of squares is the chi^2."""
        return self.residual_rows(np.asarray(theta, dtype=float).reshape(1, -1))[0]

    def residual_rows(self, pop: np.ndarray) -> np.ndarray:
        """:meth:`weighted_residuals` of each row of ``pop`` ``(P, D)`` in one call, ``(P, L*M)``."""
        pop = np.atleast_2d(np.asarray(pop, dtype=float))
        self.evaluations += pop.shape[0]
        return self.whitened(pop).reshape(pop.shape[0], -1)

    def jacobian(self, theta: np.ndarray, weighted: bool = True) -> np.ndarray:
        """d(whitened residuals)/d(theta), ``(L*M, D)``, by central differences (``weighted`` only mirrors the Objective's signature).

        Parameters span many decades (a yield displacement of microns within
        [1e-9, 1] m), so the step follows the value; probes never leave the bounds.
        """
        theta = np.asarray(theta, dtype=float).reshape(-1)
        lower, upper = self.bounds[:, 0], self.bounds[:, 1]
        h = self.JACOBIAN_STEP * np.maximum(np.abs(theta), 1e-3 * (upper - lower))
        up = np.minimum(theta + h, upper)
        down = np.maximum(theta - h, lower)
        white = self.whitened(np.concatenate([np.where(np.eye(self.dim, dtype=bool), up, theta), np.where(np.eye(self.dim, dtype=bool), down, theta)]))
        white = white.reshape(2 * self.dim, -1)
        self.evaluations += 2 * self.dim
        return ((white[: self.dim] - white[self.dim :]) / (up - down)[:, None]).T
