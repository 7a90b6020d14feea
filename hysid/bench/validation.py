"""``hysid bench validation``: hysid's diagnosis of devices and specimens it was not built on, against the truth
or an independent reference fit; the table of docs/VALIDATION.md (``--markdown docs/VALIDATION.md``).

Every simulated case is raw records extracted as real data are (100 samples per
branch), force noise 1 % of each record's peak, far from the thesis' beams:

* ``sensor_distortion``: a 0.5 kg, 40 Hz, 3 %-damped linear specimen driven by
  a pure sine at 15-55 Hz, its displacement *sensor* adding 10 % second and
  5 % third harmonic (truth: no effect, the motion is the fundamental);
* ``motion_distortion``: the same harmonics in the motion itself (truth: no
  effect, the measured waveform is the motion);
* ``mr_damper_{0v,1v,2v}``: a Spencer-type MR damper at three control levels
  (Bouc-Wen with exponent n = 2 beside a dashpot and a spring, no mass; 9 loops
  at 1-3 Hz and 5-15 mm), integrated in time independently of hysid's model
  (:func:`hysid.bench.search_problems.mr_damper_records`) (truth: a Bouc-Wen spring);
* ``friction_damper``: a damper with Bouc-Wen hysteresis and Coulomb friction
  at 2-8 Hz (truth: both);
* ``wire_rope``: a softening wire-rope-like Bouc-Wen isolator (r = -0.5) at
  10-30 Hz whose displacement sensor adds 6 % second and 3 % third harmonic
  (truth: a Bouc-Wen spring, the motion is the fundamental);
* ``rational_rate``: a linear specimen sampled at 2048 Hz and driven at
  15-35 Hz (ratios of small integers), 5 % third harmonic in the motion
  (truth: no effect, adequate);

and one real device, the ARTS-Lab friction damper of ``data/arts-friction-damper``
(CC BY-SA 4.0), against an outside reference: scipy's ``least_squares`` from 8
random starts of the ``mr_damper`` model (Bouc-Wen with its exponent free, the
reference of issue 21) on hysid's own loops.

For each case: ``hysid.diagnose`` with its defaults (from the baseline, the
displacement read by the data), the effects it names, its reading of the
displacement, its status, its final loop NRMSE (RMS force error over the
peak-to-peak force, mean over loops, as ``diagnose`` reports it) and its time;
next to it the truth's loop NRMSE (the true model at its true values on the
same loops: the floor) or the reference's. A simulated case ``matches`` when the
effects named are the truth's (a Bouc-Wen spring with its exponent free or not),
the reading is the truth's where the displacement is distorted, and the final
NRMSE is within 10 % (or 0.1 points) of the truth's; the real case when hysid's
NRMSE is within 5 % of the reference's or below it.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import hysid
from hysid.bench import search_problems as sp
from hysid_model.datasets import load_dataset
from hysid_model.loops import LoopSet
from hysid_model.model import build_model
from hysid_model.objective import Objective
from hysid_model.problem import build_objective, displaced, prepare_model
from hysid_model.synth import RawRecord, simulate_raw

POINTS = 100
CYCLES = 6
RATE_HZ = 4096.7
"""A sample rate no frequency of the cases divides (the ``rational_rate`` case is about the others)."""
DAMPER = Path(__file__).resolve().parents[2] / "data" / "arts-friction-damper"
REFERENCE_STARTS = 8
BOUC_WEN = {"bouc_wen"}
NRMSE_SLACK = (1.10, 0.1)
"""A final loop NRMSE matches the truth's within 10 % of it or 0.1 percentage points, whichever is larger."""
REFERENCE_SLACK = 1.05

LINEAR = {"xi0": 0.03, "w0": 2 * np.pi * 40.0, "meq": 0.5}
"""The specimen of the distortion cases: 0.5 kg, 40 Hz, 3 % damping."""
DISTORTION = {2: 0.10, 3: 0.05}


