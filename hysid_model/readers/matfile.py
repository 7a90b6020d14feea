"""The thesis' per-loop ``.mat`` files (Appendix A, ``PrepareExpData``).

Each file (e.g. ``SAMPLE2_05mm_436Hz.mat``) holds one loop as ``HexpT`` and
``HexpB``, N x 2 arrays of (x in m, F in N). The excitation frequencies come,
in this order of precedence, from a ``manifest.csv`` (which also fixes the
order), from an ``ef`` vector file (``ef.mat``, ``efSample2.mat``: variable
``ef``, one entry per loop file in the order of the thesis' ``hysloopsnames``:
amplitude, then frequency) or from the file names (``_436Hz``). Where a name
also gives a frequency, the two must agree within 2 %. The ``05mm`` part of a
name is the nominal amplitude in tenths of a mm, kept in the metadata; X0
itself is the peak |x| of the centred loop (the thesis' ``Xpk``).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from hysid_model.errors import HysidInputError
from hysid_model.extraction import FREQ_TOLERANCE, loop_from_branches
from hysid_model.loops import LoopSet
from hysid_model.readers.dataset_dir import MANIFEST_NAME, DatasetConfig, ManifestRow, frequency_in_name, natural_key

AMPLITUDE_PATTERN = re.compile(r"_(\d+)mm_", re.IGNORECASE)


def parse_loop_name(stem: str) -> tuple[float | None, float | None]:
    """(nominal X0 in m, frequency in Hz) from a name like ``SAMPLE2_05mm_436Hz``, None where absent."""
    match = AMPLITUDE_PATTERN.search(stem)
    return (int(match.group(1)) * 1e-4 if match else None), frequency_in_name(stem)


def load_mat(path: Path) -> dict[str, np.ndarray]:
    """Variables of a MATLAB v4-v7.2 file; v7.3 (HDF5) and unreadable files are input errors."""
    if path.stat().st_size == 0:
        raise HysidInputError(f"{path}: the file is empty")
    import scipy.io  # on first use: a fast CLI and island start
    from scipy.io.matlab import MatReadError

    try:
        return {k: v for k, v in scipy.io.loadmat(path).items() if not k.startswith("__")}
    except NotImplementedError:
        raise HysidInputError(f"{path}: MATLAB v7.3 (HDF5) files are not supported; re-save in MATLAB with save(..., '-v7')") from None
    except (MatReadError, ValueError, TypeError, OSError) as exc:
        raise HysidInputError(f"{path}: not a readable MATLAB .mat file ({' '.join(str(exc).split())})") from None


def _real(path: Path, name: str, value: np.ndarray, what: str) -> np.ndarray:
    """A numeric variable as float; complex numbers are an error, not silently cast; ``what`` it must be."""
    if np.iscomplexobj(value):
        raise HysidInputError(f"{path}: {name} holds complex numbers; {what} must be real")
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise HysidInputError(f"{path}: {name} must be {what}") from None


def _ef_vector(path: Path, variables: dict[str, np.ndarray]) -> np.ndarray:
    ef = _real(path, "ef", variables["ef"], "a numeric vector of frequencies in Hz").reshape(-1)
    if ef.size == 0 or not np.all(np.isfinite(ef)) or np.any(ef <= 0):
        raise HysidInputError(f"{path}: ef must hold positive frequencies in Hz")
    return ef


def read_mat_dataset(files: list[Path], config: DatasetConfig, n_points: int, manifest: list[ManifestRow] | None = None) -> LoopSet:
    """Loops from ``.mat`` files, resampled on ``n_points`` per branch.

    With ``manifest`` (rows of ``manifest.csv``) ``files`` are the listed loop
    files in its order and frequencies; without, ``files`` may include one
    ``ef`` vector file and are ordered by the name convention.
    """
    directory = config.directory
    loops: dict[str, dict[str, np.ndarray]] = {}
    ef_files: list[tuple[Path, np.ndarray]] = []
    for path in files:
        variables = load_mat(path)
        if "HexpT" in variables and "HexpB" in variables:
            loops[path.name] = variables
        elif "ef" in variables and manifest is None:
            ef_files.append((path, _ef_vector(path, variables)))
        else:
            found = ", ".join(sorted(variables)) or "none"
            raise HysidInputError(f"{path}: no HexpT/HexpB loop in this .mat file (variables: {found})")
    if not loops:
        raise HysidInputError(f"{directory}: no .mat file holds a HexpT/HexpB loop")
    if len(ef_files) > 1:
        raise HysidInputError(f"{directory}: more than one ef vector file ({', '.join(p.name for p, _ in ef_files)}); keep one")
    if manifest is not None:
        names = [row.file for row in manifest]
        freq = np.array([row.frequency_hz for row in manifest])
        freq_source = str(directory / MANIFEST_NAME)
    else:
        parsed = {name: parse_loop_name(Path(name).stem) for name in loops}
        if all(amp is not None for amp, _ in parsed.values()):
            names = sorted(loops, key=lambda n: (parsed[n][0], parsed[n][1], n))
        else:
            names = sorted(loops, key=natural_key)
        if ef_files:
            ef_path, ef = ef_files[0]
            if ef.size != len(names):
                raise HysidInputError(f"{ef_path}: ef has {ef.size} frequencies for {len(names)} loop files in {directory}")
            freq, freq_source = ef, str(ef_path)
        else:
            missing = [n for n in names if parsed[n][1] is None]
            if missing:
                raise HysidInputError(
                    f"{directory / missing[0]}: no frequency: give an ef vector file (ef.mat), a {MANIFEST_NAME} or a name like SAMPLE2_05mm_436Hz"
                )
            freq = np.array([parsed[n][1] for n in names])
            freq_source = "file names"
    top, bottom, x0, nominal = [], [], [], []
    for name, f in zip(names, freq):
        amp, name_freq = parse_loop_name(Path(name).stem)
        if name_freq is not None and abs(f / name_freq - 1) > FREQ_TOLERANCE:
            raise HysidInputError(
                f"{directory / name}: the name says {name_freq:g} Hz but {freq_source} gives {f:g} Hz (more than {100 * FREQ_TOLERANCE:g} % apart)"
            )
        branches = [_real(directory / name, key, loops[name][key], "a numeric N x 2 array (x, F)") for key in ("HexpT", "HexpB")]
        a, t, b = loop_from_branches(branches[0], branches[1], n_points, str(directory / name))
        x0.append(a)
        top.append(t)
        bottom.append(b)
        nominal.append(np.nan if amp is None else amp)
    meta = config.meta()
    meta.update({"format": "thesis-mat", "frequency_source": freq_source, "per_loop": {"nominal_x0_m": nominal, "file": names}})
    return LoopSet(
        name=config.name,
        freq_hz=freq,
        x0=np.array(x0),
        top=np.array(top),
        bottom=np.array(bottom),
        sigma=np.full(len(names), np.nan),
        meq_kg=config.meq_kg,
        cycles=np.ones(len(names), dtype=int),
        labels=[Path(n).stem for n in names],
        meta=meta,
    )
