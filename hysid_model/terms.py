"""Model terms: physics as data.

A model (:mod:`hysid_model.model`) is an ordered list of terms. Each term owns
its parameters (name, unit, default bounds) and contributes in up to three
stages, always vectorized over a population ``P`` and the loops ``L``:

1. ``modal``: adjust the modal quantities shared by the 1-DOF oscillator, the
   damping ratio ``xi``, natural frequency ``wn`` (rad/s) and mass ``m`` (kg),
   each of shape ``(P, L)`` (e.g. Eq. 4.8 and 4.9 make them depend on X0);
2. ``force``: add coefficients of basis features (:mod:`hysid_model.basis`) to
   the steady-state force, e.g. Eq. 4.6 / 4.10 for the oscillator;
3. ``measure``: transform the force as the measurement chain sees it.

Each stage sees the prescribed motion of the loops as a
:class:`~hysid_model.kinematics.Kinematics`.

Terms with memory (internal state, e.g. Bouc-Wen) instead return their force at
the sample phases (:meth:`Term.time_force`), from their periodic steady state
under the prescribed motion.

Every term's force is the steady-state force less its mean over a cycle: the
loops are centred (Appendix A ``centercurveloop``; extraction removes the
force's cycle mean), so the model is too. Under the ideal sine no term has a
mean; under a measured displacement with even harmonics some do.
Elements of the measurement chain (charge amplifier, channel delay) are
:class:`MeasurementTerm`: a delay times a gain per harmonic order, applied
exactly to harmonic features here and per sample to the rest by the model.

The effect library (id -> term class) is :data:`hysid_model.effects.EFFECTS`,
a user's own terms are :mod:`hysid_model.user_terms`; this module holds the
base classes, :class:`TermGroup` (terms that compose with ``+`` as PySINDy's
libraries do) and the thesis' own terms (Eq. 4.4-4.10).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Iterator
from dataclasses import dataclass
from typing import ClassVar, Protocol

import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.kinematics import Kinematics
from hysid_model.loops import LoopSet
from hysid_model.params import Parameter

Values = dict[str, np.ndarray]
"""Parameter values by name, each of shape ``(P, 1)`` so they broadcast over loops."""

Coefficients = dict[str, np.ndarray]
"""Feature name -> coefficient (N) of shape ``(P, L)``."""


@dataclass
class ModalState:
    """Damping ratio, natural frequency (rad/s) and mass (kg) per candidate and loop."""

    xi: np.ndarray
    wn: np.ndarray
    m: np.ndarray


@dataclass(frozen=True)
class DataScale:
    """The scale of a loop set, from its equivalent-linear survey (:mod:`hysid_model.survey`): what
    each term's search bounds are generous around (:meth:`Term.data_bounds`). None: not known."""

    stiffness: float
    """Typical storage (or dynamic) stiffness magnitude, N/m."""
    damping: float
    """Typical equivalent viscous damping, N s/m."""
    loss_factor: float
    mass: float | None
    wn: float | None
    """Natural frequency (rad/s) at the smallest amplitude."""
    xi: float | None
    w_min: float
    w_max: float
    x_min: float
    x_max: float
    force: float
    """Largest peak force, N."""

    @property
    def mass_scale(self) -> float:
        """The mass, else the one that would put the resonance in the middle of the band."""
        return self.mass if self.mass is not None else self.stiffness / (self.w_min * self.w_max)

    @property
    def wn_scale(self) -> float:
        return self.wn if self.wn is not None else math.sqrt(self.w_min * self.w_max)


def add_coefficient(coefs: Coefficients, name: str, value: np.ndarray) -> None:
    coefs[name] = coefs[name] + value if name in coefs else value


