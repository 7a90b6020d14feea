"""A dataset directory's description: ``dataset.toml`` and ``manifest.csv``.

``dataset.toml`` (all keys optional)::

    name = "beam-sample-2"
    meq_kg = 0.040              # equivalent mass (thesis Meq); 0 or absent = unknown (fitted)
    sample_rate_hz = 10000      # for records without a time channel (.lvm, TDMS/HDF5 without waveform timing)
    displacement_unit = "mm"    # declared units (override the file's): m, mm, um, cm, in / N, kN, mN, lbf, kip / s, ms, us
    force_unit = "N"
    time_channel = "Time"       # channels (CSV columns, TDMS/HDF5/.lvm channels) by name, or by number (1 = first)
    displacement_channel = "Displacement"
    force_channel = 2
    skip_rows = 3               # CSV records: lines before the header (a preamble of free text); found by itself, with a warning, when absent
    description = "..."

    [bounds]                    # search-space overrides, stored in LoopSet.meta["bounds"]
    xi0 = [0.0, 0.1]

    steady_t0_s = 2             # the steady (constant-amplitude) window in s of every record ...
    steady_t1_s = 5

    [[tests]]                   # ... unless its own entry gives one
    file = "run1.csv"
    steady_t0_s = 8
    steady_t1_s = 20

``manifest.csv`` lists one record per row under the header ``file,frequency_hz``
(further columns are allowed and ignored), in the order the loops are numbered;
``;`` or tab separators (with decimal commas), Windows-1252 text and file names
holding the separator unquoted (``probe_f0,2Hz.csv``) are read too.
"""

from __future__ import annotations

import csv
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeGuard

from hysid_model.errors import HysidInputError

CONFIG_NAME = "dataset.toml"
MANIFEST_NAME = "manifest.csv"
MANIFEST_COLUMNS = ("file", "frequency_hz")
MAX_MASS_KG = 1e7
"""Largest equivalent mass a dataset may state: ten times the payload of the largest shake tables."""
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6}
DISPLACEMENT_UNITS = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "cm": 1e-2, "in": 0.0254}
FORCE_UNITS = {"N": 1.0, "kN": 1e3, "mN": 1e-3, "lbf": 4.4482216152605, "kip": 4448.2216152605}


@dataclass
class DatasetConfig:
    """What ``dataset.toml`` says (defaults when the file is absent)."""

    directory: Path
    name: str
    meq_kg: float | None = None
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)
    sample_rate_hz: float | None = None
    time_unit: str | None = None
    displacement_unit: str | None = None
    force_unit: str | None = None
    time_channel: str | int | None = None
    displacement_channel: str | int | None = None
    force_channel: str | int | None = None
    skip_rows: int | None = None
    """Lines before a CSV record's header (``skip_rows`` in ``dataset.toml``, or ``--skip-rows``); None: found by
    :func:`hysid_model.readers.csv_series.sniff`."""
    steady: dict[str, tuple[float, float]] = field(default_factory=dict)
    steady_default: tuple[float, float] | None = None
    """The top-level steady window, for every record without its own [[tests]] window."""
    info: dict[str, Any] = field(default_factory=dict)
    given: frozenset[str] = frozenset()
    """Top-level keys present in ``dataset.toml`` (to tell "absent" from a default)."""

    def window(self, file: str) -> tuple[float, float] | None:
        """The steady window of a record: its [[tests]] entry's, else the dataset's, else None (found from the data)."""
        return self.steady.get(file, self.steady_default)

    def meta(self) -> dict[str, Any]:
        """Dataset-level entries of ``LoopSet.meta``."""
        out: dict[str, Any] = dict(self.info)
        if self.bounds:
            out["bounds"] = dict(self.bounds)
        return out


@dataclass
class ManifestRow:
    file: str
    frequency_hz: float
    line: int


