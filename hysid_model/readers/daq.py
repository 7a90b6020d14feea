"""DAQ files: NI TDMS (``.tdms``, npTDMS) and HDF5 (``.h5``/``.hdf5``, h5py), one record per file or one per group.

Channels are TDMS channels (named ``group/channel``) or HDF5 datasets (named by
their path; the fields of a compound dataset are ``path/field``); a name in
``dataset.toml`` may leave out the group. They are mapped to time,
displacement and force as CSV columns are (:mod:`.channels`): by default
``time_s``, ``displacement_m``, ``force_n``, so a file with those channels
reads like a CSV record. Units: ``dataset.toml``, else the channel's own (TDMS
``unit_string``; HDF5 attribute ``units`` or ``unit``), else the name's suffix,
else SI. Without a time channel the time comes from the displacement channel's
waveform timing (TDMS ``wf_start_offset``/``wf_increment``; HDF5 attributes
``dt`` or ``sample_rate_hz``, and ``t0``, on the dataset or its group), else from
``sample_rate_hz`` in ``dataset.toml``.

Two layouts (README, "HDF5 and TDMS layouts"):

* one record per file: the channels anywhere in the file (``/time_s``,
  ``/Messung/Weg [mm]``, the fields of one compound dataset), as long as each
  quantity has one channel;
* one test per group: two or more groups (HDF5 groups at any depth, TDMS
  groups) each holding a displacement and a force channel of its own
  (``/run1/displacement_m``, ``/run1/force_n``, ``/run2/...``). Each group is a
  record named after the group (:func:`record_groups`: HDF5 groups in natural
  order of their names, TDMS groups in the file's order), read on its own when
  its loop is extracted; its nominal frequency is the group's ``frequency_hz``
  attribute (TDMS property), else the number in its name (``run_2Hz``), else
  the data's.

npTDMS and h5py are optional (``pip install 'hysid[daq]'``) and imported here only.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.readers import channels
from hysid_model.readers.csv_series import TimeSeries, checked_series
from hysid_model.readers.dataset_dir import DatasetConfig, natural_key

TDMS_SUFFIXES = (".tdms",)
HDF5_SUFFIXES = (".h5", ".hdf5")
EXTRA = "pip install 'hysid[daq]'"


@dataclass
class _Channels:
    """A file's channels: names, stated units, waveform timing (t0, dt) or None, the group each is in, a loader of
    the samples, and each group's nominal frequency attribute (None: not stated)."""

    names: list[str]
    units: list[str | None]
    timing: list[tuple[float, float] | None]
    groups: list[str]
    load: Callable[[int], Any]
    frequencies: dict[str, float | None]

    def of_group(self, group: str) -> _Channels:
        """The channels of one group only (numbered from 0 again, as ``dataset.toml`` counts a group's channels)."""
        keep = [i for i, g in enumerate(self.groups) if g == group]
        return _Channels(
            [self.names[i] for i in keep],
            [self.units[i] for i in keep],
            [self.timing[i] for i in keep],
            [group] * len(keep),
            lambda k: self.load(keep[k]),
            {group: self.frequencies.get(group)},
        )


def _text(value: Any) -> str | None:
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray) and value.size == 1:
        return _text(value.reshape(-1)[0])
    return value if isinstance(value, str) else None


def _number(value: Any) -> float | None:
    try:
        number = float(np.asarray(value).reshape(-1)[0])
    except (TypeError, ValueError, IndexError):
        return None
    return number if np.isfinite(number) else None