@dataclass(frozen=True)
class Case:
    name: str
    kind: str
    description: str
    loops: Callable[[], LoopSet]
    effects: frozenset[str] | None
    """The effects the truth holds (None: a real device, judged against the reference)."""
    reading: str | None
    """The displacement reading the truth has where the displacement is distorted (None: no distortion to read)."""
    truth: tuple[str, dict[str, float], str] | None = None
    """(model, values, displacement reading) of the truth, for its loop NRMSE."""


def _noise(model: str, values: dict[str, float], freq: np.ndarray, amp: np.ndarray) -> np.ndarray:
    m = build_model(model)
    return sp.peak_noise(m, m.from_dict(values), freq, amp)


def _simulated(model: str, values: dict[str, float], freq: np.ndarray, amp: np.ndarray, rate_hz: float = RATE_HZ, **kind: Any) -> list[RawRecord]:
    m = build_model(model)
    return simulate_raw(
        m, m.from_dict(values), freq, amp, noise_n=_noise(model, values, freq, amp), seed=sp.DATA_SEED, sample_rate_hz=rate_hz, cycles=CYCLES, **kind
    )


def _linear(
    name: str,
    kind: str,
    description: str,
    motion: dict[str, Any],
    reading: str,
    rate_hz: float = RATE_HZ,
    freqs: tuple[float, ...] = (15.0, 25.0, 35.0, 45.0, 55.0),
) -> Case:
    """A case of the linear specimen ``LINEAR`` (truth: no effect, ``baseline`` at its values, the displacement read as
    ``reading``), simulated with ``motion`` (the keywords of :func:`hysid_model.synth.simulate_raw`: distortion, sensor)."""
    freq, amp = sp.grid(np.array(freqs), np.array([0.5e-3, 1e-3]))

    def loops() -> LoopSet:
        return sp.extracted("specimen", _simulated("baseline", LINEAR, freq, amp, rate_hz, **motion), None, POINTS)

    return Case(name, kind, description, loops, frozenset(), reading, ("baseline", LINEAR, reading))


def _mr_truth(level: dict[str, float]) -> dict[str, float]:
    """The damper's c0, k0 and Bouc-Wen spring as ``mr_damper`` parameters (a negligible mass carries the spring)."""
    meq = 1e-3
    w0 = float(np.sqrt(level["k0"] / meq))
    return {"xi0": level["c0"] / (2.0 * meq * w0), "w0": w0, "meq": meq, "bw_k": level["f_y"] / level["zy"], "bw_zy": level["zy"], "bw_r": 0.0, "bw_n": 2.0}


def _mr_loops(name: str, level: dict[str, float]) -> Callable[[], LoopSet]:
    """The loops of the MR damper at ``level``, made when asked."""
    return lambda: sp.extracted(name, sp.mr_damper_records(level, rate_hz=RATE_HZ, cycles=CYCLES), None, POINTS)


