"""Raw DAQ records as CSV: header ``time_s,displacement_m,force_n``, SI units, one row per sample.

Read as written by other tools too: the header may come after blank or ``#``
preamble lines, or after lines of free text (skipped with a warning when the rows
of numbers show where the header is, or by ``skip_rows`` in ``dataset.toml`` /
``--skip-rows``), names are matched without regard to case (or with a unit
suffix, or as ``dataset.toml`` names them: :mod:`.channels`), the separator is
``,``, ``;`` or a tab, and with ``;`` or tabs numbers may use a decimal comma.
A big file is parsed in chunks into its three columns (:mod:`.numbers`), never
held as text.
"""

from __future__ import annotations

import difflib
import io
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hysid_model.errors import HysidInputError, HysidWarning
from hysid_model.readers import channels
from hysid_model.readers.dataset_dir import DatasetConfig

COLUMNS = ("time_s", "displacement_m", "force_n")
MAX_LINE = 65536
"""Longest line read as text (a header, or a bad line explained): a file that is one huge line is not read whole."""
CHUNK = 1 << 22
PREAMBLE_LINES = 100
"""Lines of a preamble (blank, ``#`` comments or free text) allowed before the header."""
COMPILED_BYTES = 1 << 20
"""Files from this size on are read by the compiled reader (:mod:`.numbers`); below, ``np.loadtxt`` is quicker than
loading the compiled code (about a second)..."""
COMPILED_LOADED_BYTES = 1 << 16
"""...unless it is loaded already (a set's earlier, bigger file): then from this size on."""


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


def checked_series(
    source: str,
    t: np.ndarray,
    x: np.ndarray,
    force: np.ndarray,
    names: tuple[str, str, str] = COLUMNS,
    first_line: int = 2,
    unit: str = "line",
    units: tuple[str, str] | None = None,
) -> TimeSeries:
    """Reject NaN/inf (naming column and line) and time that does not increase; the arrays are kept as they are
    (contiguous float64: no copy of a big record's columns).

    ``first_line`` is the file line (or with ``unit`` "sample", the number) of the first sample, for the messages;
    ``units`` the displacement's and force's units as read (the checks of :mod:`hysid_model.slips` name them).
    """
    columns = [np.ascontiguousarray(a, dtype=float) for a in (t, x, force)]
    if columns[0].size < 4:
        raise HysidInputError(f"{source}: only {columns[0].size} samples; a record needs several cycles")
    bad = [int(np.argmin(np.isfinite(c))) if not np.isfinite(c).all() else None for c in columns]
    if any(b is not None for b in bad):
        row, col = min((b, k) for k, b in enumerate(bad) if b is not None)
        raise HysidInputError(f"{source}: {unit} {first_line + row}: {names[col]} is {columns[col][row]} (NaN and inf are not allowed)")
    t = columns[0]
    back = np.less_equal(t[1:], t[:-1])
    if back.any():
        k = int(np.argmax(back))
        raise HysidInputError(
            f"{source}: {unit} {first_line + k + 1}: {names[0]} does not increase ({float(t[k + 1])!r} after {float(t[k])!r}); time must be strictly increasing"
        )
    return TimeSeries(source, columns[0], columns[1], columns[2], names, units)


@dataclass
class Dialect:
    """How a CSV record is written: the header's line (0-based) and names, the separator (with ``;`` or a tab,
    numbers may have a decimal comma), the encoding, and the lines of free text skipped before the header (0-based;
    found by :func:`sniff`, not given by ``skip_rows``)."""

    header_line: int
    names: list[str]
    delimiter: str
    encoding: str
    skipped: tuple[tuple[int, str], ...] = ()
    data_header: int | None = None
    """The line right before the first rows of numbers, where the header of a file with a preamble would be."""

    def preamble_note(self) -> str | None:
        """What :func:`sniff` skipped, for a warning (None if nothing): the same words for every file of a set
        with the same preamble, so that they make one warning."""
        if not self.skipped:
            return None
        (first, text), count = self.skipped[0], len(self.skipped)
        return (
            f"skipped {count} line{'s' if count > 1 else ''} of free text before the header line {self.header_line + 1} "
            f"({self.delimiter.join(self.names)!r}), starting with line {first + 1} {_shown(text)}; "
            f"skip_rows = {self.header_line} in dataset.toml (or --skip-rows {self.header_line}) says so and keeps this quiet"
        )


def _shown(text: str, width: int = 40) -> str:
    text = text.strip()
    return repr(text if len(text) <= width else text[: width - 3] + "...")


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


def _separator(text: str) -> str:
    return ";" if ";" in text else ("\t" if "\t" in text else ",")


def _cells(text: str, delimiter: str) -> list[str]:
    return [c.strip() for c in text.rstrip("\r\n").split(delimiter)]