def frequency_in_name(stem: str) -> float | None:
    """A nominal frequency written in a record's name (``SAMPLE2_05mm_436Hz``, ``0.25Hz30lb...``, with a decimal
    comma or ``p`` too: ``9,5Hz``, ``9p5Hz``), else None."""
    match = re.search(r"(?<![\d.,])(\d+(?:[.,p]\d+)?)[\s_]*Hz", stem, re.IGNORECASE)
    return float(match.group(1).replace(",", ".").replace("p", ".").replace("P", ".")) if match else None


def natural_key(name: str) -> list[object]:
    """Sort key that orders TRAC2 before TRAC10."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", name)]


def _is_number(value: Any) -> TypeGuard[float]:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _positive(doc: dict[str, Any], key: str, where: str) -> float | None:
    if key not in doc:
        return None
    value = doc[key]
    if not (_is_number(value) and value > 0):
        raise HysidInputError(f"{where}: {key} must be a positive number, got {value!r}")
    return float(value)


def _mass(doc: dict[str, Any], where: str) -> float | None:
    """``meq_kg``: absent or 0 = unknown (None); negative, not a number or beyond ``MAX_MASS_KG`` is an error."""
    value = doc.get("meq_kg", 0.0)
    if not _is_number(value) or value < 0:
        raise HysidInputError(f"{where}: meq_kg must be a mass in kg >= 0 (0 = unknown), got {value!r}")
    check_mass(float(value), where)
    return float(value) if value > 0 else None


def check_mass(value: float, where: str) -> None:
    """A stated equivalent mass above ``MAX_MASS_KG`` is an error (no test rig moves more; numbers like
    1e300 only overflow the fit)."""
    if value > MAX_MASS_KG:
        raise HysidInputError(f"{where}: meq_kg = {value:g} kg is not a plausible equivalent mass (at most {MAX_MASS_KG:g} kg)")


def _unit(doc: dict[str, Any], key: str, table: dict[str, float], where: str) -> str | None:
    if key not in doc:
        return None
    value = doc[key]
    if value not in table:
        raise HysidInputError(f"{where}: {key} {value!r} is not one of {', '.join(table)}")
    return str(value)


def _channel(doc: dict[str, Any], key: str, where: str) -> str | int | None:
    if key not in doc:
        return None
    value = doc[key]
    if isinstance(value, str) and value.strip():
        return value
    if isinstance(value, int) and not isinstance(value, bool) and value >= 1:
        return value
    raise HysidInputError(f"{where}: {key} must be a channel name or a channel number >= 1, got {value!r}")


def _skip_rows(doc: dict[str, Any], where: str) -> int | None:
    value = doc.get("skip_rows")
    if value is None:
        return None
    check_skip_rows(value, where)
    return int(value)


def check_skip_rows(value: Any, where: str | None = None) -> None:
    """``skip_rows`` must be a whole number of lines >= 0 (``where`` names the file, else the Python parameter)."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        if where is None:
            raise HysidInputError("must be a whole number of lines >= 0", param="skip_rows", value=value)
        raise HysidInputError(f"{where}: skip_rows must be a whole number of lines >= 0, got {value!r}")


def _bounds(doc: dict[str, Any], where: str) -> dict[str, tuple[float, float]]:
    table = doc.get("bounds", {})
    if not isinstance(table, dict):
        raise HysidInputError(f"{where}: [bounds] must be a table of name = [lower, upper]")
    out = {}
    for name, pair in table.items():
        if not (isinstance(pair, list) and len(pair) == 2 and all(_is_number(v) for v in pair) and pair[0] < pair[1]):
            raise HysidInputError(f"{where}: bounds.{name} must be [lower, upper] with lower < upper, got {pair!r}")
        out[name] = (float(pair[0]), float(pair[1]))
    return out


def _window(entry: dict[str, Any], what: str, where: str) -> tuple[float, float] | None:
    """``steady_t0_s``/``steady_t1_s`` of a table, both or neither."""
    given = [key for key in ("steady_t0_s", "steady_t1_s") if key in entry]
    if not given:
        return None
    t0, t1 = entry.get("steady_t0_s"), entry.get("steady_t1_s")
    if len(given) != 2 or not (_is_number(t0) and _is_number(t1) and 0 <= t0 < t1):
        raise HysidInputError(f"{where}: {what}steady_t0_s and steady_t1_s must both be given with 0 <= t0 < t1, got {t0!r}, {t1!r}")
    return float(t0), float(t1)