def cases() -> list[Case]:
    freq_f, amp_f = sp.grid(np.array([2.0, 4.0, 8.0]), np.array([2e-3, 4e-3, 6e-3]))
    freq_w, amp_w = sp.grid(np.array([10.0, 18.0, 30.0]), np.array([0.5e-3, 1.0e-3, 2.0e-3]))
    out = [
        _linear("sensor_distortion", "sensor distortion", "linear specimen, sensor adds 10 % 2nd and 5 % 3rd harmonic", {"sensor": DISTORTION}, "fundamental"),
        _linear("motion_distortion", "sensor distortion", "linear specimen, the same harmonics in the motion", {"distortion": DISTORTION}, "measured"),
    ]
    for name, level in sp.MR_LEVELS.items():
        out.append(
            Case(
                name,
                "MR damper",
                f"Spencer-type MR damper, Bouc-Wen n = 2, yield force {level['f_y']:g} N",
                _mr_loops(name, level),
                frozenset(BOUC_WEN),
                None,
                ("mr_damper", _mr_truth(level), "measured"),
            )
        )
    out += [
        Case(
            "friction_damper",
            "friction damper",
            "Bouc-Wen hysteresis and Coulomb friction",
            lambda: sp.extracted("friction", _simulated("baseline+coulomb_friction+bouc_wen", sp.FRICTION_BW, freq_f, amp_f), None, POINTS),
            frozenset({"bouc_wen", "coulomb_friction"}),
            None,
            ("baseline+coulomb_friction+bouc_wen", sp.FRICTION_BW, "measured"),
        ),
        Case(
            "wire_rope",
            "wire rope",
            "softening Bouc-Wen (r = -0.5), sensor adds 6 % 2nd and 3 % 3rd harmonic",
            lambda: sp.extracted("wire rope", _simulated("baseline+bouc_wen", sp.WIRE_ROPE, freq_w, amp_w, sensor=sp.WIRE_ROPE_SENSOR), None, POINTS),
            frozenset(BOUC_WEN),
            "fundamental",
            ("baseline+bouc_wen", sp.WIRE_ROPE, "fundamental"),
        ),
        _linear(
            "rational_rate",
            "rational sample rate",
            "linear specimen at 2048 Hz, 15-35 Hz, 5 % 3rd harmonic in the motion",
            {"distortion": {3: 0.05}},
            "measured",
            2048.0,
            (15.0, 20.0, 25.0, 32.0, 35.0),
        ),
        Case(
            "arts_friction_damper", "real device", "ARTS-Lab band-brake friction damper (data/arts-friction-damper)", lambda: load_dataset(DAMPER), None, None
        ),
    ]
    return out


def loop_nrmse_pct(objective: Objective, theta: np.ndarray) -> float:
    """RMS force error over the peak-to-peak force, mean over loops, in % (the diagnosis' loop NRMSE)."""
    residual, forces = objective.residuals(theta), objective.y
    return float(np.mean(100.0 * np.sqrt(np.mean(residual**2, axis=1)) / (forces.max(axis=1) - forces.min(axis=1))))


def truth_nrmse(loops: LoopSet, truth: tuple[str, dict[str, float], str]) -> float:
    """The loop NRMSE of the true model at its true values (wide bounds, so that every true value lies inside)."""
    spec, values, reading = truth
    model = build_model(spec)
    wide = {p.name: (min(p.lower, values[p.name]), max(p.upper, values[p.name])) for p in model.parameters if p.name in values}
    model = prepare_model(displaced(loops, reading), model, bounds=wide)
    return loop_nrmse_pct(Objective(displaced(loops, reading), model, weights="thesis"), model.from_dict(values))


def reference_nrmse(loops: LoopSet) -> float:
    """The outside reference: scipy's least squares (its own defaults) from ``REFERENCE_STARTS`` uniform random
    starts within the bounds of ``mr_damper`` on ``loops``, the best kept (module docstring)."""
    from scipy.optimize import least_squares  # on first use: a fast CLI and island start

    objective = build_objective(loops, "mr_damper", displacement="measured")
    assert isinstance(objective, Objective)  # the closed form (build_objective's default kind)
    lower, upper = objective.bounds[:, 0], objective.bounds[:, 1]
    rng = np.random.default_rng(0)

    def residuals(theta: np.ndarray) -> np.ndarray:
        r = objective.weighted_residuals(theta)
        return np.where(np.isfinite(r), r, 1e150)

    fits = [
        least_squares(residuals, lower + (upper - lower) * rng.random(lower.size), bounds=(lower, upper), method="trf", x_scale="jac")
        for _ in range(REFERENCE_STARTS)
    ]
    return loop_nrmse_pct(objective, min(fits, key=lambda f: f.cost).x)


