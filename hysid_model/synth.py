"""The thesis' computer-generated *Synth* set (section 5.2).

120 loops: the 40 frequencies of Table 5.2 at X0 = 0.5, 1.0 and 1.5 mm (loops
ordered by amplitude, then frequency, as the thesis' ``hysloopsnames``), with
Meq = 40 g and the parameters of Table 5.3 in the final model, Eq. 4.8-4.10.
Noise follows the thesis: Gaussian, on the force only, with standard deviation
noise% x that loop's peak force (``maxF*noiselevel/100*randn``, Appendix A).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.kinematics import Kinematics
from hysid_model.loops import LoopSet
from hysid_model.model import Model
from hysid_model.waveform import displacement

FREQUENCIES_HZ = np.array(
    [
        25,
        26,
        26.5,
        27,
        27.5,
        28,
        28.2,
        28.4,
        28.6,
        28.8,
        29,
        29.1,
        29.2,
        29.3,
        29.4,
        29.5,
        29.6,
        29.7,
        29.8,
        29.9,
        30,
        30.1,
        30.2,
        30.3,
        30.4,
        30.5,
        30.6,
        30.7,
        30.8,
        30.9,
        31,
        31.2,
        31.4,
        31.6,
        31.8,
        32,
        32.5,
        33,
        33.5,
        34,
    ]
)  # Table 5.2
AMPLITUDES_M = np.array([0.5e-3, 1.0e-3, 1.5e-3])
MEQ_KG = 40e-3
TRUE_PARAMS = {"xi0": 0.0042, "S_xi": -0.4, "w0": 189.1239, "S_w": -1256.64}  # Table 5.3
BOUNDS = {"xi0": (0.0, 0.1), "S_xi": (-10.0, 10.0), "w0": (100.0, 500.0), "S_w": (-10000.0, 10000.0)}  # Table 5.4


def thesis_force(t: np.ndarray, freq_hz: float, x0: float, params: dict[str, float], meq_kg: float) -> np.ndarray:
    """Eq. 4.10 written out: the steady-state force under x = X0 sin(wt)."""
    w = 2.0 * np.pi * freq_hz
    xi = params["xi0"] + params["S_xi"] * x0
    wn = params["w0"] + params["S_w"] * x0
    amplitude = meq_kg * x0 * np.hypot(wn**2 - w**2, 2.0 * xi * wn * w)
    return amplitude * np.sin(w * t + np.arctan2(2.0 * xi * wn * w, wn**2 - w**2))


def _grid() -> tuple[np.ndarray, np.ndarray]:
    x0 = np.repeat(AMPLITUDES_M, FREQUENCIES_HZ.size)
    freq = np.tile(FREQUENCIES_HZ, AMPLITUDES_M.size)
    return freq, x0


def _labels(freq: np.ndarray, x0: np.ndarray) -> list[str]:
    return [f"SYNTH_{a * 1e4:02.0f}mm_{f:g}Hz" for f, a in zip(freq, x0)]


def check_noise(noise_pct: float) -> None:
    """Added noise is a percentage of each loop's peak force, from 0 to 100."""
    if not (isinstance(noise_pct, (int, float)) and np.isfinite(noise_pct) and 0.0 <= noise_pct <= 100.0):
        raise HysidInputError("noise must be a percentage from 0 to 100", param="noise_pct", value=noise_pct)


def synth_loops(noise_pct: float = 0.0, seed: int = 0, n_points: int = 100, params: dict[str, float] | None = None) -> LoopSet:
    """The Synth set as branch data: ``n_points`` per branch, evenly spaced in x (``reinterpolate``)."""
    check_noise(noise_pct)
    params = TRUE_PARAMS if params is None else params
    freq, x0 = _grid()
    rng = np.random.default_rng(seed)
    n_loops = freq.size
    top = np.empty((n_loops, n_points, 2))
    bottom = np.empty((n_loops, n_points, 2))
    sigma = np.empty(n_loops)
    for j in range(n_loops):
        w = 2.0 * np.pi * freq[j]
        x = np.linspace(-x0[j], x0[j], n_points)
        s = np.clip(x / x0[j], -1.0, 1.0)
        t_load = np.arcsin(s) / w
        t_unload = (np.pi - np.arcsin(s)) / w
        f_top = thesis_force(t_load, freq[j], x0[j], params, MEQ_KG)
        f_bot = thesis_force(t_unload, freq[j], x0[j], params, MEQ_KG)
        peak = max(np.abs(f_top).max(), np.abs(f_bot).max())
        sigma[j] = peak * noise_pct / 100.0
        top[j] = np.column_stack([x, f_top + sigma[j] * rng.standard_normal(n_points)])
        bottom[j] = np.column_stack([x, f_bot + sigma[j] * rng.standard_normal(n_points)])
    return LoopSet(
        name=f"synth-{noise_pct:g}pct-seed{seed}",
        freq_hz=freq,
        x0=x0,
        top=top,
        bottom=bottom,
        sigma=sigma if noise_pct > 0 else np.full(n_loops, np.nan),
        meq_kg=MEQ_KG,
        labels=_labels(freq, x0),
        meta={"source": "synth", "noise_pct": noise_pct, "seed": seed, "true_params": dict(params), "bounds": BOUNDS},
    )


@dataclass
class RawRecord:
    """One simulated DAQ record: time (s), displacement (m) and force (N)."""

    label: str
    freq_hz: float
    x0: float
    t: np.ndarray
    x: np.ndarray
    force: np.ndarray
    sigma: float


