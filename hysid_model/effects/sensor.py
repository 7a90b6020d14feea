"""Measurement-chain effects: the force record is not the force (section 4.1).

Both act on the force channel only, so they change the phase between force and
displacement and with it the loop width, the thesis' warning after Eq. 4.3.
"""

from __future__ import annotations

import math

import numpy as np

from hysid_model.kinematics import Kinematics
from hysid_model.params import Parameter
from hysid_model.terms import DataScale, MeasurementTerm, Values


class ChargeAmplifierHighpass(MeasurementTerm):
    """The charge amplifier's time constant TC as a single-pole high-pass, Eq. 4.1-4.3.

    Harmonic k of the force is seen as G = j k w TC / (1 + j k w TC): gain
    |G| of Eq. 4.1 and phase lead atan(1 / (k w TC)) of Eq. 4.2. The parameter is
    the cutoff f_c = 1 / (2 pi TC) of Eq. 4.3; f_c = 0 is an ideal amplifier.
    """

    id = "charge_amplifier_highpass"
    strength = "f_c"
    explanation = (
        "The force is recorded through the charge amplifier's single-pole high-pass (time constant TC, "
        "cutoff f_c = 1/(2 pi TC), Eq. 4.1-4.3): at low frequency the force is attenuated and leads the "
        "displacement, which widens the loops as if there were extra damping."
    )
    params = (Parameter("f_c", "Hz", 0.0, 100.0, "cutoff frequency 1/(2 pi TC) of the charge amplifier (Eq. 4.3)", physical=(0.0, math.inf)),)

    def strength_reach(self, scale: DataScale) -> float:
        """Cutoffs up to 10 x the highest excitation frequency."""
        return 10.0 * scale.w_max / (2.0 * math.pi)

    def gain(self, v: Values, kin: Kinematics, order: np.ndarray) -> np.ndarray:
        w = np.asarray(order, dtype=float)[None, None, :] * kin.omega[None, :, None]
        wc = 2.0 * np.pi * v["f_c"][:, :, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            g = 1j * w / (1j * w + wc)
        return np.where((w == 0.0) & (wc == 0.0), 1.0 + 0j, g)

    def corner(self, v: Values) -> np.ndarray:
        return 2.0 * np.pi * v["f_c"]


class ChannelDelay(MeasurementTerm):
    """A time shift between the force and the displacement channels: F_rec(t) = F(t - tau_d).

    Harmonic k is delayed by the phase k w tau_d, so the error grows with
    frequency (unlike the high-pass, whose phase error shrinks with it).
    """

    id = "channel_delay"
    strength = "delay_s"
    explanation = (
        "The force channel is recorded late (or early) relative to the displacement channel, e.g. by "
        "anti-alias filters or multiplexed sampling: every harmonic k is shifted by the phase k w delay, "
        "which narrows or widens the loops more at high frequency."
    )
    params = (Parameter("delay_s", "s", -0.01, 0.01, "delay of the force channel behind the displacement channel"),)

    def strength_reach(self, scale: DataScale) -> float:
        """Delays up to half a period of the highest frequency (beyond that the phase is ambiguous)."""
        return math.pi / scale.w_max

    def delay(self, v: Values, kin: Kinematics) -> np.ndarray:
        return v["delay_s"]
