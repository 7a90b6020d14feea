"""LabVIEW measurement files (``.lvm``), read into SI time series.

Two forms:

* the headerless numeric export of the thesis' rig, read there with MATLAB
  ``load TRAC<i>.lvm`` (Appendix A, ``PrepareExpData``): one row per sample,
  column 1 displacement in mm, column 2 force in N, no time column. The
  sample rate must come from ``dataset.toml`` (``sample_rate_hz``); other
  columns/units via ``displacement_channel``/``force_channel`` (numbers) and
  ``displacement_unit``/``force_unit``.
* the standard LVM text: a ``LabVIEW Measurement`` file header and, per
  segment, a header (``Channels``, ``Samples``, ``X0``, ``Delta_X``,
  ``Y_Unit_Label`` ...) closed by ``***End_of_Header***``, a column line
  (``X_Value``, channel names, ``Comment``) and the data. Time is the
  ``X_Value`` column (``X_Columns`` One or Multi) or ``X0 + k Delta_X``
  (``X_Columns`` No). Channels are found by name (one containing "disp" or
  "position", one containing "force" or "load") unless ``dataset.toml``
  names them or gives their numbers. Units: ``dataset.toml``, else the
  channel's ``Y_Unit_Label`` when it is a length/force unit, else SI.
"""

from __future__ import annotations

import io
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.readers.channels import UNIT_ALIASES
from hysid_model.readers.csv_series import TimeSeries, check_line_lengths, checked_series
from hysid_model.readers.dataset_dir import DISPLACEMENT_UNITS, FORCE_UNITS, DatasetConfig

END_OF_HEADER = "***End_of_Header***"
DISPLACEMENT_NAMES = ("disp", "position")
FORCE_NAMES = ("force", "load")


@dataclass
class _Segment:
    header: dict[str, list[str]] = field(default_factory=dict)
    columns: list[str] = field(default_factory=list)
    first_line: int = 0
    lines: list[str] = field(default_factory=list)


def read_lvm(path: Path, config: DatasetConfig) -> TimeSeries:
    """Read one ``.lvm`` record as (t in s, x in m, F in N)."""
    check_line_lengths(path)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        text = path.read_text(encoding="latin-1")
    if not text.strip():
        raise HysidInputError(f"{path}: the file is empty")
    if text.lstrip().startswith("LabVIEW Measurement"):
        return _read_standard(path, text, config)
    return _read_headerless(path, text, config)


def _scale(unit: str | None, table: dict[str, float], default: str) -> float:
    return table[unit if unit is not None else default]


def _read_headerless(path: Path, text: str, config: DatasetConfig) -> TimeSeries:
    if config.sample_rate_hz is None:
        raise HysidInputError(f"{path}: a headerless .lvm has no time column; set sample_rate_hz in {config.directory / 'dataset.toml'}")
    columns = []
    for key, value, default in (("displacement_channel", config.displacement_channel, 1), ("force_channel", config.force_channel, 2)):
        if isinstance(value, str):
            raise HysidInputError(f"{path}: a headerless .lvm has no channel names; give {key} as a column number (1 = first)")
        columns.append((value or default) - 1)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            data = np.loadtxt(io.StringIO(text.replace(",", " ")), ndmin=2)
    except ValueError:
        raise HysidInputError(f"{path}: not a LabVIEW measurement file (no 'LabVIEW Measurement' header) and not a table of numbers") from None
    if data.shape[1] <= max(columns):
        raise HysidInputError(f"{path}: has {data.shape[1]} columns, column {max(columns) + 1} is needed (displacement_channel/force_channel)")
    x = data[:, columns[0]] * _scale(config.displacement_unit, DISPLACEMENT_UNITS, "mm")
    force = data[:, columns[1]] * _scale(config.force_unit, FORCE_UNITS, "N")
    t = np.arange(data.shape[0]) / config.sample_rate_hz
    return checked_series(str(path), t, x, force, names=("time", "displacement", "force"), first_line=1)


