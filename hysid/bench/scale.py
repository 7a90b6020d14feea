"""``hysid bench scale``: a diagnosis that does not depend on the specimen's scale, over :data:`SEEDS` noise seeds.
The statistics of ``tests/test_realdata.py``'s far specimen.

A 1-DOF specimen far from the thesis' beams (:func:`isolator`: 12 Hz, xi0 = 0.5, 0.2 kg, stiffness softening by 40 %
over 1-3 mm, so wn by 23 %, Eq. 4.8-4.9) with hidden Coulomb friction (Eq. 2.5) at 15 % of the spring force at 1 mm,
and the same dimensionless physics at the thesis' scale (:func:`thesis_twin`: 30 Hz, 0.04 kg, 0.5-1.5 mm), each
at 1 % force noise, are diagnosed from the baseline on each seed. On every seed both must name the same effects
in the same order with the same status, among them Coulomb friction and the amplitude-dependent frequency
(:func:`verdict`). ``tests/test_realdata.py`` reads the committed result and runs the far specimen's cheapest seed
live; :func:`definitions_hash` (of this file) ties the two.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

import hysid
from hysid.bench import check_chosen, source_hash, sweep
from hysid.bench import verdict as pass_word
from hysid.report import jsondoc
from hysid_model.loops import LoopSet
from hysid_model.model import Model, build_model
from hysid_model.objective import Objective

SEEDS = range(3)
SCALES = ("far", "thesis")
POINTS = 40
"""Points per branch of the loops."""
ISOLATOR_FREQS = np.linspace(6.0, 20.0, 8)
"""The isolator's default test frequencies (Hz)."""
NAMED = ("coulomb_friction", "amplitude_dependent_frequency")
"""The effects every seed's diagnosis must name."""


def branches(model: Model, theta: np.ndarray, freqs: np.ndarray, amps: np.ndarray, noise_pct: float = 0.0, seed: int = 0, meq: float | None = None) -> LoopSet:
    """Loops of any model on the ideal sine (its force on each branch as the objective sees it), every frequency at
    every amplitude, with force noise of ``noise_pct`` % of each loop's peak force."""
    f, a = (g.reshape(-1) for g in np.meshgrid(freqs, amps))
    x = np.linspace(-1.0, 1.0, POINTS)
    pack = lambda part: np.stack([np.column_stack([x * ai, fi]) for ai, fi in zip(a, part)])
    empty = LoopSet(
        name="specimen", freq_hz=f, x0=a, top=pack(np.zeros((f.size, POINTS))), bottom=pack(np.zeros((f.size, POINTS))), sigma=np.ones(f.size), meq_kg=meq
    )
    force = Objective(empty, model, weights="ml").predict(theta)[0]
    sigma = noise_pct / 100.0 * np.abs(force).max(axis=1)
    force = force + sigma[:, None] * np.random.default_rng(seed).standard_normal(force.shape)
    return LoopSet(
        name="specimen", freq_hz=f, x0=a, top=pack(force[:, :POINTS]), bottom=pack(force[:, POINTS:]), sigma=np.where(sigma > 0, sigma, np.nan), meq_kg=meq
    )


def isolator(
    noise_pct: float = 0.0, amps: Sequence[float] = (1e-3, 2e-3, 3e-3), freqs: np.ndarray = ISOLATOR_FREQS, seed: int = 0, hidden: dict | None = None
) -> tuple[LoopSet, dict[str, float]]:
    """A 1-DOF specimen far from the thesis' beams: 12 Hz, xi0 = 0.5, 0.2 kg, stiffness softening by
    40 % over its amplitude range (wn by 23 %), optionally with hidden effects ``{effect: {param: value}}``;
    the loops (mass not given) and the true values."""
    w0 = 2 * math.pi * 12.0
    s_w = (math.sqrt(0.6) - 1.0) * w0 / amps[-1]
    spec = "+".join(["thesis", *(hidden or {})])
    model = build_model(spec).fix(meq=0.2)
    values = {"xi0": 0.5, "S_xi": 0.0, "w0": w0, "S_w": s_w, **{k: v for params in (hidden or {}).values() for k, v in params.items()}}
    return branches(model, model.from_dict(values), np.asarray(freqs), np.asarray(amps), noise_pct, seed, meq=None), values


