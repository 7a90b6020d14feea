"""``hysid bench discovery``: does ``diagnose`` find the force law its library lacks, and only where there is one?

Each specimen of :mod:`hysid.bench.discovery_cases` (ten hidden laws at two force noise levels, one noise draw
each) is diagnosed twice in this process, with discovery off (today's diagnosis, the baseline of the time
ratio) and on, each from ``baseline`` with its defaults. For each law:

* the ``formula`` of every term proposed (``diagnose --json``'s ``proposed``);
* the **shape error** against the truth (:func:`shape_error`): over the loops' motion (each loop's sine, x =
  X0 sin(phi), v = w X0 cos(phi), at :data:`SHAPE_SAMPLES` uniform phases), the difference of the force the
  final model adds to the specimen's spring, dashpot and mass (:func:`added`: the terms proposed and the
  library effects named beside them, as a Stribeck law is Coulomb friction and a hump; 0 where there are none)
  and the true law's, each less its mean over each loop, less its least-squares fit by a spring and a dashpot
  (a x + b v, one a and b for all loops), its RMS over the RMS of the true force; the figure of proposing
  nothing is the law's own (its part no spring and dashpot absorb), and that of the terms proposed alone,
  reported beside it (a term with memory, whose formula is a rate, by its periodic orbit: :func:`memory_force`);
  the parameters counted are those of the same added terms;
* the final loop NRMSE (as ``diagnose`` reports it) against the truth's floor: the true model at its true
  values on the same loops (:func:`hysid.bench.validation.truth_nrmse`);
* the time of the diagnosis with discovery over the time without (CPU time of this process, which other
  work on the machine changes less than the wall time; both recorded).

On the real friction damper of ``data/arts-friction-damper`` (ARTS-Lab, CC BY-SA 4.0), where no truth is known:
both diagnoses, what discovery proposes and its evidence, and whether held-out data support it (the held-out
error of the model with the proposal below the one without, as the diagnosis judges a library effect).

Targets (issue 33): shape error at most 20 %, no more parameters than the law has and at most four, the final
NRMSE within 1.5 times the floor, the time within 3 times; on the controls (the specimen alone, and with
Coulomb friction, over :data:`CONTROL_SEEDS` noise draws at 1 %) a proposal in at most 1 of 20 draws.
"""

from __future__ import annotations

import time
import warnings
from typing import TYPE_CHECKING, Any

import numpy as np

import hysid
from hysid.bench import check_chosen
from hysid.bench import discovery_cases as dc
from hysid.bench.validation import DAMPER, truth_nrmse
from hysid_model.errors import HysidInputError
from hysid_model.kinematics import Kinematics
from hysid_model.loops import LoopSet

if TYPE_CHECKING:  # the result's type only: hysid --help loads no diagnosis (scipy.optimize) through the bench
    from hysid.diagnosis.result import Diagnosis
    from hysid.harmonic_fits import Fit

SHAPE_SAMPLES = 256
"""Uniform phases per loop at which the shape error compares the forces."""
CONTROL_SEEDS = 20
QUICK_SEEDS = 3
CONTROL_NOISE_PCT = 1.0
TARGETS = {"shape_error": 0.20, "max_params": 4, "floor_ratio": 1.5, "time_ratio": 3.0, "false_proposals": 1}


def shape_phases(n_loops: int, samples: int = SHAPE_SAMPLES) -> np.ndarray:
    """``(L, samples)`` uniform phases of a sine's cycle, half a step off its reversals, the loading half (x' > 0) first."""
    return np.broadcast_to(-0.5 * np.pi + 2.0 * np.pi * (np.arange(samples) + 0.5) / samples, (n_loops, samples))


def loop_motion(freq_hz: np.ndarray, x0: np.ndarray, samples: int = SHAPE_SAMPLES) -> tuple[np.ndarray, np.ndarray]:
    """The sine motion of loops at ``freq_hz`` and amplitudes ``x0``: x (m) and v (m/s), ``(L, samples)`` at
    :func:`shape_phases`."""
    amplitude, w = np.asarray(x0, dtype=float)[:, None], 2.0 * np.pi * np.asarray(freq_hz, dtype=float)[:, None]
    phase = shape_phases(amplitude.shape[0], samples)
    return amplitude * np.sin(phase), w * amplitude * np.cos(phase)


