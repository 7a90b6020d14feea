"""A model is an ordered list of terms; this module evaluates it for a population.

Presets (:data:`hysid_model.presets.PRESETS`): ``baseline`` = the oscillator of Eq. 4.4/4.6 with
constant xi and wn; ``thesis`` = the final model of Eq. 4.8-4.10 (xi0, S_xi,
w0, S_w); ``mr_damper`` = the oscillator plus a Bouc-Wen spring with its
exponent free, the simple Bouc-Wen model of a magnetorheological damper. Any
effect of :data:`hysid_model.effects.EFFECTS` can be appended, ``thesis+<effect id>``,
and any term of a user's own, ``thesis+<module>:<attribute>`` (:mod:`hysid_model.user_terms`).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence

import numpy as np

from hysid_model import waveform
from hysid_model.basis import design_matrix
from hysid_model.effects import EFFECTS
from hysid_model.errors import HysidInputError
from hysid_model.kinematics import REVERSAL_TIE, Kinematics
from hysid_model.params import Parameter, on_bounds
from hysid_model.presets import PRESET_FREES, PRESETS
from hysid_model.terms import (
    Coefficients,
    MeasurementTerm,
    ModalState,
    Oscillator,
    Term,
    TermGroup,
    Values,
    add_coefficient,
)
from hysid_model.user_terms import resolve

PHYSICAL_LIMIT = "physical"
"""The kind of a bound that is the end of a parameter's physical range (:meth:`Model.bound_kinds`)."""
MAX_WIDENINGS = 3
"""How often a fit widens the data-derived bounds its best ends on (:meth:`Model.widen_at`) and refits."""

PARAMETER_ORDER = ("xi0", "S_xi", "w0", "S_w", "meq")
"""Parameters are ordered as the thesis' chromosome ``[xi0, S_xi, w0, S_w]`` (Appendix A),
since the GA's single-point crossover depends on gene order; other terms' follow in term order."""

CHAIN_ORDERS = np.arange(128)
"""Harmonic orders through which a measurement chain's proper part G filters the
sign-of-velocity feature and memory forces (the delay is applied exactly). The
neglected tail of a unit step is below 0.005 w_c/w for a high-pass at w_c."""

