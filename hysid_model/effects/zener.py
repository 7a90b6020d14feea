"""Zener's thermoelastic relaxation, Eq. 2.6."""

from __future__ import annotations

import math
from collections.abc import Collection

import numpy as np

from hysid_model.kinematics import Kinematics
from hysid_model.params import Parameter
from hysid_model.terms import Coefficients, DataScale, ModalState, Term, Values, linear_response


class ZenerThermoelastic(Term):
    """A relaxing modulus with the loss factor of Eq. 2.6, eta = Delta w tau / (1 + w^2 tau^2).

    Zener's standard linear solid, k(w) = k [1 + Delta (w^2 tau^2 + j w tau) / (1 + w^2 tau^2)]
    for a small relaxation strength Delta, with k = m wn^2: the imaginary part
    is Eq. 2.6 (a damping peak at w tau = 1), the real part the stiffening from
    the relaxed to the unrelaxed modulus that goes with it.
    """

    id = "zener_thermoelastic"
    strength = "zener_delta"
    explanation = (
        "Thermoelastic (Zener) relaxation: heat flowing between compressed and stretched fibres makes "
        "the loss factor peak at w = 1/tau (Eq. 2.6) and the stiffness rise from the relaxed to the "
        "unrelaxed value across that frequency."
    )
    params = (
        Parameter("zener_delta", "1", 0.0, 1.0, "relaxation strength Delta_r", physical=(0.0, 1.0)),
        Parameter("zener_tau", "s", 1.0e-6, 10.0, "thermal relaxation time tau_s", physical=(0.0, math.inf)),
    )

    def data_bounds(self, scale: DataScale) -> dict[str, tuple[float, float]]:
        """Relaxation times two decades beyond either end of the band."""
        return {"zener_tau": (0.01 / scale.w_max, 100.0 / scale.w_min)}

    def force(self, v: Values, state: ModalState, kin: Kinematics) -> Coefficients:
        """k Delta (w^2 tau^2 + i w tau) / (1 + w^2 tau^2) at every harmonic frequency w."""
        strength = v["zener_delta"] * state.m * state.wn**2

        def stiffness(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            wt = w * v["zener_tau"]
            scale = strength / (1.0 + wt**2)
            return scale * wt**2, scale * wt

        return linear_response(kin, stiffness)

    def shape_grid(self, kin: Kinematics, free: Collection[str] = ()) -> list[dict[str, float]]:
        """Relaxation times around the band: w tau from 1/3 at the top to 3 at the bottom frequency."""
        taus = np.geomspace(1.0 / (3.0 * kin.omega.max()), 3.0 / kin.omega.min(), 7)
        return [{"zener_tau": float(t)} for t in taus]
