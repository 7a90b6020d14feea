"""Dry (Coulomb) friction, Eq. 2.5."""

from __future__ import annotations

import math

from hysid_model import waveform
from hysid_model.kinematics import Kinematics
from hysid_model.params import Parameter
from hysid_model.terms import Coefficients, DataScale, ModalState, Term, Values


class CoulombFriction(Term):
    """F_d sgn(x') added to the force (Eq. 2.5): +F_d on loading, -F_d on unloading.

    The force jumps by 2 F_d at each reversal; its harmonics are the odd cosine
    terms 4 F_d / (pi k), so it dissipates 4 F_d X0 per cycle at any frequency.
    """

    id = "coulomb_friction"
    strength = "F_d"
    explanation = (
        "Dry sliding friction of magnitude F_d = mu N opposing the velocity (Eq. 2.5): the force jumps by "
        "2 F_d at every reversal, the loops become rectangular, and the energy dissipated per cycle, "
        "4 F_d X0, does not depend on frequency."
    )
    params = (Parameter("F_d", "N", 0.0, 1.0e6, "friction force magnitude mu N", physical=(0.0, math.inf)),)

    def strength_reach(self, scale: DataScale) -> float:
        """Friction up to twice the largest peak force."""
        return 2.0 * scale.force

    def force(self, v: Values, state: ModalState, kin: Kinematics) -> Coefficients:
        """F_d sgn(x'), less its cycle mean where the displacement's reversals are not half a cycle apart
        (even harmonics): the model's force, like the extracted loops', has no mean."""
        if kin.xh is None:
            return {"sgn": v["F_d"]}
        return {"sgn": v["F_d"], "dc": -v["F_d"] * waveform.velocity_sign_harmonics(kin.xh, 1)[:, 0].real}
