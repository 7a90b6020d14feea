"""One entry point from "a dataset" to a :class:`LoopSet`, and the dataset writer.

``load_dataset(spec)`` accepts:

* ``"synth"``: the thesis' Synth set (:func:`hysid_model.synth.synth_loops`);
* a dataset directory holding ``manifest.csv`` (``file,frequency_hz``) and one
  raw record per row (``.csv`` with ``time_s,displacement_m,force_n``,
  ``.lvm``, ``.tdms``, ``.h5``: :mod:`hysid_model.readers.records`),
  optionally ``dataset.toml``; loops are extracted with
  :func:`hysid_model.extraction.extract_loop`;
* a directory holding the tidy loops file ``loops.csv`` (what ``hysid synth``
  writes), or a tidy loops file itself; a ``dataset.toml`` next to it
  overrides the ``name``, ``meq_kg`` and ``bounds`` it sets;
* a directory of the thesis' ``.mat`` loop files (with ``ef.mat`` or a
  manifest), or one such file;
* a directory of raw records without a manifest (frequencies from the file
  names, else from the data: loops.meta["estimated_manifest"] is the
  manifest that would fix them), or one record file, or a tidy long CSV of
  several records (:mod:`hysid_model.readers.long_csv`).
"""

from __future__ import annotations

import json
import math
import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from hysid_model import notices, plausibility, slips
from hysid_model.errors import HysidInputError, HysidWarning
from hysid_model.extraction import ExtractedLoop, extract_loop
from hysid_model.loops import LoopSet
from hysid_model.readers.csv_series import write_series
from hysid_model.readers.dataset_dir import (
    MANIFEST_NAME,
    DatasetConfig,
    check_skip_rows,
    confined,
    frequency_in_name,
    inside,
    listed_file,
    read_config,
    read_manifest,
)
from hysid_model.readers.matfile import read_mat_dataset
from hysid_model.readers.records import (
    RAW_SUFFIXES,
    RawSource,
    check_records,
    directory_sources,
    load_compiled_reader,
    manifest_sources,
    manifest_text,
    sources_of_file,
)
from hysid_model.readers.tidy import is_tidy_file, read_loops, write_loops
from hysid_model.resolution import reversals_resolved
from hysid_model.synth import RawRecord, check_noise, synth_loops

TIDY_NAME = "loops.csv"
DEFAULT_POINTS = 100


def load_dataset(spec: str | Path, *, noise_pct: float = 0.0, noise_seed: int = 0, n_points: int | None = None, skip_rows: int | None = None) -> LoopSet:
    """Load the loops of ``spec`` (see the module docstring), with optional added noise.

    ``n_points`` samples per branch (default 100, the thesis' ``interppts``);
    a tidy loops file keeps its own and only checks it when one is given.
    ``skip_rows``: the lines before the header of every CSV record (a preamble of free text), as
    ``skip_rows`` in ``dataset.toml`` says (which it overrides); by default a preamble is found and skipped
    with a warning.
    ``noise_pct`` adds Gaussian force noise of std noise_pct % of each loop's
    peak force (the thesis' ``maxF*noiselevel/100*randn``, Appendix A) and
    raises ``sigma`` accordingly (an unknown sigma stays unknown).
    """
    if n_points is not None and (isinstance(n_points, bool) or not isinstance(n_points, int) or n_points < 2):
        raise HysidInputError("points per branch must be an integer >= 2", param="n_points", value=n_points)
    check_noise(noise_pct)
    if skip_rows is not None:
        check_skip_rows(skip_rows)
    if str(spec) == "synth":
        return synth_loops(noise_pct, noise_seed, n_points or DEFAULT_POINTS)
    path = Path(spec)
    if not path.exists():
        raise HysidInputError(f"{spec}: no such dataset (expected a dataset directory, a loops file, .mat/.lvm files or 'synth')")
    config = read_config(path if path.is_dir() else path.parent)
    if skip_rows is not None:
        config = replace(config, skip_rows=skip_rows)
    with notices.recorded() as raised:
        loops = _load_dir(path, config, n_points) if path.is_dir() else _load_file(path, config, n_points)
    loops.meta[notices.META_KEY] = notices.merged(notices.stored(loops.meta), raised)
    return add_noise(loops, noise_pct, noise_seed)


