"""hysid's compiled kernels (numba), compiled at once into their cache beside the sources: ``python -m hysid.kernels``.

A kernel compiles on its first call for the types it is given (``cache=True``): about 30 s of CPU for the
Bouc-Wen orbits (Eq. 2.1b at n = 1 and any n), the sums of squares, the phases shifted by a channel delay
(Eq. 4.1-4.2), the steady band of a raw record and the record reader, where a process that finds them cached
loads them in well under a second. The thesis' model (closed form) uses none of them. ``scripts/venv.sh`` runs
this module once after installing the tests' extras, so that the test processes do not compile the same kernels
side by side. It runs the product's own paths on small inputs (models with memory and with friction beside a
channel delay on ideal and on distorted loops, the memory laws discovery proposes, the reader and the extraction
of raw records), so the kernels compile for the types those paths give them; a kernel that another path calls
with other types compiles there, on first use, as before.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from hysid.bench.objective import distorted_synth
from hysid_model import datasets
from hysid_model.discovery import memory
from hysid_model.model import build_model
from hysid_model.objective import Objective
from hysid_model.synth import MEQ_KG, synth_loops, synth_raw

MODELS = ("baseline+bouc_wen", "thesis+bouc_wen+channel_delay", "thesis+coulomb_friction+channel_delay")
"""A model with memory alone and beside a channel delay (the phases shifted per candidate), and friction beside one."""


def _models() -> None:
    """Each model's objective on ideal and on distorted loops, a memory model's for candidates at n = 1 (the closed
    form) and at another exponent (the tabulated orbit), one at a time and together; the exact orbit of the
    memory laws that discovery proposes."""
    for loops in (synth_loops(0.0, 0, 40).subset(np.arange(0, 120, 30)), distorted_synth().subset(np.arange(0, 120, 30))):
        for spec in MODELS:
            model = build_model(spec).fix(meq=MEQ_KG)
            model = model.vary("bw_n") if "bw_n" in model.fixed else model
            objective = Objective(loops, model)
            values = {"xi0": 0.01, "w0": 2 * np.pi * 30.0, "bw_k": 100.0, "bw_zy": 3e-4, "bw_r": 0.3, "delay_s": 1e-4, "F_d": 0.1}
            pop = np.array([[{**values, "bw_n": n}.get(name, 0.0) for name in model.names] for n in (1.0, 1.5)])
            for candidates in (pop, pop[:1], pop[1:]):
                objective(candidates)
    spans = np.array([1e-3, 2e-3])
    travel = np.linspace(0.0, 2.0 * spans[:, None], 8, axis=-1)[..., 0]
    memory.state(np.array([3e-4, 5e-4]), np.array([1.0, 1.5]), spans, travel, np.ones_like(travel))


def _raw_records(folder: Path) -> None:
    """Two raw records of the Synth set, 3 s each (over the 1 MB from which the compiled reader reads a file), written
    as a dataset and loaded back: the reader, the steady band and the extraction."""
    datasets.write_dataset(folder, synth_raw(0.0, 0, duration_s=3.0)[:2], name="kernels", meq_kg=MEQ_KG)
    datasets.load_dataset(folder)


def compile_kernels() -> None:
    """Call every compiled kernel on small inputs, which compiles it into its cache (or loads it from there)."""
    _models()
    with tempfile.TemporaryDirectory() as folder:
        _raw_records(Path(folder) / "records")


if __name__ == "__main__":
    compile_kernels()