def _segments(path: Path, lines: list[str], k: int, sep: str) -> list[_Segment]:
    """Split the lines from ``k`` (after the file header) into segments: header rows, column names, data lines."""
    segments: list[_Segment] = []
    while k < len(lines):
        if not lines[k].strip(sep + " \r"):
            k += 1
            continue
        seg = _Segment()
        while k < len(lines) and not lines[k].startswith(END_OF_HEADER):
            cells = lines[k].rstrip("\r").split(sep)
            if cells[0]:
                seg.header[cells[0].strip()] = [c.strip() for c in cells[1:]]
            k += 1
        if k == len(lines):
            raise HysidInputError(f"{path}: a segment header has no closing {END_OF_HEADER}")
        k += 1
        if k < len(lines) and lines[k].startswith("X_Value"):
            seg.columns = [c.strip() for c in lines[k].rstrip("\r").split(sep)]
            k += 1
        seg.first_line = k + 1
        while k < len(lines) and lines[k].strip(sep + " \r") and not lines[k][:1].isalpha():
            seg.lines.append(lines[k])
            k += 1
        segments.append(seg)
    return segments


def _channel_columns(path: Path, seg: _Segment, x_columns: str) -> tuple[list[str], list[int]]:
    """Channel names and their column indices in the data lines."""
    n_channels = int(_header_number(path, "Channels", seg.header.get("Channels", ["0"])[0] or "0", "."))
    if seg.columns:
        idx = [i for i, name in enumerate(seg.columns) if name not in ("X_Value", "Comment")]
        return [seg.columns[i] for i in idx], idx
    if n_channels == 0:
        raise HysidInputError(f"{path}: the segment header gives no channel count and there is no X_Value column line")
    names = [f"channel {i + 1}" for i in range(n_channels)]
    return names, ([2 * i + 1 for i in range(n_channels)] if x_columns == "Multi" else [i + 1 for i in range(n_channels)])


def _header_number(path: Path, key: str, text: str, decimal: str) -> float:
    try:
        return float(text.replace(decimal, "."))
    except ValueError:
        raise HysidInputError(f"{path}: segment header {key} {text!r} is not a number") from None


def _cell(seg: _Segment, key: str, channel: int, x_columns: str) -> str:
    """A segment-header entry of one channel (with X_Columns Multi every channel takes two cells)."""
    row = seg.header.get(key, [])
    k = 2 * channel if x_columns == "Multi" else channel
    return row[k] if k < len(row) else ""


def _pick(path: Path, names: list[str], chosen: str | int | None, key: str, words: tuple[str, ...]) -> int:
    """Index (into ``names``) of the displacement or force channel."""
    listing = ", ".join(repr(n) for n in names)
    if isinstance(chosen, int):
        if chosen > len(names):
            raise HysidInputError(f"{path}: {key} = {chosen} but the file has {len(names)} channels ({listing})")
        return chosen - 1
    if isinstance(chosen, str):
        matches = [i for i, n in enumerate(names) if n.lower() == chosen.lower()]
        if not matches:
            raise HysidInputError(f"{path}: no channel named {chosen!r} ({key}); channels: {listing}")
        return matches[0]
    matches = [i for i, n in enumerate(names) if any(w in n.lower() for w in words)]
    if len(matches) != 1:
        found = "no" if not matches else f"{len(matches)}"
        raise HysidInputError(
            f"{path}: {found} channel names contain {' or '.join(repr(w) for w in words)} (channels: {listing}); set {key} (name or number) in dataset.toml"
        )
    return matches[0]


def _unit_factor(path: Path, configured: str | None, label: str, table: dict[str, float], key: str) -> float:
    if configured is not None:
        return table[configured]
    if not label:
        return 1.0
    unit = UNIT_ALIASES.get(label.strip().lower())
    if unit is None or unit not in table:
        raise HysidInputError(f"{path}: channel unit {label!r} is not a {key.split('_')[0]} unit; set {key} in dataset.toml")
    return table[unit]


