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

Terms with memory (internal state, e.g. Bouc-Wen) instead return their force at
the sample phases (:meth:`Term.time_force`), from their periodic steady state
under the prescribed motion.
Elements of the measurement chain (charge amplifier, channel delay) are
:class:`MeasurementTerm`: a delay times a gain per harmonic order, applied
exactly to harmonic features here and per sample to the rest by the model.

The effect library (id -> term class) is :data:`hysid_model.effects.EFFECTS`;
this module holds the base classes and the thesis' own terms (Eq. 4.4-4.10).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from hysid_model.params import Parameter

Values = dict[str, np.ndarray]
"""Parameter values by name, each of shape ``(P, 1)`` so they broadcast over loops."""

Coefficients = dict[str, np.ndarray]
"""Feature name -> coefficient (N) of shape ``(P, L)``."""


@dataclass(frozen=True)
class Kinematics:
    """What the prescribed motion x = X0 sin(wt) of each loop gives a term (Eq. 4.5)."""

    x0: np.ndarray
    omega: np.ndarray


@dataclass
class ModalState:
    """Damping ratio, natural frequency (rad/s) and mass (kg) per candidate and loop."""

    xi: np.ndarray
    wn: np.ndarray
    m: np.ndarray


def add_coefficient(coefs: Coefficients, name: str, value: np.ndarray) -> None:
    coefs[name] = coefs[name] + value if name in coefs else value


class Term:
    """Base class; subclasses set ``id``, ``explanation`` and ``params``.

    Effects of the library also name their ``strength``: the parameter whose
    value 0 switches the effect off (the nested null a diagnosis tests). If its
    lower bound is 0 the effect has a physical sign (one-sided). Parameters
    that only shape the effect and are unidentified when it is off (e.g. a
    relaxation time) get candidate values from :meth:`shape_grid`.
    """

    id: ClassVar[str] = ""
    explanation: ClassVar[str] = ""
    memory: ClassVar[bool] = False
    strength: ClassVar[str] = ""
    params: tuple[Parameter, ...] = ()

    def shape_grid(self, kin: Kinematics) -> list[dict[str, float]]:
        """Values of the shape parameters worth testing on loops ``kin`` (default: none to choose)."""
        return [{}]

    def modal(self, v: Values, state: ModalState, kin: Kinematics) -> None:
        """Stage 1: adjust ``state`` in place (default: nothing)."""

    def force(self, v: Values, state: ModalState, kin: Kinematics) -> Coefficients:
        """Stage 2: feature coefficients this term adds to the force (default: none)."""
        return {}

    def measure(self, v: Values, coefs: Coefficients, kin: Kinematics) -> Coefficients:
        """Stage 3: the force as measured (default: unchanged)."""
        return coefs

    def time_force(self, v: Values, state: ModalState, kin: Kinematics, phase: np.ndarray) -> np.ndarray:
        """Force of a memory term at phases ``(L, N)`` or ``(P, L, N)``, shape ``(P, L, N)``."""
        raise TypeError(f"term {self.id} has no memory")

    def __repr__(self) -> str:
        return f"{type(self).__name__}({', '.join(p.name for p in self.params)})"


def complex_amplitude(coefs: Coefficients, order: int) -> np.ndarray:
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
    F = m X0 [(wn^2 - w^2) sin(wt) + 2 xi wn w cos(wt)]. The equivalent mass
    ``meq`` is a parameter like the others: fixed where the specimen's mass is
    known (:meth:`hysid_model.model.Model.fix`), fitted otherwise.
    """

    id = "oscillator"
    explanation = "Mass, viscous damping ratio xi and natural frequency wn of the equivalent 1-DOF system (Eq. 4.4-4.6)."
    params = (
        Parameter("xi0", "1", 0.0, 0.1, "damping ratio (at zero amplitude)"),
        Parameter("w0", "rad/s", 100.0, 500.0, "natural frequency (at zero amplitude)"),
        Parameter("meq", "kg", 1e-3, 10.0, "equivalent mass"),
    )

    def modal(self, v: Values, state: ModalState, kin: Kinematics) -> None:
        state.xi = state.xi + v["xi0"]
        state.wn = state.wn + v["w0"]
        state.m = state.m + v["meq"]

    def force(self, v: Values, state: ModalState, kin: Kinematics) -> Coefficients:
        w = kin.omega
        scale = state.m * kin.x0
        return {
            "s1": scale * (state.wn**2 - w**2),
            "c1": scale * (2.0 * state.xi * state.wn * w),
        }


class AmplitudeDependentDamping(Term):
    """Damping ratio linear in amplitude, xi(X0) = xi0 + S_xi X0 (Eq. 4.8)."""

    id = "amplitude_dependent_damping"
    strength = "S_xi"
    explanation = (
        "The damping ratio changes linearly with the excitation amplitude (Eq. 4.8); "
        "in the thesis the resonance peak sharpens as the amplitude grows (Fig. 4.7, 4.10)."
    )
    params = (Parameter("S_xi", "1/m", -10.0, 10.0, "slope of the damping ratio with amplitude"),)

    def modal(self, v: Values, state: ModalState, kin: Kinematics) -> None:
        state.xi = state.xi + v["S_xi"] * kin.x0


class AmplitudeDependentFrequency(Term):
    """Natural frequency linear in amplitude, wn(X0) = w0 + S_w X0 (Eq. 4.9).

    Physically the softening of the supports, K = (1/Kb + 1/(Ks - A X0))^-1 (Eq. 4.7).
    """

    id = "amplitude_dependent_frequency"
    strength = "S_w"
    explanation = (
        "The natural frequency changes linearly with the excitation amplitude (Eq. 4.9): "
        "support stiffness that softens with amplitude (Eq. 4.7, Fig. 4.6, 4.9)."
    )
    params = (Parameter("S_w", "rad/s/m", -10000.0, 10000.0, "slope of the natural frequency with amplitude"),)

    def modal(self, v: Values, state: ModalState, kin: Kinematics) -> None:
        state.wn = state.wn + v["S_w"] * kin.x0