def _numeric(text: str) -> int:
    """The number of fields of a row of numbers (``;``/tab rows may use decimal commas), else 0."""
    delimiter = _separator(text)
    cells = _cells(text, delimiter)
    while len(cells) > 1 and not cells[-1]:  # a trailing separator, as spreadsheets write
        cells.pop()
    try:
        for cell in cells:
            float(cell.replace(",", ".") if delimiter != "," else cell)
    except ValueError:
        return 0
    return len(cells) if len(cells) >= 2 else 0


def _data_header(lines: list[str], content: list[int]) -> int | None:
    """The line before the first two rows of numbers with as many fields as it has (the header of a file whose
    header follows a preamble), else None."""
    for a in range(len(content) - 1):
        b = a + 1
        fields = _numeric(lines[content[b]])
        if fields and (b + 1 == len(content) or _numeric(lines[content[b + 1]]) == fields):
            header = lines[content[a]]
            if not _numeric(header) and len(_cells(header, _separator(header))) >= fields:
                return content[a]
            return None
    return None


def sniff(path: Path, skip_rows: int | None = None) -> Dialect:
    """The header and its separator (``;``, tab or ``,``).

    The header is the first line that is neither blank nor a ``#`` comment after the first ``skip_rows`` lines;
    without ``skip_rows``, a preamble of free text is skipped when the rows of numbers start under a later line
    with as many fields as they have and the first line has fewer (:attr:`Dialect.skipped` says what was skipped).
    """
    count = max(PREAMBLE_LINES, skip_rows or 0) + 4
    for encoding in ("utf-8-sig", "latin-1"):
        try:
            lines = _lines(path, encoding, count)
            break
        except UnicodeDecodeError:
            continue
    if skip_rows is not None and skip_rows >= len(lines):
        raise HysidInputError(f"{path}: skip_rows = {skip_rows} skips the whole file ({len(lines)} lines)")
    start = skip_rows or 0
    content = [k for k in range(start, min(len(lines), start + PREAMBLE_LINES + 3)) if lines[k].strip() and not lines[k].lstrip().startswith("#")]
    if not content or content[0] >= start + PREAMBLE_LINES:
        raise HysidInputError(f"{path}: the file is empty" if not "".join(lines).strip() else f"{path}: no header line (expected {','.join(COLUMNS)})")
    found = _data_header(lines, content)
    header = content[0]
    skipped: tuple[tuple[int, str], ...] = ()
    if (
        skip_rows is None
        and found is not None
        and found != header
        and len(_cells(lines[header], _separator(lines[found]))) < len(_cells(lines[found], _separator(lines[found])))
    ):
        skipped = tuple((k, lines[k]) for k in content if k < found)
        header = found
    text = lines[header].rstrip("\r\n")
    delimiter = _separator(text)
    names = [c.strip('"').strip() for c in _cells(text, delimiter)]
    return Dialect(header, names, delimiter, encoding, skipped, found)


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
                cell = cells[index].replace(",", ".") if dialect.delimiter != "," else cells[index]
                try:
                    float(cell)
                except ValueError:
                    return HysidInputError(f"{path}: line {number}: {name} {cells[index]!r} is not a number")
    return HysidInputError(f"{path}: could not be read as CSV numbers")


def _missing(path: Path, dialect: Dialect, missing: list[str]) -> HysidInputError:
    names = dialect.names
    hints = []
    for name in missing:
        close = difflib.get_close_matches(name, names, n=1, cutoff=0.5)
        hints.append(f"{name!r}" + (f" (found {close[0]!r})" if close else ""))
    rows = dialect.data_header
    skip = (
        f"; if lines {dialect.header_line + 1}-{rows} are a preamble, skip them: skip_rows = {rows} in dataset.toml or --skip-rows {rows}"
        if rows is not None and rows > dialect.header_line
        else "; a preamble before the header is skipped with skip_rows = <lines before it> in dataset.toml or --skip-rows"
    )
    return HysidInputError(
        f"{path}: missing column {', '.join(hints)}; expected columns {', '.join(COLUMNS)}, the header"
        f"{f' (line {dialect.header_line + 1})' if dialect.header_line else ''} has: "
        f"{', '.join(map(repr, names))} (names in any case, with a unit like displacement_mm or 'Displacement [mm]'; or name the "
        f"columns with time_channel, displacement_channel, force_channel in dataset.toml){skip}"
    )


def line_end(path: Path) -> bytes:
    """The byte that ends the lines of ``path``: ``\\n`` (also in ``\\r\\n`` endings, whose ``\\r`` the parsers
    take for a space), or ``\\r`` where no ``\\n`` follows it (lines as old Mac software and some DAQ exports
    end them), judged from the file's first lines."""
    with path.open("rb") as handle:
        head = handle.read(2 * MAX_LINE + 2)
    return b"\r" if b"\r" in head and b"\n" not in head else b"\n"


