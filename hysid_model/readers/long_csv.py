"""Many raw records in one tidy CSV file, keyed by a ``record`` column.

Long format (one row per sample and channel, as a database export or
``pandas.melt`` writes it)::

    record,time_s,channel,value,unit           (unit and frequency_hz optional)
    run1,0.0,displacement,0.12,mm
    run1,0.0,force,13.2,N
    ...

or one row per sample with the channels as columns::

    record,time_s,displacement_m,force_n,frequency_hz   (frequency_hz optional)

Channel names and units are matched as for a CSV record (:mod:`.channels`;
in the long format the channel names are the values of ``channel``, and a
``unit`` column states their units). A ``frequency_hz`` column gives each
record's nominal frequency (one value per record); else the record's name
(``..._12Hz``) or the data does. Separators, decimal commas and a ``#``
preamble are read as in :mod:`.csv_series`. Records keep the order in which
they first appear; a record's steady window in ``dataset.toml`` is a
``[[tests]]`` entry whose ``file`` is the record's name.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.readers import channels
from hysid_model.readers.csv_series import Dialect, TimeSeries, checked_series, read_columns, read_text_columns, sniff
from hysid_model.readers.dataset_dir import DatasetConfig

RECORD = "record"


@dataclass
class LongRecord:
    """One record of a tidy long file: its name, samples and nominal frequency (None: from the name or the data)."""

    label: str
    series: TimeSeries
    nominal_hz: float | None


def is_long_csv(dialect: Dialect) -> bool:
    return RECORD in (n.lower() for n in dialect.names)


def _column(dialect: Dialect, name: str) -> int | None:
    lower = [n.lower() for n in dialect.names]
    return lower.index(name) if name in lower else None


def _groups(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(distinct keys in order of first appearance, each row's group number in that order)."""
    unique, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    rank = np.empty(unique.size, dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(unique.size)
    return unique[np.argsort(first, kind="stable")], rank[inverse.reshape(-1)]


def _nominal(path: Path, label: str, values: np.ndarray) -> float | None:
    distinct = np.unique(values[np.isfinite(values)])
    if distinct.size > 1:
        raise HysidInputError(f"{path}: record {label!r} has {distinct.size} different frequency_hz values")
    if distinct.size == 1 and not distinct[0] > 0:
        raise HysidInputError(f"{path}: record {label!r}: frequency_hz {distinct[0]!r} is not a positive number")
    return float(distinct[0]) if distinct.size else None


def _record(
    path: Path, label: str, txf: tuple[np.ndarray, np.ndarray, np.ndarray], time: channels.Channel, picked: list[channels.Channel], freq: np.ndarray
) -> LongRecord:
    """Record ``label``'s time, displacement and force ``txf`` (in SI, time ascending), checked as one series, with its nominal frequency."""
    series = checked_series(
        f"{path} (record {label})", *txf, names=(time.name, picked[0].name, picked[1].name), unit="sample", first_line=1, units=(picked[0].unit, picked[1].unit)
    )
    return LongRecord(label, series, _nominal(path, label, freq))


def read_long(path: Path, config: DatasetConfig | None) -> list[LongRecord]:
    """The records of a tidy long CSV file (see the module docstring)."""
    dialect = sniff(path, None if config is None else config.skip_rows)
    where = str(path)
    record_col = _column(dialect, RECORD)
    if record_col is None:
        raise HysidInputError(f"{path}: no {RECORD!r} column; not a tidy file of several records")
    time = channels.choose(dialect.names, "time", config, where)
    freq_col = _column(dialect, "frequency_hz")
    labels_of_rows = read_text_columns(path, dialect, [record_col])[:, 0]
    if labels_of_rows.size == 0:
        raise HysidInputError(f"{path}: the header is there but there are no data rows")
    unique, row_record = _groups(labels_of_rows)
    labels = [str(label) for label in unique]
    del labels_of_rows
    rows_of = _rows_by_group(row_record, len(labels))
    freq = read_columns(path, dialect, [freq_col])[0] if freq_col is not None else np.full(row_record.size, math.nan)
    channel_col, value_col = _column(dialect, "channel"), _column(dialect, "value")
    if channel_col is not None and value_col is not None:
        return _long(path, dialect, config, labels, rows_of, freq, time, channel_col, value_col)
    picked = [channels.choose(dialect.names, q, config, where) for q in ("displacement", "force")]
    data = read_columns(path, dialect, [time.index] + [c.index for c in picked])
    out = []
    for label, rows in zip(labels, rows_of):
        t, x, force = data[0, rows] * time.factor, data[1, rows] * picked[0].factor, data[2, rows] * picked[1].factor
        order = np.argsort(t, kind="stable")
        out.append(_record(path, label, (t[order], x[order], force[order]), time, picked, freq[rows]))
    return out


def _rows_by_group(group: np.ndarray, n_groups: int) -> list[np.ndarray]:
    """The rows of each group, in file order."""
    order = np.argsort(group, kind="stable")
    return np.split(order, np.cumsum(np.bincount(group, minlength=n_groups))[:-1])


def _long(
    path: Path,
    dialect: Dialect,
    config: DatasetConfig | None,
    labels: list[str],
    rows_of: list[np.ndarray],
    freq: np.ndarray,
    time: channels.Channel,
    channel_col: int,
    value_col: int,
) -> list[LongRecord]:
    """Pivot the long format: per record, the displacement and force rows, each sorted by time."""
    where = str(path)
    names, row_channel = _groups(read_text_columns(path, dialect, [channel_col])[:, 0])
    unit_col = _column(dialect, "unit")
    units: list[str | None] = [None] * names.size
    if unit_col is not None:
        row_unit = read_text_columns(path, dialect, [unit_col])[:, 0]
        for k, name in enumerate(names):
            stated = np.unique(row_unit[row_channel == k])
            if stated.size > 1:
                raise HysidInputError(f"{path}: channel {name!r} is given in {stated.size} units ({', '.join(map(str, stated))})")
            units[k] = str(stated[0])
    picked = [channels.choose([str(n) for n in names], q, config, where, units) for q in ("displacement", "force")]
    data = read_columns(path, dialect, [time.index, value_col])
    out = []
    for label, mine in zip(labels, rows_of):
        parts = []
        for channel in picked:
            rows = mine[row_channel[mine] == channel.index]
            order = rows[np.argsort(data[0, rows], kind="stable")]
            parts.append((data[0, order] * time.factor, data[1, order] * channel.factor))
        (t, x), (t_f, force) = parts
        if t.size != t_f.size or not np.array_equal(t, t_f):
            raise HysidInputError(
                f"{path}: record {label!r}: {picked[0].name!r} and {picked[1].name!r} are not sampled at the same times ({t.size} and {t_f.size} samples)"
            )
        out.append(_record(path, label, (t, x, force), time, picked, freq[mine]))
    return out
