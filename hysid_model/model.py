"""A model is an ordered list of terms; this module evaluates it for a population.

Presets: ``baseline`` = the oscillator of Eq. 4.4/4.6 with constant xi and wn;
``thesis`` = the final model of Eq. 4.8-4.10 (xi0, S_xi, w0, S_w). Any effect
of :data:`hysid_model.effects.EFFECTS` can be appended, ``thesis+<effect id>``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hysid_model.basis import design_matrix
from hysid_model.effects import EFFECTS
from hysid_model.errors import HysidInputError
from hysid_model.params import Parameter
from hysid_model.terms import (
    AmplitudeDependentDamping,
    AmplitudeDependentFrequency,
    Coefficients,
    Kinematics,
    MeasurementTerm,
    ModalState,
    Oscillator,
    Term,
    Values,
    add_coefficient,
)

PARAMETER_ORDER = ("xi0", "S_xi", "w0", "S_w", "meq")
"""Parameters are ordered as the thesis' chromosome ``[xi0, S_xi, w0, S_w]`` (Appendix A),
since the GA's single-point crossover depends on gene order; other terms' follow in term order."""

CHAIN_ORDERS = np.arange(128)
"""Harmonic orders through which a measurement chain's proper part G filters the
sign-of-velocity feature and memory forces (the delay is applied exactly). The
neglected tail of a unit step is below 0.005 w_c/w for a high-pass at w_c."""

_SQUARE_WAVE = np.where(CHAIN_ORDERS % 2 == 1, 4.0 / (np.pi * np.maximum(CHAIN_ORDERS, 1)) * (-1.0) ** ((CHAIN_ORDERS - 1) // 2), 0.0)
"""Complex amplitudes of sgn(cos wt) = (4/pi) sum_k odd (-1)^((k-1)/2) cos(k wt) / k."""

PRESETS: dict[str, tuple[str, ...]] = {
    "baseline": (),
    "thesis": (AmplitudeDependentDamping.id, AmplitudeDependentFrequency.id),
}


@dataclass
class Model:
    """Terms plus the parameter bounds in force (defaults overridable per dataset)."""

    terms: list[Term]
    spec: str = ""

    def __post_init__(self) -> None:
        names = [p.name for t in self.terms for p in t.params]
        if len(set(names)) != len(names):
            raise HysidInputError(f"model {self.spec!r}: two terms define the same parameter ({', '.join(names)})")
        params = [p for t in self.terms for p in t.params]
        rank = {name: i for i, name in enumerate(PARAMETER_ORDER)}
        order = sorted(range(len(params)), key=lambda i: (rank.get(params[i].name, len(rank)), i))
        self._params: list[Parameter] = [params[i] for i in order]
        self._sensors = [t for t in self.terms if isinstance(t, MeasurementTerm)]
        probe_kin = Kinematics(x0=np.ones(1), omega=np.ones(1), meq_kg=1.0)
        v, state = self.modal_state(self.bounds.mean(axis=1)[None, :], probe_kin)
        self._filters_sgn = bool(self._sensors) and "sgn" in self._force_coefficients(v, state, probe_kin)

    # --- parameters -------------------------------------------------------
    @property
    def parameters(self) -> list[Parameter]:
        return list(self._params)

    @property
    def names(self) -> list[str]:
        return [p.name for p in self._params]

    @property
    def dim(self) -> int:
        return len(self._params)

    @property
    def bounds(self) -> np.ndarray:
        """``(D, 2)`` array of lower and upper bounds."""
        return np.array([[p.lower, p.upper] for p in self._params], dtype=float)

    @property
    def has_memory(self) -> bool:
        """True when the force is evaluated sample by sample: memory terms, or a
        measurement chain filtering the sign-of-velocity feature."""
        return self._filters_sgn or any(t.memory for t in self.terms)

    def set_bounds(self, bounds: dict[str, tuple[float, float]]) -> None:
        unknown = sorted(set(bounds) - set(self.names))
        if unknown:
            raise HysidInputError(f"bounds given for unknown parameter(s) {', '.join(unknown)}; model has {', '.join(self.names)}")
        self._params = [p.with_bounds(*bounds[p.name]) if p.name in bounds else p for p in self._params]

    def values(self, pop: np.ndarray) -> Values:
        """Split a ``(P, D)`` population into named ``(P, 1)`` columns."""
        pop = np.atleast_2d(np.asarray(pop, dtype=float))
        if pop.shape[1] != self.dim:
            raise ValueError(f"expected {self.dim} parameters ({', '.join(self.names)}), got {pop.shape[1]}")
        return {name: pop[:, i : i + 1] for i, name in enumerate(self.names)}

    def as_dict(self, theta: np.ndarray) -> dict[str, float]:
        return {name: float(x) for name, x in zip(self.names, np.asarray(theta, dtype=float).reshape(-1))}

    def from_dict(self, values: dict[str, float]) -> np.ndarray:
        missing = [n for n in self.names if n not in values]
        if missing:
            raise HysidInputError(f"values missing for parameter(s) {', '.join(missing)}")
        return np.array([float(values[n]) for n in self.names])

    # --- evaluation -------------------------------------------------------
    def modal_state(self, pop: np.ndarray, kin: Kinematics) -> tuple[Values, ModalState]:
        v = self.values(pop)
        shape = (v[self.names[0]].shape[0], kin.x0.size)
        state = ModalState(xi=np.zeros(shape), wn=np.zeros(shape), m=np.zeros(shape))
        for term in self.terms:
            term.modal(v, state, kin)
        return v, state

    def _force_coefficients(self, v: Values, state: ModalState, kin: Kinematics) -> Coefficients:
        coefs: Coefficients = {}
        for term in self.terms:
            for name, value in term.force(v, state, kin).items():
                add_coefficient(coefs, name, np.broadcast_to(value, state.xi.shape))
        return coefs

    def coefficients(self, pop: np.ndarray, kin: Kinematics) -> Coefficients:
        """Feature coefficients of the measured steady-state force, each ``(P, L)``."""
        v, state = self.modal_state(pop, kin)
        coefs = self._force_coefficients(v, state, kin)
        for term in self.terms:
            coefs = term.measure(v, coefs, kin)
        return coefs

    def force(self, pop: np.ndarray, kin: Kinematics, phase: np.ndarray, n_top: int | None = None) -> np.ndarray:
        """The measured steady-state force at any phases ``(L, N)``, ``(P, L, N)``; the first ``n_top``
        samples of each loop (default N/2) are on the loading branch."""
        n_top = phase.shape[-1] // 2 if n_top is None else n_top
        coefs = self.coefficients(pop, kin)
        names = list(coefs)
        force = np.einsum("lnm,plm->pln", design_matrix(names, phase, n_top), np.stack([coefs[k] for k in names], axis=-1))
        memory = self.memory_force(pop, kin, phase, n_top)
        return force if memory is None else force + memory

    def memory_force(self, pop: np.ndarray, kin: Kinematics, phase: np.ndarray, n_top: int | None = None) -> np.ndarray | None:
        """Force evaluated per sample at ``phase`` (L, N), ``(P, L, N)``, or None.

        That is the memory terms' force, plus, when the model has measurement
        terms, the sign-of-velocity feature; both as the measurement chain sees
        them. The first ``n_top`` samples (default N/2) of each loop are on the
        loading branch, which decides sgn at the turning points.
        """
        memory_terms = [t for t in self.terms if t.memory]
        if not memory_terms and not self._filters_sgn:
            return None
        v, state = self.modal_state(pop, kin)
        if not self._sensors:
            return sum(t.time_force(v, state, kin, phase) for t in memory_terms)
        sgn = self._force_coefficients(v, state, kin)["sgn"] if self._filters_sgn else None
        return self._through_chain(v, state, kin, phase, phase.shape[-1] // 2 if n_top is None else n_top, sgn, memory_terms)

    def _through_chain(
        self, v: Values, state: ModalState, kin: Kinematics, phase: np.ndarray, n_top: int, sgn: np.ndarray | None, memory_terms: list[Term]
    ) -> np.ndarray:
        """u(wt - w tau_d) + Re sum_k (G_k - 1) U_k exp(j k (wt - w tau_d)): the non-harmonic force u
        (Coulomb's sgn, memory forces) through the chain's delay tau_d (exact) and gain G (Eq. 4.1-4.2)."""
        n_pop = state.xi.shape[0]
        delay = np.broadcast_to(sum(np.asarray(t.delay(v, kin), dtype=float) for t in self._sensors), (n_pop, 1))[:, :, None]
        shifted = phase[None] - kin.omega[None, :, None] * delay
        out = np.zeros(shifted.shape)
        if sgn is not None:
            cos = np.cos(shifted)
            branch = np.where(np.arange(phase.shape[-1]) < n_top, 1.0, -1.0)
            out += sgn[:, :, None] * np.where(np.abs(cos) < 1e-9, branch, np.sign(cos))
        if memory_terms:
            out += sum(t.time_force(v, state, kin, shifted) for t in memory_terms)
        gain = np.ones((1, 1, CHAIN_ORDERS.size), dtype=complex)
        for t in self._sensors:
            gain = gain * t.gain(v, kin, CHAIN_ORDERS)
        if np.all(gain == 1.0):
            return out
        amplitude = np.zeros((n_pop, phase.shape[0], CHAIN_ORDERS.size), dtype=complex)
        if sgn is not None:
            amplitude += sgn[:, :, None] * _SQUARE_WAVE
        if memory_terms:
            grid = np.broadcast_to(np.linspace(0.0, 2.0 * np.pi, 2 * CHAIN_ORDERS.size, endpoint=False), (phase.shape[0], 2 * CHAIN_ORDERS.size))
            spectrum = np.fft.rfft(sum(t.time_force(v, state, kin, grid) for t in memory_terms), axis=-1)[..., : CHAIN_ORDERS.size]
            amplitude += spectrum * np.where(CHAIN_ORDERS == 0, 1.0, 2.0) / grid.shape[-1]
        lag = np.exp(-1j * CHAIN_ORDERS * kin.omega[None, :, None] * delay)
        waves = np.exp(1j * phase[..., None] * CHAIN_ORDERS)
        return out + np.einsum("plk,lnk->pln", (gain - 1.0) * amplitude * lag, waves).real

    def modal(self, theta: np.ndarray, x0: np.ndarray | float, meq_kg: float | None) -> ModalState:
        """xi, wn and m at amplitude(s) ``x0`` for one parameter vector (as listed under Table 5.3)."""
        x0 = np.atleast_1d(np.asarray(x0, dtype=float))
        kin = Kinematics(x0=x0, omega=np.ones_like(x0), meq_kg=meq_kg)
        _, state = self.modal_state(np.asarray(theta, dtype=float).reshape(1, -1), kin)
        return ModalState(xi=state.xi[0], wn=state.wn[0], m=state.m[0])

    def describe(self) -> str:
        lines = [f"model {self.spec}:"]
        for t in self.terms:
            plist = ", ".join(f"{p.name} [{p.unit}]" for p in t.params) or "no parameters"
            lines.append(f"  {t.id}: {plist}")
        return "\n".join(lines)


def build_model(spec: str = "thesis", meq_kg: float | None = None, fit_mass: bool = False) -> Model:
    """Build a model from ``baseline``/``thesis`` plus ``+effect`` ids.

    The mass is fitted when ``meq_kg`` is None (unknown) or ``fit_mass`` is set.
    """
    parts = [p.strip() for p in spec.split("+") if p.strip()]
    if not parts or parts[0] not in PRESETS:
        raise HysidInputError(f"model {spec!r}: must start with one of {', '.join(PRESETS)} (e.g. thesis+coulomb_friction)")
    effect_ids = list(PRESETS[parts[0]])
    for part in parts[1:]:
        if part not in EFFECTS:
            raise HysidInputError(f"model {spec!r}: unknown effect {part!r}; known: {', '.join(sorted(EFFECTS))}")
        if part in effect_ids:
            raise HysidInputError(f"model {spec!r}: effect {part!r} is already in the model")
        effect_ids.append(part)
    terms: list[Term] = [Oscillator(fit_mass=fit_mass or meq_kg is None)]
    terms += [EFFECTS[e]() for e in effect_ids]
    return Model(terms=terms, spec=spec)


def to_physical(state: ModalState) -> dict[str, np.ndarray]:
    """Modal (xi, wn, m) -> physical (k, c, m): k = m wn^2, c = 2 m xi wn (Eq. 2.4)."""
    return {"k": state.m * state.wn**2, "c": 2.0 * state.m * state.xi * state.wn, "m": state.m}


def from_physical(k: np.ndarray | float, c: np.ndarray | float, m: np.ndarray | float) -> ModalState:
    """Physical (k, c, m) -> modal: wn = sqrt(k/m), xi = c / (2 sqrt(k m))."""
    k, c, m = (np.asarray(a, dtype=float) for a in (k, c, m))
    if np.any(k <= 0) or np.any(m <= 0):
        raise HysidInputError("physical form needs positive stiffness k and mass m")
    wn = np.sqrt(k / m)
    return ModalState(xi=c / (2.0 * m * wn), wn=wn, m=m)
