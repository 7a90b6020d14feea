"""Is a named effect, or a fitted value, physically possible on these loops?

A diagnosis that names a sensor effect the rig cannot have, or a value no
rig produces, gives a confident wrong answer. Each check needs the data's
consent:

* a high-pass on the force channel (``charge_amplifier_highpass``, Eq. 4.1-4.3)
  removes the force's mean: where the records' force has a mean well above
  its noise (``DC_SHARE`` of the force amplitude in most loops; a preload on a
  DC-coupled load cell), the channel passes DC and the effect is impossible
  (:func:`implausible_effect`);
* a channel delay (``channel_delay``) is what anti-alias filters and
  multiplexed sampling do: from microseconds to a few milliseconds. One longer
  than ``MAX_DELAY_S`` and than ``MAX_DELAY_PERIOD`` of the shortest period stands in
  for physics the model lacks (a memory term's lag), not for the chain
  (:func:`implausible_values`);
* a fitted equivalent mass far above what the loops' own inertia supports
  (the survey's Re(F1/X1) = k - m w^2, :func:`hysid_model.survey.inertia`) is
  the oscillator standing in for stiffness and damping (:func:`mass_note`).
"""

from __future__ import annotations

import numpy as np

from hysid_model.loops import LoopSet
from hysid_model.model import Model
from hysid_model.survey import inertia, survey

DC_SHARE = 0.01
"""|mean force| / force amplitude above which a loop's force channel evidently passes DC."""
MAX_DELAY_S = 5e-3
"""Longest delay a measurement chain plausibly adds (DAQ anti-alias filters: tens of samples at kHz rates)."""
MAX_DELAY_PERIOD = 0.1
"""...unless it is also within this fraction of the shortest period (a delay far below the time scale)."""
MASS_SPAN = 5.0
"""Standard errors of the loops' inertia estimate within which a fitted mass is supported."""
MASS_FACTOR = 2.0
"""A fitted mass beyond this many times the supported upper end is named."""


def force_has_mean(loops: LoopSet) -> float | None:
    """The median over loops of |mean force| / force amplitude where it exceeds ``DC_SHARE``, else None
    (also where the loops carry no record of their mean, e.g. a tidy loops file)."""
    per_loop = loops.meta.get("per_loop") or {}
    if "force_mean_n" not in per_loop or "force_amplitude_n" not in per_loop:
        return None
    mean = np.abs(np.asarray(per_loop["force_mean_n"], dtype=float))
    amplitude = np.asarray(per_loop["force_amplitude_n"], dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        share = float(np.median(mean / amplitude))
    return share if share > DC_SHARE else None


def implausible_effect(effect: str, loops: LoopSet) -> str | None:
    """Why ``effect`` cannot be at work on ``loops`` whatever its values, or None."""
    if effect == "charge_amplifier_highpass":
        share = force_has_mean(loops)
        if share is not None:
            return (
                f"the force records keep a mean of {100 * share:.3g} % of their amplitude (median over loops): the force "
                "channel passes DC, and a high-pass would have removed it"
            )
    return None


def implausible_values(fit: object, loops: LoopSet) -> dict[str, str]:
    """The fitted values of ``fit`` (a diagnosis :class:`~hysid.harmonic_fits.Fit`) no measurement chain
    produces, each with why."""
    params = fit.params()  # type: ignore[attr-defined]
    out = {}
    if "delay_s" in params:
        delay, period = abs(params["delay_s"]), float(1.0 / loops.freq_hz.max())
        if delay > MAX_DELAY_S and delay > MAX_DELAY_PERIOD * period:
            out["delay_s"] = (
                f"a channel delay of {delay * 1e3:.3g} ms ({100 * delay / period:.3g} % of the period at "
                f"{loops.freq_hz.max():.4g} Hz) is beyond what a measurement chain adds (up to a few ms): it stands "
                "in for physics the model lacks"
            )
    return out


def mass_note(model: Model, theta: np.ndarray, loops: LoopSet) -> str | None:
    """A sentence where the fitted equivalent mass of ``model`` at ``theta`` is far above what the loops' inertia
    supports (module docstring), else None (also for a known, fixed mass)."""
    if "meq" not in model.names:
        return None
    meq = float(theta[model.names.index("meq")])
    found = inertia(loops, survey(loops).k_dyn)
    if found is None:
        return None
    m, se, _ = found
    upper = max(m, 0.0) + MASS_SPAN * se
    if not (upper > 0 and meq > MASS_FACTOR * upper):
        return None
    return (
        f"the fitted equivalent mass meq = {meq:.4g} kg is far above what the loops' inertia supports (Re(F1/X1) against w^2 gives "
        f"{m:.3g} +- {se:.2g} kg): meq, w0 and xi0 stand for each amplitude's stiffness and damping, not for a resonance"
    )
