"""Data slips found from the physics: swapped columns, a reversed sign, and unit slips of the displacement, the
force or the given mass, each named with the fix (the ``dataset.toml`` keys that set it right).

A record's numbers look plausible one by one; the physics of the whole set does not
(:func:`physics`, warnings with the codes of :data:`hysid_model.notices.CODES`):

* swapped columns or a reversed sign: a passive specimen dissipates energy, so its force leads the
  displacement (0 to 180 degrees); loops whose force lags generate energy, which swapped columns or a
  reversed channel make of any specimen. Swapped columns are told from a reversed sign by the magnitudes
  (swapped back, in the units the files state, they are plausible), by the harmonics (the "displacement"
  then carries the force's distortion and the "force" is the shaker's clean sine) or by the phase's trend
  over the frequencies (a passive specimen's phase rises with frequency; swapped it falls, reversed it rises
  from -180 degrees). The fix names the channels: ``displacement_channel = "<the force's column>"`` and
  the units each column's header states for its quantity;
* a displacement too large: the motion X0 sin(wt) needs a peak velocity w X0 and acceleration w^2 X0 that no
  rig delivers beyond ``RIG_VELOCITY`` and ``RIG_ACCELERATION`` (nor a stroke beyond ``PLAUSIBLE_X0_M``);
* a force too small: a dynamic stiffness |F1| / X0 below ``SOFTEST``;
* either way round, and for either quantity, from the inertia: the dynamic stiffness Re(F1/X1) = k - m w^2
  falls with frequency by the moving mass m (Eq. 4.6; :func:`hysid_model.survey.inertia`). A unit slip of
  the displacement by a factor s divides that inertia by s, of the force multiplies it, so the inertia the
  loops show is checked against the mass ``dataset.toml`` gives (``meq_kg``: a factor the units explain is
  named, with which unit makes the two agree; a mass written in grams too), and, with no mass given,
  against the masses a rig moves (``PLAUSIBLE_MASS_KG``). With a given mass but no frequency span to show
  the inertia, a force far below that mass's inertia m w^2 X0 in every loop (``RESONANT``) is a slip too.
  Values below 1 are no excuse: data in metres under a millimetre header are all below 1.

Where the data cannot tell a displacement slip from a force slip (the inertia sees only F / X) the warning
names both (code ``unit_slip``); only the motion tells the displacement's own scale.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

from hysid_model.errors import HysidWarning
from hysid_model.loops import LoopSet
from hysid_model.plausibility import NAMED, Measured, names
from hysid_model.readers.dataset_dir import DISPLACEMENT_UNITS, FORCE_UNITS
from hysid_model.survey import MASS_SIGNIFICANCE, dynamic_stiffness, inertia

PLAUSIBLE_X0_M = 1.0
"""No hysteresis rig strokes a metre (electrodynamic shakers +-25 mm or so, servo-hydraulic actuators +-250 mm)."""
G = 9.80665
RIG_VELOCITY = 3.0
"""Peak velocity (m/s) beyond what test rigs deliver: electrodynamic shakers reach about 2 m/s in sine (the
velocity limit of the sine envelope, besides stroke and acceleration: G. F. Lang and D. Snyder, "Understanding the
physics of electrodynamic shaker performance", Sound and Vibration, Oct. 2001; Data Physics, "Sizing shakers
review, part 1: sine and random", 2024; C. W. de Silva, Vibration: Fundamentals and Practice, whose example shaker
has 5 cm stroke, 1.5 m/s and 100 g), servo-hydraulic actuators 1 to 2 m/s (servovalve flow over piston area). The
thesis' own beam sample 2 went to 0.8 mm at 440 Hz (Tables 5.16 and 5.18): 2.2 m/s; 3 m/s leaves that a margin."""
RIG_ACCELERATION = 1000.0 * G
"""Peak acceleration (m/s^2) beyond what test rigs deliver in steady sine. A shaker's bare table reaches about
100 g (same sources), a light specimen on a small shaker more: the thesis' sample 2 at 0.8 mm and 440 Hz is 620 g.
Beyond 1000 g only shock machines go."""
SOFTEST = 1.0
"""Median dynamic stiffness |F1| / X0 (N/m) below which the force is too small for the motion: a millinewton per
millimetre, far softer than the specimens a rig holds (the thesis' Synth specimen, 40 g at 30 Hz, is 1400 N/m,
and some 10 N/m at resonance, which a median over a sweep does not see)."""
ACTIVE_DEG = 2.0
"""A loop whose force lags its displacement by more than this generates energy: no passive specimen does, while a
lag of a degree or so can be a channel delay on a lightly damped one (100 us at 30 Hz)."""
DISTORTED = 0.01
"""The displacement carries the force's distortion when its THD exceeds twice the force's by this much."""
MASS_GAP = 3.0
"""The inertia the loops show and a given mass disagree when one is this many times the other (and the
difference is ``MASS_SIGNIFICANCE`` standard errors): fixtures and a guessed mass differ by tens of per cent,
a unit slip by a factor of 1000 (or 25.4, or 4.45)."""
FACTOR_MATCH = 1.5
"""A unit slip explains a disagreement when its factor is within this factor of the disagreement's."""
PLAUSIBLE_MASS_KG = (1e-5, 1e5)
"""The moving mass a rig's measured force can hold (kg): from 10 mg (a fixture below the smallest load cell) to
100 t (a building's, not a specimen's on a rig); an inertia estimated outside it is a unit slip, when the
factor of a metric prefix brings it inside."""
RESONANT = 1e-4
"""With a given mass m, a force |F1| below this share of the mass's inertia force m w^2 X0 in every loop would
need every loop at a resonance of damping ratio below 5e-5, far below any specimen a hysteresis rig tests."""
MIN_X0_M = 1e-6
"""A unit slip that would leave loops below a micrometre is not offered: a rig's displacement sensor (an LVDT, laser
triangulation) resolves a tenth of a micrometre or so, too coarse for such a loop."""
PREFIXES = (1e3, 1e6)
"""The factors of a metric prefix slip (mm under m, um under mm; um under m)."""
UNITS = {"displacement": DISPLACEMENT_UNITS, "force": FORCE_UNITS}
SLIP_CODES = {"displacement": "unit_slip_displacement", "force": "unit_slip_force"}
"""The code of a unit slip that only one quantity explains."""


