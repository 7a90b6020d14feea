"""Simulated specimens with a force law the effect library lacks, for the discovery tests.

A 5 kg, 32 Hz linear specimen (2 % damping) driven at 4-17 Hz and 1-4 mm, raw records at 4096.7 Hz with 1 %
force noise, extracted as real data are: far from the thesis' beams, with one hidden law added as a term of
the user's kind (:func:`hysid.term`), simulated by :func:`hysid_model.synth.simulate_raw`.
"""

from __future__ import annotations

import numpy as np

from hysid.bench import search_problems as sp
from hysid.effects import coulomb_friction
from hysid_model.loops import LoopSet
from hysid_model.model import build_model
from hysid_model.synth import simulate_raw
from hysid_model.user_terms import term

SPECIMEN = {"xi0": 0.02, "w0": 2 * np.pi * 32.0, "meq": 5.0}
FREQS = np.array([4.0, 8.0, 12.0, 17.0])
AMPS = np.array([1e-3, 2.5e-3, 4e-3])
RATE_HZ = 4096.7


def fluid(x, v, hf_c, hf_alpha):
    """A fluid viscous damper, c |v|^alpha sgn v."""
    return hf_c * np.abs(v) ** hf_alpha * np.sign(v)


def orifice(x, v, ho_c):
    """Orifice damping, c v |v|."""
    return ho_c * v * np.abs(v)


def gap(x, v, hg_k, hg_g):
    """A gap (dead-zone) spring, k (|x| - g)+ sgn x."""
    return hg_k * np.maximum(np.abs(x) - hg_g, 0.0) * np.sign(x)


def stribeck(x, v, hs_f, hs_s, hs_v):
    """Stribeck friction: F_c (1 + s exp(-(v / v_s)^2)) sgn v, the static force F_c (1 + s)."""
    return hs_f * (1.0 + hs_s * np.exp(-((v / hs_v) ** 2))) * np.sign(v)


def quadratic_spring(x, v, hq_k):
    """An asymmetric spring, k x^2."""
    return hq_k * x**2


LAWS = {
    "fluid": (
        term(fluid, name="hidden_fluid", units={"hf_c": "N", "hf_alpha": "1"}, bounds={"hf_c": (0, 1e4), "hf_alpha": (0.05, 3)}, strength="hf_c"),
        {"hf_c": 100.0, "hf_alpha": 0.35},
    ),
    "orifice": (term(orifice, name="hidden_orifice", units={"ho_c": "N s^2/m^2"}, bounds={"ho_c": (0, 1e5)}), {"ho_c": 150.0}),
    "gap": (
        term(gap, name="hidden_gap", units={"hg_k": "N/m", "hg_g": "m"}, bounds={"hg_k": (0, 1e7), "hg_g": (0, 1e-2)}, strength="hg_k"),
        {"hg_k": 1.0e5, "hg_g": 1.5e-3},
    ),
    "stribeck": (
        term(
            stribeck,
            name="hidden_stribeck",
            units={"hs_f": "N", "hs_s": "1", "hs_v": "m/s"},
            bounds={"hs_f": (0, 1e3), "hs_s": (0, 10), "hs_v": (1e-4, 1.0)},
            strength="hs_f",
        ),
        {"hs_f": 20.0, "hs_s": 1.0, "hs_v": 0.02},
    ),
    "quadratic": (term(quadratic_spring, name="hidden_quadratic", units={"hq_k": "N/m^2"}, bounds={"hq_k": (-1e9, 1e9)}, strength="hq_k"), {"hq_k": 3.0e7}),
    "coulomb": (coulomb_friction, {"F_d": 30.0}),
    "none": (None, {}),
}


def specimen(law: str, seed: int = 0, noise_pct: float = 1.0, freqs: np.ndarray = FREQS, amps: np.ndarray = AMPS, points: int = 60) -> LoopSet:
    """Loops of the specimen with the hidden ``law`` of :data:`LAWS` (``none``: the linear specimen alone; ``coulomb``:
    a library effect only)."""
    hidden, values = LAWS[law]
    model = build_model("baseline") if hidden is None else build_model("baseline") + hidden
    theta = model.from_dict({**SPECIMEN, **values})
    freq, amp = sp.grid(freqs, amps)
    clean = simulate_raw(model, theta, freq, amp, noise_n=0.0, x_noise=0.0, cycles=1, sample_rate_hz=200 * float(freq.max()))
    noise = np.array([noise_pct / 100.0 * np.abs(r.force).max() for r in clean])
    records = simulate_raw(model, theta, freq, amp, noise_n=noise, seed=seed, sample_rate_hz=RATE_HZ, cycles=6)
    return sp.extracted(f"specimen with {law}", records, None, points)