def add_noise(loops: LoopSet, noise_pct: float, seed: int) -> LoopSet:
    """Thesis noise (Appendix A): F + maxF * noise_pct/100 * randn on every branch sample."""
    check_noise(noise_pct)
    if noise_pct == 0:
        return loops
    rng = np.random.default_rng(seed)
    added = loops.peak_force * noise_pct / 100.0
    out = loops.subset(np.arange(loops.n_loops))
    out.top = out.top.copy()
    out.bottom = out.bottom.copy()
    out.top[:, :, 1] += added[:, None] * rng.standard_normal(out.top.shape[:2])
    out.bottom[:, :, 1] += added[:, None] * rng.standard_normal(out.bottom.shape[:2])
    out.sigma = np.hypot(loops.sigma, added)
    out.meta = dict(out.meta, added_noise_pct=noise_pct, added_noise_seed=seed)
    return out


def _tidy(path: Path, config: DatasetConfig, n_points: int | None) -> LoopSet:
    loops = read_loops(path)
    for notice in notices.stored(loops.meta):  # what its extraction warned is said again (and kept)
        warnings.warn(HysidWarning(notice["message"], notice["code"]), stacklevel=4)
    if n_points is not None and n_points != loops.n_samples:
        raise HysidInputError(f"{path}: holds {loops.n_samples} points per branch, not the {n_points} asked for (extract again from the raw records)")
    if "name" in config.given:
        loops.name = config.name
    if "meq_kg" in config.given:
        loops.meq_kg = config.meq_kg
    if "bounds" in config.given:
        loops.meta["bounds"] = dict(config.bounds)
    return loops


def _load_file(path: Path, config: DatasetConfig, n_points: int | None) -> LoopSet:
    suffix = path.suffix.lower()
    if is_tidy_file(path):
        return _tidy(path, config, n_points)
    if suffix == ".mat":
        return read_mat_dataset([path], config, n_points or DEFAULT_POINTS)
    if suffix in RAW_SUFFIXES:
        return extract_records(sources_of_file(path, config, frequency_in_name(path.stem)), config, n_points or DEFAULT_POINTS, f"raw-{suffix[1:]}")
    if suffix == ".json":
        raise HysidInputError(
            f"{path}: a JSON document is not a dataset (the loops.json of `hysid loops --out` is a survey of the loops; "
            f"the loops themselves are the {TIDY_NAME} beside it, or the raw records)"
        )
    raise HysidInputError(f"{path}: unknown dataset file type (expected a hysid loops file, .mat, or a raw record: {', '.join(RAW_SUFFIXES)})")


def _load_dir(directory: Path, config: DatasetConfig, n_points: int | None) -> LoopSet:
    manifest = directory / MANIFEST_NAME
    tidy = directory / TIDY_NAME
    if manifest.is_file() and tidy.is_file():
        raise HysidInputError(f"{directory}: holds both {MANIFEST_NAME} (raw records) and {TIDY_NAME} (extracted loops); keep one")
    if tidy.is_file():
        return _tidy(confined(directory, TIDY_NAME, str(directory)), config, n_points)
    n = n_points or DEFAULT_POINTS
    if manifest.is_file():
        rows = read_manifest(confined(directory, MANIFEST_NAME, str(directory)))
        files = [listed_file(manifest, row) for row in rows]
        suffixes = {f.suffix.lower() for f in files}
        if suffixes == {".mat"}:
            return read_mat_dataset(files, config, n, manifest=rows)
        if not suffixes <= set(RAW_SUFFIXES):
            raise HysidInputError(
                f"{manifest}: lists {', '.join(sorted(suffixes))} files; records must be all raw records ({', '.join(RAW_SUFFIXES)}) or all .mat"
            )
        unlisted = sorted(set(config.steady) - {row.file for row in rows})
        if unlisted:
            raise HysidInputError(f"{directory / 'dataset.toml'}: [[tests]] file {unlisted[0]!r} is not listed in {MANIFEST_NAME}")
        return extract_records(manifest_sources(manifest, rows, files, config), config, n, "raw-" + "+".join(s[1:] for s in sorted(suffixes)))
    mats = sorted(p for p in directory.iterdir() if p.suffix.lower() == ".mat" and p.is_file())
    if mats:
        outside = [p.name for p in mats if not inside(directory, p)]
        if outside:
            raise HysidInputError(f"{directory}: {outside[0]!r} links outside the dataset directory; copy the file in")
        return read_mat_dataset(mats, config, n)
    sources = directory_sources(directory, config)
    if sources:
        kinds = sorted({s.path.suffix.lower()[1:] for s in sources})
        return extract_records(sources, config, n, "raw-" + "+".join(kinds), estimate_manifest=True)
    raise HysidInputError(
        f"{directory}: no dataset here (expected {MANIFEST_NAME} with raw records, {TIDY_NAME}, .mat loop files, or raw records: {', '.join(RAW_SUFFIXES)})"
    )