@dataclass(frozen=True)
class Reading:
    """How the records were read: the displacement's and force's channels as the files name them (None where the
    records name them differently), and the units the reader took them in (declared in ``dataset.toml``, stated by
    the file, or SI)."""

    channels: tuple[str, str] | None
    units: tuple[str, str]
    stated: bool = True
    """False where the format says nothing of its units (they are taken as SI)."""

    @classmethod
    def common(cls, found: list[tuple[tuple[str, str], tuple[str, str] | None]]) -> Reading | None:
        """The reading the records share ((channels, units) per record), else None (units read differently, or a
        format that does not say)."""
        units, channels = {u for _, u in found}, {c for c, _ in found}
        if len(units) != 1 or None in units:
            return None
        return cls(channels.pop() if len(channels) == 1 else None, units.pop())  # type: ignore[arg-type]

    def unit(self, quantity: str) -> str:
        return self.units[0 if quantity == "displacement" else 1]

    def as_read(self, quantity: str) -> str:
        """How ``quantity``'s numbers were taken: ``under its mm header``, or ``read as m``."""
        return f"under its {self.unit(quantity)} header" if self.stated else f"read as {self.unit(quantity)}"


SI = Reading(("displacement_m", "force_n"), ("m", "N"), stated=False)
"""What a format that names no units is taken as (the readers convert to SI)."""


