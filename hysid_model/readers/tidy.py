"""The tidy loops file: extracted branches, written by hysid and read back exactly.

::

    # hysid-loops v1
    # name: synth-10pct-seed0
    # meq_kg: 0.04                      (or "unknown")
    # meta: {"bounds": {...}, ...}      (JSON; per-loop lists under "per_loop")
    # x_harmonics: [[[re, im], ...], ...]  (optional: each loop's measured displacement harmonics, m)
    loop,label,frequency_hz,x0_m,sigma_n,cycles,branch,displacement_m,force_n
    0,SYNTH_05mm_25Hz,25.0,0.0005,nan,0,top,-0.0005,-0.0123...

One row per branch sample: the n ``top`` rows of a loop, then its n ``bottom``
rows. Floats are written with ``repr`` (shortest round-trip form), so reading
gives back the same numbers bit for bit.
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.loops import LoopSet
from hysid_model.readers.dataset_dir import check_mass

MAGIC = "# hysid-loops v1"
COLUMNS = ("loop", "label", "frequency_hz", "x0_m", "sigma_n", "cycles", "branch", "displacement_m", "force_n")
LOOP_FIELDS = ("label", "frequency_hz", "x0_m", "sigma_n", "cycles")


def is_tidy_file(path: Path) -> bool:
    """True when the file starts with the ``# hysid-loops`` line."""
    try:
        with path.open(encoding="utf-8") as handle:
            return handle.readline().startswith("# hysid-loops")
    except (OSError, UnicodeDecodeError):
        return False


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"meta value of type {type(value).__name__} cannot be written to a loops file")


def write_loops(loops: LoopSet, path: Path) -> None:
    """Write ``loops`` as a tidy loops file (exact round trip with :func:`read_loops`)."""
    out = io.StringIO()
    out.write(f"{MAGIC}\n# name: {' '.join(loops.name.split())}\n")
    out.write(f"# meq_kg: {'unknown' if loops.meq_kg is None else repr(float(loops.meq_kg))}\n")
    out.write(f"# meta: {json.dumps(loops.meta, default=_jsonable, sort_keys=True)}\n")
    if loops.x_harmonics is not None:
        pairs = np.stack([loops.x_harmonics.real, loops.x_harmonics.imag], axis=-1)
        out.write(f"# x_harmonics: {json.dumps(pairs.tolist())}\n")
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(COLUMNS)
    for j in range(loops.n_loops):
        head = [j, loops.labels[j], repr(float(loops.freq_hz[j])), repr(float(loops.x0[j])), repr(float(loops.sigma[j])), int(loops.cycles[j])]
        for branch, data in (("top", loops.top[j]), ("bottom", loops.bottom[j])):
            for xv, fv in data:
                writer.writerow(head + [branch, repr(float(xv)), repr(float(fv))])
    Path(path).write_text(out.getvalue(), encoding="utf-8")


