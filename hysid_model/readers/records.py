"""The raw records of a dataset: which files, in which order, at which nominal frequency, read how.

A record is a ``.csv`` (:mod:`.csv_series`), ``.lvm`` (:mod:`.lvm`),
``.tdms`` or ``.h5``/``.hdf5`` (:mod:`.daq`) file, or one record of a file
holding several: a tidy long CSV (:mod:`.long_csv`), a TDMS or HDF5 file of one
group per test (:func:`~.daq.record_groups`). They come from ``manifest.csv``
(its order and frequencies), or, without one, from the files of the
directory in natural order (``run2`` before ``run10``) with frequencies from
their names (``..._12Hz``) or, failing that, from the data. Every file must lie
inside the dataset directory (:func:`~.dataset_dir.confined`). The headers and
channels of every record are checked before any record is read
(:func:`check_records`), so that the mistakes of several files come in one error.
"""

from __future__ import annotations

import csv
import io
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path

from hysid_model.errors import HysidInputError, HysidWarning
from hysid_model.readers import channels
from hysid_model.readers.csv_series import Dialect, TimeSeries, read_series, record_columns, sniff
from hysid_model.readers.daq import HDF5_SUFFIXES, TDMS_SUFFIXES, check_daq, read_daq, record_groups
from hysid_model.readers.dataset_dir import DatasetConfig, ManifestRow, frequency_in_name, inside, natural_key
from hysid_model.readers.long_csv import is_long_csv, read_long
from hysid_model.readers.lvm import read_lvm

RAW_SUFFIXES = (".csv", ".lvm") + TDMS_SUFFIXES + HDF5_SUFFIXES
SET_BYTES = 16 << 20
"""CSV records adding up to this many bytes are all read by the compiled reader (:func:`load_compiled_reader`)."""


@dataclass
class RawSource:
    """One record to extract: its label, its file (relative to the dataset directory), the nominal frequency
    (None: from the data), and how to read it (called once, when its loop is extracted)."""

    label: str
    file: str
    path: Path
    nominal_hz: float | None
    read: Callable[[], TimeSeries]
    check: Callable[[], object] | None = None
    """The checks of ``read`` that need no samples (header, channels), or None."""

    @property
    def whole_file(self) -> bool:
        """True for a record that is a file of its own (not one of a tidy long file's)."""
        return self.label == self.path.stem

    @property
    def window_key(self) -> str:
        """The name its ``[[tests]]`` entry in ``dataset.toml`` uses: the file's, or a long file's record name."""
        return self.file if self.whole_file else self.label


def _given(series: TimeSeries) -> Callable[[], TimeSeries]:
    """A reader of a record read already (a tidy long file's records come all at once)."""
    return lambda: series


def read_record(path: Path, config: DatasetConfig, dialect: Dialect | None = None) -> TimeSeries:
    """One record file as (t in s, x in m, F in N) (a CSV file's ``dialect`` if sniffed already)."""
    if path.stat().st_size == 0:
        raise HysidInputError(f"{path}: the file is empty")
    suffix = path.suffix.lower()
    if suffix == ".lvm":
        return read_lvm(path, config)
    if suffix in TDMS_SUFFIXES + HDF5_SUFFIXES:
        return read_daq(path, config)
    return read_series(path, config, dialect)


def sources_of_file(path: Path, config: DatasetConfig, nominal_hz: float | None, name: str | None = None) -> list[RawSource]:
    """The records of one file: a tidy long CSV holds several, so does a TDMS or HDF5 file of one group per test;
    any other file one."""
    name = name or path.name
    suffix = path.suffix.lower()
    empty = path.stat().st_size == 0
    dialect = sniff(path, config.skip_rows) if suffix == ".csv" and not empty else None
    if dialect is not None and is_long_csv(dialect):
        return [
            RawSource(r.label, name, path, r.nominal_hz if r.nominal_hz is not None else frequency_in_name(r.label), _given(r.series))
            for r in read_long(path, config)
        ]
    if suffix in TDMS_SUFFIXES + HDF5_SUFFIXES and not empty:
        groups = record_groups(path, config)
        if groups:
            return [
                RawSource(
                    g.group,
                    name,
                    path,
                    g.nominal_hz if g.nominal_hz is not None else frequency_in_name(g.group),
                    partial(read_daq, path, config, g.group),
                    partial(check_daq, path, config, g.group),
                )
                for g in groups
            ]
    check: Callable[[], object] | None = None
    if dialect is not None:
        check = lambda: record_columns(path, config, dialect)
    elif suffix in TDMS_SUFFIXES + HDF5_SUFFIXES and not empty:
        check = lambda: check_daq(path, config)
    return [RawSource(path.stem, name, path, nominal_hz, lambda: read_record(path, config, dialect), check)]


