"""Stiffness beyond the linear spring: complex (hysteretic) and cubic (Duffing)."""

from __future__ import annotations

import math

import numpy as np

from hysid_model.kinematics import Kinematics
from hysid_model.params import Parameter
from hysid_model.terms import Coefficients, DataScale, ModalState, Term, Values, linear_response


class HystereticDamping(Term):
    """Structural damping: the spring is complex, k (1 + i eta), Eq. 2.2-2.3.

    Under x = X0 sin(wt) the imaginary part is the force eta k X0 cos(wt), with
    k = m wn^2 the oscillator's stiffness: a loop width independent of frequency
    (rate independent), where viscous damping grows with w.
    """

    id = "hysteretic_damping"
    strength = "eta"
    explanation = (
        "Rate-independent (structural, viscoelastic) damping: the stiffness is complex, k(1 + i eta) "
        "(Eq. 2.3), so the energy lost per cycle, pi eta k X0^2, does not change with frequency, "
        "unlike viscous damping which grows with it."
    )
    params = (Parameter("eta", "1", 0.0, 2.0, "loss factor of the complex stiffness", physical=(0.0, math.inf)),)

    def strength_reach(self, scale: DataScale) -> float:
        """Loss factors up to 10 x the survey's (at least 2)."""
        return max(2.0, 10.0 * scale.loss_factor)

    def force(self, v: Values, state: ModalState, kin: Kinematics) -> Coefficients:
        """i eta k at every harmonic frequency (the complex spring's loss part)."""
        loss = v["eta"] * state.m * state.wn**2
        return linear_response(kin, lambda w: (np.zeros_like(loss), loss))


class CubicStiffness(Term):
    """A Duffing spring k3 x^3 added to the force.

    x^3 = X0^3 (3 sin(wt) - sin(3 wt)) / 4: the stiffness grows (k3 > 0) or
    softens (k3 < 0) with the square of the amplitude, and a third harmonic in
    phase with the displacement appears. On a measured displacement with
    harmonics up to K the force holds the harmonics of x^3 up to 3K.
    """

    id = "cubic_stiffness"
    strength = "k3"
    explanation = (
        "A hardening (k3 > 0) or softening (k3 < 0) cubic spring, F = k3 x^3: the apparent stiffness "
        "changes with the square of the amplitude and the loops bend into an S, a third harmonic in "
        "phase with the displacement."
    )
    params = (Parameter("k3", "N/m^3", -1.0e16, 1.0e16, "cubic stiffness coefficient"),)

    def strength_reach(self, scale: DataScale) -> float:
        """Cubic stiffness that changes the stiffness by up to 10 x at the largest amplitude."""
        return 10.0 * scale.stiffness / scale.x_max**2

    def force(self, v: Values, state: ModalState, kin: Kinematics) -> Coefficients:
        """k3 times the harmonics of x^3 (on a measured displacement: of its cube, orders 1..3K)."""
        if kin.xh is None:
            cube = v["k3"] * kin.x0**3
            return {"s1": 0.75 * cube, "s3": -0.25 * cube}
        amp = kin.power_harmonics(3)
        out: Coefficients = {}
        for i in range(amp.shape[1]):
            out[f"s{i + 1}"] = -v["k3"] * amp[:, i].imag
            out[f"c{i + 1}"] = v["k3"] * amp[:, i].real
        return out
