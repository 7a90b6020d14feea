"""Sensor distortion or motion? Which displacement drives the model, decided by the data.

A displacement record with harmonics (5-20 % distortion is common) can be read
two ways. Either the specimen moves so (the shaker does not impose the sine of
Eq. 4.5): the force then responds at those harmonics as the specimen's
dynamics predict, F_k = S(k w) X_k for its linear part. Or the displacement
sensor (or its conditioning) distorts a motion that is the fundamental: the
force has no response at those orders. Either way the samples sit at the
phases where the *recorded* waveform passes their displacement
(:meth:`hysid_model.loops.LoopSet.phases`); only the motion that drives the
model differs (:attr:`~hysid_model.loops.LoopSet.motion`: ``measured`` or
``fundamental``).

:func:`choose_motion` fits a model under both readings to the loops'
harmonics (orders 0-7, whitened by the force noise,
:class:`~hysid_model.harmonics.HarmonicObjective`) and compares their chi^2:
the same data and the same parameter count, so the difference of their chi^2
is the difference of their BIC (and AIC). A reading ahead by ``BIC_MARGIN``
is taken; within it the data cannot tell the two apart, and the measured
waveform is kept (the model then sees what was recorded). The model compared
is the linear start (the ``baseline`` or ``thesis`` preset within the model
fitted): a force's response to its motion's harmonics is, to first order,
its linear dynamic stiffness, and a linear fit from the survey's estimate
finds its optimum from one start, so ``fit``, ``campaign`` and ``diagnose``
read the same loops the same way whatever model they fit.
:func:`confirm_motion` repeats the comparison with the fitted model itself at
its optimum; ``fit``, ``diagnose`` and a campaign's result
(:func:`hysid.campaigns.confirmed`) refit under its reading where it differs (``fit`` and a campaign by
one rule, :func:`refit_under_other_reading`, each within its own budget). The evidence travels with the choice: both chi^2, and order by
order how strongly the force carries the displacement's harmonics
(:func:`order_evidence`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np

from hysid.criteria import BIC_MARGIN
from hysid.harmonic_fits import fit_objective
from hysid_model.errors import HysidInputError
from hysid_model.harmonics import HarmonicObjective, Harmonics
from hysid_model.loops import LoopSet
from hysid_model.model import Model, as_model
from hysid_model.objective import Objective
from hysid_model.problem import DISPLACEMENTS, displaced, prepare_model, starting_point
from island.polish import polish

CHOICES = ("auto",) + DISPLACEMENTS
"""``displacement=`` of fit, campaign and diagnose: ``auto`` decides between ``measured`` and ``fundamental``."""
READINGS = ("measured", "fundamental")
CONFIRM_NFEV = 200
"""Residual evaluations of each polish that re-fits a fitted model under the other reading."""


@dataclass
class MotionChoice:
    """Which displacement drives the model (``displacement``), how it was decided, and the evidence."""

    displacement: str
    decided_by: str
    """``data`` (auto), ``user`` (asked for), or ``none`` (the loops carry no distortion to decide on)."""
    reason: str
    chi2: dict[str, float] = field(default_factory=dict)
    """chi^2 of the compared model under each reading (whitened harmonics; lower is better)."""
    model: str = ""
    """The model the readings were compared with."""
    orders: list[dict[str, float]] = field(default_factory=list)
    """Per harmonic order k >= 2: the displacement's and the force's median share of their fundamentals, and
    the force's share over what a linear response would carry (:func:`order_evidence`)."""

    @property
    def delta_bic(self) -> float | None:
        """BIC of the fundamental reading less the measured one's (negative: the sensor reading is better)."""
        if set(self.chi2) != set(READINGS):
            return None
        return float(self.chi2["fundamental"] - self.chi2["measured"])

    def as_dict(self) -> dict[str, Any]:
        return {
            "displacement": self.displacement,
            "meaning": WORDS[self.displacement],
            "decided_by": self.decided_by,
            "reason": self.reason,
            "model": self.model or None,
            "chi2": dict(self.chi2),
            "delta_bic": self.delta_bic,
            "orders": self.orders,
        }


WORDS = {
    "measured": "the measured waveform is the motion",
    "fundamental": "the motion is the fundamental, the displacement's harmonics are the sensor's",
    "sine": "the ideal sine X0 sin(wt) of Eq. 4.5",
}


def distorted(loops: LoopSet) -> bool:
    """True when some loop's displacement carries harmonics beyond its fundamental."""
    return loops.x_harmonics is not None and bool(np.any(np.abs(loops.x_harmonics[:, 1:]) > 0))


def order_evidence(harmonics: Harmonics) -> list[dict[str, float]]:
    """For each harmonic order k >= 2 the displacement carries: the median over loops of |X_k| / |X_1| and
    of |F_k| / |F_1|, and their ratio (``response``): about 1 or more where the force follows the motion's
    harmonics as a spring would (more for inertia, k^2), far below 1 where the harmonics are the sensor's."""
    loops = harmonics.loops
    xh = loops.x_harmonics
    assert xh is not None  # harmonics are fitted only where the displacement's are known
    names = harmonics.names
    force = harmonics.coef
    f1 = np.hypot(force[:, names.index("s1")], force[:, names.index("c1")])
    out = []
    for k in range(2, xh.shape[1] + 1):
        if f"s{k}" not in names or not np.any(np.abs(xh[:, k - 1]) > 0):
            continue
        x_share = np.abs(xh[:, k - 1]) / np.abs(xh[:, 0])
        f_share = np.hypot(force[:, names.index(f"s{k}")], force[:, names.index(f"c{k}")]) / np.maximum(f1, 1e-300)
        with np.errstate(divide="ignore", invalid="ignore"):
            response = float(np.median(f_share[x_share > 0] / x_share[x_share > 0]))
        out.append({"order": k, "displacement_share": float(np.median(x_share)), "force_share": float(np.median(f_share)), "response": response})
    return out