def _optional(module: str, package: str, kind: str, path: Path) -> Any:
    """The optional ``module`` (pip package ``package``) that reads ``kind`` files such as ``path``; where it is not
    installed, a one-line error naming the extra that brings it."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise HysidInputError(f"{path}: reading {kind} files needs {package}: {EXTRA}") from None


@contextmanager
def _tdms(path: Path) -> Iterator[_Channels]:
    nptdms = _optional("nptdms", "npTDMS", "TDMS", path)
    try:
        tdms = nptdms.TdmsFile.open(path)  # the channels' data are read when asked for, one channel at a time
    except Exception as exc:  # npTDMS raises many types on a damaged file
        raise HysidInputError(f"{path}: not a readable TDMS file ({type(exc).__name__})") from None
    with tdms:
        found = [(group.name, channel) for group in tdms.groups() for channel in group.channels()]
        timing = []
        for _, channel in found:
            props = channel.properties
            dt = _number(props.get("wf_increment"))
            timing.append((_number(props.get("wf_start_offset")) or 0.0, dt) if dt else None)

        def load(i: int) -> Any:
            try:
                return found[i][1][:]
            except Exception as exc:  # a file cut short: npTDMS raises many types
                raise HysidInputError(f"{path}: channel {found[i][0]}/{found[i][1].name} cannot be read ({type(exc).__name__})") from None

        yield _Channels(
            names=[f"{group}/{channel.name}" for group, channel in found],
            units=[_text(channel.properties.get("unit_string")) for _, channel in found],
            timing=timing,
            groups=[group for group, _ in found],
            load=load,
            frequencies={group.name: _number(group.properties.get("frequency_hz")) for group in tdms.groups()},
        )


@contextmanager
def _hdf5(path: Path) -> Iterator[_Channels]:
    h5py = _optional("h5py", "h5py", "HDF5", path)
    try:
        handle = h5py.File(path, "r")
    except OSError:
        raise HysidInputError(f"{path}: not a readable HDF5 file") from None
    entries: list[tuple[str, Any, str | None]] = []

    def visit(name: str, obj: Any) -> None:
        if isinstance(obj, h5py.Dataset) and obj.ndim == 1:
            fields = obj.dtype.names or (None,)
            entries.extend((name if f is None else f"{name}/{f}", obj, f) for f in fields)

    handle.visititems(visit)
    timing = [_hdf5_timing(ds.attrs) or _hdf5_timing(ds.parent.attrs) for _, ds, _ in entries]
    groups = [ds.parent.name.strip("/") for _, ds, _ in entries]

    def load(i: int) -> Any:
        _, ds, field = entries[i]
        return ds[()] if field is None else ds[field]

    with handle:
        yield _Channels(
            names=[name for name, _, _ in entries],
            units=[_text(ds.attrs.get("units", ds.attrs.get("unit"))) for _, ds, _ in entries],
            timing=timing,
            groups=groups,
            load=load,
            frequencies={g: _number(handle[g or "/"].attrs.get("frequency_hz")) for g in set(groups)},
        )


def _hdf5_timing(attrs: Any) -> tuple[float, float] | None:
    """(t0, dt) from the attributes ``dt`` or ``sample_rate_hz`` (``sample_rate``) and ``t0``, else None."""
    dt = _number(attrs.get("dt"))
    rate = _number(attrs.get("sample_rate_hz", attrs.get("sample_rate")))
    dt = dt or (1.0 / rate if rate else None)
    return (_number(attrs.get("t0")) or 0.0, dt) if dt and dt > 0 else None


def _samples(path: Path, found: _Channels, channel: channels.Channel) -> np.ndarray:
    data = np.asarray(found.load(channel.index))
    if np.iscomplexobj(data):
        raise HysidInputError(f"{path}: channel {channel.name!r} holds complex numbers; a record needs real samples")
    if data.dtype.kind not in "biuf":
        raise HysidInputError(f"{path}: channel {channel.name!r} holds {data.dtype} values, not numbers")
    return data.astype(float) * channel.factor


def _opened(path: Path) -> Any:
    return (_tdms if path.suffix.lower() in TDMS_SUFFIXES else _hdf5)(path)


@dataclass(frozen=True)
class GroupRecord:
    """One test of a file of one group per test: its group and nominal frequency (None: from the data)."""

    group: str
    nominal_hz: float | None


def record_groups(path: Path, config: DatasetConfig) -> list[GroupRecord]:
    """The tests of a file of one group per test (module docstring): a TDMS file's in its order, an HDF5 file's in
    natural order of their names (``run2`` before ``run10``; HDF5 lists them by name); [] for a file that is one
    record. Only the channels' names and attributes are read."""
    with _opened(path) as found:
        groups = list(dict.fromkeys(found.groups))
        if path.suffix.lower() in HDF5_SUFFIXES:
            groups.sort(key=natural_key)
        if len(groups) < 2:
            return []
        whole = [g for g in groups if _holds_record(found.of_group(g), config, f"{path}: group {g!r}")]
        if len(whole) < 2:
            return []
        return [GroupRecord(g, found.frequencies.get(g)) for g in whole]


def _holds_record(found: _Channels, config: DatasetConfig, source: str) -> bool:
    try:
        return all(channels.choose(found.names, q, config, source, found.units, required=False) is not None for q in ("displacement", "force"))
    except HysidInputError:  # two displacement channels in one group: not a test of its own
        return False


def check_daq(path: Path, config: DatasetConfig, group: str | None = None) -> None:
    """The checks of :func:`read_daq` that need no samples: the channels of displacement, force and time."""
    with _opened(path) as found:
        _chosen(path, found if group is None else found.of_group(group), config, _source(path, group))


def read_daq(path: Path, config: DatasetConfig, group: str | None = None) -> TimeSeries:
    """Read one TDMS or HDF5 record (the file's, or one group's: :func:`record_groups`) as (t in s, x in m, F in N)."""
    with _opened(path) as found:
        return _record(path, found if group is None else found.of_group(group), config, _source(path, group))


def _source(path: Path, group: str | None) -> str:
    return str(path) if group is None else f"{path} (group {group})"


def _chosen(path: Path, found: _Channels, config: DatasetConfig, source: str) -> tuple[channels.Channel, channels.Channel, channels.Channel | None]:
    if not found.names:
        raise HysidInputError(f"{source}: holds no channels")
    x_ch = channels.choose(found.names, "displacement", config, source, found.units)
    f_ch = channels.choose(found.names, "force", config, source, found.units)
    return x_ch, f_ch, channels.choose(found.names, "time", config, source, found.units, required=False)


def _record(path: Path, found: _Channels, config: DatasetConfig, source: str) -> TimeSeries:
    x_ch, f_ch, t_ch = _chosen(path, found, config, source)
    x, force = _samples(path, found, x_ch), _samples(path, found, f_ch)
    if t_ch is not None:
        t = _samples(path, found, t_ch)
    elif (timing := found.timing[x_ch.index]) is not None:
        start, dt = timing
        t = start + dt * np.arange(x.size)
    elif config.sample_rate_hz is not None:
        t = np.arange(x.size) / config.sample_rate_hz
    else:
        raise HysidInputError(
            f"{source}: no time channel (time_s or time_channel) and no sample interval on {x_ch.name!r}; "
            f"set sample_rate_hz in {config.directory / 'dataset.toml'}"
        )
    if not t.size == x.size == force.size:
        raise HysidInputError(
            f"{source}: channels of different lengths: {t.size} time, {x.size} displacement ({x_ch.name!r}), {force.size} force ({f_ch.name!r})"
        )
    return checked_series(
        source, t, x, force, names=(t_ch.name if t_ch else "time", x_ch.name, f_ch.name), first_line=0, unit="sample", units=(x_ch.unit, f_ch.unit)
    )
