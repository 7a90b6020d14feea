"""Raw DAQ records as CSV: header ``time_s,displacement_m,force_n``, SI units, one row per sample.

Read as written by other tools too: the header may come after blank or ``#``
preamble lines, names are matched without regard to case (or with a unit
suffix, or as ``dataset.toml`` names them: :mod:`.channels`), the separator is
``,``, ``;`` or a tab, and with ``;`` or tabs numbers may use a decimal comma.
"""

from __future__ import annotations

import difflib
import io
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.readers import channels
from hysid_model.readers.dataset_dir import DatasetConfig

COLUMNS = ("time_s", "displacement_m", "force_n")
MAX_LINE = 65536
"""Longest line read as text (a header, or a bad line explained): a file that is one huge line is not read whole."""
CHUNK = 1 << 22
PREAMBLE_LINES = 100
"""Blank or ``#`` comment lines allowed before the header (a DAQ's preamble)."""


@dataclass
class TimeSeries:
    """One record in SI units: time (s, strictly increasing), displacement (m), force (N); the names of the
    channels they were read from, and the displacement's and force's units as read (None where not known)."""

    source: str
    t: np.ndarray
    x: np.ndarray
    force: np.ndarray
    channels: tuple[str, str, str] = COLUMNS
    units: tuple[str, str] | None = None


def checked_series(source: str, t: np.ndarray, x: np.ndarray, force: np.ndarray, names: tuple[str, str, str] = COLUMNS,
                   first_line: int = 2, unit: str = "line", units: tuple[str, str] | None = None) -> TimeSeries:
    """Reject NaN/inf (naming column and line) and time that does not increase.

    ``first_line`` is the file line (or with ``unit`` "sample", the number) of the first sample, for the messages;
    ``units`` the displacement's and force's units as read (the checks of :mod:`hysid_model.slips` name them).
    """
    data = np.column_stack([t, x, force])
    if data.shape[0] < 4:
        raise HysidInputError(f"{source}: only {data.shape[0]} samples; a record needs several cycles")
    bad = ~np.isfinite(data)
    if np.any(bad):
        row, col = np.argwhere(bad)[0]
        raise HysidInputError(f"{source}: {unit} {first_line + row}: {names[col]} is {data[row, col]} (NaN and inf are not allowed)")
    step = np.diff(data[:, 0])
    if np.any(step <= 0):
        k = int(np.flatnonzero(step <= 0)[0])
        raise HysidInputError(
            f"{source}: {unit} {first_line + k + 1}: {names[0]} does not increase ({float(data[k + 1, 0])!r} after {float(data[k, 0])!r}); "
            "time must be strictly increasing"
        )
    return TimeSeries(source, data[:, 0].copy(), data[:, 1].copy(), data[:, 2].copy(), names, units)


@dataclass
class Dialect:
    """How a CSV record is written: the header's line (0-based) and names, the separator, decimal commas."""

    header_line: int
    names: list[str]
    delimiter: str
    decimal_comma: bool
    encoding: str


def _lines(path: Path, encoding: str, count: int) -> list[str]:
    """The first ``count`` lines (a line longer than ``MAX_LINE`` is an error: nothing reads it whole)."""
    out = []
    with path.open(encoding=encoding, newline="") as handle:
        for number in range(1, count + 1):
            line = handle.readline(MAX_LINE + 1)
            if len(line) > MAX_LINE:
                raise HysidInputError(f"{path}: line {number} is longer than {MAX_LINE} characters; not a CSV record")
            if not line:
                break
            out.append(line)
    return out


def sniff(path: Path) -> Dialect:
    """The header (the first line that is neither blank nor a ``#`` comment), its separator (``;``, tab or
    ``,``) and whether numbers use a decimal comma (a line after the header holds ``,`` with another separator)."""
    for encoding in ("utf-8-sig", "latin-1"):
        try:
            lines = _lines(path, encoding, PREAMBLE_LINES + 2)
            break
        except UnicodeDecodeError:
            continue
    header = next((k for k, line in enumerate(lines[:PREAMBLE_LINES]) if line.strip() and not line.lstrip().startswith("#")), None)
    if header is None:
        raise HysidInputError(f"{path}: the file is empty" if not "".join(lines).strip() else f"{path}: no header line (expected {','.join(COLUMNS)})")
    text = lines[header].rstrip("\r\n")
    delimiter = ";" if ";" in text else ("\t" if "\t" in text else ",")
    data = [line for line in lines[header + 1 :] if line.strip()]
    decimal_comma = delimiter != "," and bool(data) and "," in data[0]
    names = [c.strip().strip('"').strip() for c in text.split(delimiter)]
    return Dialect(header, names, delimiter, decimal_comma, encoding)