def first_long_line(path: Path) -> int | None:
    """The number of the first line longer than ``MAX_LINE`` bytes, else None: one pass over the bytes in
    chunks, because numpy's parser holds a whole line's fields at once (a 200 MB line would take GBs)."""
    line, start, offset, end = 1, 0, 0, line_end(path)[0]
    with path.open("rb") as handle:
        while chunk := handle.read(CHUNK):
            ends = np.flatnonzero(np.frombuffer(chunk, np.uint8) == end) + offset
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


def read_columns(path: Path, dialect: Dialect, usecols: list[int]) -> np.ndarray:
    """Columns ``usecols`` of the rows after the header as ``(len(usecols), rows)``, each column contiguous
    (with ``;`` or tab separators, decimal commas read as points). A file from ``COMPILED_BYTES`` on is parsed in
    chunks by the compiled reader (:mod:`.numbers`: its columns and one chunk in memory), a smaller one by
    ``np.loadtxt``, whose start is quicker (``COMPILED_LOADED_BYTES``); the numbers are the same."""
    used = [(i, dialect.names[i]) for i in usecols]
    size = path.stat().st_size
    if size >= COMPILED_BYTES or (size >= COMPILED_LOADED_BYTES and "hysid_model.readers.numbers" in sys.modules):
        from hysid_model.readers.numbers import read_numbers  # on first use: numba loads only when a big file is read

        return read_numbers(
            path,
            dialect.header_line + 1,
            dialect.delimiter,
            usecols,
            dialect.encoding,
            MAX_LINE,
            line_end(path),
            too_long=lambda line: HysidInputError(f"{path}: line {line} is longer than {MAX_LINE} characters; not a record of samples"),
            unreadable=lambda: _bad_line(path, dialect, used),
        )
    return np.ascontiguousarray(read_text_columns(path, dialect, usecols, float).T)


def read_text_columns(path: Path, dialect: Dialect, usecols: list[int], dtype: type = str) -> np.ndarray:
    """Columns ``usecols`` of the rows after the header as ``np.loadtxt`` reads them, ``(rows, len(usecols))``
    (the names of a tidy long file's records and channels; with ``;`` or tab separators, decimal commas as points)."""
    check_line_lengths(path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            if dialect.delimiter == ",":
                return np.loadtxt(
                    path,
                    delimiter=dialect.delimiter,
                    skiprows=dialect.header_line + 1,
                    usecols=usecols,
                    ndmin=2,
                    encoding=dialect.encoding,
                    dtype=dtype,
                    comments="#",
                )
            text = path.read_text(encoding=dialect.encoding).replace(",", ".")
            return np.loadtxt(
                io.StringIO(text), delimiter=dialect.delimiter, skiprows=dialect.header_line + 1, usecols=usecols, ndmin=2, dtype=dtype, comments="#"
            )
    except UnicodeDecodeError:
        raise HysidInputError(f"{path}: not UTF-8 text") from None
    except ValueError:
        raise _bad_line(path, dialect, [(i, dialect.names[i]) for i in usecols]) from None


def record_columns(path: Path, config: DatasetConfig | None, dialect: Dialect | None = None) -> tuple[Dialect, list[channels.Channel]]:
    """The dialect of a CSV record (``dialect`` if sniffed already) and its time, displacement and force columns; a
    header without them is an error (which :func:`hysid_model.readers.records.check_records` gathers for every file
    of a set)."""
    dialect = dialect or sniff(path, None if config is None else config.skip_rows)
    chosen = [channels.choose(dialect.names, q, config, str(path), required=False) for q in channels.QUANTITIES]
    missing = [channels.DEFAULT_NAMES[q] for q, c in zip(channels.QUANTITIES, chosen) if c is None]
    if missing:
        raise _missing(path, dialect, missing)
    return dialect, [c for c in chosen if c is not None]


def read_series(path: Path, config: DatasetConfig | None = None, dialect: Dialect | None = None) -> TimeSeries:
    """Read a raw record (``dialect`` if sniffed already); errors name the file, and the column/line where they can
    (see :mod:`.channels`). A preamble :func:`sniff` skipped is a warning naming it."""
    dialect, chosen = record_columns(path, config, dialect)
    note = dialect.preamble_note()
    if note is not None:  # something was skipped
        warnings.warn(HysidWarning(note, "preamble_skipped"), stacklevel=2)
    data = read_columns(path, dialect, [c.index for c in chosen])
    if data.shape[1] == 0:
        raise HysidInputError(f"{path}: the header is there but there are no data rows")
    for column, channel in zip(data, chosen):
        if channel.factor != 1.0:
            column *= channel.factor
    return checked_series(
        str(path),
        data[0],
        data[1],
        data[2],
        names=(chosen[0].name, chosen[1].name, chosen[2].name),
        first_line=dialect.header_line + 2,
        units=(chosen[1].unit, chosen[2].unit),
    )


def write_series(path: Path, t: np.ndarray, x: np.ndarray, force: np.ndarray) -> None:
    """Write a raw record (12 significant digits)."""
    np.savetxt(path, np.column_stack([t, x, force]), delimiter=",", fmt="%.12g", header=",".join(COLUMNS), comments="")
