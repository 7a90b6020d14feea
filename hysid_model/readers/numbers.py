"""The numbers of a CSV record, parsed in chunks by a compiled kernel into one array per column.

:func:`read_numbers` reads the rows after a record's header ``CHUNK`` bytes at a time: a first pass counts the
lines (so each column's array is allocated once, at its final size), a second parses each chunk of whole lines
with :func:`_parse_lines` (numba) straight into those arrays. Memory is the columns asked for, 8 bytes a value,
plus one chunk: never the file's text, nor numpy's row-by-row lists, nor a copy of the columns.

The kernel reads what ``np.loadtxt`` reads (blank lines and ``#`` comments skipped, spaces around fields, lines
ending in ``\\n``, ``\\r\\n`` or a bare ``\\r``, ``nan``/``inf``; with ``;`` or tab separators a decimal comma or point) and rounds exactly
as it does: a number of at most 19 significant digits whose digits fit in 2^53 and whose power of ten is
within 10^+-22 is one correctly rounded product or quotient (Clinger's fast path), which covers what DAQ
software writes (``%.6f``, ``%.12g``). A number it cannot round exactly (17-19 digits as Python's ``repr`` or
``%.18e`` write them, exponents beyond +-22) or a line it cannot read hands the rest of its chunk to
``np.loadtxt``, which also explains a bad line; the result is the same numbers either way.
"""

from __future__ import annotations

import io
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numba import njit

CHUNK = 1 << 22
"""Bytes parsed at once (4 MiB): the reader's memory beyond the columns themselves."""
_POW10 = np.array([10.0**k for k in range(23)])
_EXACT = 1 << 53
_MANTISSA_LIMIT = 10**18
OK, UNREAD, TOO_LONG = 0, 1, 2
"""Kernel statuses: every line read; a line it cannot read exactly (``np.loadtxt`` takes over); a line longer than
the limit."""


@njit(cache=True, nogil=True, inline="always")
def _space(byte: int, delimiter: int) -> bool:
    return byte == 32 or byte == 13 or (byte == 9 and delimiter != 9)


@njit(cache=True, nogil=True, inline="always")
def _word(buf: np.ndarray, p: int, end: int, word: bytes) -> bool:
    """Whether ``buf[p:]`` starts with ``word`` (lower-case ASCII), in any case."""
    if end - p < len(word):
        return False
    for k in range(len(word)):  # noqa: SIM110 (a numba kernel: no generator in all())
        if buf[p + k] | 32 != word[k]:
            return False
    return True


@njit(cache=True, nogil=True)
def _number(buf: np.ndarray, p: int, end: int, delimiter: int, comma: bool) -> tuple[float, int, bool]:
    """(value, position after it and its trailing spaces, exact) of the number at ``buf[p:end]``; not exact also
    for text that is no number (``np.loadtxt`` then decides)."""
    while p < end and _space(buf[p], delimiter):
        p += 1
    negative = False
    if p < end and (buf[p] == 45 or buf[p] == 43):
        negative = buf[p] == 45
        p += 1
    mantissa = np.uint64(0)
    exponent = 0
    digits = 0
    exact = True
    while p < end and 48 <= buf[p] <= 57:
        digits += 1
        if mantissa < _MANTISSA_LIMIT:
            mantissa = mantissa * np.uint64(10) + np.uint64(buf[p] - 48)
        else:
            exponent += 1
            exact = exact and buf[p] == 48
        p += 1
    if p < end and (buf[p] == 46 or (comma and buf[p] == 44)):
        p += 1
        while p < end and 48 <= buf[p] <= 57:
            digits += 1
            if mantissa < _MANTISSA_LIMIT:
                mantissa = mantissa * np.uint64(10) + np.uint64(buf[p] - 48)
                exponent -= 1
            else:
                exact = exact and buf[p] == 48
            p += 1
    value = 0.0
    if digits == 0:
        if _word(buf, p, end, b"nan"):
            value, p = np.nan, p + 3
        elif _word(buf, p, end, b"infinity"):
            value, p = np.inf, p + 8
        elif _word(buf, p, end, b"inf"):
            value, p = np.inf, p + 3
        else:
            return 0.0, p, False
    else:
        if p < end and (buf[p] == 101 or buf[p] == 69):
            p += 1
            sign = 1
            if p < end and (buf[p] == 45 or buf[p] == 43):
                sign = -1 if buf[p] == 45 else 1
                p += 1
            if p >= end or not 48 <= buf[p] <= 57:
                return 0.0, p, False
            power = 0
            while p < end and 48 <= buf[p] <= 57:
                if power < 100000:
                    power = power * 10 + (buf[p] - 48)
                p += 1
            exponent += sign * power
        if mantissa != 0:
            if mantissa > _EXACT or exponent > 22 or exponent < -22:
                return 0.0, p, False
            value = float(mantissa) * _POW10[exponent] if exponent >= 0 else float(mantissa) / _POW10[-exponent]
    while p < end and _space(buf[p], delimiter):
        p += 1
    return (-value if negative else value), p, exact