def _steady_windows(doc: dict[str, Any], where: str) -> dict[str, tuple[float, float]]:
    tests = doc.get("tests", [])
    if not isinstance(tests, list) or not all(isinstance(entry, dict) for entry in tests):
        raise HysidInputError(f"{where}: tests must be an array of tables ([[tests]])")
    out: dict[str, tuple[float, float]] = {}
    for k, entry in enumerate(tests, start=1):
        name = entry.get("file")
        if not isinstance(name, str) or not name:
            raise HysidInputError(f"{where}: [[tests]] entry {k} has no file name")
        window = _window(entry, f"[[tests]] {name}: ", where)
        if window is not None:
            out[name] = window
    return out


def read_config(directory: Path) -> DatasetConfig:
    """Read ``directory/dataset.toml``; without one, name = the directory's name and nothing else is known."""
    path = directory / CONFIG_NAME
    if not path.is_file():
        return DatasetConfig(directory=directory, name=directory.resolve().name, info={"source": str(directory)})
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise HysidInputError(f"{path}: invalid TOML: {exc}") from None
    except UnicodeDecodeError:
        raise HysidInputError(f"{path}: not UTF-8 text") from None
    where = str(path)
    name = doc.get("name", directory.resolve().name)
    if not isinstance(name, str) or not name.strip():
        raise HysidInputError(f"{where}: name must be a non-empty string, got {name!r}")
    info: dict[str, Any] = {"source": str(directory)}
    if isinstance(doc.get("description"), str):
        info["description"] = doc["description"]
    if isinstance(doc.get("true_params"), dict):
        info["true_params"] = {k: float(v) for k, v in doc["true_params"].items() if _is_number(v)}
    return DatasetConfig(
        directory=directory,
        name=name,
        meq_kg=_mass(doc, where),
        bounds=_bounds(doc, where),
        sample_rate_hz=_positive(doc, "sample_rate_hz", where),
        time_unit=_unit(doc, "time_unit", TIME_UNITS, where),
        displacement_unit=_unit(doc, "displacement_unit", DISPLACEMENT_UNITS, where),
        force_unit=_unit(doc, "force_unit", FORCE_UNITS, where),
        time_channel=_channel(doc, "time_channel", where),
        displacement_channel=_channel(doc, "displacement_channel", where),
        force_channel=_channel(doc, "force_channel", where),
        skip_rows=_skip_rows(doc, where),
        steady=_steady_windows(doc, where),
        steady_default=_window(doc, "", where),
        info=info,
        given=frozenset(doc),
    )


def _manifest_text(path: Path) -> str:
    """The manifest's text: UTF-8, else Windows-1252 (a spreadsheet's CSV export in Western Europe)."""
    data = path.read_bytes()
    for encoding in ("utf-8-sig", "cp1252"):
        try:
            return data.decode(encoding)
        except UnicodeDecodeError:
            continue
    raise HysidInputError(f"{path}: not UTF-8 text")


def _frequency(text: str, delimiter: str) -> float:
    """A frequency cell (a decimal comma where the separator is not a comma), NaN if it is no number."""
    try:
        return float(text.replace(",", ".") if delimiter != "," else text)
    except ValueError:
        return math.nan