def check_records(sources: list[RawSource], where: str) -> None:
    """Check every record's header and channels before any is read: one error names every file whose record
    cannot be read (files with the same mistake together), not one file per run. What it would warn, reading
    each record warns again."""
    problems: dict[str, list[str]] = {}
    errors = []
    for source in sources:
        if source.check is None:
            continue
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", HysidWarning)
                source.check()
        except HysidInputError as exc:
            errors.append(exc)
            name = source.file if source.whole_file else f"{source.file} (group {source.label})"
            detail = str(exc).removeprefix(f"{source.path} (group {source.label})").removeprefix(str(source.path))
            problems.setdefault(detail.removeprefix(": "), []).append(name)
    if len(errors) == 1:
        raise errors[0]
    if errors:
        listed = "; ".join(f"{', '.join(files)}: {detail}" for detail, files in problems.items())
        raise HysidInputError(f"{where}: {len(errors)} of {len(sources)} records cannot be read: {listed}")


def load_compiled_reader(sources: list[RawSource]) -> None:
    """Load the compiled CSV reader for a set whose CSV records add up to ``SET_BYTES``: loading its code takes
    about 0.6 s of CPU, which the parse of that many bytes pays back, and once loaded it reads every file from
    :data:`~.csv_series.COMPILED_LOADED_BYTES` on (a set of many small files, such as 50 of 0.5 MB)."""
    files = {s.path for s in sources if s.path.suffix.lower() == ".csv"}
    if sum(path.stat().st_size for path in files) >= SET_BYTES:
        from hysid_model.readers import numbers  # noqa: F401  (on first use: numba loads only for a big set)


def is_record_csv(path: Path, config: DatasetConfig) -> bool:
    """Whether a ``.csv`` file holds raw records (time, displacement and force columns, or a ``record`` column)."""
    try:
        dialect = sniff(path, config.skip_rows)
        return is_long_csv(dialect) or all(channels.choose(dialect.names, q, config, str(path), required=False) is not None for q in channels.QUANTITIES)
    except HysidInputError:
        return False


def manifest_sources(manifest: Path, rows: list[ManifestRow], files: list[Path], config: DatasetConfig) -> list[RawSource]:
    """The records ``manifest.csv`` lists (one per row)."""
    out = []
    for row, path in zip(rows, files):
        found = sources_of_file(path, config, row.frequency_hz, row.file)
        if len(found) != 1:
            raise HysidInputError(
                f"{manifest}: line {row.line}: {row.file!r} holds {len(found)} records; a file of several records (a tidy long CSV, "
                "a TDMS or HDF5 file of one group per test) is read without a manifest: load it alone, or a folder without manifest.csv"
            )
        out.append(found[0])
    return out


def directory_sources(directory: Path, config: DatasetConfig) -> list[RawSource]:
    """The records of a directory without ``manifest.csv``: every record file in natural order; ``.csv`` files
    that hold no records are left out with a warning."""
    candidates = sorted((p for p in directory.iterdir() if p.suffix.lower() in RAW_SUFFIXES and p.is_file()), key=lambda p: natural_key(p.name))
    outside = [p.name for p in candidates if not inside(directory, p)]
    if outside:
        raise HysidInputError(f"{directory}: {outside[0]!r} links outside the dataset directory; copy the file in")
    skipped = [p.name for p in candidates if p.suffix.lower() == ".csv" and not is_record_csv(p, config)]
    if skipped:
        warnings.warn(
            HysidWarning(
                f"{directory}: left out {', '.join(skipped)}: no time, displacement and force columns (nor a record column)"
                + ("" if config.skip_rows is None else f" in the header after skip_rows = {config.skip_rows} lines"),
                "records_left_out",
            ),
            stacklevel=3,
        )
    out = []
    for path in candidates:
        if path.name not in skipped:
            out.extend(sources_of_file(path, config, frequency_in_name(path.stem)))
    return out


def manifest_text(sources: list[RawSource], frequencies: list[float]) -> str:
    """The ``manifest.csv`` of these records at these frequencies (one row per file record)."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")  # a name holding a comma is quoted
    writer.writerows([("file", "frequency_hz")] + [(s.file, f"{f:.6g}") for s, f in zip(sources, frequencies)])
    return out.getvalue()
