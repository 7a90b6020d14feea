"""Raw DAQ records as CSV: header ``time_s,displacement_m,force_n``, SI units, one row per sample."""

from __future__ import annotations

import difflib
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hysid_model.errors import HysidInputError

COLUMNS = ("time_s", "displacement_m", "force_n")


@dataclass
class TimeSeries:
    """One record in SI units: time (s, strictly increasing), displacement (m), force (N)."""

    source: str
    t: np.ndarray
    x: np.ndarray
    force: np.ndarray


def checked_series(source: str, t: np.ndarray, x: np.ndarray, force: np.ndarray, names: tuple[str, str, str] = COLUMNS, first_line: int = 2) -> TimeSeries:
    """Reject NaN/inf (naming column and line) and time that does not increase.

    ``first_line`` is the file line of the first sample, for the messages.
    """
    data = np.column_stack([t, x, force])
    if data.shape[0] < 4:
        raise HysidInputError(f"{source}: only {data.shape[0]} samples; a record needs several cycles")
    bad = ~np.isfinite(data)
    if np.any(bad):
        row, col = np.argwhere(bad)[0]
        raise HysidInputError(f"{source}: line {first_line + row}: {names[col]} is {data[row, col]} (NaN and inf are not allowed)")
    step = np.diff(data[:, 0])
    if np.any(step <= 0):
        k = int(np.flatnonzero(step <= 0)[0])
        raise HysidInputError(
            f"{source}: line {first_line + k + 1}: {names[0]} does not increase ({float(data[k + 1, 0])!r} after {float(data[k, 0])!r}); "
            "time must be strictly increasing"
        )
    return TimeSeries(source, data[:, 0].copy(), data[:, 1].copy(), data[:, 2].copy())


def _header(path: Path) -> list[str]:
    try:
        with path.open(encoding="utf-8-sig") as handle:
            first = handle.readline()
            rest = handle.read(1)
    except UnicodeDecodeError:
        raise HysidInputError(f"{path}: not UTF-8 text") from None
    if not first.strip():
        raise HysidInputError(f"{path}: the file is empty" if not rest else f"{path}: the first line must be the header {','.join(COLUMNS)}")
    return [c.strip() for c in first.strip().split(",")]


def _bad_line(path: Path, header: list[str]) -> HysidInputError:
    """The first line numpy could not parse, explained (only run once parsing has failed)."""
    with path.open(encoding="utf-8-sig") as handle:
        for number, line in enumerate(handle, start=1):
            if number == 1 or not line.strip():
                continue
            cells = [c.strip() for c in line.rstrip("\r\n").split(",")]
            if len(cells) != len(header):
                return HysidInputError(f"{path}: line {number}: {len(cells)} values for the {len(header)} columns of the header")
            for name in COLUMNS:
                cell = cells[header.index(name)]
                try:
                    float(cell)
                except ValueError:
                    return HysidInputError(f"{path}: line {number}: {name} {cell!r} is not a number")
    return HysidInputError(f"{path}: could not be read as CSV numbers")


def read_series(path: Path) -> TimeSeries:
    """Read a raw record; errors name the file, and the column/line where they can."""
    header = _header(path)
    missing = [c for c in COLUMNS if c not in header]
    if missing:
        hints = []
        for name in missing:
            close = difflib.get_close_matches(name, header, n=1, cutoff=0.5)
            hints.append(f"{name!r}" + (f" (found {close[0]!r})" if close else ""))
        raise HysidInputError(
            f"{path}: missing column {', '.join(hints)}; expected columns {', '.join(COLUMNS)}, found: {', '.join(header)}"
        )
    duplicated = sorted({c for c in COLUMNS if header.count(c) > 1})
    if duplicated:
        raise HysidInputError(f"{path}: column {', '.join(duplicated)} appears more than once in the header")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            data = np.loadtxt(path, delimiter=",", skiprows=1, usecols=[header.index(c) for c in COLUMNS], ndmin=2, encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise HysidInputError(f"{path}: not UTF-8 text") from None
    except ValueError:
        raise _bad_line(path, header) from None
    if data.shape[0] == 0:
        raise HysidInputError(f"{path}: the header is there but there are no data rows")
    return checked_series(str(path), data[:, 0], data[:, 1], data[:, 2])


def write_series(path: Path, t: np.ndarray, x: np.ndarray, force: np.ndarray) -> None:
    """Write a raw record (12 significant digits)."""
    np.savetxt(path, np.column_stack([t, x, force]), delimiter=",", fmt="%.12g", header=",".join(COLUMNS), comments="")