class Term:
    """Base class; subclasses set ``id``, ``explanation`` and ``params``.

    Effects of the library also name their ``strength``: the parameter whose
    value 0 switches the effect off (the nested null a diagnosis tests). If its
    lower bound is 0 the effect has a physical sign (one-sided). Parameters
    that only shape the effect and are unidentified when it is off (e.g. a
    relaxation time) get candidate values from :meth:`shape_grid`; a term may
    also read starting values off the loops themselves (:meth:`data_starts`).
    """

    id: ClassVar[str] = ""
    explanation: ClassVar[str] = ""
    memory: ClassVar[bool] = False
    strength: ClassVar[str] = ""
    slope_of: ClassVar[str] = ""
    """The oscillator parameter whose change with amplitude this term is (Eq. 4.8, 4.9): it changes the loops
    only from one amplitude to another, so loops at a single amplitude cannot tell the two apart."""
    params: tuple[Parameter, ...] = ()

    def shape_grid(self, kin: Kinematics, free: Collection[str] = ()) -> list[dict[str, float]]:
        """Values of the shape parameters worth testing on loops ``kin`` (default: none to choose).

        ``free`` names the parameters searched in the model being scored: a shape parameter that is
        fixed there (e.g. Bouc-Wen's exponent ``bw_n``, fixed at 1 unless freed) gets no grid values,
        which the model would ignore."""
        return [{}]

    def data_starts(self, loops: LoopSet, free: Collection[str] = ()) -> list[dict[str, float]]:
        """Starting points for this term's parameters read off the measured ``loops`` (e.g. Bouc-Wen's
        stiffness and yield displacement from the loops' slopes and height), a few, best first; default
        none. Like :meth:`shape_grid` it gives values for a parameter fixed by default only where ``free``
        names it. The values need not lie within the model's bounds (clip them)."""
        return []

    def strength_reach(self, scale: DataScale) -> float | None:
        """How far the data's ``scale`` lets the strength reach, with a generous margin (:meth:`data_bounds`); None
        (default): the strength keeps its own bounds."""
        return None

    def data_bounds(self, scale: DataScale) -> dict[str, tuple[float, float]]:
        """Search bounds of this term's parameters that hold the data's ``scale`` with generous margins. Default: the
        strength's from 0 to its :meth:`strength_reach` where it is one-sided (its lower bound 0, a physical sign),
        else that far either side of 0; every other parameter keeps its own bounds."""
        reach = self.strength_reach(scale)
        if reach is None:
            return {}
        one_sided = next(p for p in self.params if p.name == self.strength).lower == 0.0
        return {self.strength: (0.0 if one_sided else -reach, reach)}

    def modal(self, v: Values, state: ModalState, kin: Kinematics) -> None:
        """Stage 1: adjust ``state`` in place (default: nothing)."""

    def force(self, v: Values, state: ModalState, kin: Kinematics) -> Coefficients:
        """Stage 2: feature coefficients this term adds to the force (default: none)."""
        return {}

    def measure(self, v: Values, coefs: Coefficients, kin: Kinematics) -> Coefficients:
        """Stage 3: the force as measured (default: unchanged)."""
        return coefs

    def time_force(self, v: Values, state: ModalState, kin: Kinematics, phase: np.ndarray, n_top: int | None = None) -> np.ndarray:
        """Force of a memory term at phases ``(L, N)`` or ``(P, L, N)``, shape ``(P, L, N)`` (the numpy reference).
        ``n_top``: the phases are samples of each loop's branches, the first ``n_top`` loading (each moves in its
        branch's direction, a sample at a reversal too: :meth:`~hysid_model.kinematics.Kinematics.velocity`); None: any phases."""
        raise TypeError(f"term {self.id} has no memory")

    def sampler(self, kin: Kinematics, phase: np.ndarray, n_top: int | None = None) -> Sampler | None:
        """A compiled evaluator of :meth:`time_force` at the fixed phases ``(L, N)`` of a loop set (``n_top`` as
        there), or None (then :mod:`hysid_model.sampled` uses :meth:`time_force`)."""
        return None

    @property
    def spec(self) -> str:
        """How a model string names this term (``thesis+<spec>``): a library effect by its id, a user's term by
        ``module:attribute`` (:mod:`hysid_model.user_terms`)."""
        return self.id

    def __add__(self, other: object) -> TermGroup:
        """This term and another (or a group of terms) as a group, as PySINDy concatenates its libraries:
        ``coulomb_friction + bouc_wen``; a term plus a model is the model plus the term."""
        if isinstance(other, (Term, TermGroup)):
            return TermGroup((self,)) + other
        return NotImplemented

    def __repr__(self) -> str:
        return f"{type(self).__name__}({', '.join(p.name for p in self.params)})"


class TermGroup:
    """Terms to add to a model together (``hysid.effects.coulomb_friction + hysid.effects.bouc_wen``).

    Groups compose with terms and groups into groups and with a model into a model
    (:meth:`hysid_model.model.Model.__add__`), in the order written; a term appears once.
    """

    def __init__(self, terms: tuple[Term, ...]) -> None:
        ids = [t.id for t in terms]
        twice = sorted({i for i in ids if ids.count(i) > 1})
        if twice:
            raise HysidInputError(f"effect {twice[0]!r} is twice in the group {' + '.join(ids)}")
        self.terms = tuple(terms)

    def __add__(self, other: object) -> TermGroup:
        if isinstance(other, Term):
            return TermGroup(self.terms + (other,))
        if isinstance(other, TermGroup):
            return TermGroup(self.terms + other.terms)
        return NotImplemented

    def __iter__(self) -> Iterator[Term]:
        return iter(self.terms)

    def __len__(self) -> int:
        return len(self.terms)

    def __repr__(self) -> str:
        return f"TermGroup({' + '.join(t.spec for t in self.terms)})"