def extract_records(sources: list[RawSource], config: DatasetConfig, n_points: int, fmt: str, estimate_manifest: bool = False) -> LoopSet:
    """Extract one loop per raw record (see :mod:`hysid_model.extraction`), reading one record at a time.

    With ``estimate_manifest`` (a directory without ``manifest.csv``) records whose frequency is known
    from neither a manifest nor their name get the data's; a warning says so, and ``meta`` keeps
    ``estimated_manifest``, the ``manifest.csv`` that would fix those frequencies.
    """
    check_records(sources, str(config.directory))
    load_compiled_reader(sources)
    extracted, read = [], []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", HysidWarning)
        for source in sources:
            series = source.read()
            read.append((series.channels[1:], series.units))
            extracted.append(
                extract_loop(
                    series.t,
                    series.x,
                    series.force,
                    source=series.source,
                    n_points=n_points,
                    nominal_freq_hz=source.nominal_hz,
                    steady_window=config.window(source.window_key),
                )
            )
            del series
    once_each(caught, len(sources))
    labels = [s.label for s in sources]
    per_loop: dict[str, list[Any]] = {
        "file": [s.file for s in sources],
        "nominal_frequency_hz": [math.nan if s.nominal_hz is None else s.nominal_hz for s in sources],
    }
    for key in extracted[0].meta():
        per_loop[key] = [e.meta()[key] for e in extracted]
    facts = plausibility.Measured(
        *(
            np.array([getattr(e, name) for e in extracted])
            for name in ("freq_hz", "x0", "force_amplitude", "phase_deg", "x_distortion", "force_distortion", "drift")
        )
    )
    plausibility.warn_loops(labels, facts, [e.clipping for e in extracted], str(config.directory))
    meta = config.meta()
    meta.update({"format": fmt, "per_loop": per_loop})
    loops = loop_set(config.name, extracted, labels, config.meq_kg, meta)
    estimated = [k for k, s in enumerate(sources) if s.nominal_hz is None]
    if estimate_manifest and estimated:
        files = [k for k, s in enumerate(sources) if s.whole_file]
        loops.meta["estimated_manifest"] = manifest_text([sources[k] for k in files], [sources[k].nominal_hz or extracted[k].freq_hz for k in files])
        found = ", ".join(f"{labels[k]} {extracted[k].freq_hz:.6g} Hz" for k in estimated)
        warnings.warn(
            HysidWarning(
                f"{config.directory}: no {MANIFEST_NAME}; frequencies estimated from the data: {found}"
                + (
                    f" (`hysid loops {config.directory}` prints the {MANIFEST_NAME} that fixes them; in Python it is loops.meta['estimated_manifest'])"
                    if files
                    else ""
                ),
                "estimated_frequencies",
            ),
            stacklevel=3,
        )
    for warning in slips.physics(loops, facts, str(config.directory), slips.Reading.common(read)):
        warnings.warn(warning, stacklevel=3)
    return loops


def loop_set(name: str, extracted: list[ExtractedLoop], labels: list[str], meq_kg: float | None, meta: dict[str, Any] | None = None) -> LoopSet:
    """The loop set of loops extracted from records, in their order: branches, noise, cycles and displacement
    harmonics stacked, ``meta`` (copied) with whether the reversals are resolved (``per_loop['reversals_resolved']``
    and ``reversals``, :func:`hysid_model.resolution.reversals_resolved`)."""
    meta = dict(meta or {})
    per_loop = dict(meta.get("per_loop", {}))
    resolved, reversals = reversals_resolved([e.reversal_steps for e in extracted if e.reversal_steps is not None])
    per_loop["reversals_resolved"] = [resolved] * len(extracted)
    meta.update({"per_loop": per_loop, "reversals": reversals})
    return LoopSet(
        name=name,
        freq_hz=np.array([e.freq_hz for e in extracted]),
        x0=np.array([e.x0 for e in extracted]),
        top=np.stack([e.top for e in extracted]),
        bottom=np.stack([e.bottom for e in extracted]),
        sigma=np.array([e.sigma for e in extracted]),
        meq_kg=meq_kg,
        cycles=np.array([e.cycles for e in extracted]),
        labels=labels,
        meta=meta,
        x_harmonics=stack_harmonics([e.x_harmonics for e in extracted]),
    )


