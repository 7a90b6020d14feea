"""The force transducer's own mass, Eq. 2.13."""

from __future__ import annotations

import math

from hysid_model.kinematics import Kinematics
from hysid_model.params import Parameter
from hysid_model.terms import Coefficients, DataScale, ModalState, Term, Values, linear_response


class TransducerMass(Term):
    """The transducer mass M seen in the measured force, Eq. 2.13.

    f_a = f_m / (1 + Y / Y_m) with the transducer admittance Y_m = 1 / (j w M)
    and the driving-point admittance Y = v / f_a gives f_m = f_a + j w M v =
    f_a + M x'': the record carries -M X0 w^2 sin(wt) more. This is
    indistinguishable from the equivalent mass when that is fitted.
    """

    id = "transducer_mass"
    strength = "m_t"
    explanation = (
        "The force transducer's own seismic mass M is accelerated with the specimen, so the record is "
        "the specimen force plus M x'' (Eq. 2.13): an extra inertia force that grows with w^2. It cannot "
        "be told apart from the equivalent mass when that mass is fitted."
    )
    params = (Parameter("m_t", "kg", 0.0, 10.0, "transducer mass between the gauge and the specimen", physical=(0.0, math.inf)),)

    def strength_reach(self, scale: DataScale) -> float:
        """Up to 10 x the equivalent mass (or the mass that would resonate in the band)."""
        return 10.0 * scale.mass_scale

    def force(self, v: Values, state: ModalState, kin: Kinematics) -> Coefficients:
        """M x'': dynamic stiffness -M w^2 at each harmonic frequency."""
        return linear_response(kin, lambda w: (-v["m_t"] * w**2, 0.0 * w))
