"""What a diagnosis found: :class:`Diagnosis` (the result of :func:`hysid.diagnosis.selection.diagnose`, reporting
itself like :class:`hysid.fit_result.FitResult`) and its :class:`Step` s, one per effect named."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from hysid.diagnosis.discovery import Proposed
from hysid.diagnosis.metrics import GapMetrics, References, loop_whitened_rms
from hysid.diagnosis.plausible import mass_note
from hysid.diagnosis.pruning import zero_like
from hysid.diagnosis.scoring import Candidate
from hysid.harmonic_fits import Fit, make_model
from hysid.identifiability import Identifiability
from hysid.motion import MotionChoice
from hysid.report import diagnosis as diagnosis_report
from hysid.report import tables, text
from hysid.report.bounds import widenings
from hysid.report.markdown import NOT_ASKED
from hysid.report.records import DiagnosisCurves, DiagnosisRecord, Estimates, ProposedForce
from hysid_model import notices
from hysid_model.effective import OperatingPoint, effective_table, operating_points
from hysid_model.frf import amplitude_levels
from hysid_model.harmonics import Harmonics
from hysid_model.modal import combinations
from hysid_model.model import effect_term
from hysid_model.model_names import named
from hysid_model.notices import Notice


@dataclass
class Step:
    """One accepted effect."""

    effect: str
    confusable_with: list[str]
    score: float
    before: Fit
    after: Fit
    rejected: dict[str, str]
    """Other contenders of this step and why they were not taken."""
    joint_with: str | None = None
    """The effect named together with this one (the two were taken as a pair)."""

    @property
    def params(self) -> dict[str, float]:
        names = [p.name for p in effect_term(self.effect).params]
        return {n: v for n, v in self.after.params().items() if n in names}

    @property
    def errors(self) -> dict[str, float]:
        return {n: v for n, v in self.after.errors().items() if n in self.params}

    def __repr__(self) -> str:
        joint = f" (with {self.joint_with})" if self.joint_with else ""
        confusable = f"; confusable with {', '.join(self.confusable_with)}" if self.confusable_with else ""
        return (
            f"<Step + {self.effect}{joint}: score {self.score:.4g}, whitened RMS {self.before.whitened_rms:.4g} -> "
            f"{self.after.whitened_rms:.4g}, BIC {self.after.bic - self.before.bic:+.1f}{confusable}>"
        )


@dataclass
class Refused:
    """A library effect the search's last round refused by rule 9 alone (its own shape,
    :func:`hysid.diagnosis.acceptance.own_shape`; every other rule of :func:`hysid.diagnosis.acceptance.judge` passed):
    discovery may also start from its refit (:func:`hysid.diagnosis.contest.with_discovery`)."""

    step: Step
    """The effect, its score, the model it was added to and the refit, as it would have been named."""
    why: str
    """Why rule 9 refused it."""


@dataclass
class Diagnosis:
    """What :func:`diagnose` found: the start fit, every accepted step, the final fit and its gap to the data."""

    harmonics: Harmonics
    start: Fit
    steps: list[Step]
    final: Fit
    status: str
    unexplained: dict | None
    not_identifiable: dict[str, list[str]]
    rejected: dict[str, str]
    """Contenders of the last round and why none was taken."""
    gap: list[GapMetrics]
    """The gap between model and data at the start and after every step."""
    references: References
    """Model-free levels the gap is held against (linear per loop, repeatability)."""
    identifiability: Identifiability
    """What the data cannot determine of the final model, and its correlations."""
    last_scores: list[Candidate] = field(default_factory=list)
    impossible: dict[str, str] = field(default_factory=dict)
    """Effects set aside as impossible on these loops, and why (:mod:`hysid.diagnosis.plausible`)."""
    pruned: dict[str, str] = field(default_factory=dict)
    """Terms dropped from the final model at the end as consistent with zero, and why (:mod:`hysid.diagnosis.pruning`)."""
    motion: MotionChoice | None = None
    """Which displacement drove the models, how that was decided and the evidence (:mod:`hysid.motion`)."""
    report: str | None = None
    """The report written last (:meth:`write_report`)."""
    raised: list[dict[str, str]] = field(default_factory=list)
    """The warnings raised while diagnosing (:func:`hysid_model.notices.keeps_warnings`)."""
    proposed: list[Proposed] = field(default_factory=list)
    """Force terms proposed from the data, not library effects (:mod:`hysid.diagnosis.discovery`), in the final model."""
    set_aside: dict[str, str] = field(default_factory=dict)
    """Library effects named on the way and set aside for a proposed term that explains the loops as well alone, and why."""
    discovery: dict[str, str] = field(default_factory=dict)
    """What discovery tried from each model it started from (its spec), and what came of it."""
    shape_refused: list[Refused] = field(default_factory=list)
    """The last round's library effects refused by rule 9 alone, best BIC first (:class:`Refused`)."""

    def effects_not_identifiable(self) -> dict[str, str]:
        """Why each effect of ``not_identifiable`` cannot be identified from these loops."""
        levels = amplitude_levels(self.harmonics.loops.x0)[0]
        out = {}
        for effect, absorbed in self.not_identifiable.items():
            if levels.size == 1 and effect_term(effect).slope_of:
                out[effect] = f"one amplitude level (X0 = {levels[0] * 1e3:.4g} mm) cannot show a change with amplitude: it is {', '.join(absorbed)} again"
            else:
                out[effect] = f"whatever it does, the model already does with {', '.join(absorbed)}"
        return out

    def fits(self) -> list[tuple[str, Fit]]:
        """(label, fit) for the start and after every step."""
        pruned = [("- " + ", ".join(self.pruned) + " (consistent with zero)", self.proposed[0].base if self.proposed else self.final)] if self.pruned else []
        proposed = [(f"+ proposed {p.name} (from the data)", p.fit) for p in self.proposed]
        return [("start: " + self.start.spec, self.start)] + [("+ " + s.effect, s.after) for s in self.steps] + pruned + proposed

    @property
    def params(self) -> dict[str, float]:
        """The final model's parameters."""
        return self.final.params()

    @property
    def stderr(self) -> dict[str, float]:
        """The final model's standard errors by the rule of :mod:`hysid.identifiability` (``fit``'s): NaN where
        the data cannot determine a parameter, a profile's half-width where the chi^2 is not quadratic."""
        return self.final.model.as_dict(self.identifiability.stderr)

    @cached_property
    def combinations(self) -> dict[str, tuple[float, float]]:
        """The final model's stiffness k = meq w0^2 and damping coefficient c = 2 xi0 meq w0 with standard errors."""
        return combinations(self.final.model, self.final.theta, self.identifiability.propagate)

    @cached_property
    def effective(self) -> list[OperatingPoint]:
        """The final model's effective stiffness, equivalent damping and energy per cycle at each amplitude and
        frequency of the loops, with standard errors (:mod:`hysid_model.effective`, as a fit reports them)."""
        loops = self.harmonics.loops
        return effective_table(self.final.model, self.final.theta, self.identifiability.propagate, *operating_points(loops)[:2])

    @property
    def at_bounds(self) -> dict[str, str]:
        """The final model's parameters on a bound, each with which (:meth:`hysid_model.model.Model.bound_kinds`)."""
        return self.final.model.bound_kinds(self.final.theta)

    @property
    def bounds_widened(self) -> list[dict[str, Any]]:
        """The final model's search bounds that its fits widened (each after an optimum on one), from where to where."""
        return widenings(make_model(self.harmonics, self.final.start, self.final.effects, {}, self.final.freed), self.final.model)

    @property
    def notes(self) -> list[str]:
        """What a reader must know about the final values: a mass the loops' inertia does not support, parameters
        kept although consistent with zero."""
        note = mass_note(self.final.model, self.final.theta, self.harmonics.loops)
        se = self.stderr
        zeros = [f"{n} = {v:.4g} +- {se[n]:.2g}" for n, v in self.params.items() if n in zero_like(self.params, se)]
        kept = [f"consistent with zero but kept (an oscillator parameter, or the BIC rises without it): {', '.join(zeros)}"] if zeros else []
        return ([note] if note else []) + kept

    @property
    def warnings(self) -> list[dict[str, str]]:
        """Every warning about this diagnosis, each ``{"code", "message"}``: those of loading the data, those raised
        while diagnosing, and the notes on the final values (:attr:`notes`)."""
        return notices.merged(notices.stored(self.harmonics.loops.meta), self.raised, (Notice("mass_implausible", n) for n in self.notes))

    @property
    def reaches(self) -> str:
        """Which reference the final model reaches: noise floor, repeatability, linear per loop, or none."""
        return self.references.reached(self.final.whitened_rms, self.status == "adequate")

    def tables(self) -> dict[str, list[dict[str, Any]]]:
        """``parameters`` of the final model, ``steps`` (the effects named, with their parameters) and ``gap``."""
        return tables.diagnosis_tables(self.estimates(), self.to_dict(), [label for label, _ in self.fits()])

    def estimates(self) -> Estimates:
        """What the final model estimated, as the writers of :mod:`hysid.report` take it."""
        return Estimates(self.final.model, self.final.params(), self.stderr, self.combinations, self.effective)

    def record(self) -> DiagnosisRecord:
        """What this diagnosis' writers read beyond its document (:meth:`to_dict`)."""
        fits = self.fits()
        h = self.harmonics
        return DiagnosisRecord(
            self.estimates(),
            h.loops,
            [label for label, _ in fits],
            [fit.bic for _, fit in fits],
            self.start.start,
            int(h.orders().max()),
            h.coef.shape[1],
            self.raised,
            self.report,
            [(p.law, p.number) for p in self.proposed],
        )

    def curves(self) -> DiagnosisCurves:
        """What this diagnosis' figures draw: each loop's whitened RMS and the model's force, of the start and the final model."""
        h = self.harmonics
        return DiagnosisCurves(
            loop_whitened_rms(self.start, h),
            loop_whitened_rms(self.final, h),
            self.start.objective.objective.predict(self.start.theta)[0],
            self.final.objective.objective.predict(self.final.theta)[0],
            [proposed_force(p, h) for p in self.proposed],
        )

    def to_csv(self, out_dir: str | Path) -> dict[str, Path]:
        """Each table of :meth:`tables` as ``<name>.csv`` in ``out_dir`` (a header line, SI units in the column names)."""
        return tables.write_tables(self.tables(), out_dir)

    def to_dataframes(self) -> dict[str, Any]:
        """Each table of :meth:`tables` as a pandas DataFrame (needs pandas, an optional dependency)."""
        return tables.data_frames(self.tables())

    def summary(self) -> str:
        """The gap after each step, the status and what cannot be identified, as text."""
        return text.diagnosis_summary(self.to_dict(), self.record())

    def write_report(self, out_dir: str | Path, dataset: str | None = None, *, figures: bool = True) -> Path:
        """``diagnosis.md`` with its figures and ``diagnosis.json`` in ``out_dir``; returns the Markdown path.

        ``dataset`` is how the reader reloads the data (default: the loop set's name); ``figures=False``: the
        report without its figures (in a fraction of the time), saying where each would be.
        """
        out_dir = Path(out_dir)
        self.report = str(out_dir / diagnosis_report.DIAGNOSIS_MD)
        left_out = None if figures else NOT_ASKED
        return diagnosis_report.write_diagnosis_report(self.to_dict(), self.record(), self.curves(), out_dir, dataset or self.harmonics.loops.name, left_out)

    def _repr_markdown_(self) -> str:
        return diagnosis_report.overview(self.to_dict(), self.record())

    def __repr__(self) -> str:
        return f"<Diagnosis of {self.harmonics.loops.name}: {self.start.spec} -> {self.final.spec} in {len(self.steps)} step(s), {self.status}>"

    def to_dict(self) -> dict[str, Any]:
        """The JSON document of ``hysid diagnose --json``."""
        return {
            "dataset": self.harmonics.loops.name,
            "warnings": self.warnings,
            "start_model": self.start.spec,
            "final_model": self.final.spec,
            "final_model_name": named(self.final.model),
            "displacement_model": self.motion.as_dict() if self.motion else None,
            "steps": [
                {
                    "effect": s.effect,
                    "confusable_with": s.confusable_with,
                    "params": s.params,
                    "stderr": s.errors,
                    "score": s.score,
                    "whitened_rms_before": s.before.whitened_rms,
                    "whitened_rms_after": s.after.whitened_rms,
                    "delta_bic": s.after.bic - s.before.bic,
                    "rejected": s.rejected,
                    "joint_with": s.joint_with,
                    "freed": [n for n in s.after.freed if n in {p.name for p in effect_term(s.effect).params}],
                }
                for s in self.steps
            ],
            "status": self.status,
            "unexplained_signature": self.unexplained,
            "not_identifiable": sorted(self.not_identifiable) + list(self.identifiability.not_identifiable),
            "not_identifiable_reasons": {**self.effects_not_identifiable(), **self.identifiability.not_identifiable},
            "impossible": self.impossible,
            "pruned": self.pruned,
            "correlation": self.identifiability.correlation_dict(),
            "rejected": self.rejected,
            "final_params": self.final.params(),
            "final_stderr": self.stderr,
            "combinations": {name: {"value": v, "stderr": se} for name, (v, se) in self.combinations.items()},
            "final_bounds": {p.name: [p.lower, p.upper] for p in self.final.model.parameters},
            "final_fixed": self.final.model.fixed,
            "at_bounds": sorted(self.at_bounds),
            "at_bounds_kind": self.at_bounds,
            "bounds_widened": self.bounds_widened,
            "notes": self.notes,
            "bounds_from_data": sorted(p.name for p in self.final.model.parameters if p.soft),
            "effective": [p.as_dict() for p in self.effective],
            "whitened_rms": self.final.whitened_rms,
            "references": self.references.as_dict(),
            "reaches": self.reaches,
            "noise_sigma": "known" if np.all(self.harmonics.sigma_known) else "estimated from the data",
            "samples_left_out": None if self.harmonics.loops.kept().all() else self.harmonics.loops.meta.get("reversals"),
            "gap": [g.as_dict() for g in self.gap],
            "proposed": [p.as_dict() for p in self.proposed],
            "set_aside": self.set_aside,
            "discovery": self.discovery,
        }


def proposed_force(proposed: Proposed, harmonics: Harmonics) -> ProposedForce:
    """A proposed term's force at the loops' samples and what the final model leaves of the measured force without it,
    as its figure draws them."""
    x, v, force = proposed.forces(harmonics)
    fit = proposed.fit
    left_over = fit.objective.objective.y - (fit.objective.objective.predict(fit.theta)[0] - force)
    return ProposedForce(proposed.name, proposed.notation, x, v, force, left_over)
