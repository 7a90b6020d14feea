"""The problems of ``hysid bench search``: simulated devices whose models a local method struggles to fit.

Each problem is a loop set (simulated raw records, extracted as real data are:
:func:`hysid_model.extraction.extract_loop`) and the model a user would fit to
it. The truth and the noise draw are fixed per problem (seed 0 of the data),
so that every method and every search seed meets the same data and the best
fitness any method found is one number per problem.

* ``mr_damper_{0v,1v,2v}``: a Spencer-type MR damper (Spencer et al., J. Eng.
  Mech. 123, 1997) at three control levels: a Bouc-Wen hysteretic force with
  exponent n = 2, a viscous damper and a linear spring, no mass; 9 loops at
  1-3 Hz and 5-15 mm, 1 % force noise. The records are integrated in time here
  (RK4 of z' = x' - gamma |x'| |z| z - beta x' z^2, independently of the
  library's orbit); the model fitted is the ``mr_damper`` preset (oscillator
  + Bouc-Wen with its exponent ``bw_n`` free);
* ``mr_damper_sharp``: an MR damper as a real one at high control fits (an outside
  multi-start least-squares fit of a real damper at 1.98 V found this shape): a
  Bouc-Wen force with the shape r = 39, far above r's default search bound of 3
  (a knee right after each reversal), exponent n = 2.6, yield at 0.3 mm, a
  7 kg moving mass, a viscous damper and a negligible spring; 9 loops at 1-5 Hz
  and 5-15 mm, RK4 as above; its box takes r up to 300 (the default bound
  widened twice, as a fit that ends on it widens it);
* ``friction_bouc_wen``: a damper with Bouc-Wen hysteresis and Coulomb friction
  (``baseline+coulomb_friction+bouc_wen``), 9 loops at 2-8 Hz and 2-6 mm;
* ``wire_rope_sensor``: a softening wire-rope-like Bouc-Wen isolator
  (``baseline+bouc_wen``, r = -0.5, 0.3 kg) at 10-30 Hz, whose displacement
  *sensor* adds 6 % second and 3 % third harmonic that the motion (and so the
  force) does not have: the model sees the distorted record, as hysid does by
  default;
* ``synth_bouc_wen_distorted``: ``thesis+bouc_wen`` on a subset of the Synth
  grid (section 5.2: every fourth frequency of Table 5.2 at the three
  amplitudes, 30 loops) driven by a distorted motion (5 % second, 3 % third
  harmonic, which the force does respond to);
* ``thesis_easy``: the thesis model on the same 30 Synth loops with 1 % noise:
  the easy control, where the survey's linear start and a polish suffice.

As real data, the four reversal samples of each loop are left out where
extraction cannot resolve the force there (:mod:`hysid_model.resolution`).
Sizes are cut for a bench on two cores: 24 samples per branch (the Synth
subset 32), 4 cycles per record.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hysid_model.datasets import loop_set
from hysid_model.extraction import extract_loop
from hysid_model.loops import LoopSet
from hysid_model.model import build_model
from hysid_model.problem import prepare_model
from hysid_model.synth import AMPLITUDES_M, FREQUENCIES_HZ, MEQ_KG, TRUE_PARAMS, RawRecord, simulate_raw, synth_loops
from hysid_model.waveform import displacement

POINTS = 24
"""Samples per branch of the extracted loops of the devices."""
SYNTH_POINTS = 32
"""Samples per branch of the Synth subsets."""
CYCLES = 4
NOISE_PCT = 1.0
"""Force noise, per cent of each record's peak force (the thesis' convention, Appendix A)."""
DATA_SEED = 0

MR_LEVELS = {
    "mr_damper_0v": {"c0": 1800.0, "k0": 1500.0, "f_y": 60.0, "zy": 0.05e-3},
    "mr_damper_1v": {"c0": 1400.0, "k0": 1500.0, "f_y": 600.0, "zy": 0.1e-3},
    "mr_damper_2v": {"c0": 1900.0, "k0": 1500.0, "f_y": 1100.0, "zy": 0.2e-3},
}
"""A Spencer-type damper at three control levels: viscous c0 (N s/m), spring k0 (N/m), Bouc-Wen yield force
f_y = k_bw z_y (N) and yield displacement z_y (m); gamma = beta (r = 0), exponent n = 2, no mass.
The field strengthens the hysteretic force and the viscous one with the level, as Spencer's
alpha(u) and c0(u) do."""
MR_SHARP = {"c0": 800.0, "k0": 50.0, "f_y": 600.0, "zy": 0.3e-3, "r": 39.0, "n": 2.6, "mass": 7.0}
"""The sharp-kneed damper of ``mr_damper_sharp``: viscous c0, a negligible spring k0, Bouc-Wen yield force f_y at
z_y, shape r and exponent n, moving mass (kg)."""
MR_SHARP_FREQ_HZ = np.array([1.0, 2.5, 5.0])
MR_SHARP_SUBSTEPS = 16
"""RK4 substeps per sample of the sharp damper: z' reaches (1 + r) x' / z_y at the knee, 1e4 per second at 5 Hz."""
MR_FREQ_HZ = np.array([1.0, 2.0, 3.0])
MR_AMPLITUDES_M = np.array([5e-3, 10e-3, 15e-3])
MR_RATE_HZ = 1000.0
MR_SUBSTEPS = 4


@dataclass(frozen=True)
class Problem:
    """A loop set and the model to fit; ``bounds`` hard for every method alike: the data-derived bounds
    of :func:`hysid_model.problem.prepare_model` widened once on both sides (as a fit that ends on them
    widens them, :meth:`hysid_model.params.Parameter.widened`), so that the optimum lies inside and
    no method searches a wider box than another."""

    name: str
    description: str
    loops: LoopSet
    model: str
    bounds: dict[str, tuple[float, float]]
    truth: dict[str, float] | None

    @property
    def memory(self) -> bool:
        return prepare_model(self.loops, self.model, bounds=self.bounds).has_memory


def extracted(name: str, records: list[RawRecord], meq_kg: float | None, points: int = POINTS, *, sensor: Callable | None = None) -> LoopSet:
    """Loops from raw records by the extraction real data go through; ``sensor(record)`` (if given) is the
    displacement the sensor reports instead of the motion."""
    loops = [
        extract_loop(
            r.t, r.x if sensor is None else sensor(r), r.force, source=r.label, n_points=points, nominal_freq_hz=r.freq_hz, steady_window=(r.t[0], r.t[-1])
        )
        for r in records
    ]
    return loop_set(name, loops, [r.label for r in records], meq_kg)


def grid(freqs: np.ndarray, amps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.tile(freqs, amps.size), np.repeat(amps, freqs.size)


def mr_damper_records(
    level: dict[str, float],
    seed: int = DATA_SEED,
    exponent: float = 2.0,
    *,
    rate_hz: float = MR_RATE_HZ,
    cycles: int = CYCLES,
    freqs_hz: np.ndarray = MR_FREQ_HZ,
    amplitudes_m: np.ndarray = MR_AMPLITUDES_M,
    substeps: int = MR_SUBSTEPS,
) -> list[RawRecord]:
    """Raw records of a Spencer-type damper, F = m x'' + c0 x' + k0 x + k_bw z with
    z' = x' - gamma |x'| |z|^(n-1) z - beta x' |z|^n (A = 1, gamma = (1 + r) / (2 z_y^n), beta = (1 - r) / (2 z_y^n):
    the shape ``level['r']``, 0 unless given, the mass ``level['mass']``, 0 unless given, the exponent ``level['n']``
    or ``exponent``), integrated in time by RK4 (``substeps`` per sample) from z = 0 over one extra cycle that is
    dropped; ``cycles`` kept, sampled at ``rate_hz``, at every pair of ``freqs_hz`` and ``amplitudes_m``."""
    rng = np.random.default_rng(seed)
    freq, amp = grid(np.asarray(freqs_hz, dtype=float), np.asarray(amplitudes_m, dtype=float))
    exponent, shape, mass = level.get("n", exponent), level.get("r", 0.0), level.get("mass", 0.0)
    gamma, beta = (1.0 + shape) / (2.0 * level["zy"] ** exponent), (1.0 - shape) / (2.0 * level["zy"] ** exponent)
    k_bw = level["f_y"] / level["zy"]
    records = []
    for f, a in zip(freq, amp):
        w = 2.0 * np.pi * f
        n = int(round((cycles + 1) * rate_hz / f))
        dt = 1.0 / (rate_hz * substeps)
        phase0 = rng.uniform(0.0, 2.0 * np.pi)
        velocity = lambda t: a * w * np.cos(w * t + phase0)  # noqa: B023 (called within this iteration)

        def rhs(t: float, z: float) -> float:
            v = velocity(t)  # noqa: B023 (called within this iteration)
            return v - gamma * abs(v) * abs(z) ** (exponent - 1.0) * z - beta * v * abs(z) ** exponent

        z, t = 0.0, 0.0
        zs = np.empty(n)
        for i in range(n):
            zs[i] = z
            for _ in range(substeps):
                k1 = rhs(t, z)
                k2 = rhs(t + dt / 2, z + dt / 2 * k1)
                k3 = rhs(t + dt / 2, z + dt / 2 * k2)
                k4 = rhs(t + dt, z + dt * k3)
                z += dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
                t += dt
        time = np.arange(n) / rate_hz
        x = a * np.sin(w * time + phase0)
        clean = level["c0"] * velocity(time) + (level["k0"] - mass * w**2) * x + k_bw * zs
        keep = time >= 1.0 / f
        sigma = NOISE_PCT / 100.0 * np.abs(clean[keep]).max()
        force = clean + sigma * rng.standard_normal(n)
        records.append(
            RawRecord(
                f"MR_{a * 1e3:g}mm_{f:g}Hz",
                float(f),
                float(a),
                time[keep] - time[keep][0],
                x[keep] + 1e-4 * a * rng.standard_normal(int(keep.sum())),
                force[keep],
                float(sigma),
            )
        )
    return records


def peak_noise(model, theta: np.ndarray, freq: np.ndarray, amp: np.ndarray, distortion: dict[int, complex] | None = None) -> np.ndarray:
    """NOISE_PCT of each record's peak force (noiseless records of one cycle)."""
    clean = simulate_raw(model, theta, freq, amp, noise_n=0.0, x_noise=0.0, cycles=1, distortion=distortion, sample_rate_hz=200 * float(freq.max()))
    return np.array([NOISE_PCT / 100.0 * np.abs(r.force).max() for r in clean])


