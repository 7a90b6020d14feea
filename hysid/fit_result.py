"""The result of one identification (:class:`FitResult`): the runs of ``fit`` or a campaign's islands, and what a
user reads off them.

:meth:`FitResult.from_runs` takes the best run and derives its parameters with standard errors (Cramer-Rao bound
for ML weights, sandwich covariance for the thesis weights, Appendix A; by the one rule of
:mod:`hysid.identifiability`: the full covariance, the profile where it cannot be trusted), the stiffness and
damping coefficient the data determine best, xi, fn and physical k, c, m at every amplitude (as listed under
Table 5.3), the effective stiffness and equivalent damping of the whole model at every amplitude and frequency
(:mod:`hysid_model.effective`), and the half-power cross-check of the damping (Eq. 2.7, Fig. 6.1). The result
reports itself (``summary()``, ``to_dict()``, ``write_report()``) through the writers of :mod:`hysid.report`,
which take its record, never the result.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hysid.adequacy import Adequacy, model_adequacy
from hysid.diagnosis.plausible import mass_note
from hysid.identifiability import Identifiability, assess, one_amplitude
from hysid.motion import MotionChoice
from hysid.report import markdown, tables, text
from hysid.report.records import Estimates, FitCurves, FitRecord
from hysid_model import notices
from hysid_model.effective import OperatingPoint, effective_table, operating_points
from hysid_model.errors import HysidInputError
from hysid_model.frf import HalfPower, amplitude_levels, first_harmonic, half_power_by_amplitude
from hysid_model.loops import LoopSet
from hysid_model.modal import AmplitudeResult, combinations, derived_table
from hysid_model.model import Model
from hysid_model.model_names import model_name
from hysid_model.objective import Objective
from hysid_model.uncertainty import covariance, fisher_information, scaled_inverse
from island.run import RunResult

REPR_PARAMS = 6
"""Parameters a result's one-line repr shows (the rest are in ``params`` and ``summary()``)."""


