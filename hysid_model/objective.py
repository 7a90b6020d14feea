"""The identification objective of Eq. 3.3 / Fig. 5.1, vectorized over a population.

For every loop j the model force is compared with the measured force at every
sample of both branches (top and bottom, Fig. 5.1), and the squared errors are
summed with a loop weight (Appendix A, ``erreval``/``loopsweights``):

* ``thesis``: w_j = (maxF_all / maxF_j) / NOS_j, NOS_j = samples of loop j;
* ``ml``: w_j = 1 / sigma_j^2 (maximum likelihood for Gaussian force noise).

The model is driven by each loop's motion as the loop set holds it
(:meth:`~hysid_model.loops.LoopSet.kinematics`): the measured harmonics
(:mod:`hysid_model.waveform`) where extraction found them and they are the
motion, else the fundamental, the ideal sine of Eq. 4.5. Because the force is linear in basis features
with parameter-dependent
coefficients a (:mod:`hysid_model.basis`), each loop's sum of squares is exact
in closed form, ||Phi a - y||^2 = (a - a*)^T G (a - a*) + r_min, with the Gram
matrix G = Phi^T Phi, the least-squares coefficients a* and their residual
r_min precomputed once. A population of P candidates costs O(P L M^2) instead
of O(P L N) and needs no interpolation or time integration. Models with memory
terms (or the sign of the velocity behind a measurement chain) add a force
evaluated sample by sample, by compiled kernels at the loops' fixed phases
(:mod:`hysid_model.sampled`; ``compiled=False`` keeps the numpy reference).
Samples that extraction could not resolve (the reversal samples of a force
with a cusp there, :mod:`hysid_model.resolution`) count in no sum of squares.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from hysid_model.basis import design_matrix
from hysid_model.errors import HysidInputError
from hysid_model.kinematics import Kinematics
from hysid_model.loops import LoopSet
from hysid_model.model import Model
from hysid_model.terms import ModalState, Values

if TYPE_CHECKING:
    from hysid_model.sampled import SampledMemory

Modal = tuple[Values, ModalState]
"""Parameter values and modal state of a population (:meth:`hysid_model.model.Model.modal_state`)."""

WEIGHTS = ("thesis", "ml")
BLOCK_ELEMENTS = 1 << 13
"""Candidates x loops per block of ``Objective.__call__`` (closed form): 64 KiB
temporaries stay in cache and below glibc's mmap threshold, which is ~5x faster
than one pass over a whole 6000-candidate population."""
MEMORY_BLOCK_ELEMENTS = 1 << 22
"""Candidates x loops x samples per block of the numpy reference for per-sample forces (32 MiB arrays)."""
SAMPLED_BLOCK_ELEMENTS = 1 << 18
"""Candidates x loops x samples per block of the compiled per-sample force (2 MiB: it stays in cache
between the kernel that writes it and the one that sums the squares)."""


def loop_weights(loops: LoopSet, scheme: str) -> np.ndarray:
    """Per-loop weights of the objective (see module docstring)."""
    if scheme == "thesis":
        peak = loops.peak_force
        if np.any(peak <= 0):
            raise HysidInputError(f"{loops.name}: a loop has zero peak force, so the thesis weights maxF_all/maxF_j are undefined")
        return (peak.max() / peak) / (2 * loops.n_samples)
    if scheme == "ml":
        if not loops.has_sigma:
            bad = [loops.labels[j] for j in np.flatnonzero(~(np.isfinite(loops.sigma) & (loops.sigma > 0)))]
            raise HysidInputError(
                f"{loops.name}: maximum-likelihood weights need each loop's noise sigma; "
                f"{len(bad)} loop(s) have none (first: {bad[0]}); use the thesis weights",
                param="weights",
                value="ml",
            )
        return 1.0 / loops.sigma**2
    raise HysidInputError(f"unknown weights; choose one of {', '.join(WEIGHTS)}", param="weights", value=scheme)


def sampled_memory(model: Model, kin: Kinematics, phase: np.ndarray, n_top: int) -> SampledMemory | None:
    """:meth:`Model.memory_force` at the fixed ``phase`` of a loop set for any population, compiled
    (:class:`hysid_model.sampled.SampledMemory`); None for a model without per-sample force. Imported here, not
    with this module: numba loads with the first objective that needs it (``hysid --help`` never does)."""
    if not model.has_memory:
        return None
    from hysid_model.sampled import SampledMemory

    return SampledMemory(model, kin, phase, n_top)


class Bounded(ABC):
    """A search space: ``bounds`` ``(dim, 2)``, the lower and upper bound of each of its ``dim`` parameters."""

    @property
    @abstractmethod
    def bounds(self) -> np.ndarray:
        """``(dim, 2)`` lower and upper bounds (each subclass says where they come from)."""

    @property
    def dim(self) -> int:
        return int(self.bounds.shape[0])


class ModelSpace(Bounded):
    """An objective over a model's parameters: the search space (``bounds``, ``dim``) is the model's."""

    model: Model

    @property
    def bounds(self) -> np.ndarray:
        """``(dim, 2)`` lower and upper bounds of the model's parameters."""
        return self.model.bounds