def _float(text: str, what: str, where: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise HysidInputError(f"{where}: {what} {text!r} is not a number") from None


def _int(text: str, what: str, where: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise HysidInputError(f"{where}: {what} {text!r} is not an integer") from None


def _harmonics(text: str | None, path: Path) -> np.ndarray | None:
    """The optional ``# x_harmonics:`` line as an (L, K) complex array."""
    if text is None:
        return None
    try:
        pairs = np.array(json.loads(text), dtype=float)
    except (json.JSONDecodeError, ValueError, TypeError, RecursionError):
        raise HysidInputError(f"{path}: the '# x_harmonics:' line must be a JSON array of [re, im] pairs per loop") from None
    if pairs.ndim != 3 or pairs.shape[2] != 2:
        raise HysidInputError(f"{path}: the '# x_harmonics:' line must be a JSON array of [re, im] pairs per loop")
    return pairs[..., 0] + 1j * pairs[..., 1]


def _header(lines: list[str], path: Path) -> tuple[str, float | None, dict[str, Any], np.ndarray | None, int]:
    fields: dict[str, str] = {}
    k = 1
    while k < len(lines) and lines[k].startswith("#"):
        key, _, value = lines[k][1:].partition(":")
        fields[key.strip()] = value.strip()
        k += 1
    for key in ("name", "meq_kg", "meta"):
        if key not in fields:
            raise HysidInputError(f"{path}: header line '# {key}: ...' missing")
    meq_text = fields["meq_kg"]
    meq = None if meq_text == "unknown" else _float(meq_text, "meq_kg", str(path))
    if meq is not None and not (math.isfinite(meq) and meq > 0):
        raise HysidInputError(f"{path}: meq_kg must be a positive mass or 'unknown', got {meq_text!r}")
    if meq is not None:
        check_mass(meq, str(path))
    try:
        meta = json.loads(fields["meta"])
    except json.JSONDecodeError as exc:
        raise HysidInputError(f"{path}: the '# meta:' line is not valid JSON ({exc.msg} at column {exc.colno})") from None
    except RecursionError:
        raise HysidInputError(f"{path}: the '# meta:' line nests too deeply to be hysid's metadata") from None
    if not isinstance(meta, dict):
        raise HysidInputError(f"{path}: the '# meta:' line must hold a JSON object")
    if isinstance(meta.get("bounds"), dict):
        meta["bounds"] = {name: tuple(pair) for name, pair in meta["bounds"].items()}
    return fields["name"], meq, meta, _harmonics(fields.get("x_harmonics"), path), k


def read_loops(path: Path) -> LoopSet:
    """Read a tidy loops file written by :func:`write_loops`."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise HysidInputError(f"{path}: not UTF-8 text") from None
    lines = text.splitlines()
    if not lines or not lines[0].startswith("# hysid-loops"):
        raise HysidInputError(f"{path}: not a hysid loops file (the first line must be '{MAGIC}')")
    if lines[0].strip() != MAGIC:
        raise HysidInputError(f"{path}: unsupported loops file version {lines[0][2:].strip()!r} (this hysid reads '{MAGIC[2:]}')")
    name, meq, meta, x_harmonics, k = _header(lines, path)
    rows = list(csv.reader(lines[k:]))
    if not rows or tuple(c.strip() for c in rows[0]) != COLUMNS:
        raise HysidInputError(f"{path}: line {k + 1}: expected the column header {','.join(COLUMNS)}")
    loops: dict[int, dict[str, Any]] = {}
    for offset, row in enumerate(rows[1:]):
        number = k + 2 + offset
        where = f"{path}: line {number}"
        if not row:
            continue
        if len(row) != len(COLUMNS):
            raise HysidInputError(f"{where}: {len(row)} values for the {len(COLUMNS)} columns")
        cell = dict(zip(COLUMNS, row))
        if cell["branch"] not in ("top", "bottom"):
            raise HysidInputError(f"{where}: branch must be 'top' or 'bottom', got {cell['branch']!r}")
        j = _int(cell["loop"], "loop", where)
        head = tuple(cell[f] for f in LOOP_FIELDS)
        entry = loops.get(j)
        if entry is None:
            entry = loops[j] = {
                "head": head,
                "line": number,
                "top": [],
                "bottom": [],
                "values": (
                    _float(cell["frequency_hz"], "frequency_hz", where),
                    _float(cell["x0_m"], "x0_m", where),
                    _float(cell["sigma_n"], "sigma_n", where),
                    _int(cell["cycles"], "cycles", where),
                ),
            }
        elif entry["head"] != head:
            raise HysidInputError(f"{where}: loop {j}'s {', '.join(LOOP_FIELDS)} differ from its first row (line {entry['line']})")
        entry[cell["branch"]].append((_float(cell["displacement_m"], "displacement_m", where), _float(cell["force_n"], "force_n", where)))
    if not loops:
        raise HysidInputError(f"{path}: holds no loops")
    order = sorted(loops)
    if order != list(range(len(order))):
        raise HysidInputError(f"{path}: loops must be numbered 0..{len(order) - 1}, found {order[:5]}...")
    sizes = {(len(loops[j]["top"]), len(loops[j]["bottom"])) for j in order}
    if len(sizes) != 1 or len(set(next(iter(sizes)))) != 1:
        raise HysidInputError(f"{path}: every loop needs the same number of top and bottom samples, found (top, bottom) sizes {sorted(sizes)}")
    values = np.array([loops[j]["values"] for j in order])
    return LoopSet(
        name=name,
        freq_hz=values[:, 0],
        x0=values[:, 1],
        top=np.array([loops[j]["top"] for j in order]),
        bottom=np.array([loops[j]["bottom"] for j in order]),
        sigma=values[:, 2],
        meq_kg=meq,
        cycles=values[:, 3].astype(int),
        labels=[loops[j]["head"][0] for j in order],
        meta=meta,
        x_harmonics=x_harmonics,
    )
