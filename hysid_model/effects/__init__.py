"""The effect library: model terms a diagnosis can add, by id (``thesis+<id>``).

Each effect is a :class:`hysid_model.terms.Term` with its forward model, its
parameters' units and bounds (a lower bound of 0 on its ``strength`` means the
effect has a physical sign) and a plain-language ``explanation``.
"""

from hysid_model.effects.bouc_wen import BoucWen
from hysid_model.effects.friction import CoulombFriction
from hysid_model.effects.mass import TransducerMass
from hysid_model.effects.sensor import ChannelDelay, ChargeAmplifierHighpass
from hysid_model.effects.stiffness import CubicStiffness, HystereticDamping
from hysid_model.effects.zener import ZenerThermoelastic
from hysid_model.terms import AmplitudeDependentDamping, AmplitudeDependentFrequency, Term

EFFECTS: dict[str, type[Term]] = {
    cls.id: cls
    for cls in (
        AmplitudeDependentFrequency,
        AmplitudeDependentDamping,
        ChargeAmplifierHighpass,
        TransducerMass,
        CoulombFriction,
        HystereticDamping,
        CubicStiffness,
        ZenerThermoelastic,
        BoucWen,
        ChannelDelay,
    )
}
"""id -> term class."""