@dataclass(frozen=True)
class Slip:
    """One way the numbers could have slipped: ``quantity`` "displacement", "force" or "mass", read in ``unit``
    but written in ``true_unit``; ``factor`` multiplies what was read to give the truth."""

    quantity: str
    unit: str
    true_unit: str
    factor: float
    as_read: str = ""
    """How the numbers were taken (:meth:`Reading.as_read`)."""

    def fix(self, given_mass: float | None = None) -> str:
        """Where it shows and what to declare."""
        if self.quantity == "mass":
            assert given_mass is not None  # a mass in the wrong unit was given
            return f"meq_kg in g (meq_kg = {given_mass * self.factor:.4g})"
        return f'the {self.quantity} in {self.true_unit} {self.as_read} ({self.quantity}_unit = "{self.true_unit}")'


def slips(quantity: str, reading: Reading) -> list[Slip]:
    """Every other unit of ``quantity`` the numbers read in ``reading``'s unit could have been written in, by how
    little it changes the numbers. A check that only knows the numbers are too large or too small offers the slips
    of a metric prefix alone (:func:`_prefix`: any factor beyond its threshold would do); one that measures the
    factor (the inertia against a given mass) offers any unit."""
    unit = reading.unit(quantity)
    table = UNITS[quantity]
    base = table.get(unit, 1.0)
    out = (Slip(quantity, unit, other, table[other] / base, reading.as_read(quantity)) for other in table if other != unit)
    return sorted(out, key=lambda s: abs(math.log10(s.factor)))


