"""The effect library as terms to add to a model: ``hysid.models.thesis + hysid.effects.bouc_wen``.

Each is a term of :data:`hysid_model.effects.EFFECTS` with its parameters
(name, unit, default bounds), its force, and a plain-language ``explanation``;
``hysid models`` lists them all. Terms add up to groups of terms
(``coulomb_friction + bouc_wen``) and, with a model, to models, like the terms
of your own that :func:`hysid.term` makes.
"""

from hysid_model.effects import (
    BoucWen,
    ChannelDelay,
    ChargeAmplifierHighpass,
    CoulombFriction,
    CubicStiffness,
    HystereticDamping,
    TransducerMass,
    ZenerThermoelastic,
)
from hysid_model.terms import AmplitudeDependentDamping, AmplitudeDependentFrequency

amplitude_dependent_frequency = AmplitudeDependentFrequency()
"""Natural frequency linear in amplitude (Eq. 4.9)."""
amplitude_dependent_damping = AmplitudeDependentDamping()
"""Damping ratio linear in amplitude (Eq. 4.8)."""
charge_amplifier_highpass = ChargeAmplifierHighpass()
"""The charge amplifier's high-pass filter on the force channel (Eq. 4.1-4.3)."""
transducer_mass = TransducerMass()
"""The force transducer's own mass (Eq. 2.13)."""
coulomb_friction = CoulombFriction()
"""Dry friction F_d sgn(x') (Eq. 2.5)."""
hysteretic_damping = HystereticDamping()
"""Rate-independent (structural) damping (Eq. 2.3)."""
cubic_stiffness = CubicStiffness()
"""A Duffing spring."""
bouc_wen = BoucWen()
"""The Bouc-Wen hysteretic spring (Eq. 2.1)."""
zener_thermoelastic = ZenerThermoelastic()
"""Zener's thermoelastic relaxation (Eq. 2.6)."""
channel_delay = ChannelDelay()
"""A delay between the force and displacement channels."""