def far(seed: int) -> LoopSet:
    """The isolator with Coulomb friction of 15 % of its spring force at 1 mm, 1 % force noise."""
    return isolator(noise_pct=1.0, seed=seed, hidden={"coulomb_friction": {"F_d": 0.15 * 0.2 * (2 * math.pi * 12) ** 2 * 1e-3}})[0]


def thesis_twin(seed: int) -> LoopSet:
    """The isolator's dimensionless physics at the thesis' scale: 30 Hz, 0.04 kg, 0.5-1.5 mm, 15-50 Hz, 1 % force noise."""
    w0, amps = 2 * math.pi * 30.0, np.array([0.5e-3, 1.0e-3, 1.5e-3])
    model = build_model("thesis+coulomb_friction").fix(meq=0.04)
    values = {"xi0": 0.5, "S_xi": 0.0, "w0": w0, "S_w": (math.sqrt(0.6) - 1.0) * w0 / amps[-1], "F_d": 0.15 * 0.04 * w0**2 * 0.5e-3}
    return branches(model, model.from_dict(values), ISOLATOR_FREQS * 2.5, amps, 1.0, seed)


SPECIMENS: dict[str, Callable[[int], LoopSet]] = {"far": far, "thesis": thesis_twin}


def outcome(scale: str, seed: int) -> dict[str, Any]:
    """The diagnosis from the baseline of one scale's specimen on one seed: the effects named in order, the status,
    and the CPU time it took."""
    check_chosen([scale], SCALES, "scale")
    cpu = time.process_time()
    diagnosis = hysid.diagnose(SPECIMENS[scale](seed), "baseline", cross_validate=False)
    return {"effects": [s.effect for s in diagnosis.steps], "status": diagnosis.status, "cpu_s": time.process_time() - cpu}


def same(a: dict[str, Any], b: dict[str, Any]) -> bool:
    """Two outcomes name the same effects in the same order with the same status."""
    return list(a["effects"]) == list(b["effects"]) and a["status"] == b["status"]


def verdict(outcomes: dict[str, dict[str, dict[str, Any]]]) -> dict[str, Any]:
    """The criterion: every seed of :data:`SEEDS` run at both scales, the two outcomes the same on each, and each
    naming every effect of :data:`NAMED`; the seeds that fail it."""
    failed = [
        seed
        for seed in SEEDS
        if any(str(seed) not in outcomes.get(s, {}) for s in SCALES)
        or not same(outcomes["far"][str(seed)], outcomes["thesis"][str(seed)])
        or not set(NAMED) <= set(outcomes["far"][str(seed)]["effects"])
    ]
    return {"seeds": len(SEEDS), "failed": failed, "ok": not failed}


def run(progress: Callable[[int, int, str], None] | None = None) -> dict[str, Any]:
    """A specimen far from the thesis and its twin at the thesis' scale get the same diagnosis on every seed (the
    statistics tests/test_realdata.py reads).

    ``progress(done, total, what)`` is called as each diagnosis ends."""
    say = lambda scale, seed, record: f"{scale} seed {seed}: {', '.join(record['effects']) or 'nothing'} ({record['status']})"
    return jsondoc.plain(sweep("scale", __file__, SCALES, SEEDS, outcome, say, verdict, progress))


def to_text(result: dict[str, Any]) -> str:
    lines = [f"hysid bench scale: the same diagnosis at both scales on every seed  {pass_word(result['ok'])}  ({result['cpu_s']:.0f} s CPU)"]
    for seed in SEEDS:
        a, b = (result["outcomes"][s][str(seed)] for s in SCALES)
        lines.append(f"  seed {seed}: far {', '.join(a['effects'])} ({a['status']}); thesis scale {', '.join(b['effects'])} ({b['status']})")
    return "\n".join(lines)


def definitions_hash() -> str:
    """sha256 of this file: the specimens, their seeds and the criterion as the bench ran them."""
    return source_hash(__file__)
