"""The specimens of ``hysid bench discovery``: a linear specimen with one force law the effect library lacks.

A 5 kg, 32 Hz, 2 %-damped linear specimen (the issue's: far from the thesis' beams) driven by a sine at 4,
9 and 17 Hz and 1 and 4 mm (6 loops, peak velocities 0.025-0.43 m/s; ``quick``: 4 and 17 Hz), raw records of
:data:`CYCLES` cycles at 4096.7 Hz (:func:`hysid_model.synth.simulate_raw`, force noise a share of each
record's peak force, displacement noise 1e-4 of the amplitude) written as a dataset directory and read
back by ``hysid.load`` (:func:`hysid_model.datasets.load_dataset`: its extraction, :data:`POINTS` samples
per branch), as a user's records are. Each hidden law is a plain numpy function of x (m) and v (m/s),
added to the specimen as a term of the user's kind (:func:`hysid.term`, made on first use) only to
simulate the records; the diagnosis never sees it. Laws:

* the five of the issue: a fluid viscous damper ``c |v|^0.35 sgn v``, an orifice ``c v |v|``, a gap
  (dead zone) ``k (|x| - g)+ sgn x``, Stribeck friction ``F_c sgn v (1 + s exp(-(v/v_s)^2))`` (25 N sliding, 60 N static),
  an asymmetric spring ``k x^2``;
* four unlike them, not what discovery was built on: a saturating damper ``F_0 tanh(v / v_0)``, a
  one-sided stop (bilinear spring on one side) ``k (x - g)+``, a wedge friction proportional to the
  displacement ``mu_k |x| sgn v`` (a hysteretic force whose size follows x), and a quintic spring
  ``k_5 x^5`` (a hardening polynomial of another power than the library's cubic);
* one with memory: two Jenkins (elastic-perfectly plastic) elements in parallel, a Masing/Iwan model of two
  sliders (:func:`two_slider`), whose loops the library's one Bouc-Wen spring cannot draw;

and two controls: the specimen alone, and the specimen with Coulomb friction (a library effect).
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np

import hysid
from hysid.bench import search_problems as sp
from hysid_model.datasets import write_dataset
from hysid_model.loops import LoopSet
from hysid_model.model import Model, build_model
from hysid_model.synth import simulate_raw
from hysid_model.user_terms import UserTerm, term

SPECIMEN = {"xi0": 0.02, "w0": 2.0 * np.pi * 32.0, "meq": 5.0}
"""5 kg, 32 Hz (k = 202 kN/m), 2 % damping (c = 40 N s/m)."""
FREQS_HZ = (4.0, 9.0, 17.0)
AMPLITUDES_M = (1e-3, 4e-3)
"""The ends of the issue's 1-4 mm (a middle amplitude cost a third more time on a shared machine; three frequencies
keep a held-out one on either side)."""
QUICK_FREQS_HZ = (4.0, 17.0)
QUICK_AMPLITUDES_M = (1e-3, 4e-3)
RATE_HZ = 4096.7
"""About 4096 Hz, a rate no frequency of the grid divides."""
CYCLES = 6
POINTS = 50
"""Samples per branch of the loops (the validation bench's 100 halved: the diagnosis' cost, not its question)."""
NOISE_PCT = (1.0, 3.0)
"""Force noise levels, per cent of each record's peak force (the thesis' convention, Appendix A)."""


@dataclass(frozen=True)
class Law:
    """A force law the library lacks: ``force(x, v, **truth)`` in N, its true values, units and search bounds
    (the bounds only make it a term for the simulation)."""

    name: str
    formula: str
    force: Callable[..., np.ndarray]
    params: dict[str, tuple[float, str, tuple[float, float]]]
    """A row a parameter: its true value, unit and search bounds (low, high)."""
    issue: bool = True
    """One of the issue's five (else one of the laws unlike them)."""
    memory: bool = False
    """A force with memory (a function of x and v over whole cycles, :func:`jenkins`): a memory term must describe it."""

    @property
    def truth(self) -> dict[str, float]:
        return {name: value for name, (value, _, _) in self.params.items()}

    @property
    def units(self) -> dict[str, str]:
        return {name: unit for name, (_, unit, _) in self.params.items()}

    @property
    def bounds(self) -> dict[str, tuple[float, float]]:
        return {name: bounds for name, (_, _, bounds) in self.params.items()}

    @property
    def n_params(self) -> int:
        return len(self.truth)


def fluid_viscous(x, v, hfv_c, hfv_alpha):
    return hfv_c * np.abs(v) ** hfv_alpha * np.sign(v)


def orifice(x, v, hor_c):
    return hor_c * v * np.abs(v)


def gap(x, v, hgp_k, hgp_g):
    return hgp_k * np.maximum(np.abs(x) - hgp_g, 0.0) * np.sign(x)


def stribeck(x, v, hst_fc, hst_s, hst_vs):
    return hst_fc * np.sign(v) * (1.0 + hst_s * np.exp(-((v / hst_vs) ** 2)))


def asymmetric(x, v, has_k):
    return has_k * x**2


def saturating(x, v, hsa_f, hsa_v):
    return hsa_f * np.tanh(v / hsa_v)


def one_sided_stop(x, v, hos_k, hos_g):
    return hos_k * np.maximum(x - hos_g, 0.0)


def wedge_friction(x, v, hwf_k):
    return hwf_k * np.abs(x) * np.sign(v)


def quintic(x, v, hqu_k):
    return hqu_k * x**5


