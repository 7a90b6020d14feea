"""``hysid bench shaker``: a fit of a distorted shaker's loops is efficient with the measured displacement and
biased with the ideal sine, over :data:`SEEDS` noise seeds. The statistics of ``tests/test_waveform.py``.

A 1-DOF specimen far from the thesis' beams (12 Hz, xi 0.05, 0.5 kg, xi and wn moving with the amplitude,
Eq. 4.8-4.9) is driven by a shaker with 10 % displacement distortion (:func:`distorted_records`), 1 % force
noise, and fitted twice per seed with the thesis' model: driven by the measured displacement, and by the
ideal sine of Eq. 4.5. Each parameter's error is taken in units of its Cramer-Rao bound at the truth. The
criterion (:func:`verdict`): over the seeds, the measured fits' RMS error is under :data:`EFFICIENT` bounds for
every parameter (an efficient estimator: 1 +- 0.25 over 8 draws), and the sine fits' mean error is over
:data:`BIASED` bounds for some parameter. ``tests/test_waveform.py`` reads the committed result and fits the
cheapest seed again live; :func:`definitions_hash` (of this file) ties the two.
"""

from __future__ import annotations

import tempfile
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

import hysid
from hysid.bench import source_hash, sweep_result
from hysid.bench import verdict as pass_word
from hysid.report import jsondoc
from hysid_model import waveform
from hysid_model.datasets import write_dataset
from hysid_model.errors import HysidWarning
from hysid_model.objective import Objective
from hysid_model.problem import build_objective
from hysid_model.synth import RawRecord
from hysid_model.uncertainty import cramer_rao_stderr

SEEDS = range(8)
X0 = 2e-3
DISTORTED = np.array([-1j * X0, 0.03 * X0 * np.exp(0.7j), -0.1j * X0 * np.exp(0.4j), 0.0, 0.02 * X0])
"""10 % third, 3 % second and 2 % fifth harmonic: the displacement of a real shaker (THD ~ 10.6 %)."""
FS = 4096.7
"""Samples per second, not locked to the excitation (a locked rate repeats phases: see extraction's window_overlap)."""
BOUNDS = {"xi0": (0.0, 0.5), "S_xi": (-200.0, 200.0), "w0": (30.0, 150.0), "S_w": (-3e4, 3e4)}
OPTIONS = {"population": 60, "initial_population": 600, "iterations": 10}
"""The PSO of each fit."""
EFFICIENT = 1.6
BIASED = 10.0


def distorted_records(seed: int, noise: float) -> tuple[list[RawRecord], dict[str, float]]:
    """A 1-DOF specimen far from the thesis' beams (12 Hz, xi 0.05, 0.5 kg) with amplitude-dependent
    xi and wn (Eq. 4.8-4.9), driven by a shaker with 10 % displacement distortion; the force is computed
    in the time domain from the displacement's own derivatives."""
    truth = {"xi0": 0.05, "S_xi": 20.0, "w0": 2 * np.pi * 12.0, "S_w": -4000.0}
    rng = np.random.default_rng(seed)
    records = []
    for a in (1e-3, 2e-3, 3e-3):
        for f in np.linspace(8.0, 16.0, 9):
            t = np.arange(int(10 / f * FS)) / FS
            theta = 2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)
            xh = DISTORTED[None, :] * (a / X0)
            x, x1, x2 = (waveform.displacement(xh, theta[None, :], d)[0] for d in (0, 1, 2))
            xi, wn, w = truth["xi0"] + truth["S_xi"] * a, truth["w0"] + truth["S_w"] * a, 2 * np.pi * f
            force = 0.5 * (w**2 * x2 + 2 * xi * wn * w * x1 + wn**2 * x)
            sigma = noise * 0.5 * wn**2 * a
            records.append(RawRecord(f"R_{a * 1e3:g}mm_{f:g}Hz", float(f), a, t, x, force + sigma * rng.standard_normal(t.size), sigma))
    return records, truth