@dataclass
class FitResult:
    """Everything one identification produced; build it with :meth:`from_runs`."""

    loops: LoopSet
    model: Model
    weights: str
    runs: list[RunResult]
    settings: dict[str, Any]
    best: int
    covariance: np.ndarray
    """Parameter covariance; NaN rows and columns for parameters the data cannot determine."""
    stderr_method: str
    identifiability: Identifiability
    amplitudes: list[AmplitudeResult]
    half_power: list[HalfPower]
    quality: dict[str, float | None]
    effective: list[OperatingPoint]
    """k_eff, xi_eq and the energy per cycle of the whole model at each amplitude level and frequency of the loops."""
    combinations: dict[str, tuple[float, float]]
    """The stiffness k = meq w0^2 and damping coefficient c = 2 xi0 meq w0: (value, standard error)."""
    adequacy: Adequacy | None = None
    """Whether the model describes the loops (:mod:`hysid.adequacy`, the rule ``hysid diagnose`` applies);
    None where the loops are too coarse to judge."""
    report: str | None = None
    """The report written last (:meth:`write_report`), named in the JSON document."""
    raised: list[dict[str, str]] = field(default_factory=list)
    """The warnings raised while fitting (:func:`hysid_model.notices.keeps_warnings`)."""

    @classmethod
    def from_runs(cls, objective: Objective, runs: list[RunResult], settings: dict[str, Any], *, profiles: bool = True) -> FitResult:
        """Pick the best run, and derive standard errors, per-amplitude quantities and the half-power check.
        ``profiles=False``: the errors that need the objective's profile (:func:`hysid.identifiability.assess`) are
        the curvature's, and ``stderr_method`` says so (a campaign stopped by Ctrl-C reports in seconds)."""
        if not runs:
            raise HysidInputError("a fit result needs at least one run")
        best = int(np.argmin([r.fitness for r in runs]))
        theta = runs[best].theta
        loops, model = objective.loops, objective.model
        scale = inflation(objective, theta)
        if objective.weights == "ml":
            method = f"Cramer-Rao bound of the ML weights, noise sigma {loops.sigma_source}"
        else:
            source = "known" if loops.has_sigma else "estimated from the residuals"
            method = f"sandwich covariance of the thesis-weighted least squares, noise sigma {source}"
        if scale > 1.0:
            method += f", scaled up by sqrt(chi^2/dof) = {np.sqrt(scale):.3g} (the model misses the noise floor)"
        ident = assess(
            objective,
            theta,
            scale * parameter_covariance(objective, theta),
            lambda m: Objective(objective.loops, m, weights=objective.weights),
            scale * noise_unit(objective, theta),
            profiles=profiles,
        )
        if ident.profiled:
            method += "; from the profile of the objective for " + ", ".join(ident.profiled)
        if ident.unprofiled:
            method += (
                f"; from the curvature alone for {', '.join(ident.unprofiled)}, whose profile was left out (the campaign was "
                "interrupted; hysid report computes it)"
            )
        ident.not_identifiable.update(one_amplitude(loops, model))
        levels, _ = amplitude_levels(loops.x0)
        force_amplitude = np.abs(first_harmonic(loops))
        relative = (objective.residuals(theta) / force_amplitude[:, None])[objective.keep]
        quality = {
            "rms_residual_pct": float(100.0 * np.sqrt(np.mean(relative**2))),
            "noise_sigma_pct": float(100.0 * np.sqrt(np.mean((loops.sigma / force_amplitude) ** 2))) if loops.has_sigma else None,
        }
        return cls(
            loops=loops,
            model=model,
            weights=objective.weights,
            runs=runs,
            settings=settings,
            best=best,
            covariance=ident.covariance,
            stderr_method=method,
            identifiability=ident,
            amplitudes=derived_table(model, theta, ident.propagate, levels),
            half_power=half_power_by_amplitude(loops),
            quality=quality,
            effective=effective_table(model, theta, ident.propagate, *operating_points(loops)[:2]),
            combinations=combinations(model, theta, ident.propagate),
            adequacy=model_adequacy(loops, model, theta),
        )

    @property
    def theta(self) -> np.ndarray:
        return self.runs[self.best].theta

    @property
    def fitness(self) -> float:
        return float(self.runs[self.best].fitness)

    @property
    def evaluations(self) -> int:
        return int(sum(r.evaluations for r in self.runs))

    @property
    def params(self) -> dict[str, float]:
        """The identified parameters by name (free ones; :attr:`Model.fixed` holds the rest)."""
        return self.model.as_dict(self.theta)

    @property
    def stderr(self) -> dict[str, float]:
        """One standard error per parameter (see :attr:`stderr_method`); NaN where not identifiable."""
        return self.model.as_dict(self.identifiability.stderr)

    @property
    def not_identifiable(self) -> dict[str, str]:
        """Parameters the data cannot determine, and why (:mod:`hysid.identifiability`)."""
        return self.identifiability.not_identifiable

    @property
    def misfit(self) -> float | None:
        """RMS residual over the known noise (1: the noise floor), None where the noise is not known."""
        noise = self.quality["noise_sigma_pct"]
        return None if not noise else float(self.quality["rms_residual_pct"]) / noise  # type: ignore[arg-type]

    @property
    def displacement_model(self) -> dict[str, Any] | None:
        """Which displacement drove the model (the measured waveform, its fundamental, the ideal sine), how
        that was decided and the evidence (:class:`hysid.motion.MotionChoice`)."""
        stored = self.settings.get("displacement_model")
        if stored is None and "displacement" in self.settings:  # a campaign rebuilt from its database
            return MotionChoice(self.settings["displacement"], "stored", "as the campaign was configured").as_dict()
        return stored

    @property
    def warnings(self) -> list[dict[str, str]]:
        """Every warning about this result, each ``{"code", "message"}`` (:data:`hysid_model.notices.CODES`): those
        of loading the data (the loop set carries them), those raised while fitting, then the fit's own judgments
        (:meth:`judgments`)."""
        return self.warned(self.judgments())

    def judgments(self) -> list[notices.Notice]:
        """The fit's own warnings: a model that misses the data, parameters on bounds (:func:`hysid.report.text.fit_warnings`)."""
        return text.fit_warnings(
            self.loops, self.model, self.theta, self.weights, self.settings, self.adequacy, self.misfit, mass_note(self.model, self.theta, self.loops)
        )

    def warned(self, judgments: list[notices.Notice]) -> list[dict[str, str]]:
        """The warnings of the data, those raised while fitting, then ``judgments``, each ``{"code", "message"}``."""
        return notices.merged(notices.stored(self.loops.meta), self.raised, judgments)

    @property
    def at_bounds(self) -> list[str]:
        """Parameters that ended on a bound: a physical limit (an answer: no damping of that kind), or a bound
        of the search space, derived from the data or given (the optimum may lie beyond it); :attr:`bound_kinds` says which."""
        return list(self.bound_kinds)

    @property
    def bound_kinds(self) -> dict[str, str]:
        """Each parameter on a bound with which bound it is (:meth:`hysid_model.model.Model.bound_kinds`)."""
        return self.model.bound_kinds(self.theta)

    def estimates(self) -> Estimates:
        """What this fit estimated, as the writers of :mod:`hysid.report` take it."""
        return Estimates(self.model, self.params, self.stderr, self.combinations, self.effective, self.at_bounds, self.amplitudes, self.half_power)

    def record(self) -> FitRecord:
        """What this fit's writers read (summary, report, notebook view)."""
        judged = self.judgments()
        return FitRecord(
            self.loops,
            self.estimates(),
            self.theta,
            self.weights,
            self.runs,
            self.best,
            self.evaluations,
            self.settings,
            self.quality,
            self.adequacy,
            self.displacement_model,
            self.not_identifiable,
            self.stderr_method,
            self.identifiability.correlation,
            judged,
            self.warned(judged),
            self.raised,
            self.report,
        )

    def curves(self) -> FitCurves:
        """What this fit's figures draw: the model's force at every sample and the force it fits."""
        objective = self.objective()
        return FitCurves(objective.predict(self.theta)[0], objective.y)

    def objective(self) -> Objective:
        """A fresh objective of this fit (same loops, model and weights)."""
        return Objective(self.loops, self.model, weights=self.weights)

    def to_dict(self) -> dict[str, Any]:
        """The JSON document of ``hysid fit --json``."""
        names = self.model.names
        return {
            "warnings": self.warnings,
            "params": self.params,
            "stderr": self.stderr,
            "stderr_method": self.stderr_method,
            "fitness": self.fitness,
            "evaluations": self.evaluations,
            "history": self.runs[self.best].history,
            "units": {p.name: p.unit for p in self.model.parameters},
            "bounds": {p.name: [p.lower, p.upper] for p in self.model.parameters},
            "fixed": self.model.fixed,
            "at_bounds": self.at_bounds,
            "at_bounds_kind": self.bound_kinds,
            "displacement_model": self.displacement_model,
            **self.identifiability.to_dict(),
            "combinations": {name: {"value": v, "stderr": se} for name, (v, se) in self.combinations.items()},
            "derived": [a.as_dict() for a in self.amplitudes],
            "effective": [p.as_dict() for p in self.effective],
            "half_power": [{**hp.as_dict(), "xi_fit": a.values["xi"]} for hp, a in zip(self.half_power, self.amplitudes)],
            "dataset": {
                "name": self.loops.name,
                "loops": self.loops.n_loops,
                "meq_kg": self.loops.meq_kg,
                "true_params": self.loops.meta.get("true_params"),
            },
            "model": self.model.spec,
            "model_name": model_name(self.model),
            "weights": self.weights,
            "settings": self.settings,
            "best_run": self.best,
            "quality": self.quality,
            "adequacy": None if self.adequacy is None else self.adequacy.to_dict(),
            "runs": [r.as_dict(names) for r in self.runs],
            "report": self.report,
        }

    def tables(self) -> dict[str, list[dict[str, Any]]]:
        """``parameters`` (value, standard error, unit, bounds, status) and ``amplitudes`` (fn, xi, k, c, m with
        standard errors, and the half-power xi of Eq. 2.7) as lists of plain dicts."""
        return tables.fit_tables(self.estimates())

    def to_csv(self, out_dir: str | Path) -> dict[str, Path]:
        """Each table of :meth:`tables` as ``<name>.csv`` in ``out_dir`` (a header line, SI units in the column names)."""
        return tables.write_tables(self.tables(), out_dir)

    def to_dataframes(self) -> dict[str, Any]:
        """Each table of :meth:`tables` as a pandas DataFrame (needs pandas, an optional dependency)."""
        return tables.data_frames(self.tables())

    def summary(self) -> str:
        """What a user reads after a fit (like lmfit's ``fit_report()``): data, model, parameters, amplitudes."""
        return text.fit_summary(self.record())

    def write_report(self, out_dir: str | Path, *, figures: bool = True) -> Path:
        """``report.md``, ``result.json`` and the PNG figures in ``out_dir``; returns the report's path.
        ``figures=False``: the report without its figures (in a fraction of the time), saying where each would be."""
        out_dir = Path(out_dir)
        self.report = str(out_dir / markdown.REPORT)
        left_out = None if figures else markdown.NOT_ASKED
        return markdown.write_fit_report(self.record(), out_dir, self.to_dict(), None if left_out else self.curves(), figures_left_out=left_out)

    def _repr_markdown_(self) -> str:
        return markdown.fit_overview(self.record())

    def __repr__(self) -> str:
        shown = [f"{name} {value:.4g}" for name, value in self.params.items()]
        values = ", ".join(shown[:REPR_PARAMS]) + (f", ... ({len(shown)} in all)" if len(shown) > REPR_PARAMS else "")
        return f"<FitResult {self.model.spec} on {self.loops.name}: fitness {self.fitness:.6g}; {values}>"


def parameter_covariance(objective: Objective, theta: np.ndarray) -> np.ndarray:
    """The fit's covariance: the Cramer-Rao bound for ML weights, the sandwich covariance for the thesis' (Appendix A)."""
    if objective.weights == "ml":
        return scaled_inverse(fisher_information(objective, theta))
    return covariance(objective, theta)


def inflation(objective: Objective, theta: np.ndarray) -> float:
    """chi^2/dof where it exceeds 1 under ML weights (the model misses the known noise floor: every variance is
    scaled up by it, as the diagnosis does), else 1 (the thesis' weights estimate their unit from the residuals)."""
    if objective.weights != "ml":
        return 1.0
    return max(1.0, float(objective(theta[None, :])[0]) / max(int(objective.keep.sum()) - objective.dim, 1))


def noise_unit(objective: Objective, theta: np.ndarray) -> float:
    """The objective's value of one unit of chi^2: 1 for ML weights, else the mean weighted residual at the optimum."""
    if objective.weights == "ml":
        return 1.0
    return max(float(objective(theta[None, :])[0]) / max(int(objective.keep.sum()) - objective.dim, 1), 1e-300)
