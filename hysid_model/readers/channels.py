"""Which column or channel of a DAQ record is time, displacement and force, and in which unit.

Every raw-record format (CSV, tidy long CSV, TDMS, HDF5) names its channels;
hysid maps them the same way:

* a name given in ``dataset.toml`` (``time_channel``, ``displacement_channel``,
  ``force_channel``; case-insensitive; a number counts columns from 1), else
* the CSV names ``time_s``, ``displacement_m``, ``force_n`` (case-insensitive),
  else a name ``<quantity>_<unit>`` such as ``Displacement_mm`` or
  ``force_kN``, or the bare ``time``, ``displacement``, ``force`` of a channel
  whose unit the file states, else
* a name as DAQ software and spreadsheets write it: a word for the quantity
  (``SYNONYMS``: ``t``, ``disp``, ``x``, ``position``, ``load``, ...) with its
  unit in brackets, parentheses, after a slash, a space or an underscore
  (``Time [s]``, ``t/s``, ``DISP_MM``, ``load (kN)``), or with no unit at all
  (read as SI, with a warning for displacement and force).

Units, in this order: the unit declared in ``dataset.toml``
(``time_unit``, ``displacement_unit``, ``force_unit``), else the unit the file
states for the channel (a TDMS ``unit_string``, an HDF5 ``units`` attribute)
or its name's suffix (``_mm``); the two must then agree. Else SI.
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from typing import Literal, overload

from hysid_model.errors import HysidInputError, HysidWarning
from hysid_model.readers.dataset_dir import DISPLACEMENT_UNITS, FORCE_UNITS, TIME_UNITS, DatasetConfig

QUANTITIES = ("time", "displacement", "force")
DEFAULT_NAMES = {"time": "time_s", "displacement": "displacement_m", "force": "force_n"}
UNITS = {"time": TIME_UNITS, "displacement": DISPLACEMENT_UNITS, "force": FORCE_UNITS}
SI = {"time": "s", "displacement": "m", "force": "N"}
UNIT_ALIASES = {
    "s": "s",
    "sec": "s",
    "second": "s",
    "seconds": "s",
    "ms": "ms",
    "us": "us",
    "m": "m",
    "meter": "m",
    "meters": "m",
    "metre": "m",
    "metres": "m",
    "mm": "mm",
    "millimeter": "mm",
    "millimeters": "mm",
    "millimetre": "mm",
    "millimetres": "mm",
    "um": "um",
    "micrometer": "um",
    "micrometers": "um",
    "µm": "um",
    "cm": "cm",
    "in": "in",
    "inch": "in",
    "inches": "in",
    "n": "N",
    "newton": "N",
    "newtons": "N",
    "kn": "kN",
    "kilonewton": "kN",
    "kilonewtons": "kN",
    "mn": "mN",
    "lbf": "lbf",
    "lb": "lbf",
    "lbs": "lbf",
    "kip": "kip",
    "kips": "kip",
}
"""Unit labels as files write them (lower case) -> the unit names of ``dataset.toml``."""
SYNONYMS = {
    "time": ("time", "t", "zeit", "temps", "tiempo", "tempo"),
    "displacement": ("displacement", "disp", "x", "position", "pos", "deflection", "stroke", "extension", "weg", "dx"),
    "force": ("force", "load", "f", "kraft", "fz", "load_cell", "loadcell"),
}
"""Words a header uses for each quantity (lower case), the quantity's own name first."""
_LABEL = re.compile(r"^(?P<word>[a-z_]+?)(?:\s*[\[(]\s*(?P<bracket>[^\])]*?)\s*[\])]|\s*/\s*(?P<slash>\w+)|[_ ]+(?:in\s+)?(?P<suffix>[a-zµ]+))?$")


@dataclass(frozen=True)
class Channel:
    """One chosen channel: its position among the file's channels, its name, unit and factor to SI."""

    index: int
    name: str
    unit: str
    factor: float


def _unit_of(label: str | None, quantity: str) -> str | None:
    """The unit a file's label names for ``quantity`` (None for no label; error handling is the caller's)."""
    if label is None or not label.strip():
        return None
    unit = UNIT_ALIASES.get(label.strip().lower())
    return unit if unit in UNITS[quantity] else ""


def _suffix_unit(name: str, quantity: str) -> str | None:
    """``displacement_mm`` -> "mm" (for the quantity's own name only)."""
    match = re.fullmatch(rf"{quantity}_(\w+)", name.strip(), re.IGNORECASE)
    return _unit_of(match.group(1), quantity) or None if match else None