def outcome(seed: int) -> dict[str, Any]:
    """One seed: each parameter's error (fit - truth) in Cramer-Rao bounds with the measured displacement and with
    the ideal sine, and the CPU time it took."""
    cpu = time.process_time()
    records, truth = distorted_records(seed, 0.01)
    with tempfile.TemporaryDirectory() as folder, warnings.catch_warnings():
        warnings.simplefilter("ignore", HysidWarning)  # the displacement's distortion, which is the point here
        loops = hysid.load(write_dataset(Path(folder) / "shaker", records, name="shaker", meq_kg=0.5), n_points=40)
    measured = hysid.fit(loops, "thesis", bounds=BOUNDS, algo="pso", seed=seed, options=OPTIONS)
    sine = hysid.fit(loops, "thesis", bounds=BOUNDS, algo="pso", seed=seed, options=OPTIONS, displacement="sine")
    objective = build_objective(loops, "thesis", bounds=BOUNDS)
    assert isinstance(objective, Objective)  # the closed form (build_objective's default kind)
    crb = dict(zip(objective.model.names, cramer_rao_stderr(objective, objective.model.from_dict(truth))))
    ratios = lambda fit: {n: (fit.params[n] - truth[n]) / crb[n] for n in objective.model.names}
    return {"measured": ratios(measured), "sine": ratios(sine), "cpu_s": time.process_time() - cpu}


def verdict(outcomes: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The criterion over every seed of :data:`SEEDS`: the measured fits' RMS error in bounds, per parameter, under
    :data:`EFFICIENT`; the sine fits' largest mean error over :data:`BIASED`."""
    runs = [outcomes[str(seed)] for seed in SEEDS if str(seed) in outcomes]
    names = list(runs[0]["measured"]) if runs else []
    rms = {n: float(np.sqrt(np.mean([r["measured"][n] ** 2 for r in runs]))) for n in names}
    bias = {n: float(np.mean([r["sine"][n] for r in runs])) for n in names}
    ok = len(runs) == len(SEEDS) and all(v < EFFICIENT for v in rms.values()) and max((abs(v) for v in bias.values()), default=0.0) > BIASED
    return {"seeds": len(runs), "measured_rms": rms, "sine_mean": bias, "ok": ok}


def run(progress: Callable[[int, int, str], None] | None = None) -> dict[str, Any]:
    """A distorted shaker fitted at the Cramer-Rao bound with its measured displacement, and biased with the ideal
    sine, over 8 seeds (the statistics tests/test_waveform.py reads).

    ``progress(done, total, what)`` is called as each seed's fits end."""
    began, cpu = time.perf_counter(), time.process_time()
    outcomes: dict[str, dict[str, Any]] = {}
    for seed in SEEDS:
        outcomes[str(seed)] = record = outcome(seed)
        if progress is not None:
            progress(len(outcomes), len(SEEDS), f"seed {seed}: {record['cpu_s']:.0f} s CPU")
    return jsondoc.plain(sweep_result("shaker", __file__, outcomes, verdict(outcomes), began, cpu))


def to_text(result: dict[str, Any]) -> str:
    rms = ", ".join(f"{n} {v:.2f}" for n, v in result["measured_rms"].items())
    bias = ", ".join(f"{n} {v:+.1f}" for n, v in result["sine_mean"].items())
    return "\n".join(
        [
            f"hysid bench shaker: measured displacement at the Cramer-Rao bound, ideal sine biased  {pass_word(result['ok'])}  ({result['cpu_s']:.0f} s CPU)",
            f"  measured: RMS error in bounds over {result['seeds']} seeds: {rms} (each under {EFFICIENT:g})",
            f"  ideal sine: mean error in bounds: {bias} (largest over {BIASED:g})",
        ]
    )


def definitions_hash() -> str:
    """sha256 of this file: the specimen, its seeds and the criterion as the bench ran them."""
    return source_hash(__file__)