class Sampler(Protocol):
    """A memory term's force at fixed phases, compiled (:meth:`Term.sampler`)."""

    def add(self, v: Values, shift: np.ndarray | None, out: np.ndarray) -> None:
        """Add the force of candidates ``v`` to ``out`` ``(P, L, N)``, at the phases less ``shift`` ``(P, L)`` if given."""


Stiffness = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
"""A linear term's dynamic stiffness S(w) = re + i im (N/m) at the frequencies ``w``: ``(L,)`` for the ideal
sine, ``(K, 1, L)`` for the K harmonic orders of a measured displacement (all in one call); each part broadcasts
against the ``(P, L)`` candidate arrays, to ``(P, L)`` or ``(K, P, L)``."""


def linear_response(kin: Kinematics, stiffness: Stiffness) -> Coefficients:
    """Force coefficients of a linear term: F_k = S(k w) X_k at every harmonic order k of the displacement.

    For the ideal sine (X_1 = -i X0) this is s1 = Re S(w) X0, c1 = Im S(w) X0:
    Eq. 4.6 for the oscillator. Linear terms stay closed form per harmonic on
    any measured displacement; the stiffness is evaluated at every order at once.
    """
    if kin.xh is None:
        re, im = stiffness(kin.omega)
        return {"s1": re * kin.x0, "c1": im * kin.x0}
    names, a, b = kin.order_parts
    re, im = stiffness(kin.orders[:, None, None] * kin.omega)
    s, c = -(re * b + im * a), re * a - im * b
    out: Coefficients = {}
    for i, (sk, ck) in enumerate(names):
        out[sk], out[ck] = s[i], c[i]
    return out


def complex_amplitude(coefs: Coefficients, order: int) -> np.ndarray | complex:
    """Harmonic ``order`` as one complex amplitude A: s sin(k wt) + c cos(k wt) = Re[A e^{j k wt}], A = c - j s."""
    zero = 0.0
    return coefs.get(f"c{order}", zero) - 1j * coefs.get(f"s{order}", zero)


class MeasurementTerm(Term):
    """A linear time-invariant element between the force and its record.

    Its response at harmonic order k of the excitation (k w) is
    T_k = exp(-j k w tau_d) G_k: a pure delay ``tau_d`` (:meth:`delay`) times a
    proper part G_k (:meth:`gain`) with G_k -> 1 for k -> inf. Harmonic and
    constant features are filtered exactly here; the model filters the
    sign-of-velocity feature and memory forces sample by sample
    (:meth:`hysid_model.model.Model.memory_force`), so this stage hands it the
    ``sgn`` coefficient as 0.
    """

    def delay(self, v: Values, kin: Kinematics) -> np.ndarray | float:
        """Delay of the force channel (s), shape ``(P, 1)`` or scalar."""
        return 0.0

    def gain(self, v: Values, kin: Kinematics, order: np.ndarray) -> np.ndarray | complex:
        """G at orders ``order`` (K,) of every loop's frequency: ``(P, L, K)`` complex, or 1."""
        return 1.0

    def corner(self, v: Values) -> np.ndarray | None:
        """w_c (rad/s) ``(P, 1)`` when :meth:`gain` is the single-pole high-pass G = s / (s + w_c), else None.

        With it the sign-of-velocity feature passes the chain exactly and
        compiled (:mod:`hysid_model.sampled`); a term that overrides :meth:`gain`
        without it is filtered by the spectral reference path.
        """
        return None

    def transfer(self, v: Values, kin: Kinematics, order: np.ndarray) -> np.ndarray:
        """T = exp(-j k w delay) G, shape ``(P, L, K)``."""
        k = np.asarray(order, dtype=float)[None, None, :]
        phase_lag = k * kin.omega[None, :, None] * np.asarray(self.delay(v, kin), dtype=float)[..., None]
        return np.exp(-1j * phase_lag) * self.gain(v, kin, np.asarray(order))

    def measure(self, v: Values, coefs: Coefficients, kin: Kinematics) -> Coefficients:
        out: Coefficients = {}
        orders = sorted({int(name[1:]) for name in coefs if name[:1] in "sc" and name[1:].isdigit()})
        for name in coefs:
            if name not in ("dc", "sgn") and not (name[:1] in "sc" and name[1:].isdigit()):
                raise ValueError(f"{self.id} cannot filter the force feature {name!r}")
        if orders:
            t = self.transfer(v, kin, np.array(orders))
            for i, k in enumerate(orders):
                a = t[:, :, i] * complex_amplitude(coefs, k)
                out[f"s{k}"], out[f"c{k}"] = -a.imag, a.real
        if "dc" in coefs:
            out["dc"] = coefs["dc"] * np.real(self.transfer(v, kin, np.array([0]))[..., 0])
        if "sgn" in coefs:
            out["sgn"] = np.zeros_like(coefs["sgn"])
        return out