def run_case(case: Case) -> dict[str, Any]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        loops = case.loops()
        began = time.perf_counter()
        diagnosis = hysid.diagnose(loops)
        seconds = time.perf_counter() - began
        named = {s.effect for s in diagnosis.steps}
        final = diagnosis.gap[-1].nrmse_pct
        reading = diagnosis.motion.displacement if diagnosis.motion else None
        row: dict[str, Any] = {
            "case": case.name,
            "kind": case.kind,
            "description": case.description,
            "loops": loops.n_loops,
            "named": sorted(named),
            "final_model": diagnosis.final.spec,
            "status": diagnosis.status,
            "reading": reading,
            "nrmse_pct": final,
            "seconds": seconds,
        }
        if case.truth is not None:
            floor = truth_nrmse(loops, case.truth)
            nrmse_ok = final <= max(NRMSE_SLACK[0] * floor, floor + NRMSE_SLACK[1])
            reading_ok = case.reading is None or reading == case.reading
            row.update(
                {
                    "truth_effects": sorted(case.effects or ()),
                    "truth_reading": case.reading,
                    "truth_nrmse_pct": floor,
                    "matches": bool(named == set(case.effects or ()) and reading_ok and nrmse_ok),
                }
            )
        else:
            reference = reference_nrmse(loops)
            row.update({"reference_nrmse_pct": reference, "matches": bool(final <= REFERENCE_SLACK * reference)})
    return row


def run(names: list[str] | None = None) -> dict[str, Any]:
    """Validation: hysid's diagnosis of simulated devices and a real one against the truth or a reference fit."""
    chosen = [c for c in cases() if names is None or c.name in names]
    began = time.perf_counter()
    rows = [run_case(c) for c in chosen]
    return {"cases": rows, "matches": sum(r["matches"] for r in rows), "of": len(rows), "bench_s": time.perf_counter() - began}


def to_text(result: dict[str, Any]) -> str:
    lines = [f"hysid bench validation: {result['matches']} of {result['of']} cases match the truth or the reference"]
    for r in result["cases"]:
        against = (
            f"truth {', '.join(r['truth_effects']) or 'no effect'}, NRMSE {r['truth_nrmse_pct']:.3g} %"
            if "truth_nrmse_pct" in r
            else f"reference NRMSE {r['reference_nrmse_pct']:.3g} %"
        )
        lines.append(
            f"  {r['case']:<22} {'match' if r['matches'] else 'MISS ':<5}  named {', '.join(r['named']) or 'nothing':<32} "
            f"reading {r['reading'] or '-':<11} NRMSE {r['nrmse_pct']:.3g} %  ({against}); {r['seconds']:.1f} s"
        )
    return "\n".join(lines)


def to_markdown(result: dict[str, Any], environment: dict[str, Any]) -> str:
    """docs/VALIDATION.md: the table, how it was made, and the command that makes it again."""
    head = ["case", "what", "hysid names", "displacement read as", "status", "loop NRMSE", "truth or reference", "verdict", "time"]
    rows = []
    for r in result["cases"]:
        if "truth_nrmse_pct" in r:
            truth = (
                f"{', '.join(r['truth_effects']) or 'no effect'}"
                + (f", {r['truth_reading']}" if r["truth_reading"] else "")
                + f"; NRMSE {r['truth_nrmse_pct']:.3g} %"
            )
        else:
            truth = f"least squares, 8 starts, mr_damper: NRMSE {r['reference_nrmse_pct']:.3g} %"
        rows.append(
            [
                f"`{r['case']}`",
                r["description"],
                f"`{r['final_model']}`",
                r["reading"] or "-",
                r["status"],
                f"{r['nrmse_pct']:.3g} %",
                truth,
                "match" if r["matches"] else "**miss**",
                f"{r['seconds']:.0f} s",
            ]
        )
    table = "\n".join(["| " + " | ".join(head) + " |", "|" + "|".join([":--"] * len(head)) + "|"] + ["| " + " | ".join(row) + " |" for row in rows])
    machine = environment.get("machine", {})
    doc = (__doc__ or "").split("\n\n", 1)[1].strip()
    return "\n".join(
        [
            "# Validation: hysid on devices it was not built on",
            "",
            f"Generated {environment.get('date', '')} on {machine.get('hostname', '')} ({machine.get('cpu_model', '')}, "
            f"load {machine.get('load_avg_1m', '')}) by `hysid bench validation --markdown docs/VALIDATION.md` "
            f"({result['bench_s']:.0f} s). **{result['matches']} of {result['of']} cases match.**",
            "",
            table,
            "",
            "## How",
            "",
            doc,
            "",
        ]
    )