_SQUARE_WAVE = np.where(CHAIN_ORDERS % 2 == 1, 4.0 / (np.pi * np.maximum(CHAIN_ORDERS, 1)) * (-1.0) ** ((CHAIN_ORDERS - 1) // 2), 0.0)
"""Complex amplitudes of sgn(cos wt) = (4/pi) sum_k odd (-1)^((k-1)/2) cos(k wt) / k (the ideal sine's sgn(x'))."""


class Model:
    """An ordered list of terms and the parameters in force: bounds, and values where fixed.

    Like lmfit's ``Parameters``: every parameter of every term is either
    searched within its bounds or fixed at a known value (``vary=False``), so
    the known equivalent mass is the fixed parameter ``meq``. The search space
    (``names``, ``dim``, ``bounds``, and the vectors ``theta`` every method
    takes) holds the free parameters only. Models compose with ``+`` (a term of
    :mod:`hysid_model.effects` or another model) and never change in place:
    :meth:`with_bounds`, :meth:`fix` and :meth:`vary` return new models.
    """

    def __init__(self, terms: Sequence[Term], spec: str = "", overrides: Mapping[str, Parameter] | None = None) -> None:
        self.terms = list(terms)
        if not any(isinstance(t, Oscillator) for t in self.terms):
            raise HysidInputError("a model needs the oscillator term (start from a preset: baseline or thesis)")
        names = [p.name for t in self.terms for p in t.params]
        if len(set(names)) != len(names):
            raise HysidInputError(f"model {spec!r}: two terms define the same parameter ({', '.join(names)})")
        params = [p for t in self.terms for p in t.params]
        rank = {name: i for i, name in enumerate(PARAMETER_ORDER)}
        order = sorted(range(len(params)), key=lambda i: (rank.get(params[i].name, len(rank)), i))
        self._overrides = {k: v for k, v in (overrides or {}).items() if k in names}
        self._all: list[Parameter] = [self._overrides.get(params[i].name, params[i]) for i in order]
        self._params = [p for p in self._all if p.vary]
        self._fixed = {p.name: float(p.value) for p in self._all if not p.vary}  # type: ignore[arg-type]
        self.spec = spec or spec_of(self.terms, [p.name for p in self._params])
        self._sensors = [t for t in self.terms if isinstance(t, MeasurementTerm)]
        probe_kin = Kinematics(x0=np.ones(1), omega=np.ones(1))
        v, state = self.modal_state(self.bounds.mean(axis=1)[None, :], probe_kin)
        self._filters_sgn = bool(self._sensors) and "sgn" in self._force_coefficients(v, state, probe_kin)

    # --- parameters -------------------------------------------------------
    @property
    def parameters(self) -> list[Parameter]:
        """The free parameters, in the order of a parameter vector ``theta``."""
        return list(self._params)

    @property
    def all_parameters(self) -> list[Parameter]:
        """Every parameter, free and fixed, in model order."""
        return list(self._all)

    @property
    def fixed(self) -> dict[str, float]:
        """Fixed parameters and their values."""
        return dict(self._fixed)

    @property
    def names(self) -> list[str]:
        return [p.name for p in self._params]

    @property
    def dim(self) -> int:
        return len(self._params)

    @property
    def bounds(self) -> np.ndarray:
        """``(D, 2)`` array of lower and upper bounds of the free parameters."""
        return np.array([[p.lower, p.upper] for p in self._params], dtype=float).reshape(-1, 2)

    @property
    def has_memory(self) -> bool:
        """True when the force is evaluated sample by sample: memory terms, or a
        measurement chain filtering the sign-of-velocity feature."""
        return self._filters_sgn or any(t.memory for t in self.terms)

    @property
    def sensors(self) -> list[MeasurementTerm]:
        """The measurement chain: the model's measurement terms."""
        return list(self._sensors)

    @property
    def filters_sgn(self) -> bool:
        """True when the measurement chain filters the sign-of-velocity feature sample by sample."""
        return self._filters_sgn

    def _changed(self, changes: Mapping[str, Parameter]) -> Model:
        return Model(self.terms, self.spec, {**self._overrides, **changes})

    def _parameter(self, name: str, what: str) -> Parameter:
        for p in self._all:
            if p.name == name:
                return p
        raise HysidInputError(f"{what} given for unknown parameter {name!r}; model {self.spec} has {', '.join(p.name for p in self._all)}")

    def with_bounds(self, bounds: Mapping[str, tuple[float, float]], soft: bool = False) -> Model:
        """This model with other search bounds, ``{name: (lower, upper)}``; ``soft`` marks bounds derived
        from the data, which a fit may widen (:meth:`widen_at`)."""
        changes = {}
        for name, pair in bounds.items():
            p = self._parameter(name, "bounds")
            try:
                lower, upper = (float(b) for b in pair)
            except (TypeError, ValueError):
                raise HysidInputError("bounds must be a pair of numbers (lower, upper)", param=f"bounds[{name!r}]", value=pair) from None
            changes[name] = p.with_bounds(lower, upper, soft)
        return self._changed(changes)

    def widen_at(self, theta: np.ndarray) -> tuple[Model, dict[str, tuple[float, float]]]:
        """This model with every soft bound that ``theta`` sits on widened (:meth:`Parameter.widened`),
        and the new bounds of the parameters widened (none: nothing to widen)."""
        bounds = self.bounds
        span = bounds[:, 1] - bounds[:, 0]
        theta = np.asarray(theta, dtype=float).reshape(-1)
        low = theta - bounds[:, 0] <= 1e-6 * span
        high = bounds[:, 1] - theta <= 1e-6 * span
        changes = {}
        for p, lo, hi in zip(self._params, low, high):
            if p.soft and (lo or hi):
                wider = p.widened(bool(lo), bool(hi))
                if (wider.lower, wider.upper) != (p.lower, p.upper):
                    changes[p.name] = wider
        widened = {name: (p.lower, p.upper) for name, p in changes.items()}
        return (self._changed(changes), widened) if changes else (self, {})

    def fix(self, values: Mapping[str, float] | None = None, **kwargs: float) -> Model:
        """This model with parameters fixed at known values (``model.fix(meq=0.04)``)."""
        changes = {}
        for name, value in {**(values or {}), **kwargs}.items():
            p = self._parameter(name, "a fixed value")
            try:
                number = float(value)
            except (TypeError, ValueError):
                raise HysidInputError("a fixed value must be a number", param=name, value=value) from None
            changes[name] = p.fixed_at(number)
        return self._changed(changes)

    def vary(self, *names: str) -> Model:
        """This model with fixed parameters searched again (within their bounds)."""
        return self._changed({name: self._parameter(name, "vary").varied() for name in names})

    def at_bounds(self, theta: np.ndarray) -> list[str]:
        """Free parameters of ``theta`` that sit on a bound of the search space that is not a physical
        limit (the optimum may lie beyond it; a friction force of 0 is an answer, not a search artifact)."""
        return [name for name, kind, _, _ in self._on_bounds(theta) if kind != PHYSICAL_LIMIT]

    def bound_kinds(self, theta: np.ndarray) -> dict[str, str]:
        """Every free parameter of ``theta`` on a bound, with which (``"physical lower bound 0"``, ``"data-derived
        upper bound 0.15"``, ``"default upper bound 3"``, ``"given lower bound 100"``): its physical limit (a
        damping ratio of 0), a bound derived from the data, its term's default search bound, or a bound that
        was given (by the user or the dataset)."""
        return {name: f"{kind} {where} bound {side:g}" for name, kind, where, side in self._on_bounds(theta)}

    def _on_bounds(self, theta: np.ndarray) -> list[tuple[str, str, str, float]]:
        """(name, kind, "lower"/"upper", bound) of every free parameter of ``theta`` on a bound."""
        theta = np.asarray(theta, dtype=float).reshape(-1)
        defaults = {q.name: (q.lower, q.upper) for t in self.terms for q in t.params}
        out = []
        for p, value, hit in zip(self._params, theta, on_bounds(self.bounds, theta)):
            if hit:
                low = value - p.lower <= p.upper - value
                side = p.lower if low else p.upper
                default = side == defaults[p.name][0 if low else 1]
                kind = PHYSICAL_LIMIT if side in p.physical else ("default" if default else "data-derived" if p.soft else "given")
                out.append((p.name, kind, "lower" if low else "upper", side))
        return out

    def __add__(self, other: Term | TermGroup | Model) -> Model:
        """This model plus an effect term, a group of terms (``coulomb_friction + bouc_wen``) or another model's
        terms: ``thesis + coulomb_friction``; an oscillator among them is this model's own."""
        if isinstance(other, Model):
            added, overrides = [t for t in other.terms if not isinstance(t, Oscillator)], other._overrides
        elif isinstance(other, TermGroup):
            added, overrides = [t for t in other if not isinstance(t, Oscillator)], {}
        elif isinstance(other, Term) and not isinstance(other, Oscillator):
            added, overrides = [other], {}
        else:
            return NotImplemented
        ids = [t.id for t in self.terms]
        for term in added:
            if term.id in ids:
                raise HysidInputError(f"model {self.spec!r}: effect {term.id!r} is already in the model")
            ids.append(term.id)
        spec = "+".join([self.spec] + [t.spec for t in added])
        return Model(self.terms + added, spec, {**self._overrides, **overrides})

    def __radd__(self, other: Term | TermGroup) -> Model:
        """A term (or a group) plus a model is the model plus it: a model string starts with its preset."""
        return self.__add__(other) if isinstance(other, (Term, TermGroup)) else NotImplemented

    def values(self, pop: np.ndarray) -> Values:
        """Split a ``(P, D)`` population into named ``(P, 1)`` columns, fixed parameters included."""
        pop = np.atleast_2d(np.asarray(pop, dtype=float))
        if pop.shape[1] != self.dim:
            raise HysidInputError(f"model {self.spec}: expected {self.dim} parameter values ({', '.join(self.names)}), got {pop.shape[1]}")
        out = {name: pop[:, i : i + 1] for i, name in enumerate(self.names)}
        for name, value in self._fixed.items():
            out[name] = np.full((pop.shape[0], 1), value)
        return out

    def as_dict(self, theta: np.ndarray) -> dict[str, float]:
        """Free parameter values by name."""
        return {name: float(x) for name, x in zip(self.names, np.asarray(theta, dtype=float).reshape(-1))}

    def from_dict(self, values: Mapping[str, float]) -> np.ndarray:
        """The parameter vector of ``values`` (free parameters; entries for fixed ones are ignored)."""
        missing = [n for n in self.names if n not in values]
        if missing:
            raise HysidInputError(f"values missing for parameter(s) {', '.join(missing)}")
        return np.array([float(values[n]) for n in self.names])

    # --- evaluation -------------------------------------------------------
    def modal_state(self, pop: np.ndarray, kin: Kinematics) -> tuple[Values, ModalState]:
        v = self.values(pop)
        shape = (v["xi0"].shape[0], kin.x0.size)
        state = ModalState(xi=np.zeros(shape), wn=np.zeros(shape), m=np.zeros(shape))
        for term in self.terms:
            term.modal(v, state, kin)
        return v, state

    def _force_coefficients(self, v: Values, state: ModalState, kin: Kinematics) -> Coefficients:
        coefs: Coefficients = {}
        shape = state.xi.shape
        for term in self.terms:
            for name, value in term.force(v, state, kin).items():
                add_coefficient(coefs, name, value if np.shape(value) == shape else np.broadcast_to(value, shape))
        return coefs

    def coefficients(self, pop: np.ndarray, kin: Kinematics) -> Coefficients:
        """Feature coefficients of the measured steady-state force, each ``(P, L)``."""
        return self.measured_coefficients(*self.modal_state(pop, kin), kin)

    def measured_coefficients(self, v: Values, state: ModalState, kin: Kinematics) -> Coefficients:
        """:meth:`coefficients` from the parameter values and modal state of :meth:`modal_state`."""
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
        n_top = phase.shape[-1] // 2 if n_top is None else n_top
        if not self._sensors:
            return sum(t.time_force(v, state, kin, phase, n_top) for t in memory_terms)
        sgn = self.sgn_coefficient(v, state, kin) if self._filters_sgn else None
        return self._through_chain(v, state, kin, phase, n_top, sgn, memory_terms)

    def sgn_coefficient(self, v: Values, state: ModalState, kin: Kinematics) -> np.ndarray:
        """The coefficient of the sign-of-velocity feature before the measurement chain, ``(P, L)``."""
        return self._force_coefficients(v, state, kin)["sgn"]

    def _through_chain(
        self, v: Values, state: ModalState, kin: Kinematics, phase: np.ndarray, n_top: int, sgn: np.ndarray | None, memory_terms: list[Term]
    ) -> np.ndarray:
        """u(wt - w tau_d) + Re sum_k (G_k - 1) U_k exp(j k (wt - w tau_d)): the non-harmonic force u
        (Coulomb's sgn, memory forces) through the chain's delay tau_d (exact) and gain G (Eq. 4.1-4.2).

        sgn(x') jumps by +-2 at the reversals: where the delay moves a jump into a sample's cell
        (:func:`hysid_model.waveform.sample_cells`) the sample sees it averaged over the cell, so that
        the force, and chi^2, are continuously differentiable in the delay (a point sample would flip
        as a reversal crosses it). Where no jump is in a cell (every sample at zero delay) that is sgn
        at the sample itself."""
        n_pop = state.xi.shape[0]
        delay = np.broadcast_to(sum(np.asarray(t.delay(v, kin), dtype=float) for t in self._sensors), (n_pop, 1))[:, :, None]
        shifted = phase[None] - kin.omega[None, :, None] * delay
        out = np.zeros(shifted.shape)
        if sgn is not None:
            velocity = kin.displacement(shifted, 1)
            branch = np.where(np.arange(phase.shape[-1]) < n_top, 1.0, -1.0)
            sign = np.where(np.abs(velocity) < REVERSAL_TIE * kin.x0[:, None], branch, np.sign(velocity))
            before, after = waveform.sample_cells(phase, n_top, *kin.reversals)
            for reversal, jump, past in zip(kin.reversals, (2.0, -2.0), (sign > 0, sign < 0)):
                offset = np.mod(reversal[None, :, None] + kin.omega[None, :, None] * delay - phase[None] + np.pi, 2 * np.pi) - np.pi
                inside = (offset > -before) & (offset < after)
                sign = sign + jump * np.where(inside, waveform.past_jump(offset, before, after) - past, 0.0)
            out += sgn[:, :, None] * sign
        if memory_terms:
            out += sum(t.time_force(v, state, kin, shifted) for t in memory_terms)  # delayed: the motion's own direction
        gain = np.ones((1, 1, CHAIN_ORDERS.size), dtype=complex)
        for t in self._sensors:
            gain = gain * t.gain(v, kin, CHAIN_ORDERS)
        if np.all(gain == 1.0):
            return out
        amplitude = np.zeros((n_pop, phase.shape[0], CHAIN_ORDERS.size), dtype=complex)
        if sgn is not None:
            square = _SQUARE_WAVE if kin.xh is None else waveform.velocity_sign_harmonics(kin.xh, CHAIN_ORDERS.size)
            amplitude += sgn[:, :, None] * square
        if memory_terms:
            grid = np.broadcast_to(np.linspace(0.0, 2.0 * np.pi, 2 * CHAIN_ORDERS.size, endpoint=False), (phase.shape[0], 2 * CHAIN_ORDERS.size))
            spectrum = np.fft.rfft(sum(t.time_force(v, state, kin, grid) for t in memory_terms), axis=-1)[..., : CHAIN_ORDERS.size]
            amplitude += spectrum * np.where(CHAIN_ORDERS == 0, 1.0, 2.0) / grid.shape[-1]
        lag = np.exp(-1j * CHAIN_ORDERS * kin.omega[None, :, None] * delay)
        waves = np.exp(1j * phase[..., None] * CHAIN_ORDERS)
        return out + np.einsum("plk,lnk->pln", (gain - 1.0) * amplitude * lag, waves).real

    def modal(self, theta: np.ndarray, x0: np.ndarray | float) -> ModalState:
        """xi, wn and m at amplitude(s) ``x0`` for one parameter vector (as listed under Table 5.3)."""
        x0 = np.atleast_1d(np.asarray(x0, dtype=float))
        kin = Kinematics(x0=x0, omega=np.ones_like(x0))
        _, state = self.modal_state(np.asarray(theta, dtype=float).reshape(1, -1), kin)
        return ModalState(xi=state.xi[0], wn=state.wn[0], m=state.m[0])

    def describe(self) -> str:
        """Every term with its parameters: unit, bounds, or the fixed value."""
        lines = [f"model {self.spec}:"]
        params = {p.name: p for p in self._all}
        for t in self.terms:
            shown = []
            for p in (params[q.name] for q in t.params):
                where = f"in [{p.lower:g}, {p.upper:g}]" if p.vary else f"fixed at {p.value:g}"
                shown.append(f"{p.name} [{p.unit}] {where}")
            lines.append(f"  {t.id}: {', '.join(shown) or 'no parameters'}")
        return "\n".join(lines)

    def __repr__(self) -> str:
        fixed = "".join(f", {k}={v:g} fixed" for k, v in self.fixed.items())
        return f"Model({self.spec!r}: {', '.join(self.names)}{fixed})"


def spec_of(terms: Sequence[Term], free: Collection[str] = ()) -> str:
    """The model string of ``terms`` with the parameters ``free`` searched: the preset that holds the most of
    them, first the parameters it frees (so that :func:`build_model` frees them again), then ``+effect`` for
    every other term (:attr:`Term.spec`)."""
    effects = [t for t in terms if not isinstance(t, Oscillator)]
    ids = {t.id for t in effects}
    fits = [name for name, preset in PRESETS.items() if set(preset) <= ids and set(PRESET_FREES.get(name, ())) <= set(free)]
    preset = max(fits, key=lambda name: (len(PRESET_FREES.get(name, ())), len(PRESETS[name])))
    return "+".join([preset] + [t.spec for t in effects if t.id not in PRESETS[preset]])


def effect_term(spec: str) -> Term:
    """The term ``spec`` names in a model string: a library effect by its id (:data:`EFFECTS`), else a user's term
    by ``module:attribute`` or by the name it was made with in this process (:func:`hysid_model.user_terms.resolve`)."""
    return EFFECTS[spec]() if spec in EFFECTS else resolve(spec)


def build_model(spec: str = "thesis") -> Model:
    """Build a model from a preset (:data:`~hysid_model.presets.PRESETS`) plus ``+effect`` ids (``thesis+coulomb_friction``) and
    a user's terms (``thesis+myterms:drag``, :func:`effect_term`).

    Every parameter is free, the equivalent mass ``meq`` too, except those an
    effect fixes by default (the Bouc-Wen exponent ``bw_n`` = 1) and its preset
    does not free (:data:`~hysid_model.presets.PRESET_FREES`); fix what is known with
    :meth:`Model.fix` (:func:`hysid_model.problem.prepare_model` fixes a
    dataset's known mass), free a fixed one with :meth:`Model.vary`.
    """
    if not isinstance(spec, str):
        raise HysidInputError("a model is a string such as 'thesis+coulomb_friction' or a hysid Model", param="model", value=spec)
    parts = [p.strip() for p in spec.split("+") if p.strip()]
    if not parts or parts[0] not in PRESETS:
        raise HysidInputError(f"must start with one of {', '.join(PRESETS)} (e.g. thesis+coulomb_friction)", param="model", value=spec)
    terms: list[Term] = [Oscillator()] + [EFFECTS[e]() for e in PRESETS[parts[0]]]
    added: list[Term] = []
    for part in parts[1:]:
        try:
            term = effect_term(part)
        except HysidInputError as exc:
            raise HysidInputError(exc.detail, param="model", value=spec) from None
        if term.id in [t.id for t in terms + added]:
            raise HysidInputError(f"effect {part!r} is already in the model", param="model", value=spec)
        added.append(term)
    return Model(terms + added, "+".join([parts[0]] + [t.spec for t in added])).vary(*PRESET_FREES.get(parts[0], ()))


def as_model(model: str | Model) -> Model:
    """A :class:`Model` from a model string or a model."""
    return model if isinstance(model, Model) else build_model(model)


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