def motion(freq_hz: np.ndarray, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(peak velocity m/s, peak acceleration m/s^2, beyond a rig) of the motion x0 sin(2 pi f t), per loop."""
    w = 2 * np.pi * freq_hz
    v, a = w * x0, w * w * x0
    return v, a, (x0 > PLAUSIBLE_X0_M) | (v > RIG_VELOCITY) | (a > RIG_ACCELERATION)


def _most(flags: np.ndarray) -> bool:
    return bool(np.count_nonzero(flags) * 2 > flags.size)


def _values(values: np.ndarray, fmt: str) -> str:
    if values.size <= NAMED:
        return ", ".join(fmt.format(v) for v in values)
    return f"{fmt.format(values.min())} to {fmt.format(values.max())}"


def swap_fix(reading: Reading | None) -> str:
    """The ``dataset.toml`` lines that read swapped columns right: each quantity from the other's column, in the
    unit its own header states."""
    if reading is None or reading.channels is None:
        units = "" if reading is None else f' (displacement_unit = "{reading.units[0]}", force_unit = "{reading.units[1]}")'
        return (
            f"name the columns with displacement_channel and force_channel in dataset.toml{units or ' (and their units with displacement_unit and force_unit)'}, "
            "or put the columns in their order"
        )
    (x_name, f_name), (x_unit, f_unit) = reading.channels, reading.units
    return (
        f'set displacement_channel = {json.dumps(f_name)}, displacement_unit = "{x_unit}", force_channel = '
        f'{json.dumps(x_name)} and force_unit = "{f_unit}" in dataset.toml (or put the columns in their order)'
    )


def physics(loops: LoopSet, m: Measured, where: str, reading: Reading | None = None) -> list[HysidWarning]:
    """The warnings of the physics checks of the module docstring, at most one about the energy's sign and one
    about units (the first check that finds a slip: the motion, which tells the displacement's scale, then the given
    mass, the stiffness and the inertia's range); none once the columns look swapped (the units of swapped columns
    mean nothing)."""
    labels, r = loops.labels, reading or SI
    energy = _energy(labels, m, where, reading)
    if energy is not None and energy.code == "swapped_columns":
        return [energy]
    found = inertia(loops, dynamic_stiffness(loops).real)
    checks = (
        lambda: _fast(labels, m, where, r),
        lambda: _given_mass(loops, m, found, where, r),
        lambda: _soft(m, where, r),
        lambda: _mass_range(found, where, r) if loops.meq_kg is None else None,
    )
    unit = next((w for check in checks if (w := check()) is not None), None)
    return [w for w in (energy, unit) if w is not None]


def _energy(labels: list[str], m: Measured, where: str, reading: Reading | None) -> HysidWarning | None:
    """Loops that generate energy: swapped columns (from the magnitudes swapped back, or the harmonics), a reversed
    sign, or either (:func:`_lag_cause`)."""
    phase = (m.phase_deg + 180.0) % 360.0 - 180.0
    if not _most(phase < 0):
        return None
    active = phase < -ACTIVE_DEG
    r = reading or SI
    fx, ff = DISPLACEMENT_UNITS[r.units[0]], FORCE_UNITS[r.units[1]]
    x_back, f_back = m.force_amplitude * fx / ff, m.x0 * ff / fx  # each column in the unit its own header states
    with np.errstate(divide="ignore", invalid="ignore"):
        stiffness, swapped_stiffness = float(np.median(m.force_amplitude / m.x0)), float(np.median(f_back / x_back))
    sv, sa, swapped_fast = motion(m.freq_hz, x_back)
    implausible = bool(motion(m.freq_hz, m.x0)[2].any()) or not stiffness >= SOFTEST
    back = implausible and not swapped_fast.any() and swapped_stiffness >= SOFTEST
    carried = _most(active) and _most(m.x_distortion > 2 * m.force_distortion + DISTORTED)  # a delay's lag is small
    if back or carried:
        why = (
            f"swapped back, the motion (at most {sv.max():.3g} m/s and {sa.max() / G:.3g} g) and the stiffness "
            f"({swapped_stiffness:.3g} N/m) are plausible, as they are not now"
            if back
            else f"the 'displacement' carries the force's harmonics (THD {100 * np.median(m.x_distortion):.3g} % against "
            f"{100 * np.median(m.force_distortion):.3g} % in the 'force')"
        )
        return HysidWarning(
            f"{where}: displacement and force look swapped in {names(labels, np.arange(m.x0.size), m.x0, 'X0 = {:.4g} m')}, "
            f"force amplitude {_values(m.force_amplitude, '{:.3g} N')}: the loops generate energy (the force lags "
            f"the displacement by {-np.median(phase):.3g} degrees; a passive specimen's leads it) and {why}; {swap_fix(reading)}",
            "swapped_columns",
        )
    if not _most(active):
        return None
    cause, code = _lag_cause(m.freq_hz[active], phase[active], reading)
    return HysidWarning(
        f"{where}: the loops generate energy in {names(labels, np.flatnonzero(active), -phase, 'a lag of {:.3g} deg')}: "
        f"a passive specimen's force leads its displacement; {cause}",
        code,
    )


def _lag_cause(freq_hz: np.ndarray, phase: np.ndarray, reading: Reading | None) -> tuple[str, str]:
    """Which fault the phases over the frequencies point to, and its code: a passive specimen's phase rises with
    frequency, swapped columns mirror it (it falls), a reversed sign shifts it by 180 degrees (it still rises)."""
    if freq_hz.size >= 3 and np.ptp(phase) > 10.0 and np.ptp(freq_hz) > 0:
        slope = np.polyfit(np.log(freq_hz), phase, 1)[0]
        if slope < 0:
            return (f"the lag grows with frequency, a passive specimen's mirrored: force and displacement look swapped; {swap_fix(reading)}", "swapped_columns")
        return (
            "the phase rises with frequency from -180 degrees, a passive specimen's turned over: the force's (or the "
            "displacement's) sign looks reversed (a load cell mounted the other way round, or a channel's negative "
            "scale): reverse it in the files",
            "sign_reversed",
        )
    return (f"are force and displacement swapped ({swap_fix(reading)}), or is one channel's sign reversed?", "energy_generated")


def _fast(labels: list[str], m: Measured, where: str, r: Reading) -> HysidWarning | None:
    """A displacement that moves as no rig does: too large by a unit slip (the first that makes it plausible)."""
    v, a, fast = motion(m.freq_hz, m.x0)
    if not fast.any():
        return None
    idx = np.flatnonzero(fast)
    slip = next((s for s in slips("displacement", r) if _prefix(s) and s.factor < 1 and not motion(m.freq_hz, m.x0 * s.factor)[2].any()), None)
    fix = (
        "no unit slip makes it plausible: check the displacement channel"
        if slip is None
        else f"x {slip.factor:.3g} ({slip.true_unit}) makes it at most {(v * slip.factor).max():.3g} m/s and "
        f'{(a * slip.factor).max() / G:.3g} g (declare displacement_unit = "{slip.true_unit}" in dataset.toml)'
    )
    return HysidWarning(
        f"{where}: the displacement moves as no rig does in {names(labels, idx, v, 'peak velocity {:.3g} m/s')}, "
        f"peak acceleration up to {a[idx].max() / G:.3g} g and X0 up to {m.x0[idx].max():.4g} m; shakers reach about "
        f"2 m/s and some hundred g, servo-hydraulic actuators 1-2 m/s: is the displacement in {slip.true_unit if slip else 'mm'} "
        f"{r.as_read('displacement')}? {fix}",
        "unit_slip_displacement",
    )


def _soft(m: Measured, where: str, r: Reading) -> HysidWarning | None:
    """A force too small for the motion (a median dynamic stiffness below ``SOFTEST``): a force read too small, or
    a displacement read too large where the motion stays plausible and its loops above ``MIN_X0_M`` set right."""
    with np.errstate(divide="ignore", invalid="ignore"):
        stiffness = float(np.median(m.force_amplitude / m.x0))
    if stiffness >= SOFTEST:
        return None
    force = next((s for s in slips("force", r) if _prefix(s) and s.factor > 1 and stiffness * s.factor >= SOFTEST), None)
    shorter = next(
        (
            s
            for s in slips("displacement", r)
            if _prefix(s)
            and s.factor < 1
            and stiffness / s.factor >= SOFTEST
            and m.x0.min() * s.factor >= MIN_X0_M
            and not motion(m.freq_hz, m.x0 * s.factor)[2].any()
        ),
        None,
    )
    candidates = [s for s in (force, shorter) if s is not None]
    return _named(
        f"{where}: the force is too small for the motion: a dynamic stiffness |F1|/X0 of {stiffness:.3g} N/m over "
        "the loops (median), softer than any specimen a rig holds",
        candidates,
        None,
        f", making it {stiffness * _mass_factor(candidates[0]):.3g} N/m" if candidates else "",
    )


def _given_mass(loops: LoopSet, m: Measured, found: tuple[float, float, np.ndarray] | None, where: str, r: Reading) -> HysidWarning | None:
    """The inertia the loops show against the given mass; with no frequency span to show it, the force against
    that mass's inertia force (see the module docstring). None without a given mass."""
    given = loops.meq_kg
    if given is None:
        return None
    if found is None:
        return _resonant(m, given, where, r)
    mass, se, per_level = found
    significant = bool(mass > MASS_SIGNIFICANCE * se and np.all(per_level > 0))
    ratio = mass / given
    if abs(mass - given) <= MASS_SIGNIFICANCE * se or 1 / MASS_GAP <= ratio <= MASS_GAP:
        return None
    candidates = [
        s
        for s in slips("displacement", r) + slips("force", r) + [Slip("mass", "kg", "g", 1e-3)]
        if significant and abs(math.log(ratio * _mass_factor(s))) < math.log(FACTOR_MATCH)
    ]
    times = "" if not significant else (f" is {ratio:.4g} times" if ratio > 1 else f" is 1/{1 / ratio:.4g} of")
    head = f"{where}: {_shown(mass, se)}{times or ' contradicts'} the given mass meq_kg = {given:g} kg"
    if not candidates:
        return HysidWarning(
            f"{head}: no unit slip of the displacement or the force explains it; is meq_kg right (the moving mass whose inertia the measured force holds)?",
            "mass_contradicted",
        )
    return _named(head, candidates, given)


def _mass_range(found: tuple[float, float, np.ndarray] | None, where: str, r: Reading) -> HysidWarning | None:
    """With no given mass: an inertia the loops show clearly that no rig's measured force holds (``PLAUSIBLE_MASS_KG``)."""
    if found is None:
        return None
    mass, se, per_level = found
    low, high = PLAUSIBLE_MASS_KG
    if not (mass > MASS_SIGNIFICANCE * se and np.all(per_level > 0)) or low <= mass <= high:
        return None
    candidates = [s for q in UNITS for s in [next((s for s in slips(q, r) if _prefix(s) and low <= mass * _mass_factor(s) <= high), None)] if s]
    return _named(
        f"{where}: {_shown(mass, se)} is {'more' if mass > high else 'less'} than a rig's measured force holds ({1e6 * low:g} mg to {high / 1e3:g} t)",
        candidates,
        None,
        f", making the inertia {mass * _mass_factor(candidates[0]):.3g} kg" if candidates else "",
    )


def _shown(mass: float, se: float) -> str:
    return f"the loops' inertia, {mass:.3g} +- {se:.2g} kg (the fall of their dynamic stiffness Re(F1/X1) = k - m w^2 with frequency, Eq. 4.6),"


def _resonant(m: Measured, given: float, where: str, r: Reading) -> HysidWarning | None:
    """With a given mass and no frequency span: a force below ``RESONANT`` of the mass's inertia force in every loop."""
    share = m.force_amplitude / (given * (2 * np.pi * m.freq_hz) ** 2 * m.x0)
    if not share.max() < RESONANT:
        return None
    candidates = (
        [s for s in slips("force", r) if s.factor > 1 and _prefix(s)][:1]
        + [s for s in slips("displacement", r) if s.factor < 1 and _prefix(s)][:1]
        + [Slip("mass", "kg", "g", 1e-3)]
    )
    return _named(
        f"{where}: the force is at most {share.max():.2g} of the inertia force m w^2 X0 of the given mass meq_kg = "
        f"{given:g} kg in every loop, as if each were at a resonance damped below {RESONANT / 2:g}",
        candidates,
        given,
    )


def _prefix(s: Slip) -> bool:
    """Whether ``s`` is a metric prefix slip (``PREFIXES``: mm under m, N under kN, ...)."""
    return any(math.isclose(abs(math.log10(s.factor)), math.log10(p), rel_tol=1e-9) for p in PREFIXES)


def _mass_factor(s: Slip) -> float:
    """What setting the slip ``s`` right multiplies the inertia the loops show by (over the given mass): the
    displacement's factor divides the dynamic stiffness and so the inertia, the force's multiplies it, a mass in
    grams shrinks the given mass."""
    return {"displacement": 1.0 / s.factor, "force": s.factor, "mass": 1.0 / s.factor}[s.quantity]


def _named(head: str, candidates: list[Slip], given: float | None, after: str = "") -> HysidWarning:
    """The unit-slip warning: ``head``, then the slips that explain it (``after``: what the first makes of the data),
    coded by the quantity where only one can."""
    quantities = {s.quantity for s in candidates}
    code = SLIP_CODES[next(iter(quantities))] if len(quantities) == 1 and "mass" not in quantities else "unit_slip"
    if not candidates:
        return HysidWarning(f"{head}: no unit slip explains it; check the displacement and force channels and meq_kg", code)
    fixes = [s.fix(given) for s in candidates]
    listed = fixes[0] if len(fixes) == 1 else ", ".join(fixes[:-1]) + f" or {fixes[-1]}"
    return HysidWarning(f"{head}: a unit slip? {listed}, in dataset.toml{after}" + ("; the loops cannot tell which" if len(quantities) > 1 else ""), code)