def synth_raw(
    noise_pct: float = 0.0,
    seed: int = 0,
    sample_rate_hz: float = 10_000.0,
    duration_s: float = 0.4,
    params: dict[str, float] | None = None,
) -> list[RawRecord]:
    """The Synth set as raw time series over several cycles (thesis grid: 1e-4 s over 0.4 s)."""
    check_noise(noise_pct)
    params = TRUE_PARAMS if params is None else params
    freq, x0 = _grid()
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(duration_s * sample_rate_hz))) / sample_rate_hz
    records = []
    for label, f, a in zip(_labels(freq, x0), freq, x0):
        clean = thesis_force(t, f, a, params, MEQ_KG)
        sigma = np.abs(clean).max() * noise_pct / 100.0
        x = a * np.sin(2.0 * np.pi * f * t)
        records.append(RawRecord(label, float(f), float(a), t, x, clean + sigma * rng.standard_normal(t.size), float(sigma)))
    return records


def model_force(model: Model, theta: np.ndarray, freq_hz: float, x0: float, phase: np.ndarray, x_harmonics: np.ndarray | None = None) -> np.ndarray:
    """Steady-state force of ``model`` at ``theta`` under x = X0 sin(phase), phase = w t (Eq. 4.5), or under
    the displacement with harmonics ``x_harmonics`` ``(K,)`` (:mod:`hysid_model.waveform`, X_1 = -i X0).

    Samples where the displacement rises (x' >= 0) are on the loading branch;
    the model is evaluated on both branches as for a loop, and the result is
    returned in the order of ``phase``.
    """
    phase = np.asarray(phase, dtype=float).reshape(-1)
    xh = None if x_harmonics is None else np.asarray(x_harmonics, dtype=complex).reshape(1, -1)
    kin = Kinematics(x0=np.array([float(x0)]), omega=np.array([2.0 * np.pi * float(freq_hz)]), xh=xh)
    rising = kin.displacement(phase[None, :], 1)[0] >= 0.0
    order = np.concatenate([np.flatnonzero(rising), np.flatnonzero(~rising)])
    force = model.force(np.asarray(theta, dtype=float).reshape(1, -1), kin, phase[order][None, :], int(np.count_nonzero(rising)))[0, 0]
    out = np.empty_like(force)
    out[order] = force
    return out


def harmonics(x0: float, ratios: dict[int, complex] | None) -> np.ndarray:
    """``(K,)`` displacement harmonics with X_1 = -i X0 and X_k = r_k X_1 for ``ratios`` ``{k: r_k}``."""
    xh = np.zeros(1 + max(ratios or {0: 0}), dtype=complex)
    xh[0] = -1j * x0
    for k, r in (ratios or {}).items():
        xh[k - 1] = r * xh[0]
    return xh


def simulate_raw(
    model: Model,
    theta: np.ndarray,
    freq_hz: np.ndarray,
    x0: np.ndarray,
    *,
    noise_n: float | np.ndarray,
    seed: int = 0,
    sample_rate_hz: float = 5000.0,
    cycles: int = 8,
    x_noise: float = 1e-4,
    distortion: dict[int, complex] | None = None,
    sensor: dict[int, complex] | None = None,
) -> list[RawRecord]:
    """Raw steady-state records of any model: ``cycles`` periods sampled at ``sample_rate_hz``.

    Each record starts at a random phase; the force gets Gaussian noise of std
    ``noise_n`` (N, scalar or per record), the displacement noise of std
    ``x_noise`` times X0. ``distortion`` ``{k: r_k}`` adds displacement
    harmonics X_k = r_k X_1 (a real r_k is r_k X0 sin(k wt)) to the motion, as a
    shaker does; ``sensor`` ``{k: r_k}`` adds them to the recorded displacement
    only, as a distorting displacement sensor does (the force follows the motion).
    For hidden-effect tests of ``hysid diagnose``.
    """
    freq_hz = np.asarray(freq_hz, dtype=float).reshape(-1)
    x0 = np.asarray(x0, dtype=float).reshape(-1)
    noise = np.broadcast_to(np.asarray(noise_n, dtype=float), freq_hz.shape)
    if freq_hz.shape != x0.shape or np.any(freq_hz <= 0) or np.any(x0 <= 0) or np.any(noise < 0):
        raise HysidInputError("simulate_raw needs matching positive frequencies and amplitudes and a noise >= 0")
    rng = np.random.default_rng(seed)
    records = []
    for f, a, sigma in zip(freq_hz, x0, noise):
        w = 2.0 * np.pi * f
        t = np.arange(int(round(cycles * sample_rate_hz / f))) / sample_rate_hz
        phase = w * t + rng.uniform(0.0, 2.0 * np.pi)
        xh = harmonics(a, distortion)
        clean = model_force(model, theta, f, a, phase, xh if distortion else None)
        recorded = harmonics(a, {**(distortion or {}), **{k: (distortion or {}).get(k, 0.0) + r for k, r in (sensor or {}).items()}})
        x = displacement(recorded[None, :], phase[None, :])[0] + x_noise * a * rng.standard_normal(t.size)
        label = f"SIM_{a * 1e3:.4g}mm_{f:g}Hz"
        records.append(RawRecord(label, float(f), float(a), t, x, clean + sigma * rng.standard_normal(t.size), float(sigma)))
    return records
