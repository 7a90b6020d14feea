"""DAQ files: NI TDMS (``.tdms``, npTDMS) and HDF5 (``.h5``/``.hdf5``, h5py), one record per file.

Channels are TDMS channels (named ``group/channel``) or HDF5 datasets (named by
their path; the fields of a compound dataset are ``path/field``); a name in
``dataset.toml`` may leave out the group. They are mapped to time,
displacement and force as CSV columns are (:mod:`.channels`): by default
``time_s``, ``displacement_m``, ``force_n``, so a file with those channels
reads like a CSV record. Units: ``dataset.toml``, else the channel's own (TDMS
``unit_string``; HDF5 attribute ``units`` or ``unit``), else the name's suffix,
else SI. Without a time channel the time comes from the displacement channel's
waveform timing (TDMS ``wf_start_offset``/``wf_increment``; HDF5 attributes
``dt`` or ``sample_rate_hz``, and ``t0``), else from ``sample_rate_hz`` in
``dataset.toml``.

npTDMS and h5py are optional (``pip install 'hysid[daq]'``) and imported here only.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.readers import channels
from hysid_model.readers.csv_series import TimeSeries, checked_series
from hysid_model.readers.dataset_dir import DatasetConfig

TDMS_SUFFIXES = (".tdms",)
HDF5_SUFFIXES = (".h5", ".hdf5")
EXTRA = "pip install 'hysid[daq]'"


@dataclass
class _Channels:
    """A file's channels: names, stated units, waveform timing (t0, dt) or None, and a loader of the samples."""

    names: list[str]
    units: list[str | None]
    timing: list[tuple[float, float] | None]
    load: Callable[[int], Any]


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


@contextmanager
def _tdms(path: Path) -> Iterator[_Channels]:
    try:
        from nptdms import TdmsFile
    except ImportError:
        raise HysidInputError(f"{path}: reading TDMS files needs npTDMS: {EXTRA}") from None
    try:
        tdms = TdmsFile.read(path)
    except Exception as exc:  # npTDMS raises many types on a damaged file
        raise HysidInputError(f"{path}: not a readable TDMS file ({type(exc).__name__})") from None
    found = [(group.name, channel) for group in tdms.groups() for channel in group.channels()]
    timing = []
    for _, channel in found:
        props = channel.properties
        dt = _number(props.get("wf_increment"))
        timing.append((_number(props.get("wf_start_offset")) or 0.0, dt) if dt else None)
    yield _Channels(
        names=[f"{group}/{channel.name}" for group, channel in found],
        units=[_text(channel.properties.get("unit_string")) for _, channel in found],
        timing=timing,
        load=lambda i: found[i][1][:],
    )


@contextmanager
def _hdf5(path: Path) -> Iterator[_Channels]:
    try:
        import h5py
    except ImportError:
        raise HysidInputError(f"{path}: reading HDF5 files needs h5py: {EXTRA}") from None
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
    timing = []
    for _, ds, _ in entries:
        attrs = ds.attrs
        dt = _number(attrs.get("dt"))
        rate = _number(attrs.get("sample_rate_hz", attrs.get("sample_rate")))
        dt = dt or (1.0 / rate if rate else None)
        timing.append((_number(attrs.get("t0")) or 0.0, dt) if dt and dt > 0 else None)

    def load(i: int) -> Any:
        _, ds, field = entries[i]
        return ds[()] if field is None else ds[field]

    with handle:
        yield _Channels(
            names=[name for name, _, _ in entries],
            units=[_text(ds.attrs.get("units", ds.attrs.get("unit"))) for _, ds, _ in entries],
            timing=timing,
            load=load,
        )


def _samples(path: Path, found: _Channels, channel: channels.Channel) -> np.ndarray:
    data = np.asarray(found.load(channel.index))
    if np.iscomplexobj(data):
        raise HysidInputError(f"{path}: channel {channel.name!r} holds complex numbers; a record needs real samples")
    if data.dtype.kind not in "biuf":
        raise HysidInputError(f"{path}: channel {channel.name!r} holds {data.dtype} values, not numbers")
    return data.astype(float) * channel.factor


def read_daq(path: Path, config: DatasetConfig) -> TimeSeries:
    """Read one TDMS or HDF5 record as (t in s, x in m, F in N)."""
    with (_tdms if path.suffix.lower() in TDMS_SUFFIXES else _hdf5)(path) as found:
        return _record(path, found, config)


def _record(path: Path, found: _Channels, config: DatasetConfig) -> TimeSeries:
    source = str(path)
    if not found.names:
        raise HysidInputError(f"{path}: holds no channels")
    x_ch = channels.choose(found.names, "displacement", config, source, found.units)
    f_ch = channels.choose(found.names, "force", config, source, found.units)
    t_ch = channels.choose(found.names, "time", config, source, found.units, required=False)
    x, force = _samples(path, found, x_ch), _samples(path, found, f_ch)
    if t_ch is not None:
        t = _samples(path, found, t_ch)
    elif found.timing[x_ch.index] is not None:
        start, dt = found.timing[x_ch.index]
        t = start + dt * np.arange(x.size)
    elif config.sample_rate_hz is not None:
        t = np.arange(x.size) / config.sample_rate_hz
    else:
        raise HysidInputError(
            f"{path}: no time channel (time_s or time_channel) and no sample interval on {x_ch.name!r}; "
            f"set sample_rate_hz in {config.directory / 'dataset.toml'}"
        )
    if not t.size == x.size == force.size:
        raise HysidInputError(
            f"{path}: channels of different lengths: {t.size} time, {x.size} displacement ({x_ch.name!r}), {force.size} force ({f_ch.name!r})"
        )
    return checked_series(source, t, x, force, names=(t_ch.name if t_ch else "time", x_ch.name, f_ch.name), first_line=0, unit="sample",
                          units=(x_ch.unit, f_ch.unit))