class Oscillator(Term):
    """Linear 1-DOF oscillator with equivalent viscous damping, Eq. 4.4.

    Under x = X0 sin(wt) its steady-state force is closed form (Eq. 4.6):
    F = m X0 [(wn^2 - w^2) sin(wt) + 2 xi wn w cos(wt)]; under a measured
    displacement the same holds harmonic by harmonic (:func:`linear_response`). The equivalent mass
    ``meq`` is a parameter like the others: fixed where the specimen's mass is
    known (:meth:`hysid_model.model.Model.fix`), fitted otherwise.
    """

    id = "oscillator"
    explanation = "Mass, viscous damping ratio xi and natural frequency wn of the equivalent 1-DOF system (Eq. 4.4-4.6)."
    params = (
        Parameter("xi0", "1", 0.0, 0.1, "damping ratio (at zero amplitude)", physical=(0.0, math.inf)),
        Parameter("w0", "rad/s", 100.0, 500.0, "natural frequency (at zero amplitude)", physical=(0.0, math.inf)),
        Parameter("meq", "kg", 1e-3, 10.0, "equivalent mass", physical=(0.0, math.inf)),
    )

    def data_bounds(self, scale: DataScale) -> dict[str, tuple[float, float]]:
        """A decade either side of the survey's natural frequency (or of the band), damping ratios up to
        10 x the survey's (at least 2; without a mass, 10 x the ratio its equivalent damping gives at the mass
        that stands in, c w / 2 k: a damper's viscous force far above its spring's needs xi >> 1), two decades
        either side of its mass."""
        xi = 10.0 * (scale.xi if scale.xi is not None else scale.damping * scale.wn_scale / (2.0 * scale.stiffness))
        return {
            "xi0": (0.0, max(2.0, xi)),
            "w0": (scale.wn_scale / 10.0, 10.0 * scale.wn_scale) if scale.wn is not None else (scale.w_min / 10.0, 10.0 * scale.w_max),
            "meq": (scale.mass_scale / 100.0, 100.0 * scale.mass_scale),
        }

    def modal(self, v: Values, state: ModalState, kin: Kinematics) -> None:
        state.xi = state.xi + v["xi0"]
        state.wn = state.wn + v["w0"]
        state.m = state.m + v["meq"]

    def force(self, v: Values, state: ModalState, kin: Kinematics) -> Coefficients:
        """m x'' + c x' + k x: S(w) = m (wn^2 - w^2 + 2 i xi wn w) at each harmonic frequency."""
        m, wn, xi = state.m, state.wn, state.xi
        return linear_response(kin, lambda w: (m * (wn**2 - w**2), m * (2.0 * xi * wn * w)))


class AmplitudeDependentDamping(Term):
    """Damping ratio linear in amplitude, xi(X0) = xi0 + S_xi X0 (Eq. 4.8)."""

    id = "amplitude_dependent_damping"
    strength = "S_xi"
    slope_of = "xi0"
    explanation = (
        "The damping ratio changes linearly with the excitation amplitude (Eq. 4.8); "
        "in the thesis the resonance peak sharpens as the amplitude grows (Fig. 4.7, 4.10)."
    )
    params = (Parameter("S_xi", "1/m", -10.0, 10.0, "slope of the damping ratio with amplitude"),)

    def strength_reach(self, scale: DataScale) -> float:
        """Slopes that change xi by up to 10 x its value (at least 0.1) over the largest amplitude."""
        return 10.0 * max(scale.xi or 0.0, 0.01) / scale.x_max

    def modal(self, v: Values, state: ModalState, kin: Kinematics) -> None:
        state.xi = state.xi + v["S_xi"] * kin.x0


class AmplitudeDependentFrequency(Term):
    """Natural frequency linear in amplitude, wn(X0) = w0 + S_w X0 (Eq. 4.9).

    Physically the softening of the supports, K = (1/Kb + 1/(Ks - A X0))^-1 (Eq. 4.7).
    """

    id = "amplitude_dependent_frequency"
    strength = "S_w"
    slope_of = "w0"
    explanation = (
        "The natural frequency changes linearly with the excitation amplitude (Eq. 4.9): "
        "support stiffness that softens with amplitude (Eq. 4.7, Fig. 4.6, 4.9)."
    )
    params = (Parameter("S_w", "rad/s/m", -10000.0, 10000.0, "slope of the natural frequency with amplitude"),)

    def strength_reach(self, scale: DataScale) -> float:
        """Slopes that move wn by up to 90 % over the largest amplitude (it stays positive)."""
        return 0.9 * scale.wn_scale / scale.x_max

    def modal(self, v: Values, state: ModalState, kin: Kinematics) -> None:
        state.wn = state.wn + v["S_w"] * kin.x0
