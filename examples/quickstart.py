"""hysid from Python in five steps: load, fit, look, diagnose, campaign.

    python examples/quickstart.py                 # the thesis' Synth set with 5 % noise
    python examples/quickstart.py path/to/dataset [out_dir]

Every result object reports itself: ``.params``, ``.stderr``, ``.summary()``,
``.to_dict()`` (the ``--json`` document), ``.write_report(dir)``, and a
Markdown view in Jupyter.
"""

import sys
import tempfile
from pathlib import Path

import hysid

dataset = sys.argv[1] if len(sys.argv) > 1 else "synth"
out = Path(sys.argv[2]) if len(sys.argv) > 2 else Path(tempfile.mkdtemp(prefix="hysid-quickstart-"))

# 1. Load: a dataset directory, a loops file, .mat/.lvm files, or the built-in Synth set.
loops = hysid.load(dataset, noise_pct=5.0 if dataset == "synth" else 0.0, noise_seed=1)
print(f"{loops.name}: {loops.n_loops} loops, {loops.freq_hz.min():g}-{loops.freq_hz.max():g} Hz")

# 2. Fit the thesis model (Eq. 4.8-4.10): a model is data, composed from terms,
#    with the known mass as a fixed parameter and bounds you choose.
model = hysid.models.thesis.with_bounds({"w0": (100.0, 300.0)})
result = hysid.fit(loops, model, algo="pso", options={"population": 100, "initial_population": 1000, "iterations": 10})

# 3. Look at it: numbers, text, a report with figures.
print(result.params["w0"], "+-", result.stderr["w0"], "rad/s")
print(result.summary())
print("report:", result.write_report(out / "fit"))

# 4. Diagnose: which effect of the library is the start model missing?
diagnosis = hysid.diagnose(loops, "baseline", cross_validate=False)
print(diagnosis.summary())

# 5. A small campaign: GA and PSO islands sharing their best (threads of this process here;
#    without single_node=True they are processes talking over Zenoh).
sizes = {"population": 30, "initial_population": 100, "iterations": 20}
campaign = hysid.campaign(loops, model, islands=2, single_node=True, options={"ga": sizes, "pso": sizes}, migration=hysid.Migration(interval=5, k=2))
print(campaign.summary())
print("report:", campaign.write_report(out / "campaign"))