def simulated(
    model_spec: str,
    values: dict[str, float],
    freq: np.ndarray,
    amp: np.ndarray,
    *,
    rate_hz: float,
    distortion: dict[int, complex] | None = None,
    cycles: int = CYCLES,
) -> list[RawRecord]:
    model = build_model(model_spec)
    theta = model.from_dict(values)
    noise = peak_noise(model, theta, freq, amp, distortion)
    return simulate_raw(model, theta, freq, amp, noise_n=noise, seed=DATA_SEED, sample_rate_hz=rate_hz, cycles=cycles, distortion=distortion)


FRICTION_BW = {"xi0": 0.3, "w0": 2 * np.pi * 3.0, "meq": 20.0, "F_d": 80.0, "bw_k": 8.0e5, "bw_zy": 0.15e-3, "bw_r": 0.5}
"""A friction damper with Bouc-Wen hysteresis: k = meq w0^2 = 7.1 kN/m, c = 2 meq xi0 w0 = 226 N s/m,
a 80 N friction force and a 120 N hysteretic force yielding at 0.6 mm."""
WIRE_ROPE = {"xi0": 0.04, "w0": 2 * np.pi * 18.0, "meq": 0.3, "bw_k": 4.0e4, "bw_zy": 0.4e-3, "bw_r": -0.5}
"""A wire-rope-like isolator carrying 0.3 kg: a linear spring of 3.8 kN/m, light viscous damping and a
softening hysteretic spring of 40 kN/m yielding at 0.4 mm (16 N)."""
WIRE_ROPE_SENSOR = {2: 0.06, 3: 0.03}
"""Harmonics the displacement sensor adds (relative to the fundamental): the motion has none."""
SYNTH_BOUC_WEN = {**TRUE_PARAMS, "meq": MEQ_KG, "bw_k": 400.0, "bw_zy": 0.3e-3, "bw_r": 0.5}
SYNTH_DISTORTION: dict[int, complex] = {2: 0.05, 3: 0.03}