def jenkins(x, v, k, f):
    """An elastic-perfectly plastic (Jenkins) element, a spring ``k`` (N/m) in series with a slider of slip force ``f`` (N),
    on its steady periodic orbit: from the reversal at the lowest displacement, where its force is -F_m, it loads as
    the spring until it slips at F_m (F_m = f, or k times the half span where it never slips). A function of the
    travel since the last reversal: the reversals are the extremes of ``x`` over its last axis (whole cycles)."""
    lo, hi = np.min(x, axis=-1, keepdims=True), np.max(x, axis=-1, keepdims=True)
    peak = np.minimum(f, 0.5 * k * (hi - lo))
    return np.where(v >= 0.0, np.minimum(k * (x - lo) - peak, peak), np.maximum(peak - k * (hi - x), -peak))


def two_slider(x, v, hts_f, hts_k, hts_fr, hts_kr):
    """Two Jenkins elements in parallel (a Masing/Iwan model of two sliders): slip force ``hts_f`` and stiffness ``hts_k``,
    and ``hts_fr`` times the one and ``hts_kr`` times the other."""
    return jenkins(x, v, hts_k, hts_f) + jenkins(x, v, hts_kr * hts_k, hts_fr * hts_f)


LAWS = {
    law.name: law
    for law in (
        Law(
            "fluid_viscous",
            "c |v|^alpha sgn v, alpha = 0.35",
            fluid_viscous,
            {"hfv_c": (120.0, "N (s/m)^alpha", (0.0, 1e4)), "hfv_alpha": (0.35, "1", (0.05, 2.0))},
        ),
        Law("orifice", "c v |v|", orifice, {"hor_c": (800.0, "N s^2/m^2", (0.0, 1e5))}),
        Law("gap", "k (|x| - g)+ sgn x", gap, {"hgp_k": (8e4, "N/m", (0.0, 1e7)), "hgp_g": (1.2e-3, "m", (0.0, 1e-2))}),
        Law(
            "stribeck",
            "F_c sgn v (1 + s exp(-(v/v_s)^2)), static F_c (1 + s)",
            stribeck,
            {"hst_fc": (25.0, "N", (0.0, 1e3)), "hst_s": (1.4, "1", (0.0, 10.0)), "hst_vs": (0.04, "m/s", (1e-4, 1.0))},
        ),
        Law("asymmetric", "k x^2", asymmetric, {"has_k": (1.5e7, "N/m^2", (-1e9, 1e9))}),
        Law("saturating", "F_0 tanh(v / v_0)", saturating, {"hsa_f": (50.0, "N", (0.0, 1e4)), "hsa_v": (0.08, "m/s", (1e-4, 10.0))}, issue=False),
        Law("one_sided_stop", "k (x - g)+", one_sided_stop, {"hos_k": (6e4, "N/m", (0.0, 1e7)), "hos_g": (1.5e-3, "m", (0.0, 1e-2))}, issue=False),
        Law("wedge_friction", "mu_k |x| sgn v", wedge_friction, {"hwf_k": (1.5e4, "N/m", (0.0, 1e7))}, issue=False),
        Law("quintic", "k_5 x^5", quintic, {"hqu_k": (2.4e14, "N/m^5", (-1e17, 1e17))}, issue=False),
        Law(
            "two_slider",
            "two Jenkins elements in parallel (Masing/Iwan): slip F and stiffness k, and 3 F with 0.2 k",
            two_slider,
            {"hts_f": (20.0, "N", (0.0, 1e3)), "hts_k": (1e5, "N/m", (1.0, 1e7)), "hts_fr": (3.0, "1", (0.0, 10.0)), "hts_kr": (0.2, "1", (0.01, 10.0))},
            issue=False,
            memory=True,
        ),
    )
}
"""The hidden laws (module docstring); strengths of 10-50 % of the spring's force at the largest amplitude."""
CONTROLS = {"no_effect": ("baseline", {}), "coulomb_friction": ("baseline+coulomb_friction", {"F_d": 30.0})}
"""The controls: model and values beside :data:`SPECIMEN` (no missing effect; a library effect only)."""


@cache
def hidden_term(name: str) -> UserTerm:
    """Law ``name`` as a term of the user's kind, for the simulation (made on first use: importing registers nothing)."""
    law = LAWS[name]
    strength = next(iter(law.truth))
    return term(law.force, name=f"hidden_{name}", units=law.units, bounds=law.bounds, strength=strength, explanation=law.formula)


def truth_model(case: str) -> tuple[Model, dict[str, float], str]:
    """The true model of a law or a control, its true values and its model string."""
    if case in CONTROLS:
        spec, values = CONTROLS[case]
        return build_model(spec), {**SPECIMEN, **values}, spec
    made = hidden_term(case)
    return build_model("baseline") + made, {**SPECIMEN, **LAWS[case].truth}, f"baseline+{made.spec}"


def grid(quick: bool) -> tuple[np.ndarray, np.ndarray]:
    return sp.grid(np.array(QUICK_FREQS_HZ if quick else FREQS_HZ), np.array(QUICK_AMPLITUDES_M if quick else AMPLITUDES_M))


def loops_of(case: str, noise_pct: float, seed: int, quick: bool = False) -> LoopSet:
    """Raw records of ``case`` (a law or a control) with force noise ``noise_pct`` % of each record's peak (draw
    ``seed``), written as a dataset directory and loaded by ``hysid.load`` as a user's records are."""
    model, values, _ = truth_model(case)
    theta = model.from_dict(values)
    freq, amp = grid(quick)
    noise = noise_pct / sp.NOISE_PCT * sp.peak_noise(model, theta, freq, amp)
    records = simulate_raw(model, theta, freq, amp, noise_n=noise, seed=seed, sample_rate_hz=RATE_HZ, cycles=CYCLES)
    with tempfile.TemporaryDirectory(prefix="hysid-discovery-") as folder:
        directory = write_dataset(Path(folder) / case, records, name=f"{case}-{noise_pct:g}pct-seed{seed}")
        return hysid.load(directory, n_points=POINTS)