def _row_cells(cells: list[str], columns: int, i_file: int, i_freq: int, delimiter: str, directory: Path) -> list[str]:
    """A row's cells, as many as the header's: a row with more is a file name holding the separator, unquoted
    (``probe_f0,2Hz.csv,0.2``), and, in a comma-separated file, maybe a decimal comma in the frequency too. Of the
    ways to join the surplus cells, the one naming a file in the directory, with a positive frequency, wins."""
    extra = len(cells) - columns
    if extra <= 0:
        return cells
    joins = []
    for in_freq in (0, 1) if delimiter == "," else (0,):
        widths = [1] * columns
        widths[i_file] += extra - in_freq
        widths[i_freq] += in_freq
        if min(widths) < 1:
            continue
        bounds = [sum(widths[:k]) for k in range(columns + 1)]
        joined = [("." if k == i_freq else delimiter).join(cells[bounds[k] : bounds[k + 1]]) for k in range(columns)]
        if _frequency(joined[i_freq], delimiter) > 0:
            joins.append(joined)
    named = [j for j in joins if (directory / j[i_file]).is_file()]
    return (named or joins or [cells])[0]


def read_manifest(path: Path) -> list[ManifestRow]:
    """Rows of ``manifest.csv`` (header ``file,frequency_hz``, in any case), checked for duplicates and bad frequencies.

    Written as spreadsheets write it too: separated by ``;`` or tabs (then the frequency may have a decimal comma),
    in Windows-1252, and with file names holding the separator unquoted (German names such as ``probe_f0,2Hz.csv``).
    """
    text = _manifest_text(path)
    lines = [(k, line) for k, line in enumerate(text.splitlines(), start=1) if line.strip()]
    if not lines:
        raise HysidInputError(f"{path}: the file is empty (expected the header 'file,frequency_hz' and one row per record)")
    first = lines[0][1]
    delimiter = ";" if ";" in first else ("\t" if "\t" in first else ",")
    header = [c.strip().lower() for c in next(csv.reader([first], delimiter=delimiter))]
    if not all(c in header for c in MANIFEST_COLUMNS):
        raise HysidInputError(f"{path}: the first line must be the header 'file,frequency_hz' (found {first.strip()!r})")
    i_file, i_freq = header.index("file"), header.index("frequency_hz")
    rows: list[ManifestRow] = []
    seen: dict[str, int] = {}
    for number, line in lines[1:]:
        cells = [c.strip() for c in next(csv.reader([line], delimiter=delimiter))]
        if len(cells) <= max(i_file, i_freq):
            raise HysidInputError(f"{path}: line {number}: expected {len(header)} columns ({', '.join(header)}), got {len(cells)}")
        cells = _row_cells(cells, len(header), i_file, i_freq, delimiter, path.parent)
        name, freq_text = cells[i_file], cells[i_freq]
        freq = _frequency(freq_text, delimiter)
        if not (math.isfinite(freq) and freq > 0):
            raise HysidInputError(f"{path}: line {number}: frequency_hz {freq_text!r} is not a positive number")
        if not name:
            raise HysidInputError(f"{path}: line {number}: empty file name")
        if name in seen:
            raise HysidInputError(f"{path}: line {number}: {name!r} is listed twice (also on line {seen[name]})")
        seen[name] = number
        rows.append(ManifestRow(name, freq, number))
    if not rows:
        raise HysidInputError(f"{path}: lists no records (only the header)")
    return rows


def inside(directory: Path, path: Path) -> bool:
    """Whether ``path``, with every link followed, lies inside ``directory``."""
    return path.resolve().is_relative_to(directory.resolve())


def confined(directory: Path, name: str, where: str) -> Path:
    """``directory / name`` for a file a dataset names; an absolute path, a ``..`` or a link leading out of
    the directory is an error (nothing outside is read, so no message shows its content)."""
    relative = Path(name)
    if relative.is_absolute() or ".." in relative.parts or name.startswith(("/", "\\")):
        raise HysidInputError(f"{where}: {name!r} is not a file inside the dataset directory (absolute paths and '..' are refused)")
    target = directory / relative
    if not inside(directory, target):
        raise HysidInputError(f"{where}: {name!r} links outside the dataset directory; copy the file in")
    return target


def listed_file(path: Path, row: ManifestRow) -> Path:
    """The record a manifest row names, which must exist inside the manifest's directory."""
    target = confined(path.parent, row.file, f"{path}: line {row.line}")
    if not target.is_file():
        raise HysidInputError(f"{path}: line {row.line}: listed file {row.file!r} does not exist in {path.parent}")
    return target