def _bad_line(path: Path, dialect: Dialect, used: list[tuple[int, str]]) -> HysidInputError:
    """The first line numpy could not parse, explained (only run once parsing has failed)."""
    with path.open(encoding=dialect.encoding, newline="") as handle:
        number = 0
        while True:
            line = handle.readline(MAX_LINE + 1)
            number += 1
            if not line:
                break
            if len(line) > MAX_LINE:
                return HysidInputError(f"{path}: line {number} is longer than {MAX_LINE} characters")
            if number <= dialect.header_line + 1 or not line.strip() or line.lstrip().startswith("#"):
                continue
            cells = [c.strip() for c in line.rstrip("\r\n").split(dialect.delimiter)]
            if len(cells) != len(dialect.names):
                return HysidInputError(f"{path}: line {number}: {len(cells)} values for the {len(dialect.names)} columns of the header")
            for index, name in used:
                cell = cells[index].replace(",", ".") if dialect.decimal_comma else cells[index]
                try:
                    float(cell)
                except ValueError:
                    return HysidInputError(f"{path}: line {number}: {name} {cells[index]!r} is not a number")
    return HysidInputError(f"{path}: could not be read as CSV numbers")


def _missing(path: Path, names: list[str], missing: list[str]) -> HysidInputError:
    hints = []
    for name in missing:
        close = difflib.get_close_matches(name, names, n=1, cutoff=0.5)
        hints.append(f"{name!r}" + (f" (found {close[0]!r})" if close else ""))
    return HysidInputError(
        f"{path}: missing column {', '.join(hints)}; expected columns {', '.join(COLUMNS)}, the header has: {', '.join(map(repr, names))} "
        "(names in any case, with a unit like displacement_mm or 'Displacement [mm]'; or name the columns with "
        "time_channel, displacement_channel, force_channel in dataset.toml)"
    )


def first_long_line(path: Path) -> int | None:
    """The number of the first line longer than ``MAX_LINE`` bytes, else None: one pass over the bytes in
    chunks, because numpy's parser holds a whole line's fields at once (a 200 MB line would take GBs)."""
    line, start, offset = 1, 0, 0
    with path.open("rb") as handle:
        while chunk := handle.read(CHUNK):
            ends = np.flatnonzero(np.frombuffer(chunk, np.uint8) == 10) + offset
            if ends.size:
                lengths = ends - np.concatenate([[start], ends[:-1] + 1])
                too_long = np.flatnonzero(lengths > MAX_LINE)
                if too_long.size:
                    return line + int(too_long[0])
                line, start = line + ends.size, int(ends[-1]) + 1
            offset += len(chunk)
            if offset - start > MAX_LINE:
                return line
    return None


def check_line_lengths(path: Path) -> None:
    number = first_long_line(path)
    if number is not None:
        raise HysidInputError(f"{path}: line {number} is longer than {MAX_LINE} characters; not a record of samples")


def read_columns(path: Path, dialect: Dialect, usecols: list[int], dtype: type = float) -> np.ndarray:
    """Columns ``usecols`` of the rows after the header, as numpy parses them (decimal commas turned to points)."""
    check_line_lengths(path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            if not dialect.decimal_comma:
                return np.loadtxt(path, delimiter=dialect.delimiter, skiprows=dialect.header_line + 1, usecols=usecols,
                                  ndmin=2, encoding=dialect.encoding, dtype=dtype, comments="#")
            text = path.read_text(encoding=dialect.encoding).replace(",", ".")
            return np.loadtxt(io.StringIO(text), delimiter=dialect.delimiter, skiprows=dialect.header_line + 1,
                              usecols=usecols, ndmin=2, dtype=dtype, comments="#")
    except UnicodeDecodeError:
        raise HysidInputError(f"{path}: not UTF-8 text") from None
    except ValueError:
        raise _bad_line(path, dialect, [(i, dialect.names[i]) for i in usecols]) from None


def read_series(path: Path, config: DatasetConfig | None = None) -> TimeSeries:
    """Read a raw record; errors name the file, and the column/line where they can (see :mod:`.channels`)."""
    dialect = sniff(path)
    chosen = [channels.choose(dialect.names, q, config, str(path), required=False) for q in channels.QUANTITIES]
    missing = [channels.DEFAULT_NAMES[q] for q, c in zip(channels.QUANTITIES, chosen) if c is None]
    if missing:
        raise _missing(path, dialect.names, missing)
    data = read_columns(path, dialect, [c.index for c in chosen])
    if data.shape[0] == 0:
        raise HysidInputError(f"{path}: the header is there but there are no data rows")
    t, x, force = (data[:, k] * c.factor for k, c in enumerate(chosen))
    return checked_series(str(path), t, x, force, names=tuple(c.name for c in chosen), first_line=dialect.header_line + 2,
                          units=(chosen[1].unit, chosen[2].unit))


def write_series(path: Path, t: np.ndarray, x: np.ndarray, force: np.ndarray) -> None:
    """Write a raw record (12 significant digits)."""
    np.savetxt(path, np.column_stack([t, x, force]), delimiter=",", fmt="%.12g", header=",".join(COLUMNS), comments="")