def shape_error(truth: np.ndarray, proposed: np.ndarray, x: np.ndarray, v: np.ndarray) -> float:
    """RMS of (proposed - truth) less its least-squares fit by a spring and a dashpot (a x + b v, one a and b over
    all samples), over the RMS of ``truth``; all forces at the motion ``x``, ``v`` ``(L, samples)`` (module
    docstring), each less its mean over each loop (the loops are centred: a constant force is not in the data)."""
    truth = truth - truth.mean(axis=-1, keepdims=True)
    difference = np.broadcast_to(np.asarray(proposed, dtype=float), truth.shape)
    difference = (difference - difference.mean(axis=-1, keepdims=True) - truth).ravel()
    basis = np.column_stack([x.ravel(), v.ravel()])
    absorbed = basis @ np.linalg.lstsq(basis, difference, rcond=None)[0]
    return float(np.sqrt(np.mean((difference - absorbed) ** 2)) / np.sqrt(np.mean(truth**2)))


def added(fit: Fit, freq_hz: np.ndarray, x0: np.ndarray, samples: int = SHAPE_SAMPLES) -> tuple[np.ndarray, int]:
    """What the model of ``fit`` adds to its start model's spring, dashpot and mass (the effects named and the terms
    proposed, whatever carries the law) at the motion of :func:`loop_motion`: its force less the same model's with
    every added term's strength at 0, ``(L, samples)``, and the added terms' parameters in all."""
    model, theta = fit.model, np.array(fit.theta, dtype=float)
    kin = Kinematics(np.asarray(x0, dtype=float), 2.0 * np.pi * np.asarray(freq_hz, dtype=float))
    phase = shape_phases(kin.x0.size, samples)
    off, n_params = theta.copy(), 0
    for term in (t for t in model.terms if t.id in fit.effects):
        off[model.names.index(term.strength)] = 0.0
        n_params += sum(p.name in model.names for p in term.params)
    forces = model.force(np.stack([theta, off]), kin, phase, samples // 2)
    return forces[0] - forces[1], n_params


def formula_force(formula: str, x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """A proposal's ``formula`` (a numpy expression in ``x`` and ``v``) evaluated at ``x``, ``v``."""
    return np.broadcast_to(np.asarray(eval(formula, {"__builtins__": {}, "np": np, "numpy": np}, {"x": x, "v": v}), dtype=float), x.shape)


def memory_force(diagnosis: Diagnosis, loops: LoopSet) -> np.ndarray:
    """The sum of the proposed terms with memory (whose ``formula`` is the rate of their force, not a force of x and v)
    at the motion of :func:`loop_motion`: each term's periodic orbit under each loop's sine."""
    kin = Kinematics(x0=np.asarray(loops.x0, dtype=float), omega=2.0 * np.pi * np.asarray(loops.freq_hz, dtype=float))
    phase = shape_phases(kin.x0.size)
    return sum((p.term_force(kin, phase) for p in diagnosis.proposed if p.law.memory), np.zeros(phase.shape))


def diagnosed(loops: LoopSet, discover: bool) -> tuple[Diagnosis, float, float]:
    """``hysid.diagnose`` of ``loops`` from ``baseline`` with discovery on or off: the diagnosis, its CPU and wall seconds."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cpu, wall = time.process_time(), time.perf_counter()
        diagnosis = hysid.diagnose(loops, "baseline", discover=discover)
        return diagnosis, time.process_time() - cpu, time.perf_counter() - wall


def proposals(diagnosis: Diagnosis) -> list[dict[str, Any]]:
    """What the diagnosis proposed (``diagnose --json``'s ``proposed``): formula, plain notation, values, errors, evidence."""
    keep = ("formula", "memory", "notation", "params", "stderr", "evidence")
    return [{k: p[k] for k in keep if k in p} for p in diagnosis.to_dict().get("proposed") or []]


def outcome(diagnosis: Diagnosis, cpu: float, wall: float) -> dict[str, Any]:
    """What a diagnosis ended with: the effects named on the way (and those set aside for a proposal), the final model,
    its status and loop NRMSE, what discovery tried from each model and what came of it, and the seconds."""
    return {
        "named": sorted({s.effect for s in diagnosis.steps}),
        "set_aside": sorted(diagnosis.set_aside),
        "final_model": diagnosis.final.spec,
        "status": diagnosis.status,
        "nrmse_pct": diagnosis.gap[-1].nrmse_pct,
        "discovery": diagnosis.discovery,
        "cpu_s": cpu,
        "wall_s": wall,
    }


def run_law(name: str, noise_pct: float, quick: bool) -> dict[str, Any]:
    """One hidden law at one noise level: both diagnoses and the measures of the module docstring."""
    law = dc.LAWS[name]
    loops = dc.loops_of(name, noise_pct, 0, quick)
    base, discovered = outcome(*diagnosed(loops, False)), None
    diagnosis, cpu, wall = diagnosed(loops, True)
    discovered = outcome(diagnosis, cpu, wall)
    proposed = proposals(diagnosis)
    x, v = loop_motion(loops.freq_hz, loops.x0)
    truth = law.force(x, v, **law.truth)
    found = sum((formula_force(p["formula"], x, v) for p in proposed if not p["memory"]), memory_force(diagnosis, loops))
    final, n_params = added(diagnosis.final, loops.freq_hz, loops.x0)
    _, values, spec = dc.truth_model(name)
    floor = truth_nrmse(loops, (spec, values, "measured"))
    row = {
        "law": name,
        "truth": law.formula,
        "truth_params": law.truth,
        "issue_law": law.issue,
        "noise_pct": noise_pct,
        "loops": loops.n_loops,
        "baseline": base,
        "discovery": discovered,
        "proposed": proposed,
        "n_params": n_params,
        "proposed_params": sum(len(p["params"]) for p in proposed),
        "law_params": law.n_params,
        "shape_error": shape_error(truth, final, x, v),
        "proposed_shape_error": shape_error(truth, found, x, v),
        "nothing_proposed_shape_error": shape_error(truth, np.zeros_like(x), x, v),
        "floor_nrmse_pct": floor,
        "floor_ratio": discovered["nrmse_pct"] / floor,
        "time_ratio": discovered["cpu_s"] / base["cpu_s"],
        "wall_ratio": discovered["wall_s"] / base["wall_s"],
    }
    row["meets"] = {
        "proposed": bool(proposed),
        "shape": bool(proposed) and row["shape_error"] <= TARGETS["shape_error"],
        "params": bool(proposed) and n_params <= min(law.n_params, TARGETS["max_params"]),
        "floor": row["floor_ratio"] <= TARGETS["floor_ratio"],
        "time": row["time_ratio"] <= TARGETS["time_ratio"],
    }
    row["meets_all"] = all(row["meets"].values())
    return row


def run_control(name: str, seeds: int, quick: bool) -> dict[str, Any]:
    """A control over ``seeds`` noise draws: diagnoses with discovery, and the draws in which anything was proposed."""
    draws = []
    for seed in range(seeds):
        diagnosis, cpu, wall = diagnosed(dc.loops_of(name, CONTROL_NOISE_PCT, seed, quick), True)
        draws.append({"seed": seed, **outcome(diagnosis, cpu, wall), "proposed": [p["formula"] for p in proposals(diagnosis)]})
    false = sum(bool(d["proposed"]) for d in draws)
    return {
        "control": name,
        "model": dc.CONTROLS[name][0],
        "noise_pct": CONTROL_NOISE_PCT,
        "seeds": seeds,
        "false_proposals": false,
        "meets": false <= TARGETS["false_proposals"] * seeds / 20,
        "draws": draws,
    }


def run_real() -> dict[str, Any]:
    """The real friction damper: both diagnoses, the proposals and their evidence (module docstring)."""
    loops = hysid.load(DAMPER)
    base = outcome(*diagnosed(loops, False))
    diagnosis, cpu, wall = diagnosed(loops, True)
    proposed = proposals(diagnosis)
    held = [(p.get("evidence") or {}).get("held_out_before") for p in proposed], [(p.get("evidence") or {}).get("held_out_after") for p in proposed]
    supported = [None if b is None or a is None else bool(a < b) for b, a in zip(*held)]
    return {
        "device": "arts_friction_damper",
        "loops": loops.n_loops,
        "baseline": base,
        "discovery": outcome(diagnosis, cpu, wall),
        "proposed": proposed,
        "held_out_supports": supported,
        "time_ratio": cpu / base["cpu_s"],
    }


def run(
    quick: bool = False,
    seeds: int | None = None,
    laws: tuple[str, ...] = tuple(dc.LAWS),
    controls: tuple[str, ...] = tuple(dc.CONTROLS),
    noise: tuple[float, ...] = dc.NOISE_PCT,
    real: bool = True,
) -> dict[str, Any]:
    """Discovery: ten force laws the library lacks at two noise levels (shape error, parameters, NRMSE vs floor, time) and two controls."""
    seeds = (QUICK_SEEDS if quick else CONTROL_SEEDS) if seeds is None else seeds
    check_chosen(laws, dc.LAWS, "law")
    check_chosen(controls, dc.CONTROLS, "control")
    if seeds < 1 or any(not 0.0 < n <= 100.0 for n in noise):
        raise HysidInputError("need at least one noise seed and noise levels in (0, 100] %", param="seeds", value=seeds)
    began = time.perf_counter()
    diagnosed(dc.loops_of("no_effect", CONTROL_NOISE_PCT, 0, True), True)  # warm-up: imports and compiled kernels out of the first timing
    rows = [run_law(name, level, quick) for name in laws for level in noise]
    checks = [run_control(name, seeds, quick) for name in controls]
    return tallied(
        {
            "bench": "discovery",
            "quick": quick,
            "targets": TARGETS,
            "points_per_branch": dc.POINTS,
            "laws": rows,
            "controls": checks,
            "real": run_real() if real else None,
            "bench_s": time.perf_counter() - began,
        }
    )


def tallied(result: dict[str, Any]) -> dict[str, Any]:
    """``result`` with its counts: law cases meeting every target, and whether every control does."""
    return {
        **result,
        "meet_all": sum(r["meets_all"] for r in result["laws"]),
        "of": len(result["laws"]),
        "controls_meet": all(c["meets"] for c in result["controls"]),
    }


def combined(parts: list[dict[str, Any]]) -> dict[str, Any]:
    """The results of runs of disjoint parts (laws, noise levels, controls, the real device: run side by side in
    several processes) as one, the laws in the bench's order; ``bench_s`` is the longest part's, ``parts`` their number."""
    if not parts or len({p.get("quick") for p in parts}) != 1 or len({p.get("points_per_branch") for p in parts}) != 1:
        raise HysidInputError("give the JSON of discovery runs of the same kind (all --quick or none, the same points per branch)", param="merge")
    keys = [(r["law"], r["noise_pct"]) for p in parts for r in p["laws"]] + [(c["control"], None) for p in parts for c in p["controls"]]
    if len(keys) != len(set(keys)) or sum(p["real"] is not None for p in parts) > 1:
        raise HysidInputError("the runs to merge overlap (a law at one noise level, a control or the real device in two of them)", param="merge")
    return tallied(
        {
            **parts[0],
            "laws": sorted((r for p in parts for r in p["laws"]), key=lambda r: (list(dc.LAWS).index(r["law"]), r["noise_pct"])),
            "controls": [c for p in parts for c in p["controls"]],
            "real": next((p["real"] for p in parts if p["real"] is not None), None),
            "bench_s": max(p["bench_s"] for p in parts),
            "parts": len(parts),
        }
    )


def proposed_text(row: dict[str, Any]) -> str:
    return " + ".join(p.get("notation") or p["formula"] for p in row["proposed"]) or "nothing"


def to_text(result: dict[str, Any]) -> str:
    lines = [
        f"hysid bench discovery{' (quick)' if result['quick'] else ''}: {result['meet_all']} of {result['of']} law cases meet every target; "
        f"controls {'meet' if result['controls_meet'] else 'MISS'} (false proposals at most 1 in 20)"
    ]
    for r in result["laws"]:
        m = r["meets"]
        lines.append(f"  {r['law']:<15} {r['noise_pct']:g} %  proposed {proposed_text(r)}")
        lines.append(
            f"    shape error {100 * r['shape_error']:.1f} % (proposed alone: {100 * r['proposed_shape_error']:.1f} %, "
            f"nothing proposed: {100 * r['nothing_proposed_shape_error']:.1f} %) "
            f"{'ok' if m['shape'] else 'MISS'}; params {r['n_params']} (law {r['law_params']}) {'ok' if m['params'] else 'MISS'}; "
            f"NRMSE {r['discovery']['nrmse_pct']:.3g} % vs floor {r['floor_nrmse_pct']:.3g} % ({r['floor_ratio']:.2f}x) "
            f"{'ok' if m['floor'] else 'MISS'}; time {r['discovery']['cpu_s']:.0f} s vs {r['baseline']['cpu_s']:.0f} s "
            f"({r['time_ratio']:.2f}x) {'ok' if m['time'] else 'MISS'}; named {', '.join(r['discovery']['named']) or 'nothing'}"
        )
    for c in result["controls"]:
        lines.append(f"  control {c['control']:<17} proposals in {c['false_proposals']} of {c['seeds']} draws {'ok' if c['meets'] else 'MISS'}")
    if result.get("real"):
        lines.append("  real friction damper: " + real_text(result["real"]))
    lines.append(f"  ({result['bench_s']:.0f} s)")
    return "\n".join(lines)


def real_text(real: dict[str, Any]) -> str:
    """One paragraph on the real damper: what each diagnosis ended with, what was proposed, and its held-out evidence."""
    b, d = real["baseline"], real["discovery"]
    text = (
        f"{real['loops']} loops; without discovery `{b['final_model']}`, {b['status']}, loop NRMSE {b['nrmse_pct']:.3g} %; "
        f"with discovery `{d['final_model']}`, {d['status']}, {d['nrmse_pct']:.3g} % ({real['time_ratio']:.2f}x the time). "
    )
    if not real["proposed"]:
        tried = "; ".join(f"from `{start}`: {what}" for start, what in (d.get("discovery") or {}).items())
        return text + "Nothing proposed" + (f" (discovery tried {tried})." if tried else ".")
    parts = []
    for p, ok in zip(real["proposed"], real["held_out_supports"]):
        e = p.get("evidence") or {}
        held = f"held-out error {e['held_out_before']:.4g} -> {e['held_out_after']:.4g}" if ok is not None else "no held-out error"
        parts.append(
            f"proposed `{p.get('notation') or p['formula']}` ({held}, delta BIC {e.get('delta_bic', float('nan')):.4g}, "
            f"share of the excess removed {e.get('share_of_excess_removed', float('nan')):.3g}): held-out data "
            + ("support it" if ok else "do not support it" if ok is not None else "were not checked")
        )
    return text + "; ".join(parts) + "."


def to_markdown(result: dict[str, Any], environment: dict[str, Any]) -> str:
    """The discovery section of docs/VALIDATION.md: the table of the laws, the controls' counts, how it was made."""
    head = [
        "hidden law",
        "noise",
        "proposed",
        "shape error (nothing proposed)",
        "parameters (law)",
        "loop NRMSE vs floor",
        "CPU time with / without discovery",
        "targets",
    ]
    rows = []
    for r in result["laws"]:
        missed = [k for k, ok in r["meets"].items() if not ok]
        rows.append(
            [
                f"`{r['law']}`: {r['truth']}",
                f"{r['noise_pct']:g} %",
                f"`{proposed_text(r)}`",
                f"{100 * r['shape_error']:.1f} % ({100 * r['nothing_proposed_shape_error']:.1f} %)",
                f"{r['n_params']} ({r['law_params']})",
                f"{r['discovery']['nrmse_pct']:.3g} % vs {r['floor_nrmse_pct']:.3g} % ({r['floor_ratio']:.2f}x)",
                f"{r['discovery']['cpu_s']:.0f} s / {r['baseline']['cpu_s']:.0f} s ({r['time_ratio']:.2f}x)",
                "met" if not missed else "**missed: " + ", ".join(missed) + "**",
            ]
        )
    cells = [[cell.replace("|", "\\|") for cell in row] for row in rows]  # |v| inside a table cell
    table = ["| " + " | ".join(head) + " |", "|" + "|".join([":--"] * len(head)) + "|"] + ["| " + " | ".join(row) + " |" for row in cells]
    controls = [
        f"* `{c['control']}` (`{c['model']}`, {c['noise_pct']:g} % noise): something proposed in **{c['false_proposals']} of "
        f"{c['seeds']}** noise draws ({'met' if c['meets'] else 'missed'}: at most 1 in 20)"
        for c in result["controls"]
    ]
    machine = environment.get("machine", {})
    doc = (__doc__ or "").split("\n\n", 1)[1].strip()
    parts = f", the longest of {result['parts']} parts run side by side and merged by --merge" if result.get("parts", 1) > 1 else ""
    return "\n".join(
        [
            "## Discovery: force laws the library lacks",
            "",
            f"Generated {environment.get('date', '')} on {machine.get('hostname', '')} ({machine.get('cpu_model', '')}, load "
            f"{machine.get('load_avg_1m', '')}) by `hysid bench discovery{' --quick' if result['quick'] else ''} --markdown docs/VALIDATION.md` "
            f"({result['bench_s']:.0f} s{parts}). **{result['meet_all']} of {result['of']} law cases meet every target.**",
            "",
            *table,
            "",
            "Controls:",
            "",
            *controls,
            "",
            *(
                [
                    (
                        "Real device, the ARTS-Lab band-brake friction damper (`data/arts-friction-damper`: Dataset-Friction-Damper-with-Backlash, "
                        "ARTS-Laboratory, Coble, Huggins, Cao, Ricles and Downey 2022, CC BY-SA 4.0, converted subset; see its README): "
                        + real_text(result["real"]).replace("|", "\\|")
                    ),
                    "",
                ]
                if result.get("real")
                else []
            ),
            "### How",
            "",
            doc,
            "",
            (dc.__doc__ or "").split("\n\n", 1)[1].strip(),
            "",
        ]
    )