def synth_subset() -> tuple[np.ndarray, np.ndarray]:
    """Every fourth frequency of Table 5.2 at the three Synth amplitudes (30 loops)."""
    return grid(FREQUENCIES_HZ[::4], AMPLITUDES_M)


def sensor_distorted(r: RawRecord) -> np.ndarray:
    """The record's displacement as a sensor with :data:`WIRE_ROPE_SENSOR` reports it (phase from the record)."""
    w = 2.0 * np.pi * r.freq_hz
    phase = np.arctan2(-np.mean(r.x * np.cos(w * r.t)), np.mean(r.x * np.sin(w * r.t)))  # x = X0 sin(wt - phase)
    xh = np.zeros(1 + max(WIRE_ROPE_SENSOR), dtype=complex)
    xh[0] = -1j * r.x0
    for k, rel in WIRE_ROPE_SENSOR.items():
        xh[k - 1] = rel * xh[0]
    extra = displacement(xh[None, :], (w * r.t - phase)[None, :])[0] - r.x0 * np.sin(w * r.t - phase)
    return r.x + extra


def build(name: str) -> Problem:
    """One problem of :data:`PROBLEMS` (its data simulated and extracted now)."""
    if name in MR_LEVELS:
        loops = extracted(name, mr_damper_records(MR_LEVELS[name]), None)
        model, truth = "mr_damper", {k: v for k, v in MR_LEVELS[name].items()}
        description = f"Spencer-type MR damper (Bouc-Wen n = 2, viscous, spring), f_y {MR_LEVELS[name]['f_y']:g} N; exponent free"
    elif name == "mr_damper_sharp":
        loops = extracted(name, mr_damper_records(MR_SHARP, freqs_hz=MR_SHARP_FREQ_HZ, substeps=MR_SHARP_SUBSTEPS), None)
        model, truth = "mr_damper", dict(MR_SHARP)
        description = "MR damper with a sharp knee (Bouc-Wen r = 39, n = 2.6), 7 kg, negligible spring; exponent free"
    elif name == "friction_bouc_wen":
        freq, amp = grid(np.array([2.0, 4.0, 8.0]), np.array([2e-3, 4e-3, 6e-3]))
        loops = extracted(name, simulated("baseline+coulomb_friction+bouc_wen", FRICTION_BW, freq, amp, rate_hz=1000.0), None)
        model, truth = "baseline+coulomb_friction+bouc_wen", dict(FRICTION_BW)
        description = "damper with Bouc-Wen hysteresis and Coulomb friction"
    elif name == "wire_rope_sensor":
        freq, amp = grid(np.array([10.0, 18.0, 30.0]), np.array([0.5e-3, 1.0e-3, 2.0e-3]))
        records = simulated("baseline+bouc_wen", WIRE_ROPE, freq, amp, rate_hz=2500.0)
        loops = extracted(name, records, None, sensor=sensor_distorted)
        model, truth = "baseline+bouc_wen", dict(WIRE_ROPE)
        description = "softening wire-rope-like Bouc-Wen; the displacement sensor adds 6 % 2nd and 3 % 3rd harmonic"
    elif name == "synth_bouc_wen_distorted":
        freq, amp = synth_subset()
        records = simulated("thesis+bouc_wen", SYNTH_BOUC_WEN, freq, amp, rate_hz=5000.0, distortion=SYNTH_DISTORTION)
        loops = extracted(name, records, MEQ_KG, SYNTH_POINTS)
        model, truth = "thesis+bouc_wen", dict(SYNTH_BOUC_WEN)
        description = "thesis+bouc_wen on 30 Synth loops, motion with 5 % 2nd and 3 % 3rd harmonic"
    elif name == "thesis_easy":
        freq, amp = synth_subset()
        full = synth_loops(NOISE_PCT, DATA_SEED, SYNTH_POINTS)
        loops = full.subset(np.flatnonzero(np.isin(full.freq_hz, freq)))
        model, truth = "thesis", dict(TRUE_PARAMS)
        description = "the thesis model on 30 Synth loops, 1 % noise (easy control)"
    else:
        raise KeyError(name)
    wide = [p.widened(True, True) if p.soft else p for p in prepare_model(loops, model).parameters]
    bounds = {p.name: (p.lower, p.upper) for p in wide}
    if name == "mr_damper_sharp":  # r = 39: the default bound 3 widened twice
        bounds["bw_r"] = (bounds["bw_r"][0], 300.0)
    return Problem(name, description, loops, model, bounds, truth)


PROBLEMS = (
    "synth_bouc_wen_distorted",
    "mr_damper_0v",
    "friction_bouc_wen",
    "mr_damper_1v",
    "mr_damper_2v",
    "mr_damper_sharp",
    "wire_rope_sensor",
    "thesis_easy",
)