def label(name: str, quantity: str) -> tuple[bool, str | None]:
    """Whether a header ``name`` is one of ``quantity``'s words (``SYNONYMS``) with a unit of it or none, and that
    unit: ``"Time [s]"`` -> (True, "s"), ``"DISP_MM"`` -> (True, "mm"), ``"x"`` -> (True, None), ``"f [Hz]"`` ->
    (False, None) for force (Hz is not a force unit). A name with a slash is read whole first (``t/s``: a unit
    after the slash), then as a channel in a group (``Messung/Weg``, ``Messung/Weg [mm]``, TDMS and HDF5)."""
    texts = [name] + ([name.rsplit("/", 1)[-1]] if "/" in name else [])
    for text in texts:
        match = _LABEL.fullmatch(text.strip().lower())
        if match is None:
            continue
        word, unit_label = match["word"], match["bracket"] or match["slash"] or match["suffix"]
        if word in SYNONYMS[quantity] and unit_label is None:
            return True, None
        if unit_label is not None and word.rstrip("_") in SYNONYMS[quantity]:
            unit = _unit_of(unit_label, quantity)
            if unit:
                return True, unit
    return False, None


def _configured(config: DatasetConfig | None, quantity: str) -> tuple[str | int | None, str | None]:
    """(channel, unit) that ``dataset.toml`` declares for a quantity."""
    if config is None:
        return None, None
    return getattr(config, f"{quantity}_channel"), getattr(config, f"{quantity}_unit")


@overload
def choose(
    names: list[str], quantity: str, config: DatasetConfig | None, source: str, file_units: list[str | None] | None = None, required: Literal[True] = True
) -> Channel: ...
@overload
def choose(
    names: list[str], quantity: str, config: DatasetConfig | None, source: str, file_units: list[str | None] | None = None, required: bool = True
) -> Channel | None: ...
def choose(
    names: list[str], quantity: str, config: DatasetConfig | None, source: str, file_units: list[str | None] | None = None, required: bool = True
) -> Channel | None:
    """The channel of ``quantity`` among ``names`` (see the module docstring); ``file_units`` are the units the
    file states per channel. None when it is absent and not ``required``."""
    chosen, declared = _configured(config, quantity)
    lower = [n.strip().lower() for n in names]
    short = [n.rsplit("/", 1)[-1] for n in lower]  # a channel in a group (TDMS, HDF5) may be named without it
    listing = ", ".join(repr(n) for n in names) or "none"
    key = f"{quantity}_channel"
    if isinstance(chosen, int):
        if chosen > len(names):
            raise HysidInputError(f"{source}: {key} = {chosen} but there are {len(names)} channels ({listing})")
        index = chosen - 1
    elif isinstance(chosen, str):
        target = chosen.strip().lower()
        matches = [i for i, n in enumerate(lower) if n == target] or [i for i, n in enumerate(short) if n == target]
        if len(matches) != 1:
            what = "no channel" if not matches else f"{len(matches)} channels"
            raise HysidInputError(f"{source}: {what} named {chosen!r} ({key} in dataset.toml); channels: {listing}")
        index = matches[0]
    else:
        matches = [i for i, n in enumerate(short) if n == DEFAULT_NAMES[quantity]]
        if not matches:
            stated = file_units or [None] * len(names)
            matches = [i for i, n in enumerate(short) if (n == quantity and stated[i]) or _suffix_unit(n, quantity)]
        if not matches:
            matches = [i for i, n in enumerate(names) if label(n, quantity)[0]]
        if len(matches) > 1:
            raise HysidInputError(
                f"{source}: {len(matches)} {quantity} channels ({', '.join(repr(names[i]) for i in matches)}); name one with {key} in dataset.toml"
            )
        if not matches:
            if not required:
                return None
            raise HysidInputError(
                f"{source}: no {quantity} channel: expected {DEFAULT_NAMES[quantity]!r} (any case), a name like "
                f"'{quantity}_<unit>' or '{quantity.capitalize()} [unit]', or {key} in dataset.toml; channels: {listing}"
            )
        index = matches[0]
    return Channel(index, names[index], *_unit(names[index], quantity, declared, None if file_units is None else file_units[index], source))


def _unit(name: str, quantity: str, declared: str | None, stated: str | None, source: str) -> tuple[str, float]:
    table = UNITS[quantity]
    key = f"{quantity}_unit"
    if declared is not None:
        return declared, table[declared]
    from_file = _unit_of(stated, quantity)
    if from_file == "":
        raise HysidInputError(f"{source}: channel {name!r} states the unit {stated!r}, not a {quantity} unit; set {key} in dataset.toml")
    from_name = _suffix_unit(name.rsplit("/", 1)[-1], quantity) or label(name, quantity)[1]
    if from_file and from_name and from_file != from_name:
        raise HysidInputError(f"{source}: channel {name!r} states the unit {stated!r} but its name says {from_name}; set {key} in dataset.toml")
    unit = from_file or from_name
    if unit is None:
        if quantity != "time" and name.strip().lower() != DEFAULT_NAMES[quantity]:  # a unit slip in time shows as a wrong frequency
            warnings.warn(
                HysidWarning(f"channel {name!r} states no unit: read as {SI[quantity]} (set {key} in dataset.toml if it is not)", "no_unit"), stacklevel=2
            )
        unit = SI[quantity]
    return unit, table[unit]
