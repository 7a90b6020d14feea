"""The presets a model string starts from (:data:`PRESETS`), what each frees and what each models.

``baseline`` = the oscillator of Eq. 4.4/4.6 with constant xi and wn; ``thesis`` = the final model
of Eq. 4.8-4.10 (xi0, S_xi, w0, S_w); ``mr_damper`` = the oscillator plus a Bouc-Wen spring with
its exponent free. :func:`hysid_model.model.build_model` builds a model from a preset and effects;
a user's term may not take a preset's name (:func:`hysid_model.user_terms.term`).
"""

from __future__ import annotations

from hysid_model.effects.bouc_wen import BoucWen
from hysid_model.terms import AmplitudeDependentDamping, AmplitudeDependentFrequency

PRESETS: dict[str, tuple[str, ...]] = {
    "baseline": (),
    "thesis": (AmplitudeDependentDamping.id, AmplitudeDependentFrequency.id),
    "mr_damper": (BoucWen.id,),
}
"""Preset -> the effects it adds to the oscillator."""

PRESET_FREES: dict[str, tuple[str, ...]] = {"mr_damper": ("bw_n",)}
"""Preset -> parameters its effects fix by default that it searches (the Bouc-Wen exponent of ``mr_damper``)."""

PRESET_EXPLANATIONS: dict[str, str] = {
    "baseline": "The 1-DOF oscillator of Eq. 4.4 / 4.6: mass, constant viscous damping ratio and natural frequency.",
    "thesis": "The thesis' final model (Eq. 4.8-4.10): damping ratio and natural frequency linear in the amplitude.",
    "mr_damper": (
        "The oscillator plus a Bouc-Wen spring, exponent n free (Eq. 2.1): F = c x' + k x + k_bw z (and the mass), "
        "Spencer et al.'s (1997) simple model of MR dampers that fits any smooth hysteretic device (elastomeric "
        "bearings, wire-rope isolators); reports name it baseline + bouc_wen (bw_n free)."
    ),
}
"""Preset -> what it models (``hysid models``).

``mr_damper`` is the simple Bouc-Wen model of Spencer et al. (1997), F = c0 x' + k0 x + alpha z: the
oscillator's dashpot and spring are c0 and k0, the Bouc-Wen spring alpha z with the exponent n free.
Their 'modified' model's internal dashpot c1 (with the spring k1 of the accumulator) is left out: it
drives z by an internal displacement y with y' = (alpha z + c0 x' + k0 (x - y)) / (c0 + c1), which
makes the damper a two-state system whose loops depend on the rate, so the orbit is no longer a
function of the travel (:mod:`hysid_model.bouc_wen_orbit`) but would need a time integration per
candidate, and c1 trades off with c0 and the shape of z on loops at one frequency."""