def once_each(caught: list[warnings.WarningMessage], records: int) -> None:
    """Warn again what reading ``records`` records warned, each message once, with how many records said it
    (a header without units in 32 files is one warning, not 32)."""
    counts: dict[str, list[Any]] = {}
    for w in caught:
        if isinstance(w.message, HysidWarning):
            counts.setdefault(str(w.message), [w.message.code, 0])[1] += 1
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    for message, (code, count) in counts.items():
        warnings.warn(HysidWarning(message + (f" (in {count} of {records} records)" if count > 1 else ""), code), stacklevel=4)


def stack_harmonics(rows: list[np.ndarray]) -> np.ndarray:
    """Per-loop displacement harmonics of different lengths as one ``(L, K)`` array (missing orders 0)."""
    out = np.zeros((len(rows), max(r.size for r in rows)), dtype=complex)
    for j, r in enumerate(rows):
        out[j, : r.size] = r
    return out


def _toml_value(value: Any) -> str:
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return repr(float(value)) if math.isfinite(value) else ("nan" if math.isnan(value) else ("inf" if value > 0 else "-inf"))
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def _write_toml(path: Path, top: dict[str, Any], tables: dict[str, dict[str, Any]]) -> None:
    lines = [f"{key} = {_toml_value(value)}" for key, value in top.items() if value is not None]
    for name, table in tables.items():
        if table:
            lines += ["", f"[{name}]"] + [f"{key} = {_toml_value(value)}" for key, value in table.items()]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def _fresh_directory(out_dir: Path) -> None:
    if out_dir.exists() and (not out_dir.is_dir() or any(out_dir.iterdir())):
        raise HysidInputError(f"{out_dir}: already exists and is not an empty directory; choose a new one (nothing was written)")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise HysidInputError(f"{out_dir}: cannot create the directory ({exc.strerror})") from None


def write_dataset(
    out_dir: str | Path,
    data: LoopSet | list[RawRecord],
    *,
    name: str | None = None,
    meq_kg: float | None = None,
    bounds: dict[str, tuple[float, float]] | None = None,
    true_params: dict[str, float] | None = None,
    description: str | None = None,
) -> Path:
    """Write a dataset directory that :func:`load_dataset` reads back.

    A :class:`LoopSet` becomes ``loops.csv`` (tidy, exact round trip; its own
    name, mass and meta). Raw records become one ``<label>.csv`` each
    (``time_s,displacement_m,force_n``), ``manifest.csv`` and ``dataset.toml``
    (``name``, ``meq_kg``, ``sample_rate_hz``, ``[bounds]``, ``[true_params]``).
    The directory must be new or empty, so nothing stored is overwritten.
    """
    out = Path(out_dir)
    if isinstance(data, LoopSet):
        _fresh_directory(out)
        write_loops(data, out / TIDY_NAME)
        return out
    if not data:
        raise HysidInputError("write_dataset: no records to write")
    _fresh_directory(out)
    rows = ["file,frequency_hz"]
    for rec in data:
        filename = f"{rec.label}.csv"
        write_series(out / filename, rec.t, rec.x, rec.force)
        rows.append(f"{filename},{rec.freq_hz!r}")
    (out / MANIFEST_NAME).write_text("\n".join(rows) + "\n", encoding="utf-8")
    dt = np.diff(data[0].t)
    _write_toml(
        out / "dataset.toml",
        {
            "name": name or out.resolve().name,
            "meq_kg": 0.0 if meq_kg is None else float(meq_kg),
            "sample_rate_hz": float(1.0 / dt.mean()),
            "description": description,
        },
        {"bounds": {k: list(v) for k, v in (bounds or {}).items()}, "true_params": dict(true_params or {})},
    )
    return out