def linear_start(model: Model) -> str:
    """The preset within ``model`` that the readings are compared with: ``thesis`` if it has both amplitude slopes."""
    return "thesis" if {"S_xi", "S_w"} <= {p.name for p in model.all_parameters} else "baseline"


def _reading_fit(
    harmonics: Harmonics, start: str, loops: LoopSet, bounds: Mapping[str, tuple[float, float]] | None, fixed: Mapping[str, float] | None
) -> float:
    model = prepare_model(
        harmonics.loops,
        start,
        bounds={k: v for k, v in (bounds or {}).items() if k in ("xi0", "w0", "meq", "S_xi", "S_w")},
        fixed={k: v for k, v in (fixed or {}).items() if k in ("xi0", "w0", "meq", "S_xi", "S_w")},
    )
    fit = fit_objective(HarmonicObjective(harmonics, model), start, (), [starting_point(harmonics.loops, model)])
    return fit.chi2


def choose_motion(
    loops: LoopSet,
    model: str | Model = "baseline",
    displacement: str = "auto",
    *,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    fixed: Mapping[str, float] | None = None,
) -> MotionChoice:
    """How ``loops``' displacement drives a ``model``: as asked, or (``auto``) the reading of the module
    docstring the data prefer. ``bounds``/``fixed`` as for the fit (those of the linear start apply)."""
    if displacement not in CHOICES:
        raise HysidInputError(f"choose one of {', '.join(CHOICES)}", param="displacement", value=displacement)
    if loops.x_harmonics is None:
        return MotionChoice("sine", "none", "the loops carry no displacement waveform")
    if not distorted(loops):
        return MotionChoice("measured" if displacement == "auto" else displacement, "none", "the displacement has no harmonics beyond its fundamental")
    if displacement != "auto":
        return MotionChoice(displacement, "user", "as asked")
    start = linear_start(as_model(model))
    chi2 = {}
    for reading in READINGS:
        harmonics = Harmonics.from_loops(displaced(loops, reading))
        chi2[reading] = _reading_fit(harmonics, start, loops, bounds, fixed)
    evidence = order_evidence(Harmonics.from_loops(loops))
    return decide(chi2, start, evidence)


def decide(chi2: dict[str, float], model: str, evidence: list[dict[str, float]]) -> MotionChoice:
    """The reading ``chi2`` prefers by at least ``BIC_MARGIN``, else the measured waveform, with the reason."""
    delta = chi2["fundamental"] - chi2["measured"]
    shares = ", ".join(f"order {e['order']}: x {100 * e['displacement_share']:.3g} %, F {100 * e['force_share']:.3g} %" for e in evidence[:3])
    if delta <= -BIC_MARGIN:
        reason = (
            f"the force does not respond to the displacement's harmonics ({shares}): driven by the fundamental "
            f"the {model} model fits better, BIC lower by {-delta:.4g}"
        )
        return MotionChoice("fundamental", "data", reason, dict(chi2), model, evidence)
    if delta >= BIC_MARGIN:
        reason = f"the force responds to the displacement's harmonics ({shares}): driven by them the {model} model fits better, BIC lower by {delta:.4g}"
        return MotionChoice("measured", "data", reason, dict(chi2), model, evidence)
    reason = f"the data cannot tell sensor distortion from motion (BIC differs by {delta:+.3g}, less than {BIC_MARGIN:g}); the measured waveform is kept"
    return MotionChoice("measured", "data", reason, dict(chi2), model, evidence)


def confirm_motion(loops: LoopSet, model: Model, theta: np.ndarray, choice: MotionChoice) -> MotionChoice | None:
    """The other reading, if the fitted ``model`` at ``theta`` (fitted under ``choice``) fits the loops' harmonics
    better under it by ``BIC_MARGIN`` after a polish from ``theta``; else None. Only for a choice the data made."""
    if choice.decided_by != "data":
        return None
    other = "fundamental" if choice.displacement == "measured" else "measured"
    chi2 = {}
    for reading in READINGS:
        objective = HarmonicObjective(Harmonics.from_loops(displaced(loops, reading)), model)
        chi2[reading] = float(polish(objective, theta, max_nfev=CONFIRM_NFEV).fitness) if reading == other else float(objective(theta[None, :])[0])
    flipped = decide(chi2, model.spec, choice.orders)
    if flipped.displacement != other or flipped.chi2[choice.displacement] - flipped.chi2[other] < BIC_MARGIN:
        return None
    flipped.reason += f" (the {linear_start(model)} start alone preferred the other reading)"
    return flipped


Refit = TypeVar("Refit")


def refit_under_other_reading(
    loops: LoopSet,
    model: Model,
    theta: np.ndarray,
    choice: MotionChoice,
    under: Callable[[str], Objective],
    search: Callable[[Objective, np.ndarray], Refit],
) -> tuple[MotionChoice, Refit] | None:
    """The refit under the other displacement reading, one rule for ``hysid fit`` and a campaign's result: where
    ``model``, fitted under ``choice`` to its best ``theta``, reads the loops the other way (:func:`confirm_motion`),
    the problem ``under`` that reading is searched again from ``theta`` (within its bounds) by ``search`` (the
    fit's runs; a campaign's refit, within the campaign's own budget). Returns that reading and what ``search``
    returned; None where the reading stands."""
    flipped = confirm_motion(loops, model, theta, choice)
    if flipped is None:
        return None
    objective = under(flipped.displacement)
    return flipped, search(objective, np.clip(theta, objective.bounds[:, 0], objective.bounds[:, 1]))