class Objective(ModelSpace):
    """Weighted sum of squared force errors over all loops; lower is better."""

    def __init__(self, loops: LoopSet, model: Model, weights: str = "thesis", compiled: bool = True) -> None:
        self.loops = loops
        self.model = model
        self.weights = weights
        self.kin = loops.kinematics()
        self.phase = loops.phases()
        self.y = loops.forces()
        self.keep = loops.kept()
        """The samples the model must explain (:meth:`LoopSet.kept`): the rest count in no sum of squares."""
        self._masked = not bool(self.keep.all())
        self._y = self.y * self.keep
        self.loop_weight = loop_weights(loops, weights)
        self.evaluations = 0
        probe = model.bounds.mean(axis=1)[None, :]
        self.features = list(model.coefficients(probe, self.kin))
        full = design_matrix(self.features, self.phase, loops.n_samples)
        self.phi = full * self.keep[:, :, None] if self._masked else full
        """The features at every sample kept (0 at the others), ``(L, 2n, M)``."""
        self._features = np.ascontiguousarray(self.phi.transpose(0, 2, 1))
        self._all_features = np.ascontiguousarray(full.transpose(0, 2, 1)) if self._masked else self._features
        self.sampled = sampled_memory(model, self.kin, self.phase, loops.n_samples) if compiled else None
        """The per-sample force compiled at these loops' phases (:mod:`hysid_model.sampled`); None for a
        memoryless model or ``compiled=False`` (the numpy reference :meth:`Model.memory_force`)."""
        if self.sampled is not None:  # compile (or load from the disk cache) here, not in the first evaluation
            self._sse(probe)
        if model.has_memory:
            block = SAMPLED_BLOCK_ELEMENTS if self.sampled is not None else MEMORY_BLOCK_ELEMENTS
            self._block_rows = max(1, block // (loops.n_loops * 2 * loops.n_samples))
        else:
            self._block_rows = max(1, BLOCK_ELEMENTS // loops.n_loops)

    @cached_property
    def gram(self) -> np.ndarray:
        """Gram matrices Phi^T Phi of the features, ``(L, M, M)``."""
        return np.einsum("lnm,lnk->lmk", self.phi, self.phi)

    @cached_property
    def a_star(self) -> np.ndarray:
        """Least-squares feature coefficients of each loop, ``(L, M)``."""
        return np.stack([np.linalg.lstsq(p, y, rcond=None)[0] for p, y in zip(self.phi, self._y)])

    @cached_property
    def r_min(self) -> np.ndarray:
        """Each loop's least-squares residual sum of squares, ``(L,)``."""
        return np.sum((np.einsum("lnm,lm->ln", self.phi, self.a_star) - self._y) ** 2, axis=1)

    @cached_property
    def _gram_terms(self) -> list[tuple[int, int, np.ndarray]]:
        m = len(self.features)
        return [(i, k, self.gram[:, i, k] * (1.0 if i == k else 2.0)) for i in range(m) for k in range(i, m)]

    def _coefficients(self, pop: np.ndarray, modal: Modal | None = None) -> list[np.ndarray]:
        coefs = self.model.measured_coefficients(*(modal or self.model.modal_state(pop, self.kin)), self.kin)
        if set(coefs) != set(self.features):
            raise RuntimeError(f"model features changed between candidates: {sorted(coefs)} vs {self.features}")
        return [coefs[name] for name in self.features]

    def _coefficient_array(self, pop: np.ndarray, modal: Modal | None = None) -> np.ndarray:
        return np.stack(self._coefficients(pop, modal), axis=-1)

    def _sse(self, pop: np.ndarray) -> np.ndarray:
        """Unweighted sum of squared errors per candidate and loop, ``(P, L)``.

        Memoryless models use the Gram form of the module docstring, written out
        as sum over feature pairs i <= k of (2 - [i == k]) G_ik d_i d_k with
        d = a - a* (for the few features of a model this beats a generic einsum).
        """
        if self.sampled is not None:
            modal = self.model.modal_state(pop, self.kin)
            return self.sampled.sum_of_squares(modal, self._coefficient_array(pop, modal), self._features, self._y, self.keep if self._masked else None)
        if self.model.has_memory:
            return np.sum(((self.predict(pop) - self.y) * self.keep) ** 2, axis=2)
        d = [c - self.a_star[:, m] for m, c in enumerate(self._coefficients(pop))]
        sse = np.broadcast_to(self.r_min, d[0].shape)
        for i, k, g in self._gram_terms:
            sse = sse + g * (d[i] * d[k])
        return sse

    def __call__(self, pop: np.ndarray) -> np.ndarray:
        """Fitness of each row of a ``(P, D)`` population (or one ``(D,)`` vector).

        The population is evaluated in blocks of rows (see ``BLOCK_ELEMENTS``).
        """
        pop = np.atleast_2d(np.asarray(pop, dtype=float))
        self.evaluations += pop.shape[0]
        rows = self._block_rows
        with np.errstate(all="ignore"):
            fitness = np.concatenate([self._sse(pop[i : i + rows]) @ self.loop_weight for i in range(0, max(pop.shape[0], 1), rows)])
        return np.where(np.isfinite(fitness), fitness, np.inf)

    def predict(self, pop: np.ndarray) -> np.ndarray:
        """Model force at every sample, ``(P, L, 2n)`` (top branch first), those left out (:attr:`keep`) included."""
        pop = np.atleast_2d(np.asarray(pop, dtype=float))
        modal = self.model.modal_state(pop, self.kin)
        force = np.ascontiguousarray(np.matmul(self._coefficient_array(pop, modal).transpose(1, 0, 2), self._all_features).transpose(1, 0, 2))
        if self.sampled is not None:
            return self.sampled.force(modal, out=force)
        memory = self.model.memory_force(pop, self.kin, self.phase)
        return force if memory is None else force + memory

    def memory_force(self, pop: np.ndarray) -> np.ndarray | None:
        """The per-sample part of the model force (memory terms, sgn through the chain), ``(P, L, 2n)``, or None."""
        if self.sampled is not None:
            return self.sampled.force(self.model.modal_state(np.atleast_2d(np.asarray(pop, dtype=float)), self.kin))
        return self.model.memory_force(pop, self.kin, self.phase)

    def residuals(self, theta: np.ndarray) -> np.ndarray:
        """Model minus measured force per loop and sample, ``(L, 2n)``, those left out (:attr:`keep`) included."""
        return self.predict(np.asarray(theta, dtype=float).reshape(1, -1))[0] - self.y

    def weighted_residuals(self, theta: np.ndarray) -> np.ndarray:
        """Flat residual vector whose sum of squares is the objective (for least squares)."""
        return self.residual_rows(np.asarray(theta, dtype=float).reshape(1, -1))[0]

    def residual_rows(self, pop: np.ndarray) -> np.ndarray:
        """:meth:`weighted_residuals` of each row of ``pop`` ``(P, D)`` in one call, ``(P, L*2n)``."""
        pop = np.atleast_2d(np.asarray(pop, dtype=float))
        return ((self.predict(pop) - self.y) * (self.keep * np.sqrt(self.loop_weight)[:, None])).reshape(pop.shape[0], -1)

    def jacobian(self, theta: np.ndarray, weighted: bool = True) -> np.ndarray:
        """d(residuals)/d(theta), ``(L*2n, D)``, by central differences on the closed form."""
        theta = np.asarray(theta, dtype=float).reshape(-1)
        span = self.bounds[:, 1] - self.bounds[:, 0]
        h = 1e-6 * np.maximum(span, 1e-12)
        probes = np.concatenate([theta + np.diag(h), theta - np.diag(h)])
        pred = self.predict(probes)
        d = self.dim
        jac = ((pred[:d] - pred[d:]) * self.keep / (2.0 * h)[:, None, None]).reshape(d, -1).T
        if weighted:
            jac = jac * np.repeat(np.sqrt(self.loop_weight), 2 * self.loops.n_samples)[:, None]
        return jac

    def per_loop_sse(self, theta: np.ndarray) -> np.ndarray:
        """Unweighted sum of squared errors of each loop for one parameter vector (over the samples kept)."""
        return np.sum((self.residuals(theta) * self.keep) ** 2, axis=1)
