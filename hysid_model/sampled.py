"""The per-sample force of a model at the fixed phases of a loop set, compiled (:mod:`hysid_model.bouc_wen_kernels`,
:mod:`hysid_model.shifted_kernels`, :mod:`hysid_model.squares_kernels`).

:meth:`hysid_model.model.Model.memory_force` is the numpy reference: the
memory terms' force and, behind a measurement chain, the sign-of-velocity
feature, at any phases. An objective evaluates it at the same phases for every
candidate, so :class:`SampledMemory` prepares what depends only on the loops
once and evaluates a population through the kernels:

* memory terms through their :meth:`~hysid_model.terms.Term.sampler`
  (Bouc-Wen: its exact orbit, one multiply-add per sample on a uniform travel
  grid; a user's terms: their numpy law at motion prepared once,
  :mod:`hysid_model.user_laws`), at phases delayed by the chain's delay;
* F sgn(x') delayed and through a single-pole high-pass exactly: the periodic
  response of G = s / (s + w_c) to the square wave sgn(x') is exponential
  between the reversals (:func:`hysid_model.shifted_kernels.velocity_sign_chain`);
  the reference sums its first 128 harmonics (``CHAIN_ORDERS``) instead. A
  jump the delay moves into a sample's cell is averaged over the cell in both
  (:func:`hysid_model.waveform.sample_cells`).

What the kernels do not cover is evaluated by the reference, whole: a memory
term without a sampler, a memory term behind a chain with a gain (the
spectral filtering of ``Model._through_chain``), or a gain that is not one
single-pole high-pass (:meth:`~hysid_model.terms.MeasurementTerm.corner`).
"""

from __future__ import annotations

import numpy as np

from hysid_model import waveform
from hysid_model.kinematics import Kinematics
from hysid_model.model import Model
from hysid_model.shifted_kernels import motion_tables, velocity_sign_chain
from hysid_model.squares_kernels import sum_of_squares
from hysid_model.terms import MeasurementTerm, ModalState, Term, Values


def has_gain(term: MeasurementTerm) -> bool:
    """True if ``term`` overrides the unit gain of :class:`MeasurementTerm`."""
    return type(term).gain is not MeasurementTerm.gain


class SampledMemory:
    """``model.memory_force(pop, kin, phase, n_top)`` for any population at these fixed phases."""

    def __init__(self, model: Model, kin: Kinematics, phase: np.ndarray, n_top: int) -> None:
        self.model, self.kin, self.n_top = model, kin, int(n_top)
        self.phase = np.ascontiguousarray(np.broadcast_to(phase, (kin.x0.size, phase.shape[-1])), dtype=float)
        memory_terms: list[Term] = [t for t in model.terms if t.memory]
        self.sensors = model.sensors
        gains = [t for t in self.sensors if has_gain(t)]
        samplers = [t.sampler(kin, self.phase, self.n_top) for t in memory_terms]
        self.compiled = (
            all(s is not None for s in samplers)
            and len(gains) <= 1
            and not (gains and memory_terms)
            and all(type(t).corner is not MeasurementTerm.corner for t in gains)
        )
        """False where the reference evaluates (see the module docstring)."""
        self.samplers = samplers if self.compiled else []
        self.gain = gains[0] if gains and self.compiled else None
        if self.compiled and model.filters_sgn:
            self.motion = motion_tables(kin.harmonics, self.phase)
            lo, hi = kin.reversals
            self.theta_lo, self.theta_hi = np.ascontiguousarray(lo, dtype=float), np.ascontiguousarray(hi, dtype=float)
            self.cells = tuple(np.ascontiguousarray(c) for c in waveform.sample_cells(self.phase, self.n_top, lo, hi))
            self.x0 = np.ascontiguousarray(kin.x0, dtype=float)

    def sum_of_squares(
        self, modal: tuple[Values, ModalState], coef: np.ndarray, features: np.ndarray, y: np.ndarray, keep: np.ndarray | None = None
    ) -> np.ndarray:
        """``(P, L)``: sum over samples of (coef . features + this force - y)^2 for the candidates of ``modal``
        (:meth:`~hysid_model.model.Model.modal_state`), with the linear coefficients ``coef`` ``(P, L, M)``
        of ``features`` ``(L, M, N)`` and the data ``y`` ``(L, N)``; ``keep`` ``(L, N)``: the samples that
        count (features and data are 0 at the others already, this force is made so)."""
        out = np.empty(coef.shape[:2])
        force = self.force(modal)
        if keep is not None:
            force *= keep
        sum_of_squares(coef, features, force, y, out)
        return out

    def force(self, modal: tuple[Values, ModalState], out: np.ndarray | None = None) -> np.ndarray:
        """The per-sample force ``(P, L, N)`` of the candidates of ``modal`` (parameter values and modal
        state, :meth:`~hysid_model.model.Model.modal_state`); added to ``out`` (C-contiguous) if given."""
        v, state = modal
        n_pop = state.xi.shape[0]
        if out is None:
            out = np.zeros((n_pop,) + self.phase.shape)
        if not self.compiled:
            pop = np.hstack([v[name] for name in self.model.names])
            out += self.model.memory_force(pop, self.kin, self.phase, self.n_top)
            return out
        shift = None
        if self.sensors:
            delay = sum(np.asarray(t.delay(v, self.kin), dtype=float) for t in self.sensors)
            shift = np.ascontiguousarray(np.broadcast_to(delay * self.kin.omega[None, :], (n_pop, self.kin.x0.size)), dtype=float)
        for sampler in self.samplers:
            sampler.add(v, shift, out)
        if self.model.filters_sgn:
            sgn = np.ascontiguousarray(np.broadcast_to(self.model.sgn_coefficient(v, state, self.kin), state.xi.shape), dtype=float)
            rho = np.zeros(state.xi.shape)
            if self.gain is not None:
                rho = np.ascontiguousarray(np.broadcast_to(self.gain.corner(v) / self.kin.omega[None, :], state.xi.shape), dtype=float)
            assert shift is not None
            velocity_sign_chain(sgn, shift, rho, *self.motion, self.phase, self.x0, self.theta_lo, self.theta_hi, self.n_top, *self.cells, out)
        return out