def _read_standard(path: Path, text: str, config: DatasetConfig) -> TimeSeries:
    lines = text.splitlines()
    end = next((k for k, line in enumerate(lines) if line.startswith(END_OF_HEADER)), None)
    if end is None:
        raise HysidInputError(f"{path}: the file header has no closing {END_OF_HEADER}")
    sep_line = next((line for line in lines[1:end] if line.startswith("Separator")), "Separator\tTab")
    sep = sep_line[len("Separator") : len("Separator") + 1]
    if sep not in ("\t", ",") or sep_line[len("Separator") + 1 :].split(sep)[0].strip() != {"\t": "Tab", ",": "Comma"}[sep]:
        raise HysidInputError(f"{path}: unsupported Separator line {sep_line.strip()!r} (Tab or Comma)")
    file_header = {}
    for line in lines[1:end]:
        cells = line.rstrip("\r").split(sep)
        file_header[cells[0].strip()] = cells[1].strip() if len(cells) > 1 else ""
    decimal = file_header.get("Decimal_Separator", ".")
    x_columns = file_header.get("X_Columns", "One")
    segments = _segments(path, lines, end + 1, sep)
    if not segments or not any(seg.lines for seg in segments):
        raise HysidInputError(f"{path}: no data rows after the headers")
    t_parts: list[np.ndarray] = []
    x_parts: list[np.ndarray] = []
    f_parts: list[np.ndarray] = []
    for seg in segments:
        if not seg.lines:
            continue
        names, cols = _channel_columns(path, seg, x_columns)
        i_x = _pick(path, names, config.displacement_channel, "displacement_channel", DISPLACEMENT_NAMES)
        i_f = _pick(path, names, config.force_channel, "force_channel", FORCE_NAMES)
        block = "\n".join(seg.lines)
        if decimal == "," and sep != ",":
            block = block.replace(",", ".")
        need = [cols[i_x], cols[i_f]] + ([0 if x_columns == "One" else cols[i_x] - 1] if x_columns in ("One", "Multi") else [])
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)
                data = np.loadtxt(io.StringIO(block), delimiter=sep, usecols=need, ndmin=2)
        except ValueError:
            raise HysidInputError(f"{path}: data rows from line {seg.first_line} are not numbers in the channel columns") from None
        t: np.ndarray
        if x_columns in ("One", "Multi"):
            t = data[:, 2]
        else:
            delta_text, start_text = _cell(seg, "Delta_X", i_x, x_columns), _cell(seg, "X0", i_x, x_columns)
            if delta_text:
                delta = _header_number(path, "Delta_X", delta_text, decimal)
                start = _header_number(path, "X0", start_text, decimal) if start_text else 0.0
            elif config.sample_rate_hz is not None:
                delta, start = 1.0 / config.sample_rate_hz, (t_parts[-1][-1] + 1.0 / config.sample_rate_hz if t_parts else 0.0)
            else:
                raise HysidInputError(f"{path}: no Delta_X for the channels and no X_Value column; set sample_rate_hz in dataset.toml")
            t = start + delta * np.arange(data.shape[0])
        x_scale = _unit_factor(path, config.displacement_unit, _cell(seg, "Y_Unit_Label", i_x, x_columns), DISPLACEMENT_UNITS, "displacement_unit")
        f_scale = _unit_factor(path, config.force_unit, _cell(seg, "Y_Unit_Label", i_f, x_columns), FORCE_UNITS, "force_unit")
        t_parts.append(t)
        x_parts.append(data[:, 0] * x_scale)
        f_parts.append(data[:, 1] * f_scale)
    return checked_series(
        str(path),
        np.concatenate(t_parts),
        np.concatenate(x_parts),
        np.concatenate(f_parts),
        names=("X_Value", "displacement", "force"),
        first_line=segments[0].first_line,
    )
