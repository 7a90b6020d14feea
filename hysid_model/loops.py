"""The loop set: every measured hysteresis loop as a loading and an unloading branch.

A loop is stored as in the thesis' ``HexpT``/``HexpB`` (Appendix A): the top
(loading, x' > 0) and bottom (unloading, x' < 0) branches, each resampled on
``n`` displacement points (``reinterpolate``) and centred (``centercurveloop``).
All loops of a set share ``n`` so that a whole population can be evaluated
against all of them in one vectorized call.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

import numpy as np

from hysid_model import waveform
from hysid_model.errors import HysidInputError
from hysid_model.kinematics import Kinematics

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

MOTIONS = ("measured", "fundamental")
"""What a loop set's displacement harmonics are: the specimen's motion, or the sensor's distortion of a motion
that is the fundamental alone (:attr:`LoopSet.motion`)."""
INERTIA_LIMIT = 1e6
"""A known mass whose inertia force exceeds the measured forces a million times is a typo (a specimen at
resonance with a damping ratio of 1e-4 stays at 5e3)."""

Record = TypeVar("Record", bound="DataclassInstance")


def at_loops(record: Record, idx: np.ndarray, per_loop: tuple[str, ...], **changes: Any) -> Record:
    """``record`` (a dataclass holding one entry per loop) at the loops ``idx``: every field named in ``per_loop``
    (an array indexed ``[loop, ...]``) taken at ``idx``, the fields in ``changes`` as given, the others as they are."""
    return replace(record, **{name: getattr(record, name)[idx] for name in per_loop}, **changes)


@dataclass
class LoopSet:
    """Loops of one specimen; arrays are indexed ``[loop]`` or ``[loop, sample]``.

    ``top`` and ``bottom`` have shape ``(L, n, 2)`` holding displacement (m) and
    force (N). ``sigma`` is each loop's force-noise standard deviation (N), NaN
    where unknown. ``meq_kg`` is the known equivalent mass, or None when unknown
    (then it is fitted). ``x_harmonics`` ``(L, K)`` complex is each loop's
    measured displacement as harmonics of its fundamental
    (:mod:`hysid_model.waveform`), None where the displacement is taken as the
    ideal sine X0 sin(wt) of Eq. 4.5. ``motion`` says what those harmonics are:
    ``"measured"``, the specimen's motion (the model is driven by the whole
    waveform), or ``"fundamental"``, the displacement sensor's distortion (the
    motion is the fundamental X0 sin(theta); the harmonics still place every
    sample at its phase, :meth:`phases`). ``meta["per_loop"]``, when present, maps
    names to lists with one entry per loop (kept aligned by :meth:`subset`).
    """

    name: str
    freq_hz: np.ndarray
    x0: np.ndarray
    top: np.ndarray
    bottom: np.ndarray
    sigma: np.ndarray
    meq_kg: float | None = None
    cycles: np.ndarray | None = None
    labels: list[str] = field(default_factory=list)
    meta: dict[str, Any] = field(default_factory=dict)
    x_harmonics: np.ndarray | None = None
    motion: str = "measured"

    PER_LOOP: ClassVar[tuple[str, ...]] = ("freq_hz", "x0", "top", "bottom", "sigma", "cycles")
    """The array fields indexed ``[loop, ...]`` (:meth:`subset` takes them at the loops it keeps)."""

    def __post_init__(self) -> None:
        self.freq_hz = np.asarray(self.freq_hz, dtype=float).reshape(-1)
        self.x0 = np.asarray(self.x0, dtype=float).reshape(-1)
        self.top = np.asarray(self.top, dtype=float)
        self.bottom = np.asarray(self.bottom, dtype=float)
        self.sigma = np.asarray(self.sigma, dtype=float).reshape(-1)
        n_loops = self.freq_hz.size
        if self.cycles is None:
            self.cycles = np.zeros(n_loops, dtype=int)
        self.cycles = np.asarray(self.cycles, dtype=int).reshape(-1)
        if not self.labels:
            self.labels = [f"loop{j:03d}" for j in range(n_loops)]
        if n_loops == 0:
            raise HysidInputError(f"{self.name}: the loop set is empty")
        if self.top.ndim != 3 or self.top.shape[2] != 2 or self.top.shape != self.bottom.shape:
            raise HysidInputError(f"{self.name}: branches must be (loops, samples, 2) arrays of equal shape")
        for arr, what in ((self.x0, "x0"), (self.sigma, "sigma"), (self.cycles, "cycles")):
            if arr.size != n_loops:
                raise HysidInputError(f"{self.name}: {what} has {arr.size} entries for {n_loops} loops")
        if self.top.shape[0] != n_loops or len(self.labels) != n_loops:
            raise HysidInputError(f"{self.name}: {self.top.shape[0]} branch pairs and {len(self.labels)} labels for {n_loops} loops")
        if not (np.all(np.isfinite(self.top)) and np.all(np.isfinite(self.bottom))):
            raise HysidInputError(f"{self.name}: branch data hold NaN or inf")
        if np.any(~np.isfinite(self.freq_hz)) or np.any(self.freq_hz <= 0):
            raise HysidInputError(f"{self.name}: every loop needs a positive frequency")
        if np.any(~np.isfinite(self.x0)) or np.any(self.x0 <= 0):
            raise HysidInputError(f"{self.name}: every loop needs a positive amplitude X0")
        if self.meq_kg is not None and not (np.isfinite(self.meq_kg) and self.meq_kg > 0):
            raise HysidInputError(f"{self.name}: meq_kg must be a positive mass or unknown (None), got {self.meq_kg}")
        measured = float(np.max(self.peak_force))
        if self.meq_kg is not None and measured > 0:  # all-zero forces: a template to predict on, nothing to compare
            with np.errstate(over="ignore"):
                inertia = float(np.max(self.meq_kg * self.omega**2 * self.x0))
            if not inertia <= INERTIA_LIMIT * measured:
                raise HysidInputError(
                    f"{self.name}: meq_kg = {self.meq_kg:g} kg is not plausible: its inertia force m w^2 X0 reaches {inertia:.3g} N, "
                    f"more than {INERTIA_LIMIT:g} times the largest measured force ({measured:.3g} N)"
                )
        if self.motion not in MOTIONS:
            raise HysidInputError(f"{self.name}: the motion must be one of {', '.join(MOTIONS)}, not {self.motion!r}")
        if self.x_harmonics is not None:
            self.x_harmonics = waveform.check(self.x_harmonics, self.name)
            if self.x_harmonics.shape[0] != n_loops:
                raise HysidInputError(f"{self.name}: displacement harmonics for {self.x_harmonics.shape[0]} loops, not {n_loops}")
            if not np.allclose(np.abs(self.x_harmonics[:, 0]), self.x0, rtol=1e-9, atol=0.0):
                raise HysidInputError(f"{self.name}: the displacement's fundamental amplitude differs from X0")

    @property
    def n_loops(self) -> int:
        return int(self.freq_hz.size)

    @property
    def n_samples(self) -> int:
        """Samples per branch (the thesis' ``interppts``)."""
        return int(self.top.shape[1])

    @property
    def omega(self) -> np.ndarray:
        return 2.0 * np.pi * self.freq_hz

    @property
    def peak_force(self) -> np.ndarray:
        """max |F| over both branches of each loop (the thesis' ``maxF``)."""
        return np.maximum(np.abs(self.top[:, :, 1]).max(axis=1), np.abs(self.bottom[:, :, 1]).max(axis=1))

    @property
    def has_sigma(self) -> bool:
        return bool(np.all(np.isfinite(self.sigma)) and np.all(self.sigma > 0))

    @property
    def sigma_source(self) -> str:
        """Where ``sigma`` comes from, in words: estimated from the records' scatter (loops extracted from raw
        records), given (a loops file, the noise added to the Synth set), or unknown."""
        if not self.has_sigma:
            return "unknown"
        if "sigma_raw_n" in (self.meta.get("per_loop") or {}):
            return "estimated from the scatter of the records' cycles"
        return "given"

    @property
    def measured_displacement(self) -> bool:
        """True when the loops carry their measured displacement harmonics (not the ideal sine)."""
        return self.x_harmonics is not None

    @property
    def sensor_distortion(self) -> bool:
        """True when the displacement's harmonics are the sensor's and the motion is the fundamental."""
        return self.x_harmonics is not None and self.motion == "fundamental"

    def displacement_harmonics(self) -> np.ndarray:
        """``(L, K)`` harmonics of the motion: the measured ones, else (the ideal sine, or a sensor's
        distortion of it) the fundamental's (K = 1)."""
        return self.x_harmonics if self.x_harmonics is not None and self.motion == "measured" else waveform.ideal(self.x0)

    def kinematics(self) -> Kinematics:
        """The motion a model of these loops is driven by (:class:`~hysid_model.kinematics.Kinematics`): X0, w and,
        where the measured waveform is the motion, its harmonics."""
        return Kinematics(x0=self.x0, omega=self.omega, xh=self.x_harmonics if self.motion == "measured" else None)

    def phases(self) -> np.ndarray:
        """Phase wt of every sample, shape ``(L, 2n)``: top branch first, then bottom.

        With x = X0 sin(wt) (Eq. 4.5) the loading branch has cos(wt) >= 0 and
        the unloading branch cos(wt) <= 0. With the measured displacement the
        phase of a sample is where that waveform passes the sample's x on its
        branch (:func:`hysid_model.waveform.branch_phases`).
        """
        if self.x_harmonics is not None:
            return waveform.branch_phases(self.x_harmonics, self.top[:, :, 0], self.bottom[:, :, 0])
        s_top = np.clip(self.top[:, :, 0] / self.x0[:, None], -1.0, 1.0)
        s_bot = np.clip(self.bottom[:, :, 0] / self.x0[:, None], -1.0, 1.0)
        return np.concatenate([np.arcsin(s_top), np.pi - np.arcsin(s_bot)], axis=1)

    def forces(self) -> np.ndarray:
        """Measured force at every sample, shape ``(L, 2n)``: top branch, then bottom."""
        return np.concatenate([self.top[:, :, 1], self.bottom[:, :, 1]], axis=1)

    def kept(self) -> np.ndarray:
        """Which samples a model must explain, ``(L, 2n)`` bool (top branch, then bottom): all but the four
        reversal samples of a loop whose force extraction could not resolve there
        (``meta["per_loop"]["reversals_resolved"]``, :mod:`hysid_model.resolution`)."""
        n = self.n_samples
        keep = np.ones((self.n_loops, 2 * n), dtype=bool)
        resolved = (self.meta.get("per_loop") or {}).get("reversals_resolved")
        if resolved is not None:
            keep[np.ix_(~np.asarray(resolved, dtype=bool), np.array([0, n - 1, n, 2 * n - 1]))] = False
        return keep

    def rows(self) -> list[dict[str, Any]]:
        """One dict per loop: label, frequency, X0, peak force, noise sigma, cycles (+ phase, displacement
        distortion and clipping, ``clipped`` "displacement"/"force"/"velocity" at ``clip_level`` m, N or m/s, when extracted
        from raw records); ``hysid loops --json``."""
        per_loop = self.meta.get("per_loop", {})
        out = []
        for j in range(self.n_loops):
            sigma = float(self.sigma[j])
            row: dict[str, Any] = {
                "label": self.labels[j],
                "frequency_hz": float(self.freq_hz[j]),
                "x0_m": float(self.x0[j]),
                "peak_force_n": float(self.peak_force[j]),
                "sigma_n": sigma if np.isfinite(sigma) else None,
                "cycles": int(self.cycles[j]),
            }
            for key in ("phase_deg", "x_distortion"):
                if key in per_loop:
                    row[key] = float(per_loop[key][j])
            if "clipped" in per_loop:
                clipped = per_loop["clipped"][j]
                row["clipped"] = clipped or None
                row["clip_level"] = per_loop["clip_level"][j] if clipped else None
            out.append(row)
        return out

    def __repr__(self) -> str:
        mass = "unknown" if self.meq_kg is None else f"{self.meq_kg:.4g} kg"
        return (
            f"<LoopSet {self.name}: {self.n_loops} loops at {self.freq_hz.min():.4g}-{self.freq_hz.max():.4g} Hz, "
            f"X0 {1e3 * self.x0.min():.4g}-{1e3 * self.x0.max():.4g} mm, {self.n_samples} samples per branch, meq {mass}>"
        )

    def subset(self, index: np.ndarray | list[int]) -> LoopSet:
        """These loops at ``index`` (:func:`at_loops`): the per-loop arrays, labels, ``meta["per_loop"]`` and harmonics."""
        idx = np.asarray(index, dtype=int)
        x_harmonics = None if self.x_harmonics is None else self.x_harmonics[idx]
        return at_loops(self, idx, self.PER_LOOP, labels=[self.labels[i] for i in idx], meta=self._meta_subset(idx), x_harmonics=x_harmonics)

    def _meta_subset(self, idx: np.ndarray) -> dict[str, Any]:
        """``meta`` for a subset: per-loop lists under ``meta["per_loop"]`` are sliced with the loops."""
        meta = dict(self.meta)
        if isinstance(meta.get("per_loop"), dict):
            meta["per_loop"] = {key: [values[i] for i in idx] for key, values in meta["per_loop"].items()}
        return meta

    def as_ideal_sine(self) -> LoopSet:
        """These loops with the displacement taken as the ideal sine X0 sin(wt) (the thesis' Eq. 4.5)."""
        out = self.subset(np.arange(self.n_loops))
        out.x_harmonics, out.motion = None, "measured"
        return out

    def with_motion(self, motion: str) -> LoopSet:
        """These loops with their displacement harmonics read as ``motion`` (:data:`MOTIONS`)."""
        out = self.subset(np.arange(self.n_loops))
        out.motion = motion
        out.__post_init__()
        return out

    def with_meq(self, meq_kg: float | None) -> LoopSet:
        out = self.subset(np.arange(self.n_loops))
        out.meq_kg = meq_kg
        out.__post_init__()
        return out