@njit(cache=True, nogil=True)
def _parse_lines(buf: np.ndarray, delimiter: int, comma: bool, target: np.ndarray, out: np.ndarray, row: int, max_line: int) -> tuple[int, int, int, int]:
    """Parse the whole lines of ``buf`` (each ending in ``\\n``, the last one may not) into ``out[:, row:]``:
    field j goes to ``out[target[j]]`` (-1: not read); fields beyond ``target`` are not read.

    Returns (next row, lines done, status, byte offset of the line it stopped at)."""
    n = buf.size
    fields = target.size
    i = 0
    line = 0
    while i < n:
        j = i
        while j < n and buf[j] != 10:
            j += 1
        if j - i > max_line:
            return row, line, TOO_LONG, i
        k = i
        while k < j and _space(buf[k], delimiter):
            k += 1
        if k < j and buf[k] != 35:
            if row >= out.shape[1]:
                return row, line, UNREAD, i
            field = 0
            while True:
                if target[field] >= 0:
                    value, k, exact = _number(buf, k, j, delimiter, comma)
                    if not exact or (k < j and buf[k] != delimiter and buf[k] != 35):
                        return row, line, UNREAD, i
                    out[target[field], row] = value
                else:
                    while k < j and buf[k] != delimiter and buf[k] != 35:
                        k += 1
                field += 1
                if field == fields:
                    break
                if k >= j or buf[k] != delimiter:
                    return row, line, UNREAD, i  # too few fields (or a comment cutting them short)
                k += 1
            row += 1
        i = j + 1
        line += 1
    return row, line, OK, n


def count_lines(path: Path, newline: bytes = b"\n") -> int:
    """Lines of a file whose lines end in ``newline`` (the last one counts without it), in chunks."""
    lines, last = 0, newline
    with path.open("rb") as handle:
        while chunk := handle.read(CHUNK):
            lines += chunk.count(newline)
            last = chunk[-1:]
    return lines + (last != newline)


def _read_line(handle: io.BufferedReader, newline: bytes, limit: int) -> bytes:
    """The next line of ``handle`` with the ``newline`` that ends it, at most ``limit`` bytes (``readline`` for
    lines ending in a bare ``\\r``)."""
    if newline == b"\n":
        return handle.readline(limit)
    line = b""
    while len(line) < limit and (ahead := handle.peek(1)[: limit - len(line)]):
        cut = ahead.find(newline)
        line += handle.read(len(ahead) if cut < 0 else cut + 1)
        if cut >= 0:
            break
    return line


def read_numbers(
    path: Path,
    skip_lines: int,
    delimiter: str,
    usecols: list[int],
    encoding: str,
    max_line: int,
    newline: bytes,
    too_long: Callable[[int], Exception],
    unreadable: Callable[[], Exception],
) -> np.ndarray:
    """Columns ``usecols`` of the lines after the first ``skip_lines``, as ``(len(usecols), rows)`` float64 (each
    column contiguous); decimal commas are read with ``;`` or tab separators. Lines end in ``newline``: ``\\n``
    (``\\r\\n`` too) or a bare ``\\r`` (each chunk's turned into ``\\n`` as it is read). ``too_long(line)`` is raised for
    a line longer than ``max_line`` bytes, ``unreadable()`` when ``np.loadtxt`` cannot read a chunk either."""
    fields = max(usecols) + 1
    target = np.full(fields, -1, dtype=np.int64)
    for k, col in enumerate(usecols):
        target[col] = k
    out = np.empty((len(usecols), max(count_lines(path, newline) - skip_lines, 0)))
    sep, comma = ord(delimiter), delimiter != ","
    row, line = 0, 1
    buf = bytearray(CHUNK + max_line + 1)  # a chunk after the start of a line that the last one cut
    view = memoryview(buf)
    with path.open("rb") as handle:
        for _ in range(skip_lines):
            if len(_read_line(handle, newline, max_line + 2)) > max_line + 1:
                raise too_long(line)
            line += 1
        filled = 0
        while True:
            got = handle.readinto(view[filled : filled + CHUNK])
            size = filled + got
            if newline != b"\n":
                buf[filled:size] = buf[filled:size].replace(newline, b"\n")
            end = buf.rfind(b"\n", 0, size) + 1 if got else size
            if end:
                row, done, status, at = _parse_lines(np.frombuffer(buf, np.uint8, count=end), sep, comma, target, out, row, max_line)
                if status == TOO_LONG:
                    raise too_long(line + done)
                if status == UNREAD:
                    row = _loadtxt_rest(bytes(view[at:end]), delimiter, usecols, encoding, out, row, unreadable)
                line += buf.count(b"\n", 0, end)
            if size - end > max_line:
                raise too_long(line)
            buf[: size - end] = bytes(view[end:size])
            filled = size - end
            if not got:
                break
    return out[:, :row]


def _loadtxt_rest(text: bytes, delimiter: str, usecols: list[int], encoding: str, out: np.ndarray, row: int, unreadable: Callable[[], Exception]) -> int:
    """``np.loadtxt`` of the lines the kernel left, into ``out[:, row:]``; returns the next row."""
    try:
        decoded = text.decode(encoding)
    except UnicodeDecodeError:
        raise unreadable() from None
    if delimiter != ",":
        decoded = decoded.replace(",", ".")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data": a chunk of comments
            data = np.loadtxt(io.StringIO(decoded), delimiter=delimiter, usecols=usecols, ndmin=2, comments="#")
    except ValueError:
        raise unreadable() from None
    if row + data.shape[0] > out.shape[1]:
        raise unreadable()
    out[:, row : row + data.shape[0]] = data.T
    return row + data.shape[0]
